"""A world whose angle cannot be measured keeps what it measured before: the baffle test's bulk
density is taken from the fill before the lift, so a pile whose face leaves too few profile bins
for an angle (seen in 15 of 100 quick-scale baffle runs of the README's first diagnosis) still
gives its density, and the diagnosis's forward model reads it (the angle stays missing). The
report then says how many fills gave a value instead of printing "± nan"."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from calibration.model_description import ModelDescription
from validation.dem_forward import DEMForwardModel, ObservableSpec
from validation.report import _dem_cell

# a small quick-scale baffle fill; min_bins beyond the box's 12 profile bins: no angle can be measured
SETTINGS = {"fill_mass": 9.0, "lift_to": 0.25, "max_time_after_lift": 0.3, "min_bins": 50}


def test_bulk_density_survives_a_failed_angle(tmp_path):
    specs = [ObservableSpec("alpha", "baffle", "static_angle", SETTINGS),
             ObservableSpec("rho", "baffle", "bulk_density", SETTINGS)]
    fm = DEMForwardModel(ModelDescription.from_config({"contact_law": {"rolling": "none"}}), None, [], specs,
                         scale="quick", device="cpu", processes=1, cache=tmp_path / "dem_runs.jsonl")
    out = fm.evaluate((), [{"mu_s_pp": 0.5, "mu_s_pw": 0.5}], 1, ("alpha", "rho"))
    assert np.isnan(out[0, 0, 0])  # the angle failed ...
    assert 800.0 < out[0, 0, 1] < 3000.0  # ... the density of the fill was measured [kg/m^3]
    (rec,) = fm._cache.values()
    assert rec["status"] == "failed" and "no angle can be measured" in rec["error"]
    assert rec["observables"]["static_angle"] is None


def test_report_says_how_many_fills_gave_a_value():
    c = SimpleNamespace(replicates=2, n_ok=np.array([2, 1, 0]), mean=np.array([30.0, 11.5, np.nan]),
                        spread=np.array([0.5, np.nan, np.nan]))
    assert _dem_cell(c, 0) == "30 ± 0.5"
    assert _dem_cell(c, 1) == "11.5 (1 of 2 fills)"
    assert _dem_cell(c, 2) == "no value (0 of 2 fills)"
