"""Pinned digests and JSON bytes from fixed inputs (issue 30, item 3: one provenance module, one
JSON helper). Moving the helpers must not change a DEM-cache world id, a campaign fingerprint or
a record-file header, or the DEM caches under docs/results and the campaigns already written
would no longer be found; nor the bytes of a results file."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from calibration.campaign_records import fingerprint
from warpdem.record_files import _header_fingerprint, header_line, is_header


def test_dem_cache_world_ids_are_pinned():
    from validation.dem_forward import DEMForwardModel, _fingerprint

    obj = {"b": [1, 2.5, (3, "x")], "a": {"z": None, "p": Path("/tmp/q")}, "n": float("nan")}
    assert _fingerprint(obj) == "408c96676babb095b53a"
    world_id = DEMForwardModel._world_id  # uses no state of the forward model
    assert world_id(None, "abc123", "def456", {"mu_r": 0.1, "e": 0.5000000000001}, 2, None) == "6821ad7c7a9b7f802e8d"
    assert world_id(None, "abc123", "def456", {"mu_r": 0.1}, 0, 30.0) == "6773080c34bb52310eb7"


def test_campaign_fingerprint_is_pinned():
    determined_by = {
        "setup": {"format": 2, "experiment": {"name": "drum", "settings": {"rpm": 30, "fill": (1, 2)}},
                  "code": {"warpdem": "0.1", "source_sha256": "0123456789abcdef", "files": 3}},
        "point": {"parameters": {"mu_s": np.float64(0.3), "n": np.int64(4), "arr": np.array([1.0, 2.0])},
                  "fills": [0, 1], "bad": float("inf")}}
    assert fingerprint(determined_by) == "eeef5ee3cd04737eef54"


def test_record_file_header_fingerprint_is_pinned():
    assert _header_fingerprint("dem_cache", "2026-11-28T06:00:00") == "ef95f69b80f2fc131fd4"
    assert is_header(json.loads(header_line("dem_cache")), "dem_cache")


PUMP_BYTES = ('{\n "a": 0.10000000149011612,\n "b": [\n  3,\n  [\n   1.5,\n   null\n  ]\n ],\n "c": {\n  "d": '
              '[\n   [\n    1.0,\n    null\n   ],\n   [\n    2.0,\n    3.0\n   ]\n  ],\n  "p": "x/y"\n },\n '
              '"e": true,\n "f": null,\n "1": "int key"\n}')


def test_pump_results_json_bytes_are_pinned(tmp_path):
    from pump.outputs import save_json

    data = {"a": np.float32(0.1), "b": [np.int64(3), (1.5, float("nan"))],
            "c": {"d": np.array([[1.0, np.inf], [2, 3]]), "p": Path("x/y")}, "e": True, "f": None, 1: "int key"}
    save_json(tmp_path / "r.json", data)
    assert (tmp_path / "r.json").read_text() == PUMP_BYTES


def test_diagnosis_jsonable_is_pinned():
    from validation.diagnose import _jsonable

    data = {"a": np.float32(0.1), "b": [np.int64(3), (1.5, float("nan"))], "e": np.bool_(True), "f": None,
            1: "int key", "c": {"d": np.array([[1.0, np.inf], [2, 3]])}}
    assert json.dumps(_jsonable(data)) == ('{"a": 0.10000000149011612, "b": [3, [1.5, null]], "e": true, "f": null, '
                                           '"1": "int key", "c": {"d": [[1.0, null], [2.0, 3.0]]}}')


def test_json_default_hook_is_pinned():
    from warpdem.json_io import json_default

    data = {"a": np.float32(0.1), "b": np.array([1, 2]), "t": (1, 2), "n": float("nan"), "k": np.bool_(True)}
    assert json.dumps(data, indent=2, default=json_default) == (
        '{\n  "a": 0.10000000149011612,\n  "b": [\n    1,\n    2\n  ],\n  "t": [\n    1,\n    2\n  ],\n'
        '  "n": NaN,\n  "k": true\n}')


def test_helper_modules_leave_the_code_version_alone():
    """The JSON and digest helpers cannot change a DEM angle: they are not part of the source hash
    that tells a cached world's code (an edit to them must not orphan the DEM caches)."""
    from calibration.campaign_records import SOURCES_LEFT_OUT

    assert {"warpdem/json_io.py", "warpdem/provenance.py"} <= SOURCES_LEFT_OUT
