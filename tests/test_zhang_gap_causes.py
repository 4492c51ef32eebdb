"""benchmarks/zhang_gap_causes.py (issue 32, item 2): the variants are built as their hypotheses say
(no DEM), the default rows are the reproduction's largest gaps plus controls, and a quick CPU run of
1 row x 2 variants x 2 fills in both experiments writes one JSONL line per (variant, row, experiment,
replicate) and a summary; run again, it repeats nothing."""
import json
import math
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import zhang_gap_causes as zgc  # noqa: E402

import warpdem as wd  # noqa: E402
from calibration import campaign as cp  # noqa: E402
from calibration.experiments import RotatingDrum  # noqa: E402
from calibration.reproduction import paper_points  # noqa: E402

# a quick baffle of 16 kg (about 580 spheres of 24-30 mm) and a 30 % quick drum turned once
TINY = {"baffle": {"fill_mass": 16.0, "max_time_after_lift": 1.0},
        "drum": {"fill_fraction": 0.3, "discard": 0, "record": 1}}


@pytest.fixture(scope="module")
def cfg():
    return cp.load_config(zgc.DEFAULT_CONFIG)


def test_default_rows_are_the_largest_gaps_and_two_controls(cfg):
    points = paper_points(cfg)
    stored = zgc.stored_angles(zgc.DEFAULT_RESULTS, points)
    assert len(stored) == 80  # 40 points x (A, B30)
    a = zgc.choose_rows(points, stored, "baffle", None, 6, 2)
    b = zgc.choose_rows(points, stored, "drum", None, 6, 2)
    assert [r.row for r in a] == [132, 137, 12, 88, 10, 61, 124, 58]
    assert [r.row for r in b] == [132, 68, 88, 34, 139, 85, 32, 11]
    assert [r.group for r in a] == ["largest_gap"] * 6 + ["control"] * 2
    r132 = a[0]
    assert r132.paper_deg == 44.2 and r132.stored_deg == pytest.approx(44.2 - 17.22, abs=0.01)
    assert r132.parameters == {"mu_s_pp": 0.743, "mu_r_pp": 0.355, "mu_s_pw": 0.395, "mu_r_pw": 0.548}


def test_variants_change_what_their_hypotheses_say(cfg):
    build = lambda v, e: zgc.experiment_for(cfg, e, v, "paper", {}, 0)  # noqa: E731
    base_drum, base_baffle = build("as_run", "drum"), build("as_run", "baffle")
    assert base_drum.contact_law.describe() == "hertz+history+rolling:cdt+cohesion:none"
    assert base_drum.fill_per_world and (base_drum.discard, base_drum.record, base_drum.sections) == (5, 10, 72)
    assert build("edem_rolling_arm", "baffle").contact_law.rolling == "cdt_body_arm"
    assert build("cdt_liggghts", "drum").contact_law.rolling == "cdt_liggghts"
    assert build("epsd2", "drum").contact_law.rolling == "epsd2"
    assert build("clump_damping_body", "drum").contact_law.clump_damping_mass == "body"
    assert build("drum_smooth", "drum").sections == 288
    short = build("short", "drum")
    assert {"discard": short.discard, "record": short.record} == RotatingDrum.PRESETS["short"]
    assert (build("long_protocol", "drum").discard, build("long_protocol", "drum").record) == (10, 10)
    assert not zgc.applies("drum_smooth", "baffle") and zgc.applies("spheres", "baffle")
    # half the recommended step of the clumps' smallest member sphere
    half = build("dt_half", "baffle")
    mat = base_baffle.bulk_material()
    lim = wd.time_step_limits_for([(mat.particle, *mat.smallest_sphere)], base_baffle.v_ref)
    assert min(half.dt_rayleigh_fraction * lim.rayleigh, lim.limit) == pytest.approx(0.5 * lim.recommended, rel=1e-12)
    # spheres: one per clump, same volume, mass and number fraction
    sph = build("spheres", "baffle").bulk_material()
    for (t, f), (s, g) in zip(mat.clumps, sph.clumps):
        assert len(s.radii) == 1 and f == g and s.volume == t.volume and s.mass == t.mass
        assert 4.0 / 3.0 * math.pi * s.radii[0] ** 3 == pytest.approx(t.volume, rel=1e-12)
    assert sph.mean_particle_mass == pytest.approx(mat.mean_particle_mass, rel=1e-12)


