"""A diagnosis's DEM cache never serves a world that other engine or experiment code made: every
record carries the code version (``calibration.campaign_records.code_version``), a record of
another version (or of none, written before versions were recorded) is left in the file, named on
the screen and run again; ``cache_code_version: any`` reuses such records on purpose."""
import json

import pytest

import warpdem as wd
from calibration.campaign_records import code_version
from calibration.model_description import ModelDescription
from validation.config import DiagnosisConfig
from validation.dem_forward import DEMForwardModel
from warpdem import ConfigError


def record(wid: str, code: str | None, angle: float = 30.0) -> dict:
    rec = {"id": wid, "experiment": "baffle", "status": "ok", "parameters": {"mu_s_pp": 0.5}, "replicate": 0,
           "rpm": None, "observables": {"static_angle": angle}}
    if code is not None:
        rec["code"] = code
    return rec


def forward(cache, **kw) -> DEMForwardModel:
    return DEMForwardModel(ModelDescription(wd.ContactLaw()), None, (), (), cache=cache, **kw)


def test_records_carry_this_codes_version(tmp_path):
    cache = tmp_path / "dem_cache.jsonl"
    forward(cache)._store(record("a", None))
    stored = json.loads(cache.read_text().splitlines()[1])
    assert stored["code"] == code_version()["source_sha256"]
    assert set(forward(cache)._cache) == {"a"}


def test_worlds_of_other_code_are_not_served_but_kept_and_named(tmp_path, capsys):
    cache = tmp_path / "dem_cache.jsonl"
    forward(cache)._store(record("mine", None))
    with open(cache, "a") as fh:
        fh.write(json.dumps(record("theirs", "0123456789abcdef")) + "\n")
        fh.write(json.dumps(record("old", None)) + "\n")
    before = cache.read_text()
    fm = forward(cache)
    assert set(fm._cache) == {"mine"} and fm.cache_other_code == 2
    err = capsys.readouterr().err
    assert "2 cached world(s) were made by other engine or experiment code" in err
    assert "0123456789abcdef" in err and "unrecorded" in err and "cache_code_version: any" in err
    assert cache.read_text() == before  # nothing cut from the file
    assert set(forward(cache, cache_code_version="any")._cache) == {"mine", "theirs", "old"}


def test_a_world_run_again_under_this_code_wins_over_its_stale_record(tmp_path):
    cache = tmp_path / "dem_cache.jsonl"
    fm = forward(cache)
    with open(cache, "a") as fh:
        fh.write(json.dumps(record("w", "0123456789abcdef", angle=20.0)) + "\n")
    fm._store(record("w", None, angle=25.0))  # the same world, run again by this code
    for mode in ("match", "any"):
        assert forward(cache, cache_code_version=mode)._cache["w"]["observables"]["static_angle"] == 25.0


def test_the_setting_is_checked():
    with pytest.raises(ConfigError, match="cache_code_version"):
        forward(None, cache_code_version="sometimes")
    with pytest.raises(Exception, match="cache_code_version"):
        DiagnosisConfig.model_validate({"measurements": "m.yaml", "parameters": {"mu_s_pp": [0.1, 0.9]},
                                        "cache_code_version": "sometimes"})
