"""Campaign records that cannot be silently reused (issue 12): every record carries a fingerprint
of what determines it; a resume with another contact law, material, experiment setting, fixed
parameter or code version is refused naming the difference; an identical re-run repeats no DEM
run (design, targets, confirmation, validation); a torn last line is reported and re-run; the
wall time is summed over sittings. The DEM is a counting stub (the records are what is tested)."""
import json

import pytest
import yaml

import calibration.campaign as cp
import calibration.campaign_records as cr
from warpdem import ConfigError

BASE = {
    "name": "fp", "device": "cpu",
    "parameters": {"mu_s_pp": [0.1, 0.8], "mu_s_pw": [0.1, 0.8]},
    "fixed": {"mu_r_pp": 0.1},
    "design": {"samples": 8, "held_out": 2, "seed": 3},
    "batch_worlds": 3,
    "responses": [
        {"name": "alpha", "experiment": "baffle", "target": {"dem_at": {"mu_s_pp": 0.5, "mu_s_pw": 0.3}, "runs": 2}},
        {"name": "beta", "experiment": "drum", "target": {"dem_at": {"mu_s_pp": 0.5, "mu_s_pw": 0.3}}},
    ],
    "validation": {"name": "gamma", "experiment": "cylinder", "target": {"dem_at": {"mu_s_pp": 0.5, "mu_s_pw": 0.3}}},
    "optimisation": {"pop_size": 20, "n_generations": 10, "tolerance_deg": 2.0, "n_dense": 500},
    "confirmation": {"runs": 1, "refine_rounds": 0},
    "surrogate": {"n_splits": 2, "n_repeats": 1},
    "sensitivity": {"n": 64},
}


def stub_angle(experiment: str, p: dict) -> float:
    """A smooth stand-in for a DEM angle [deg]."""
    return {"baffle": 15 + 25 * p["mu_s_pp"] + 5 * p["mu_s_pw"],
            "drum": 20 + 8 * p["mu_s_pp"] + 30 * p["mu_s_pw"]}.get(experiment, 30 + 5 * p["mu_s_pp"])


class DemCalls(list):
    """One entry per DEM call: (response, first fill, number of parameter sets)."""

    def sets(self, response: str | None = None, fills_from: int = 0, fills_below: int = 10**9) -> int:
        return sum(n for r, f, n in self if (response is None or r == response) and fills_from <= f < fills_below)


@pytest.fixture
def dem(monkeypatch):
    calls = DemCalls()

    def run_response(resp, parameter_sets, cfg, progress=False, first_fill=0, vtk_folder=None):
        calls.append((resp.name, first_fill, len(parameter_sets)))
        out = []
        for p in parameter_sets:
            a = stub_angle(resp.experiment, p)
            out.append(dict(status="ok", error=None, angle_deg=a, replicate_angles_deg=[a] * resp.replicates,
                            wall_s=2.0, worlds=len(parameter_sets) * resp.replicates))
        return out

    monkeypatch.setattr(cp, "run_response", run_response)
    return calls


def with_response_change(raw: dict, **change) -> dict:
    return {**raw, "responses": [{**raw["responses"][0], **change}] + raw["responses"][1:]}


CHANGES = {
    "contact law": ({**BASE, "contact_law": {"rolling": "epsd2"}},
                    "contact law differs: recorded hertz+history+rolling:epsd+cohesion:none, "
                    "config hertz+history+rolling:epsd2+cohesion:none"),
    "material": ({**BASE, "material": {"type": "spheres", "diameter": [0.010, 0.012]}},
                 "material differs: recorded the experiment's scale default, config {"),
    "experiment setting": (with_response_change(BASE, settings={"lift_speed": 0.05}),
                           "response(s) alpha: experiment differs: settings.lift_speed recorded (not set), config 0.05"),
    "replicates": (with_response_change(BASE, replicates=2),
                   "response(s) alpha: experiment differs: replicates recorded 1, config 2"),
    "scale": (with_response_change(BASE, scale="paper"),
              "response(s) alpha: experiment differs: scale recorded quick, config paper"),
    "fixed parameter": ({**BASE, "fixed": {"mu_r_pp": 0.2}}, "fixed parameters differ: mu_r_pp recorded 0.1, config 0.2"),
    "fill mode": ({**BASE, "fills": "shared"}, "fill mode differs: recorded independent, config shared"),
}