def test_quick_run_writes_lines_and_summary_and_resumes(tmp_path, capsys):
    out = tmp_path / "gap"
    argv = ["--scale", "quick", "--device", "cpu", "--rows", "47", "--variants", "as_run", "cdt_liggghts",
            "--replicates", "2", "--out", str(out), "--settings", json.dumps(TINY)]
    assert zgc.main(argv) == 0
    lines = [json.loads(x) for x in (out / "runs.jsonl").read_text().splitlines()]
    keys = {(r["variant"], r["row"], r["experiment"], r["replicate"]) for r in lines}
    assert len(lines) == 8 and keys == {(v, 47, e, j) for v in ("as_run", "cdt_liggghts")
                                        for e in ("baffle", "drum") for j in (0, 1)}
    for r in lines:
        assert r["paper_deg"] == {"baffle": 33.6, "drum": 52.0}[r["experiment"]]
        assert r["stored_deg"] == pytest.approx({"baffle": 29.399, "drum": 49.87}[r["experiment"]], abs=0.01)
        assert r["fill_index"] == r["replicate"]  # the same fills in every variant: a paired comparison
        assert r["contact_law"].startswith("hertz+history+rolling:" + ("cdt+" if r["variant"] == "as_run"
                                                                        else "cdt_liggghts+"))
        assert r["status"] in ("ok", "failed") and r["dt_s"] > 0 and r["scale"] == "quick"
        if r["status"] == "ok":
            assert math.isfinite(r["angle_deg"]) and r["gap_deg"] == pytest.approx(r["angle_deg"] - r["paper_deg"])
        else:
            assert r["error"]
    md = (out / "summary.md").read_text()
    assert "## A: baffle" in md and "## B30: drum" in md and "`cdt_liggghts`" in md and "| 47 |" in md
    doc = json.loads((out / "summary.json").read_text())["summary"]
    for e in ("baffle", "drum"):
        v = doc[e]["variants"]
        assert set(v) == {"as_run", "cdt_liggghts"} and v["as_run"]["worlds"] == 2
        assert v["as_run"]["ok"] >= 1 and v["cdt_liggghts"]["ok"] >= 1  # (all 8 measured when written)
        if v["as_run"]["ok"] == 2 and v["cdt_liggghts"]["ok"] == 2:
            assert v["cdt_liggghts"]["pairs"] == 2 and v["as_run"]["fill_sd_deg"] is not None
    assert not list((out / "checkpoints").rglob("*.npz"))  # removed once recorded
    capsys.readouterr()
    assert zgc.main(argv) == 0  # again: every batch is recorded, nothing runs
    assert "(recorded)" in capsys.readouterr().out
    assert len((out / "runs.jsonl").read_text().splitlines()) == 8


def _line(variant, row, rep, angle, paper, stored, group="largest_gap"):
    return {"variant": variant, "experiment": "baffle", "row": row, "replicate": rep, "fill_index": 10 * row + rep,
            "group": group, "role": "training", "parameters": {}, "status": "ok", "angle_deg": angle,
            "paper_deg": paper, "gap_deg": angle - paper, "stored_deg": stored, "dt_s": 1e-5, "scale": "paper",
            "setup_key": variant}


def test_summary_numbers_from_known_lines():
    """Two largest-gap rows (paper 40 and 50 deg, stored 30 and 40), fills +-1 deg about 31 and 41
    for as_run; the variant is 5 deg steeper on every fill."""
    lines = []
    for row, paper, stored, mid in ((1, 40.0, 30.0, 31.0), (2, 50.0, 40.0, 41.0)):
        for rep, d in enumerate((-1.0, 1.0)):
            lines.append(_line("as_run", row, rep, mid + d, paper, stored))
            lines.append(_line("cdt_liggghts", row, rep, mid + d + 5.0, paper, stored))
    doc = zgc.summarize(lines)["baffle"]
    base, var = doc["variants"]["as_run"], doc["variants"]["cdt_liggghts"]
    assert base["groups"]["largest_gap"]["mean_gap_deg"] == pytest.approx(-9.0)
    # pooled fill variance 2 deg^2 (two fills at +-1); SE = sqrt(2 (1/2 + 1/2)) / 2 rows
    assert base["fill_sd_deg"] == pytest.approx(math.sqrt(2.0))
    assert base["groups"]["largest_gap"]["se_deg"] == pytest.approx(math.sqrt(2.0) / 2)
    assert var["groups"]["largest_gap"]["mean_gap_deg"] == pytest.approx(-4.0)
    assert var["change_vs_as_run_deg"] == pytest.approx(5.0) and var["change_se_deg"] == pytest.approx(0.0)
    assert var["pairs"] == 4 and var["share_of_gap_closed"] == pytest.approx(5.0 / 9.0)
    assert base["rmse_deg"] == pytest.approx(9.0)
    chk = doc["as_run_check"]
    assert chk["mean_diff_deg"] == pytest.approx(1.0) and chk["rows"] == 2
    # each row: our mean of 2 fills against one stored fill: variance 2/2 + 2 = 3; SE = sqrt(6) / 2
    assert chk["se_deg"] == pytest.approx(math.sqrt(6.0) / 2) and chk["within_noise"]
    md = zgc.summary_markdown(zgc.summarize(lines), {"command": "x"})
    assert "`cdt_liggghts` +5.00 deg (+56 % of the gap closed)" in md
