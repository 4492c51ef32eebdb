"""Every bad input refused at load with one message, nothing the user wrote lost (issue 29).

Each case runs ``warpdem COMMAND ...`` in this process through :func:`warpdem.cli.main` (the
command line's error boundary) and must give exit code 2, a message naming the key (or option,
or file), no traceback, and no DEM: building a simulation, running an experiment or building the
pump model fails the case. The table is in docs/bad_inputs.md.
"""
from __future__ import annotations

import copy
import json
import traceback
from pathlib import Path
from typing import Any, Callable

import pytest
import warp as wp
import yaml

import warpdem as wd
from warpdem.cli import main, run_command

ROOT = Path(__file__).resolve().parents[1]
LAB_TEXT = (ROOT / "validation/configs/tiny_lab.yaml").read_text()
DIAGNOSIS = yaml.safe_load((ROOT / "validation/configs/tiny_diagnosis.yaml").read_text())
CAMPAIGN = yaml.safe_load((ROOT / "calibration/configs/quick_calibration.yaml").read_text())
PUMP = yaml.safe_load((ROOT / "pump/configs/quick_pump.yaml").read_text())
EXPERIMENT = {"experiment": "baffle", "scale": "quick", "device": "cpu",
              "parameters": [{"mu_s_pp": 0.3, "mu_s_pw": 0.3, "mu_r_pp": 0.05, "mu_r_pw": 0.05}]}
NOT_UTF8 = b"name: caf\xe9\nparameters: {}\n"  # Latin-1, as an old editor saves it
no_cuda = pytest.mark.skipif(wp.is_cuda_available(), reason="needs a machine without a CUDA device")


def edited(base: dict, path: str, value: Any) -> dict:
    """``base`` with the dotted ``path`` set to ``value`` (list indices as numbers)."""
    doc = copy.deepcopy(base)
    *parents, last = path.split(".")
    node = doc
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node.setdefault(key, {})
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return doc


def put(name: str, doc: Any) -> str:
    """Write ``doc`` (mapping: YAML; str: text; bytes: raw) to ``name`` in the working folder."""
    p = Path(name)
    if isinstance(doc, bytes):
        p.write_bytes(doc)
    else:
        p.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc, sort_keys=False))
    return name


def lab(old: str = "", new: str = "", name: str = "lab.yaml") -> str:
    """The tiny lab's measurement file with ``old`` replaced by ``new``."""
    assert old in LAB_TEXT
    return put(name, LAB_TEXT.replace(old, new, 1))


def diag(**changes: Any) -> list[str]:
    """``diagnose CONFIG --prefetch`` of the tiny diagnosis with top-level ``changes`` (its
    measurement file: the tiny lab's, unless ``measurements`` is given)."""
    doc = {**DIAGNOSIS, "measurements": "tiny_lab.yaml", "output": "out", **changes}
    return ["diagnose", put("diagnosis.yaml", doc), "--prefetch"]


def diag_with_lab(old: str, new: str) -> list[str]:
    return diag(measurements=lab(old, new))


def into_out(doc: dict, base: dict) -> dict:
    """``doc`` writing into ``out`` of the case's folder, unless the case changed its output."""
    return {**doc, "output": "out"} if doc.get("output") == base.get("output") else doc


def camp(doc: dict, *extra: str) -> list[str]:
    return ["calibrate", put("campaign.yaml", into_out(doc, CAMPAIGN)), "--max-samples", "1", *extra]


def pump(doc: dict, *extra: str) -> list[str]:
    return ["pump", put("pump.yaml", into_out(doc, PUMP)), "--no-vtk", *extra]


def exp(doc: dict, *extra: str) -> list[str]:
    return ["experiment", put("experiment.yaml", into_out(doc, EXPERIMENT)), "--no-plots", *extra]


def cuda_case(name: str, argv_of: Callable[[], list[str]], words: list[str]):
    """A case that asks for CUDA: it runs on a machine without a CUDA device."""
    return pytest.param((name, argv_of, words), marks=no_cuda, id=name)