@pytest.mark.parametrize("what", list(CHANGES))
def test_changed_setup_is_refused_naming_the_difference(tmp_path, dem, capsys, what):
    cp.Campaign(cp.parse_config(BASE), tmp_path, verbose=False).run_design(progress=False)
    n_records = len((tmp_path / "samples.jsonl").read_text().splitlines())
    raw, message = CHANGES[what]
    dem.clear()
    with pytest.raises(ConfigError) as exc:
        cp.Campaign(cp.parse_config(raw), tmp_path, verbose=False).run_design(progress=False)
    assert message in str(exc.value), str(exc.value)
    assert "new output folder (--out NEW_DIR, or --new-folder" in str(exc.value)
    # the same from the command line: exit code 2, the message, no traceback, no DEM run, nothing written
    config = tmp_path / "changed.yaml"
    config.write_text(yaml.safe_dump(raw))
    assert cp.calibrate_main([str(config), "--out", str(tmp_path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert dem == [] and len((tmp_path / "samples.jsonl").read_text().splitlines()) == n_records


def test_only_the_differences_are_named(tmp_path, dem):
    """Two changes at once: both named, nothing that stayed the same."""
    cp.Campaign(cp.parse_config(BASE), tmp_path, verbose=False).run_design(progress=False, max_samples=2)
    raw = {**with_response_change(BASE, settings={"lift_speed": 0.05}), "contact_law": {"rolling": "cdt"}}
    with pytest.raises(ConfigError) as exc:
        cp.Campaign(cp.parse_config(raw), tmp_path, verbose=False).run_design(progress=False)
    msg = str(exc.value)
    assert "contact law differs" in msg and "settings.lift_speed" in msg
    assert "material" not in msg and "fixed parameters" not in msg and "code version" not in msg
    assert "response(s) beta" not in msg  # beta's experiment did not change


def test_changed_code_version_is_refused(tmp_path, dem, monkeypatch):
    cfg = cp.parse_config(BASE)
    cp.Campaign(cfg, tmp_path, verbose=False).run_design(progress=False, max_samples=1)
    real = cr.code_version()
    assert real["warpdem"] and len(real["source_sha256"]) == 16 and real["files"] > 10
    monkeypatch.setattr(cp, "code_version", lambda: {**real, "source_sha256": "0123456789abcdef"})
    with pytest.raises(ConfigError, match="code version differs: source_sha256 recorded [0-9a-f]{16}, "
                                          "this code 0123456789abcdef"):
        cp.Campaign(cfg, tmp_path, verbose=False).run_design(progress=False)


def test_changed_design_parameter_range_still_refused(tmp_path, dem):
    """The design check (sample number + parameter values) runs after the setup check."""
    cp.Campaign(cp.parse_config(BASE), tmp_path, verbose=False).run_design(progress=False, max_samples=2)
    raw = {**BASE, "parameters": {"mu_s_pp": [0.2, 0.8], "mu_s_pw": [0.1, 0.8]}}
    with pytest.raises(ConfigError, match="the design changed"):
        cp.Campaign(cp.parse_config(raw), tmp_path, verbose=False).run_design(progress=False)


def test_identical_rerun_reuses_every_record(tmp_path, dem):
    cfg = cp.parse_config(BASE)
    first = cp.Campaign(cfg, tmp_path, verbose=False).run(progress=False)
    # DEM work of the first run: targets (2 + 1 + 1 sets), design (2 x 8), confirmation (2 x 1), validation (1)
    assert dem.sets() == 4 + 16 + 2 + 1
    runs = [json.loads(line) for line in (tmp_path / "runs.jsonl").read_text().splitlines()]
    assert sorted((r["kind"], r["response"]) for r in runs) == [
        ("confirmation", "alpha"), ("confirmation", "beta"), ("target", "alpha"), ("target", "beta"),
        ("target", "gamma"), ("validation", "gamma")]
    for rec in runs + [json.loads(line) for line in (tmp_path / "samples.jsonl").read_text().splitlines()]:
        assert rec["fingerprint"] == cr.fingerprint(rec["determined_by"])
        assert set(rec["determined_by"]) == {"setup", "point"}
        assert set(rec["determined_by"]["setup"]) == set(cr.SETUP_LABELS)
    dem.clear()
    again = cp.Campaign(cp.parse_config(BASE), tmp_path, verbose=False).run(progress=False)
    assert dem == []  # nothing ran again
    assert again["targets"] == first["targets"]
    assert again["confirmation"]["responses"] == first["confirmation"]["responses"]
    assert again["validation"] == first["validation"]
    assert len((tmp_path / "runs.jsonl").read_text().splitlines()) == len(runs)  # nothing appended


def test_target_records_survive_an_interrupted_design(tmp_path, dem, monkeypatch):
    """Ctrl-C during the design: the targets already run are recorded and not run again."""
    stub = cp.run_response

    def interrupted(resp, parameter_sets, cfg, progress=False, first_fill=0, vtk_folder=None):
        if first_fill < cp.TARGET_FILLS:  # a design batch
            raise KeyboardInterrupt
        return stub(resp, parameter_sets, cfg, progress, first_fill, vtk_folder)

    monkeypatch.setattr(cp, "run_response", interrupted)
    with pytest.raises(KeyboardInterrupt):
        cp.Campaign(cp.parse_config(BASE), tmp_path, verbose=False).run(progress=False)
    assert dem.sets(fills_from=cp.TARGET_FILLS, fills_below=cp.CONFIRMATION_FILLS) == 2 + 1 + 1
    monkeypatch.setattr(cp, "run_response", stub)
    dem.clear()
    res = cp.Campaign(cp.parse_config(BASE), tmp_path, verbose=False).run(progress=False)
    assert dem.sets(fills_from=cp.TARGET_FILLS, fills_below=cp.CONFIRMATION_FILLS) == 0  # targets reused
    assert dem.sets(fills_below=cp.TARGET_FILLS) == 16  # the design ran
    assert res["targets"]["alpha"]["source"].endswith("mean of 2 loose fill(s)")
    # a target at other known parameters is another run: it runs (and is recorded), the design is reused
    dem.clear()
    moved = with_response_change(BASE, target={"dem_at": {"mu_s_pp": 0.6, "mu_s_pw": 0.3}, "runs": 2})
    res = cp.Campaign(cp.parse_config(moved), tmp_path, verbose=False).run(progress=False)
    assert [c[:1] + c[2:] for c in dem if cp.TARGET_FILLS <= c[1] < cp.CONFIRMATION_FILLS] == [("alpha", 2)]
    assert dem.sets(fills_below=cp.TARGET_FILLS) == 0
    assert res["targets"]["alpha"]["deg"] == pytest.approx(stub_angle("baffle", {"mu_s_pp": 0.6, "mu_s_pw": 0.3}))


@pytest.mark.parametrize("file", ["samples.jsonl", "runs.jsonl"])
def test_torn_last_line_is_reported_and_rerun(tmp_path, dem, capsys, file):
    cfg = cp.parse_config(BASE)
    cp.Campaign(cfg, tmp_path, verbose=False).run(progress=False)
    path = tmp_path / file
    lines = path.read_text().splitlines()
    torn = json.loads(lines[-1])
    path.write_text("".join(ln + "\n" for ln in lines[:-1]) + lines[-1][: len(lines[-1]) // 3])
    dem.clear()
    cp.Campaign(cfg, tmp_path, verbose=True).run(progress=False)
    out = capsys.readouterr().out
    assert f"{path}: the last line (line {len(lines)}) is incomplete: a write was interrupted" in out
    if file == "samples.jsonl":  # exactly the torn sample ran again
        assert dem == [(torn["response"], torn["index"], 1)]
    else:  # the last run record (the validation) ran again
        assert torn["kind"] == "validation" and dem == [("gamma", cp.VALIDATION_FILLS, 1)]
    again = path.read_text().splitlines()
    assert len(again) == len(lines) and json.loads(again[-1])["fingerprint"] == torn["fingerprint"]


def test_records_without_fingerprint_or_edited_are_refused(tmp_path, dem, capsys):
    cfg = cp.parse_config(BASE)
    cp.Campaign(cfg, tmp_path, verbose=False).run_design(progress=False, max_samples=2)
    path = tmp_path / "samples.jsonl"
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    # a record of format 1 (before fingerprints): never reused silently
    old = {k: v for k, v in lines[2].items() if k not in ("fingerprint", "determined_by")}
    path.write_text("".join(json.dumps(r) + "\n" for r in lines[:2] + [old] + lines[3:]))
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump(BASE))
    assert cp.calibrate_main([str(config), "--out", str(tmp_path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"{path}: line 3 (sample {old['index']} of response '{old['response']}') has no fingerprint" in err
    assert "record format 1" in err and "Traceback" not in err
    # a record whose recorded setup was edited to fit another config: its fingerprint no longer matches
    edited = json.loads(json.dumps(lines[0]))
    edited["determined_by"]["setup"]["contact_law"] = "hertz+mindlin+rolling:epsd2+cohesion:none"
    path.write_text("".join(json.dumps(r) + "\n" for r in [edited] + lines[1:]))
    with pytest.raises(ConfigError, match="line 1 .*fingerprint does not match .* edited or damaged"):
        cp.Campaign(cp.parse_config({**BASE, "contact_law": {"rolling": "epsd2"}}), tmp_path,
                    verbose=False).run_design(progress=False)
    assert dem.sets() == 4  # only the first part ran


def test_new_folder_option_picks_a_fitting_folder(tmp_path, dem, capsys):
    out = tmp_path / "out"
    base, changed = tmp_path / "base.yaml", tmp_path / "changed.yaml"
    base.write_text(yaml.safe_dump(BASE))
    changed.write_text(yaml.safe_dump({**BASE, "contact_law": {"rolling": "epsd2"}}))
    part = ["--max-samples", "2", "--no-progress"]
    assert cp.calibrate_main([str(base), "--out", str(out)] + part) == 0
    assert cp.calibrate_main([str(changed), "--out", str(out)] + part) == 2
    assert cp.calibrate_main([str(changed), "--out", str(out), "--new-folder"] + part) == 0
    assert "holds records of another setup" in capsys.readouterr().err
    assert len((tmp_path / "out-2" / "samples.jsonl").read_text().splitlines()) == 4
    dem.clear()
    # each config resumes in its own folder
    assert cp.calibrate_main([str(changed), "--out", str(out), "--new-folder"] + part) == 0
    assert cp.calibrate_main([str(base), "--out", str(out), "--new-folder"] + part) == 0
    assert len((out / "samples.jsonl").read_text().splitlines()) == 8
    assert len((tmp_path / "out-2" / "samples.jsonl").read_text().splitlines()) == 8
    assert not (tmp_path / "out-3").exists() and dem.sets() == 8


def test_wall_time_is_summed_over_sittings(tmp_path, dem, monkeypatch):
    cfg = cp.parse_config(BASE)
    cp.Campaign(cfg, tmp_path, verbose=False).run_design(progress=False, max_samples=3)
    first = json.loads((tmp_path / "sittings.json").read_text())
    assert len(first) == 1 and not first[0]["finished"]
    # pretend the first sitting took an hour (its record is what a later sitting reads)
    first[0]["wall_s"] = 3600.0
    (tmp_path / "sittings.json").write_text(json.dumps(first))
    res = cp.Campaign(cfg, tmp_path, verbose=False).run(progress=False)
    sittings = json.loads((tmp_path / "sittings.json").read_text())
    assert len(sittings) == 2 and sittings[1]["finished"] and res["sittings"] == 2
    assert res["wall_s"] == pytest.approx(3600.0 + res["wall_s_this_sitting"], abs=0.11)
    assert 0 < res["wall_s_this_sitting"] < 3600
    # the stub reports 2 s per DEM call: the design's DEM time over both sittings is 2 s per design call
    design_calls = [c for c in dem if c[1] < cp.TARGET_FILLS]
    assert len(design_calls) == 6 and res["design_dem_wall_s_all_sessions"] == pytest.approx(2.0 * 6, abs=0.01)
    assert res["dem_wall_s_all_sittings"] == pytest.approx(2.0 * len(dem), abs=0.01)
    summary = (tmp_path / "summary.md").read_text()
    assert f"Total wall time {res['wall_s']} s over 2 sitting(s)" in summary


def test_fingerprint_fills_are_the_fills_the_dem_gets(tmp_path, dem):
    """The fill indices in a record are those its worlds were given (replicates, gaps, VTK splits)."""
    raw = {**with_response_change(BASE, replicates=2), "vtk": {"every": 0.1, "samples": [4]},
           "validation": {**BASE["validation"], "replicates": 2}}
    cp.Campaign(cp.parse_config(raw), tmp_path, verbose=False).run_design(progress=False)
    recs = {(r["response"], r["index"]): r for r in map(json.loads, (tmp_path / "samples.jsonl").read_text().splitlines())}
    given = {}
    for response, first_fill, n in dem:
        r = 2 if response == "alpha" else 1
        for k in range(n):
            given[(response, (first_fill + k * r) // r)] = list(range(first_fill + k * r, first_fill + (k + 1) * r))
    assert {k: rec["determined_by"]["point"]["fills"] for k, rec in recs.items()} == given
    assert recs[("alpha", 4)]["determined_by"]["point"]["fills"] == [8, 9]


def test_record_files_keep_whole_lines(tmp_path):
    """append_records writes whole lines; a complete last line that lost its newline gets one back
    (the next append does not join it); write_atomic leaves no temporary file."""
    path = tmp_path / "r.jsonl"
    cr.append_records(path, [{"a": 1}, {"a": 2}])
    assert path.read_text() == '{"a": 1}\n{"a": 2}\n'
    path.write_text(path.read_text().rstrip("\n"))
    assert [r for _, r in cr.read_records(path, log=print)] == [{"a": 1}, {"a": 2}]
    cr.append_records(path, [{"a": 3}])
    assert [r["a"] for _, r in cr.read_records(path)] == [1, 2, 3]
    path.write_text('{"a": 1}\n[1, 2]\n{"a": 3}\n')
    with pytest.raises(ConfigError, match="line 2 is not valid JSON"):
        cr.read_records(path)
    cr.write_atomic(tmp_path / "x.json", "{}\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.jsonl", "x.json"]
