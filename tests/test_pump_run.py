"""The pump command end to end: config errors, a short smoke run with every output, and the
quick config (slow)."""
import json
from pathlib import Path

import numpy as np
import pytest

from pump.run import load_config, pump_main, run_config
from warpdem.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
QUICK = ROOT / "pump" / "configs" / "quick_pump.yaml"
PAPER = ROOT / "pump" / "configs" / "paper_pump.yaml"


def test_configs_load_and_bad_keys_are_named(tmp_path):
    q = load_config(QUICK)
    p = load_config(PAPER)
    assert q["device"] == "cpu" and p["device"] == "cuda"
    assert p["design"].get("speed_rpm", 1450) == 1450 and p["run"]["revolutions"] == 15
    assert p["run"]["dt"] == pytest.approx(1.15e-6) and p["particles"]["volume_fraction"] == 0.01
    with pytest.raises(ConfigError, match=r"fluids: unknown key; valid: contact, coupling, design"):
        load_config({"fluids": {}})
    with pytest.raises(ConfigError, match=r"fluid.spacing: unknown key; valid: added_mass"):
        load_config({"fluid": {"spacing": 0.01}})
    with pytest.raises(ConfigError, match="run.dt"):
        load_config({"run": {"dt": -1}})
    bad = tmp_path / "bad.yaml"
    bad.write_text("design: {speed: 1450}\n")
    assert pump_main([str(bad), "--output", str(tmp_path / "o"), "--no-progress"]) == 2


def test_short_run_writes_every_output(tmp_path):
    cfg = load_config(QUICK)
    cfg["output"] = str(tmp_path)
    cfg["run"].update(revolutions=1.0, vtk_every=0.02)
    cfg["particles"]["volume_fraction"] = 0.06
    assert run_config(cfg, progress=False) == 0
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["particles"]["injected"] == res["particles"]["scheduled"] > 0
    for k, err in res["fluid_checks"]["flow_rate_error"].items():
        assert abs(err) < 0.02, k
    for name in ("report.md", "report.html", "wear_regions.png", "wear_impeller.vtp", "wear_casing.vtp", "series.npz", "wear_energy.png",
                 "wear_maps.png", "trajectories.png", "flow_field.png", "force_vs_time.png", "particle_counts.png",
                 "passage_position.png", "vtk/particles.pvd", "vtk/impeller.pvd", "vtk/casing.pvd"):
        assert (tmp_path / name).exists(), name
    import pyvista as pv

    wear = pv.read(tmp_path / "wear_impeller.vtp")
    assert {"energy_n", "energy_t", "pressure_n", "pressure_t", "dnv_depth_rate_mm_y", "archard_depth_rate_mm_y",
            "impacts", "region", "component", "blade_zone"} <= set(wear.cell_data)
    # one revolution is all spin-up: no samples, so every finding reads "cannot tell", nothing is ranked
    assert res["wear"]["window"]["samples"] == 0
    assert {t["verdict"] for f in ("volute_wears_most", "leading_edge_highest_normal_energy")
            for t in res["findings"][f].values()} == {"cannot tell"}
    assert not any(r["converged"] for r in res["wear"]["regions"].values())
    report = (tmp_path / "report.md").read_text()
    assert "wear_regions.png" in report
    # the side rooms and the drag's velocity are stated; the side-room liners are regions of the report
    assert res["side_rooms"]["side_gap_m"] == 0.020 and res["drag"] == {"law": "di_felice", "velocity": "centre"}
    assert "side clearance 20 mm" in report and "| suction_liner |" in report and "| back_liner |" in report
    assert "fluid velocity at the particle's centre" in report
    frames = sorted((tmp_path / "vtk").glob("particles_*.vtp"))
    assert len(frames) >= 2
    last = pv.read(frames[-1])
    assert last.n_points > 0 and {"id", "radius", "velocity"} <= set(last.point_data)
    series = np.load(tmp_path / "series.npz")
    assert series["time"].size == series["region_counts"].shape[0]


@pytest.mark.slow
def test_quick_config_end_to_end(tmp_path):
    """The quick CPU config (about a minute on 2 cores): fluid checks, particle balance and
    the two findings that do not depend on how long the volute has been filling."""
    cfg = load_config(QUICK)
    cfg["output"] = str(tmp_path)
    assert run_config(cfg, progress=False, vtk=False) == 0
    res = json.loads((tmp_path / "results.json").read_text())
    p = res["particles"]
    assert p["lost"] == 0 and p["left_outlet"] > 0 and p["injected"] == p["scheduled"]
    # 4 mm grid: -3.4 % (20 mm side gaps): the cylinder at r2 interpolates across r2, where the swirl falls
    # steeply into the wide volute (K_v / K_2 = 0.34); one spacing inside r2 the grid gives the analytic head
    # within 0.3 % (docs/pump_wear.md, section 7)
    assert res["fluid_checks"]["euler_head_grid_m"] == pytest.approx(res["fluid_checks"]["euler_head_design_m"],
                                                                     rel=0.04)
    f = res["findings"]
    assert f["leading_edge_highest_normal_energy"]["per_area"]["verdict"] == "reproduced"
    assert f["particles_enter_along_pressure_side"]["pressure_half_fraction_entry"] > 0.6
    assert res["wear"]["window"]["samples"] == 10  # 12 revolutions - 2 of spin-up, one world