def a_file(name: str = "afile") -> str:
    return put(name, "not a folder\n")


DUPLICATE_TOP = "name: a\nname: b\n"
FOREIGN_RECORDS = '{"sample": 1, "value": 2.0}\n{"sample": 2, "value": 3.0}\n{"sample": 3, "va'

# (id, argv builder (runs in the case's folder), words the message must hold)
CASES: list[tuple[str, Callable[[], list[str]], list[str]]] = [
    # ---------------------------------------------------------------- warpdem diagnose
    cuda_case("diag-cuda-option", lambda: diag()[:2] + ["--device", "cuda"], ["--device", "no CUDA device"]),
    cuda_case("diag-cuda-config", lambda: diag(device="cuda"), ["device", "no CUDA device"]),
    ("diag-device-tpu-config", lambda: diag(device="tpu"), ["device", "tpu"]),
    ("diag-device-tpu-option", lambda: diag()[:2] + ["--device", "tpu"], ["--device", "tpu"]),
    ("diag-processes-text-option", lambda: diag() + ["--processes", "abc"], ["--processes", "abc"]),
    ("diag-processes-zero-option", lambda: diag() + ["--processes", "0"], ["--processes"]),
    ("diag-processes-text-config", lambda: diag(processes="many"), ["processes"]),
    ("diag-unknown-experiment-in-measurements", lambda: diag_with_lab("  baffle:", "  bafle:"), ["bafle", "lab.yaml"]),
    ("diag-unknown-setting-in-measurements", lambda: diag_with_lab("min_bins: 2", "min_bin: 2"), ["min_bin"]),
    ("diag-effect-ranges-unknown-parameter", lambda: diag(effect_ranges={"mu_zz": [0, 1]}),
     ["effect_ranges", "mu_zz"]),
    ("diag-fill-mass-true", lambda: diag_with_lab("fill_mass: 9.0", "fill_mass: true"), ["fill_mass", "True"]),
    ("diag-fill-mass-huge", lambda: diag_with_lab("fill_mass: 9.0", "fill_mass: 1.0e+6"),
     ["fill_mass", "MAX_PARTICLES_PER_WORLD"]),
    ("diag-fill-mass-yaml-text", lambda: diag_with_lab("fill_mass: 9.0", 'fill_mass: "9.0"'),
     ["fill_mass", "without quotes"]),
    ("diag-fill-mass-negative", lambda: diag_with_lab("fill_mass: 9.0", "fill_mass: -9.0"), ["fill_mass"]),
    ("diag-fill-mass-inf", lambda: diag_with_lab("fill_mass: 9.0", "fill_mass: .inf"), ["fill_mass"]),
    ("diag-output-is-a-file", lambda: diag(output=a_file()), ["output", "afile"]),
    ("diag-output-under-a-file", lambda: diag(output=a_file() + "/sub"), ["output", "afile"]),
    ("diag-output-option-is-a-file", lambda: diag() + ["--output", a_file()], ["--output", "afile"]),
    ("diag-duplicate-top-key", lambda: ["diagnose", put("d.yaml", DUPLICATE_TOP + yaml.safe_dump(
        {k: v for k, v in DIAGNOSIS.items() if k != "name"} | {"measurements": "tiny_lab.yaml"}))],
     ["name", "line 2", "d.yaml"]),
    ("diag-duplicate-parameter", lambda: ["diagnose", put("d.yaml", yaml.safe_dump(
        {k: v for k, v in DIAGNOSIS.items() if k != "parameters"} | {"measurements": "tiny_lab.yaml"})
        + "parameters:\n  mu_s_pp: [0.1, 0.9]\n  mu_s_pp: [0.2, 0.8]\n")], ["mu_s_pp", "given twice"]),
    ("diag-duplicate-observable-in-measurements",
     lambda: diag_with_lab("          bulk_density:", "          static_angle:"), ["static_angle", "lab.yaml"]),
    ("diag-duplicate-condition-in-measurements", lambda: diag(measurements=put(
        "lab.yaml", LAB_TEXT + "      9kg: {}\n")), ["9kg", "lab.yaml", "given twice"]),
    ("diag-cache-is-the-measurement-file", lambda: diag(cache="tiny_lab.yaml"), ["cache", "tiny_lab.yaml"]),
    ("diag-cache-is-the-config", lambda: diag(cache="diagnosis.yaml"), ["cache", "diagnosis.yaml"]),
    ("diag-cache-is-a-folder", lambda: (Path("somewhere").mkdir(), diag(cache="somewhere"))[1],
     ["cache", "somewhere"]),
    ("diag-cache-is-other-records", lambda: diag(cache=put("other.jsonl", FOREIGN_RECORDS)), ["cache", "other.jsonl"]),
    ("diag-cache-under-a-file", lambda: diag(cache=a_file() + "/dem.jsonl"), ["cache", "afile"]),
    ("diag-output-cannot-be-created", lambda: diag(output="/proc/warpdem-test/out"), ["output", "cannot create"]),
    ("diag-cache-is-binary", lambda: diag(cache=put("blob.bin", bytes(range(256)))), ["cache", "blob.bin"]),
    ("diag-config-not-utf8", lambda: ["diagnose", put("d.yaml", NOT_UTF8)], ["d.yaml", "UTF-8"]),
    ("diag-measurements-not-utf8", lambda: diag(measurements=put("lab.yaml", NOT_UTF8)), ["lab.yaml", "UTF-8"]),
    ("diag-replicates-text", lambda: diag(diagnosis={"replicates": "two"}), ["diagnosis.replicates"]),
    ("diag-unknown-top-key", lambda: diag(candidate=["rolling_resistance"]), ["candidate"]),
    ("diag-unknown-scale", lambda: diag(scale="huge"), ["scale", "huge"]),
    ("diag-unknown-parameter", lambda: diag(parameters={"mu_s_p": [0.1, 0.9]}), ["mu_s_p"]),
    # ---------------------------------------------------------------- warpdem experiment
    cuda_case("exp-cuda-option", lambda: exp(EXPERIMENT, "--device", "cuda"), ["--device", "no CUDA device"]),
    cuda_case("exp-cuda-config", lambda: exp({**EXPERIMENT, "device": "cuda"}), ["device", "no CUDA device"]),
    ("exp-device-tpu-config", lambda: exp({**EXPERIMENT, "device": "tpu"}), ["device", "tpu"]),
    ("exp-processes-text-option", lambda: exp(EXPERIMENT, "--processes", "abc"), ["--processes", "abc"]),
    ("exp-processes-text-config", lambda: exp({**EXPERIMENT, "processes": "many"}), ["processes", "many"]),
    ("exp-output-is-a-file", lambda: exp({**EXPERIMENT, "output": a_file()}), ["output", "afile"]),
    ("exp-output-option-under-a-file", lambda: exp(EXPERIMENT, "--output", a_file() + "/x"), ["--output", "afile"]),
    ("exp-duplicate-key", lambda: ["experiment", put("e.yaml", "experiment: baffle\n" + yaml.safe_dump(EXPERIMENT))],
     ["experiment", "line", "given twice"]),
    ("exp-duplicate-key-json", lambda: ["experiment", put("e.json", '{"experiment": "baffle", "experiment": "drum"}')],
     ["experiment", "e.json", "given twice"]),
    ("exp-fill-mass-true", lambda: exp({**EXPERIMENT, "settings": {"fill_mass": True}}), ["fill_mass"]),
    ("exp-fill-mass-huge", lambda: exp({**EXPERIMENT, "settings": {"fill_mass": 1.0e6}}),
     ["fill_mass", "MAX_PARTICLES_PER_WORLD"]),
    ("exp-config-not-utf8", lambda: ["experiment", put("e.yaml", NOT_UTF8)], ["e.yaml", "UTF-8"]),
    ("exp-lift-speed-text", lambda: exp({**EXPERIMENT, "settings": {"lift_speed": "fast"}}), ["lift_speed"]),
    # ---------------------------------------------------------------- warpdem calibrate
    cuda_case("cal-cuda-option", lambda: camp(CAMPAIGN, "--device", "cuda"), ["--device", "no CUDA device"]),
    cuda_case("cal-cuda-config", lambda: camp({**CAMPAIGN, "device": "cuda"}), ["device", "no CUDA device"]),
    ("cal-device-tpu", lambda: camp({**CAMPAIGN, "device": "tpu"}), ["device", "tpu"]),
    ("cal-dem-at-missing-parameter", lambda: camp(edited(CAMPAIGN, "responses.0.target.dem_at", {"mu_s_pp": 0.45})),
     ["dem_at", "mu_s_pw"]),
    ("cal-tolerance-length", lambda: camp(edited(CAMPAIGN, "optimisation.tolerance_deg", [1.0, 1.0, 1.0])),
     ["tolerance_deg", "3 value(s) for 2 response(s)"]),
    ("cal-negative-rpm", lambda: camp(edited(CAMPAIGN, "responses.1.settings", {"rpm": -30})), ["rpm"]),
    ("cal-batch-worlds-text", lambda: camp({**CAMPAIGN, "batch_worlds": "many"}), ["batch_worlds", "many"]),
    ("cal-batch-worlds-fraction", lambda: camp({**CAMPAIGN, "batch_worlds": 2.5}), ["batch_worlds"]),
    ("cal-replicates-text", lambda: camp(edited(CAMPAIGN, "responses.0.replicates", "two")),
     ["responses[0]", "replicates"]),
    ("cal-replicates-true", lambda: camp(edited(CAMPAIGN, "responses.0.replicates", True)), ["replicates"]),
    ("cal-duplicate-parameter", lambda: ["calibrate", put("c.yaml", yaml.safe_dump(
        {k: v for k, v in CAMPAIGN.items() if k != "parameters"})
        + "parameters:\n  mu_s_pp: [0.15, 0.75]\n  mu_s_pp: [0.2, 0.7]\n")], ["mu_s_pp", "given twice"]),
    ("cal-duplicate-response-name", lambda: camp(edited(CAMPAIGN, "validation.name", "alpha_static")),
     ["alpha_static", "twice"]),
    ("cal-validation-experiment-typo", lambda: camp(edited(CAMPAIGN, "validation.experiment", "cylindre")),
     ["cylindre", "gamma_cylinder"]),
    ("cal-response-setting-typo", lambda: camp(edited(CAMPAIGN, "responses.1.settings", {"rmp": 30})),
     ["rmp", "beta_dynamic"]),
    ("cal-response-fill-huge", lambda: camp(edited(CAMPAIGN, "responses.0.settings", {"fill_mass": 1.0e6})),
     ["fill_mass", "MAX_PARTICLES_PER_WORLD"]),
    ("cal-response-fill-true", lambda: camp(edited(CAMPAIGN, "responses.0.settings", {"fill_mass": True})),
     ["fill_mass"]),
    ("cal-out-option-is-a-file", lambda: camp(CAMPAIGN, "--out", a_file()), ["--out", "afile"]),
    ("cal-output-is-a-file", lambda: camp({**CAMPAIGN, "output": a_file()}), ["output", "afile"]),
    ("cal-config-not-utf8", lambda: ["calibrate", put("c.yaml", NOT_UTF8)], ["c.yaml", "UTF-8"]),
    ("cal-foreign-samples-file", lambda: (Path("out").mkdir(), put("out/samples.jsonl", FOREIGN_RECORDS),
                                          camp(CAMPAIGN))[2], ["samples.jsonl", "--out"]),
    ("cal-binary-runs-file", lambda: (Path("out").mkdir(), put("out/runs.jsonl", bytes(range(256))),
                                      camp(CAMPAIGN))[2], ["runs.jsonl", "--out"]),
    # ---------------------------------------------------------------- warpdem pump
    cuda_case("pump-cuda-option", lambda: pump(PUMP, "--device", "cuda"), ["--device", "no CUDA device"]),
    ("pump-device-tpu", lambda: pump({**PUMP, "device": "tpu"}), ["device", "tpu"]),
    ("pump-revolutions-inf", lambda: pump(edited(PUMP, "run.revolutions", float("inf"))), ["run.revolutions"]),
    ("pump-revolutions-nan", lambda: pump(edited(PUMP, "run.revolutions", float("nan"))), ["run.revolutions"]),
    ("pump-revolutions-option-zero", lambda: pump(PUMP, "--revolutions", "0"), ["run.revolutions", "0"]),
    ("pump-worlds-option-zero", lambda: pump(PUMP, "--worlds", "0"), ["run.worlds"]),
    ("pump-dt-tiny", lambda: pump(edited(PUMP, "run.dt", 1e-12)), ["run.dt", "MAX_STEPS"]),
    ("pump-dt-text", lambda: pump(edited(PUMP, "run.dt", "small")), ["run.dt"]),
    ("pump-record-every-inf", lambda: pump(edited(PUMP, "run.record_every", float("inf"))), ["run.record_every"]),
    ("pump-output-is-a-file", lambda: pump({**PUMP, "output": a_file()}), ["output", "afile"]),
    ("pump-output-option-under-a-file", lambda: pump(PUMP, "--output", a_file() + "/x"), ["--output", "afile"]),
    ("pump-duplicate-section", lambda: ["pump", put("p.yaml", "run: {dt: 1.0e-5}\n" + yaml.safe_dump(PUMP))],
     ["run", "given twice"]),
    ("pump-config-not-utf8", lambda: ["pump", put("p.yaml", NOT_UTF8)], ["p.yaml", "UTF-8"]),
    # ---------------------------------------------------------------- warpdem measure
    ("measure-json-into-missing-folder", lambda: ["measure", "--file", put("m.yaml", LAB_TEXT), "--json", "no/x.json"],
     ["--json", "no"]),
    ("measure-json-is-a-folder", lambda: (Path("f").mkdir(), ["measure", "--file", put("m.yaml", LAB_TEXT),
                                                              "--json", "f"])[1], ["--json", "folder"]),
    ("measure-file-not-utf8", lambda: ["measure", "--file", put("m.yaml", NOT_UTF8)], ["m.yaml", "UTF-8"]),
    ("measure-file-duplicate-observable", lambda: ["measure", "--file", lab("          bulk_density:",
                                                                            "          static_angle:")],
     ["static_angle", "given twice"]),
    ("measure-file-duplicate-key-json", lambda: ["measure", "--file", put("m.json", '{"format": 1, "format": 2}')],
     ["format", "m.json"]),
    # ---------------------------------------------------------------- warpdem pour / bench
    cuda_case("pour-cuda-option", lambda: ["pour", "--device", "cuda"], ["--device", "no CUDA device"]),
    ("pour-device-tpu", lambda: ["pour", "--device", "tpu"], ["--device", "tpu"]),
    ("pour-spheres-zero", lambda: ["pour", "--spheres", "0"], ["--spheres"]),
    ("pour-out-is-a-file", lambda: ["pour", "--out", a_file()], ["--out", "afile"]),
    cuda_case("bench-cuda-option", lambda: ["bench", "--device", "cuda"], ["--device", "no CUDA device"]),
    ("bench-device-tpu", lambda: ["bench", "--device", "tpu"], ["--device", "tpu"]),
    ("bench-worlds-zero", lambda: ["bench", "--worlds", "0"], ["--worlds"]),
    ("bench-spheres-text", lambda: ["bench", "--spheres", "many"], ["--spheres", "many"]),
    # ---------------------------------------------------------------- warpdem
    ("unknown-command", lambda: ["diagnoze"], ["diagnoze"]),
]


