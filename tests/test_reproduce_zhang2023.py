"""The seed paper reproduced end to end (calibration/reproduction.py, examples/reproduce_zhang2023.py):
the paper's points in our parameter names and bounds, the space-filling subsets, and the report's
comparison numbers with the DEM replaced by a fake that knows the paper's EDEM angles (the
campaign's plumbing is what is tested; a real-DEM smoke run at quick scale is marked slow)."""
import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.interpolate import RBFInterpolator
from scipy.spatial.distance import pdist

import calibration.campaign as cp
import calibration.reproduction as rp
from calibration.paper_data import PAPER_CSV, PAPER_OPTIMUM, load_paper_data
from warpdem import ConfigError

ROOT = Path(__file__).resolve().parents[1]
PAPER_CONFIG = ROOT / "calibration" / "configs" / "paper_gravel.yaml"
TABLE1 = ROOT / "calibration" / "data" / "zhang2023_table1.yaml"


def verdict_line(printed: str) -> str:
    """The first printed line that is not a campaign log line."""
    return next(line for line in printed.splitlines() if not line.startswith("[calibrate"))


def small_config(tmp_path: Path, **changes) -> Path:
    """paper_gravel.yaml with small analysis budgets (the DEM is faked), targets by absolute path."""
    raw = yaml.safe_load(PAPER_CONFIG.read_text())
    for r in raw["responses"] + [raw["validation"]]:
        r["target"]["file"] = str(TABLE1)
    raw.update(optimisation={"pop_size": 40, "n_generations": 10, "n_dense": 2000},
               sensitivity={"n": 256}, surrogate={"n_splits": 3, "n_repeats": 1},
               confirmation={"runs": 1, "refine_rounds": 0}, checkpoints={"enabled": False})
    raw.update(changes)
    path = tmp_path / "paper_small.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


class PaperDem:
    """A stand-in for the DEM that returns the paper's EDEM angle (+ ``bias`` deg) at its
    Appendix-A points and a thin-plate RBF through them elsewhere; the cylinder answers the
    baffle's angle minus 1 deg. ``calls``: (response name, number of parameter sets)."""

    def __init__(self, bias: float = 0.0):
        data = load_paper_data()
        self.X = np.vstack([data.X_train, data.X_val])  # paper names = our names in paper_gravel
        self.Y = np.vstack([data.Y_train, data.Y_val])
        self.rbf = [RBFInterpolator(self.X, self.Y[:, j]) for j in range(2)]
        self.bias = bias
        self.calls: list[tuple[str, int]] = []

    def angle(self, experiment: str, p: dict) -> float:
        x = np.array([p["mu_s_pp"], p["mu_r_pp"], p["mu_s_pw"], p["mu_r_pw"]])
        j = 1 if experiment == "drum" else 0
        hit = np.flatnonzero(np.all(np.abs(self.X - x) < 1e-12, axis=1))
        a = float(self.Y[hit[0], j]) if len(hit) else float(self.rbf[j](x[None])[0])
        return a + self.bias - (1.0 if experiment == "cylinder" else 0.0)

    def install(self, monkeypatch):
        def run_response(resp, parameter_sets, cfg, progress=False, first_fill=0, vtk_folder=None):
            self.calls.append((resp.name, len(parameter_sets)))
            out = []
            for p in parameter_sets:
                a = self.angle(resp.experiment, p)
                out.append(dict(status="ok", error=None, angle_deg=a, replicate_angles_deg=[a] * resp.replicates,
                                wall_s=1.0))
            return out

        monkeypatch.setattr(cp, "run_response", run_response)
        return self


# ----------------------------------------------------------------------------- the points
def test_the_140_points_land_in_our_parameter_names_and_bounds():
    cfg = cp.load_config(PAPER_CONFIG)
    pts = rp.paper_points(cfg)
    assert len(pts) == 140 and pts.parameter_names == tuple(cfg.space.names)
    assert list(pts.rows) == list(range(1, 141))
    assert pts.roles.count("training") == 100 and all(r == "validation" for r in pts.roles[100:])
    assert cfg.space.contains(pts.X).all()
    # row 1 of Appendix A: 0.519, 0.343, 0.761, 0.248 -> 40.3 / 62.9 deg (read from the CSV by name)
    with open(PAPER_CSV) as fh:
        first = next(csv.DictReader(fh))
    assert dict(zip(pts.parameter_names, pts.X[0])) == {k: float(first[k]) for k in pts.parameter_names}
    assert pts.paper_deg[0].tolist() == [float(first["alpha_static_deg"]), float(first["beta_dynamic_deg"])]
    # each paper coefficient is our sub-model parameter of the same meaning and pair type
    specs = cfg.model.parameter_specs()
    for paper, ours in rp.model_parameter_names(cfg).items():
        param, pair, _ = rp.PAPER_PARAMETER_MEANING[paper]
        assert ours.endswith(f"_{pair}") and specs[ours].name == param


def test_points_follow_the_configs_parameter_order(tmp_path):
    raw = yaml.safe_load(PAPER_CONFIG.read_text())
    raw["parameters"] = {k: raw["parameters"][k] for k in ("mu_r_pw", "mu_s_pw", "mu_r_pp", "mu_s_pp")}
    cfg = cp.parse_config(raw, base_dir=PAPER_CONFIG.parent)
    pts = rp.paper_points(cfg)
    ref = rp.paper_points(cp.load_config(PAPER_CONFIG))
    assert pts.parameter_names == ("mu_r_pw", "mu_s_pw", "mu_r_pp", "mu_s_pp")
    np.testing.assert_array_equal(pts.X, ref.X[:, [3, 2, 1, 0]])


def test_configs_that_cannot_take_the_paper_points_are_refused():
    raw = yaml.safe_load(PAPER_CONFIG.read_text())
    narrow = dict(raw, parameters={**raw["parameters"], "mu_s_pp": [0.0, 0.5]})
    with pytest.raises(ConfigError, match="row .* outside the config's parameter box"):
        rp.paper_points(cp.parse_config(narrow, base_dir=PAPER_CONFIG.parent))
    three = dict(raw, parameters={k: v for k, v in raw["parameters"].items() if k != "mu_r_pw"})
    with pytest.raises(ConfigError, match="mu_r_pw.*does not calibrate"):
        rp.paper_points(cp.parse_config(three, base_dir=PAPER_CONFIG.parent))
    with pytest.raises(ConfigError, match="fix the others"):
        rp.paper_points(cp.parse_config(dict(raw, parameters={**raw["parameters"], "restitution_pp": [0.2, 0.9]}),
                                        base_dir=PAPER_CONFIG.parent))


def test_subsets_are_space_filling_nested_and_keep_the_paper_split():
    cfg = cp.load_config(PAPER_CONFIG)
    pts = rp.paper_points(cfg)
    everything = rp.select_points(pts, 140, cfg.space)
    assert sorted(everything.rows) == list(range(1, 141))
    for n in (2, 10, 40, 100):
        sub = rp.select_points(pts, n, cfg.space)
        assert list(sub.rows) == list(everything.rows[:n])  # nested: a subset run extends to 140
        assert int(sub.validation.sum()) == n * 40 // 140
        assert all((r > 100) == (role == "validation") for r, role in zip(sub.rows, sub.roles))
    sub = rp.select_points(pts, 40, cfg.space)
    U = cfg.space.to_unit(pts.X)
    rng = np.random.default_rng(0)
    random_best = max(pdist(U[rng.choice(140, 40, replace=False)]).min() for _ in range(200))
    assert pdist(cfg.space.to_unit(sub.X)).min() > random_best  # better spread than any of 200 random picks
    for bad in (1, 141):
        with pytest.raises(ConfigError, match="--points"):
            rp.select_points(pts, bad, cfg.space)


# ----------------------------------------------------------------------------- comparison numbers
def test_region_statistics_find_the_parameter_behind_the_gap():
    cfg = cp.load_config(PAPER_CONFIG)
    pts = rp.paper_points(cfg)
    j = list(pts.parameter_names).index("mu_s_pw")
    low = pts.X[:, j] < 0.4
    ours = pts.paper_deg - 6.0 * low[:, None]  # ours 6 deg lower at low wall friction only
    comp = rp.compare_with_paper(pts, ours, cfg.space)
    for name in ("alpha_static_deg", "beta_dynamic_deg"):
        reg = comp["responses"][name]["by_region"]["mu_s_pw"]
        assert reg["low"]["bias_deg"] == pytest.approx(-6.0) and reg["high"]["bias_deg"] == pytest.approx(0.0)
        assert reg["low"]["n"] == int(low.sum()) and reg["high"]["n"] == int((~low).sum())
        assert comp["responses"][name]["explained_by"]["parameter"] == "mu_s_pw"
        assert comp["responses"][name]["rmse_deg"] == pytest.approx(6.0 * np.sqrt(low.mean()))
    missing = ours.copy()
    missing[5:, 1] = np.nan
    part = rp.compare_with_paper(pts, missing, cfg.space)
    assert part["responses"]["beta_dynamic_deg"]["n"] == 5
    assert "so far (preliminary)" in rp.reproduction_verdict(part).headline