def _case_id(case) -> str:
    return case.values[0][0] if hasattr(case, "values") else case[0]


@pytest.fixture
def no_dem(monkeypatch):
    """Any simulation, experiment run or pump model built fails the case: a refusal at load spends no DEM."""
    import calibration.experiments.common as common
    import pump.run

    def dem(*args, **kwargs):
        raise AssertionError("DEM work started: the input was not refused at load")

    monkeypatch.setattr(wd.Simulation, "__init__", dem)
    monkeypatch.setattr(common.Experiment, "run", dem)
    monkeypatch.setattr(pump.run, "build_case", dem)


@pytest.mark.parametrize("case", CASES, ids=[_case_id(c) for c in CASES])
def test_a_bad_input_is_refused_at_load_with_one_message(case, tmp_path, monkeypatch, capsys, no_dem):
    name, argv_of, words = case
    monkeypatch.chdir(tmp_path)
    put("tiny_lab.yaml", LAB_TEXT)
    try:
        rc = main(argv_of())
    except BaseException:  # noqa: BLE001 - the boundary must catch everything
        pytest.fail(f"{name}: an exception left warpdem.cli.main:\n{traceback.format_exc()}")
    out, err = capsys.readouterr()
    assert rc == 2, f"{name}: exit code {rc}\n{err}"
    assert "Traceback" not in err + out, err
    for word in words:
        assert word in err, f"{name}: the message does not name {word!r}:\n{err}"