def test_linear_effects_show_which_parameter_acts_differently_in_our_dem(tmp_path):
    """Ours = the paper's + 6 deg x (mu_r_pp scaled to [0, 1]): the fitted effect of mu_r_pp is 6 deg
    larger in ours, every other effect the same, and the report's section names mu_r_pp."""
    cfg = cp.load_config(PAPER_CONFIG)
    pts = rp.paper_points(cfg)
    j = list(pts.parameter_names).index("mu_r_pp")
    u = (pts.X[:, j] - cfg.space.lower[j]) / (cfg.space.upper[j] - cfg.space.lower[j])
    ours = pts.paper_deg + 6.0 * u[:, None]
    comp = rp.compare_with_paper(pts, ours, cfg.space)
    for name in ("alpha_static_deg", "beta_dynamic_deg"):
        le = comp["responses"][name]["linear_effects"]
        for p in le["parameters"]:
            want = 6.0 if p == "mu_r_pp" else 0.0
            assert le["ours"]["effects"][p] - le["paper"]["effects"][p] == pytest.approx(want, abs=1e-9)
    section = rp._linear_effects_section(comp)
    assert "mu_r_pp's effect" in section.blocks[-1]
    few = rp.select_points(pts, 5, cfg.space)
    assert rp.compare_with_paper(few, few.paper_deg, cfg.space)["responses"]["alpha_static_deg"]["linear_effects"] is None