def test_there_are_many_distinct_cases():
    assert len({_case_id(c) for c in CASES}) == len(CASES) >= 80


# ------------------------------------------------------------------------ nothing the user wrote is lost
FOREIGN_FILES = {
    "measurement file": LAB_TEXT,
    "diagnosis config": yaml.safe_dump(DIAGNOSIS),
    "one-line JSON config": json.dumps(EXPERIMENT),
    "pretty JSON": json.dumps(EXPERIMENT, indent=2),
    "JSON lines of other records, the last torn": FOREIGN_RECORDS,
    "binary": bytes(range(256)) * 4,
    "a forged header": '{"warpdem_records": "warpdem-dem-cache", "created": "x", "fingerprint": "0"}\n{"a": 1}\n{"b',
    "cache records then a foreign one": '{"id": "a", "experiment": "baffle", "status": "ok", "parameters": {}}\n'
                                        '{"sample": 1}\n',
}


@pytest.mark.parametrize("kind", list(FOREIGN_FILES))
def test_the_dem_cache_never_changes_a_file_that_is_not_a_cache(kind, tmp_path):
    from calibration.model_description import ModelDescription
    from validation.dem_forward import DEMForwardModel

    content = FOREIGN_FILES[kind]
    path = tmp_path / "users_file.yaml"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    before = path.read_bytes()
    with pytest.raises(wd.ConfigError, match=r"cache: .*users_file.yaml is not a DEM cache.*left untouched"):
        DEMForwardModel(ModelDescription(wd.ContactLaw()), None, (), (), cache=path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["users_file.yaml"]  # no .torn, no temporary file


def test_diagnose_with_the_measurement_file_as_cache_leaves_it_byte_identical(tmp_path, monkeypatch, capsys, no_dem):
    monkeypatch.chdir(tmp_path)
    put("tiny_lab.yaml", LAB_TEXT)
    config = put("diagnosis.yaml", {**DIAGNOSIS, "measurements": "tiny_lab.yaml", "cache": "tiny_lab.yaml"})
    before = {p: Path(p).read_bytes() for p in ("tiny_lab.yaml", config)}
    assert main(["diagnose", config, "--prefetch"]) == 2
    assert "torn" not in capsys.readouterr().err
    assert {p: Path(p).read_bytes() for p in before} == before
    put("diagnosis.yaml", {**DIAGNOSIS, "measurements": "tiny_lab.yaml", "cache": "diagnosis.yaml"})
    before = {p: Path(p).read_bytes() for p in ("tiny_lab.yaml", config)}
    assert main(["diagnose", config, "--prefetch"]) == 2
    assert {p: Path(p).read_bytes() for p in before} == before


def test_a_campaign_never_changes_a_record_file_it_did_not_write(tmp_path, capsys, no_dem):
    """A foreign samples.jsonl in the output folder (its last line not JSON) is refused as it is."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "samples.jsonl").write_text(FOREIGN_RECORDS)
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({**CAMPAIGN, "output": str(out)}))
    assert main(["calibrate", str(config), "--max-samples", "1"]) == 2
    assert "samples.jsonl" in capsys.readouterr().err
    assert (out / "samples.jsonl").read_text() == FOREIGN_RECORDS
    assert sorted(p.name for p in out.iterdir()) == ["samples.jsonl"]


def test_a_new_cache_starts_with_its_header_and_proves_itself(tmp_path):
    from warpdem.record_files import NotARecordFile, RecordFile, is_header

    rf = RecordFile(tmp_path / "c.jsonl", "test-records", lambda r: "id" in r, key="cache", what="test cache")
    rf.read()
    rf.append([{"id": 1}])
    rf.append([{"id": 2}, {"id": 3}])
    lines = (tmp_path / "c.jsonl").read_text().splitlines()
    assert len(lines) == 4 and is_header(json.loads(lines[0]), "test-records")
    assert [r["id"] for _, r in rf.read().records] == [1, 2, 3]
    other = RecordFile(tmp_path / "c.jsonl", "other-records", lambda r: "id" in r, key="cache", what="other cache")
    with pytest.raises(NotARecordFile, match="line 1 is not a other cache record"):  # another kind's header
        other.read()


# ------------------------------------------------------------------------ the loader and the boundary
def test_a_repeated_key_is_named_with_its_line_and_merge_keys_still_work():
    from warpdem.config_io import DuplicateKeyError, parse_yaml

    with pytest.raises(DuplicateKeyError, match=r"f.yaml: line 4: key 'rpm' is given twice .*first on line 3"):
        parse_yaml("a: 1\nb:\n  rpm: 15\n  rpm: 30\n", "f.yaml")
    assert parse_yaml("base: &b {x: 1, y: 2}\nuse:\n  <<: *b\n  y: 3\n", "f.yaml")["use"] == {"x": 1, "y": 3}
    assert parse_yaml("- {a: 1}\n- {a: 2}\n", "f.yaml") == [{"a": 1}, {"a": 2}]  # the same key in two mappings


def test_the_boundary_gives_2_for_a_mistake_and_a_traceback_only_for_a_bug(capsys, monkeypatch):
    def mistake(_):
        raise wd.ConfigError("cfg.yaml: run.dt must be > 0")

    def missing(_):
        open("/nonexistent-folder/x.json", "w")

    def bug(_):
        raise ZeroDivisionError("division by zero")

    def interrupted(_):
        raise KeyboardInterrupt

    assert run_command("x", mistake, []) == 2
    err = capsys.readouterr().err
    assert err == "warpdem x: cfg.yaml: run.dt must be > 0\n"
    assert run_command("x", missing, []) == 2
    assert "/nonexistent-folder/x.json" in capsys.readouterr().err
    assert run_command("x", bug, []) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "ZeroDivisionError" in err and "a bug in warpdem" in err
    assert run_command("x", interrupted, []) == 130
    monkeypatch.setenv("WARPDEM_TRACEBACK", "1")
    assert run_command("x", mistake, []) == 2
    assert "Traceback" in capsys.readouterr().err


def test_write_atomic_leaves_the_old_file_or_the_new_one(tmp_path):
    from warpdem.config_io import write_atomic

    path = tmp_path / "r.json"
    write_atomic(path, "{}\n")
    write_atomic(path, b'{"a": 1}\n')
    assert path.read_text() == '{"a": 1}\n' and sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]
    with pytest.raises(FileNotFoundError):
        write_atomic(tmp_path / "missing" / "x.json", "{}")


def test_an_output_folder_that_cannot_be_written_is_refused(tmp_path, monkeypatch):
    import tempfile

    from warpdem.config_io import check_output_folder

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", denied)
    with pytest.raises(wd.ConfigError, match=r"--out: the output folder .*out is not writable \(Permission denied\)"):
        check_output_folder(tmp_path / "out", "--out")