def test_fake_dem_with_the_papers_angles_is_reproduced_end_to_end(tmp_path, monkeypatch, capsys):
    """The whole command with a DEM that returns the paper's EDEM angles: RMSE 0, 'Reproduced',
    surrogate, NSGA-II, confirmation, validation, the paper's optimum and both report files."""
    dem = PaperDem().install(monkeypatch)
    out = tmp_path / "run"
    assert rp.main(["--config", str(small_config(tmp_path)), "--points", "24", "--out", str(out),
                    "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert verdict_line(printed).startswith("Reproduced: RMSE 0.00 deg (A) and 0.00 deg (B30)")
    summary = json.loads((out / "reproduction.json").read_text())
    for name in ("alpha_static_deg", "beta_dynamic_deg"):
        r = summary["comparison"]["responses"][name]
        assert r["n"] == 24 and r["rmse_deg"] == 0.0 and r["bias_deg"] == 0.0
    assert summary["verdict"]["met"] is True
    # our DEM at the paper's optimum is recorded and reported (fake: RBF through the paper's angles)
    x = {k: PAPER_OPTIMUM[k] for k in PAPER_OPTIMUM}
    assert summary["paper_optimum_ours_deg"]["alpha_static"] == pytest.approx(dem.angle("baffle", x))
    assert summary["paper_optimum_ours_deg"]["gamma_cylinder"] == pytest.approx(dem.angle("cylinder", x))
    md = (out / "reproduction.md").read_text()
    assert md.index("Reproduced") < md.index("## Point by point")  # verdict first
    for heading in ("Confirmation at the optimum (Table 9)", "Validation on the hollow cylinder (Table 10)",
                    "Sensitivity (Fig. 13)", "Optimum (Section 4.2, Table 8)", "By region of the parameter box"):
        assert heading in md
    html = (out / "reproduction.html").read_text()
    assert "Reproduced: RMSE 0.00 deg" in html and "data:image/png;base64," in html
    assert (out / "reproduction_points.png").stat().st_size > 10_000
    # the campaign's held-out samples are the paper's validation rows
    res = json.loads((out / "results.json").read_text())
    assert res["surrogate"]["held_out"]["n"] == 24 * 40 // 140
    # a second run repeats no DEM run and gives the same verdict
    n_calls = len(dem.calls)
    assert rp.main(["--config", str(small_config(tmp_path)), "--points", "24", "--out", str(out),
                    "--no-progress"]) == 0
    assert len(dem.calls) == n_calls


def test_fake_dem_4_deg_too_high_is_not_reproduced_and_runs_in_parts(tmp_path, monkeypatch, capsys):
    dem = PaperDem(bias=4.0).install(monkeypatch)
    cfg_path, out = str(small_config(tmp_path)), str(tmp_path / "parts")
    common = ["--config", cfg_path, "--points", "10", "--out", out, "--no-progress"]
    assert rp.main(common + ["--max-samples", "4", "--only", "alpha_static"]) == 0
    assert verdict_line(capsys.readouterr().out).startswith("No DEM result")  # B30 not run yet
    assert dem.calls == [("alpha_static", 4)]
    assert rp.main(common + ["--max-samples", "10"]) == 0  # the rest of A, all of B30
    assert dem.calls[1:] == [("alpha_static", 6), ("beta_dynamic", 10)]
    printed = capsys.readouterr().out
    assert verdict_line(printed).startswith("Not reproduced: RMSE 4.00 deg (A) and 4.00 deg (B30) against the 3 deg target")
    summary = json.loads((Path(out) / "reproduction.json").read_text())
    for name in ("alpha_static_deg", "beta_dynamic_deg"):
        r = summary["comparison"]["responses"][name]
        assert r["bias_deg"] == pytest.approx(4.0) and r["rmse_deg"] == pytest.approx(4.0)
        assert r["by_region"]["mu_s_pw"]["low"]["bias_deg"] == pytest.approx(4.0)
    assert summary["verdict"]["met"] is False
    assert "Not yet: the campaign's analysis" in (Path(out) / "reproduction.md").read_text()
    # extending the subset in the same folder runs only the new points
    assert rp.main(["--config", cfg_path, "--points", "14", "--out", out, "--no-progress", "--max-samples", "140"]) == 0
    assert dem.calls[3:] == [("alpha_static", 4), ("beta_dynamic", 4)]
    # --report-only runs nothing
    assert rp.main(["--config", cfg_path, "--points", "14", "--out", out, "--report-only"]) == 0
    assert len(dem.calls) == 5


def test_time_limited_parts_start_no_batch_that_would_overrun(tmp_path, monkeypatch, capsys):
    """With --time-limit, each call runs the design in batches expected to fit (from the benchmark
    figures, then from its own records), then the analysis, and stops cleanly before a batch that
    would not fit; repeating the same command completes it. DEM time is a fake clock: 30 s per world."""
    clock = [0.0]
    monkeypatch.setattr(rp.time, "perf_counter", lambda: clock[0])
    dem = PaperDem().install(monkeypatch)
    fake = cp.run_response

    def timed(resp, parameter_sets, cfg, progress=False, first_fill=0, vtk_folder=None):
        clock[0] += 30.0 * len(parameter_sets)
        return [dict(r, wall_s=30.0 * len(parameter_sets)) for r in fake(resp, parameter_sets, cfg)]

    monkeypatch.setattr(cp, "run_response", timed)
    cmd = ["--config", str(small_config(tmp_path)), "--points", "10", "--out", str(tmp_path / "t"), "--no-progress",
           "--time-limit", "300"]
    used = []
    for _ in range(8):
        t0, n0 = clock[0], len(dem.calls)
        assert rp.main(cmd) == 0
        used.append(clock[0] - t0)
        printed = capsys.readouterr().out
        if n0 == 0:  # the first part: the baffle's 10 points (10 x 12.1 s expected), then no drum batch fits
            assert dem.calls == [("alpha_static", 10)] and "part stopped at its time limit" in printed
        if "complete:" in printed:
            break
    assert "complete:" in printed and verdict_line(printed).startswith("Reproduced")
    assert max(used) <= 300 and len(used) >= 3
    assert sum(n for name, n in dem.calls if name == "beta_dynamic") == 10 + 1 + 1  # design, confirmation, optimum


def test_records_of_an_lhs_campaign_are_refused(tmp_path, monkeypatch):
    PaperDem().install(monkeypatch)
    cfg = cp.load_config(small_config(tmp_path))
    cfg.samples, cfg.held_out = 6, 2
    cp.Campaign(cfg, tmp_path / "lhs", verbose=False).run_design(progress=False)
    with pytest.raises(ConfigError, match="design"):
        rp.reproduce(small_config(tmp_path), n_points=6, out=tmp_path / "lhs", max_samples=2, verbose=False,
                     progress=False)


@pytest.mark.slow
def test_real_dem_smoke_at_quick_scale(tmp_path):
    """Two points at quick scale, the static angle of one of them, real DEM on the CPU (70 s on a busy
    2-core machine, hence slow): the record at the right point, and the report."""
    out = tmp_path / "smoke"
    assert rp.main(["--config", str(small_config(tmp_path)), "--device", "cpu", "--scale", "quick", "--points", "2",
                    "--max-samples", "1", "--only", "alpha_static", "--out", str(out), "--no-progress"]) == 0
    recs = [json.loads(line) for line in (out / "samples.jsonl").read_text().splitlines()]
    assert len(recs) == 1 and recs[0]["status"] == "ok" and 0 < recs[0]["angle_deg"] < 90
    cfg = cp.load_config(PAPER_CONFIG)
    first = rp.select_points(rp.paper_points(cfg), 2, cfg.space)
    assert recs[0]["parameters"] == dict(zip(first.parameter_names, first.X[0].tolist()))
    summary = json.loads((out / "reproduction.json").read_text())
    assert summary["comparison"]["responses"]["alpha_static_deg"]["n"] == 1 and not summary["complete"]
    assert (out / "reproduction.html").exists()
