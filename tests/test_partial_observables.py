"""A world whose angle cannot be measured keeps, in its record, what it measured before: the
baffle test's bulk density is taken from the fill before the lift, so a pile whose face leaves too
few profile bins for an angle (7-15 of the 100 quick-scale worlds of the README's first diagnosis)
still reports its density. The diagnosis leaves such a world out whole (the angles a failure hides
are the steep ones; fitting the density of those runs alone moved the first diagnosis's best fit to
where no angle could be measured). The report says how many fills gave a value instead of printing
"± nan", and the verdict names an observable the DEM could not measure at the best fit instead of
counting it among those beyond 2 sigma."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from calibration.model_description import ModelDescription
from validation.dem_forward import DEMForwardModel, ObservableSpec
from validation.report import _dem_cell

# a small quick-scale baffle fill; min_bins beyond the box's 12 profile bins: no angle can be measured
SETTINGS = {"fill_mass": 9.0, "lift_to": 0.25, "max_time_after_lift": 0.3, "min_bins": 50}


def test_bulk_density_of_a_failed_angle_is_recorded(tmp_path):
    specs = [ObservableSpec("alpha", "baffle", "static_angle", SETTINGS),
             ObservableSpec("rho", "baffle", "bulk_density", SETTINGS)]
    fm = DEMForwardModel(ModelDescription.from_config({"contact_law": {"rolling": "none"}}), None, [], specs,
                         scale="quick", device="cpu", processes=1, cache=tmp_path / "dem_runs.jsonl")
    out = fm.evaluate((), [{"mu_s_pp": 0.5, "mu_s_pw": 0.5}], 1, ("alpha", "rho"))
    (rec,) = fm._cache.values()
    assert rec["status"] == "failed" and "no angle can be measured" in rec["error"]
    assert rec["observables"]["static_angle"] is None
    assert 800.0 < rec["observables"]["bulk_density"] < 3000.0  # the fill's density was measured [kg/m^3]
    assert np.isnan(out).all()  # the diagnosis leaves the failed world out whole
    assert fm.dem_failures["baffle"]["worlds"] == 1  # and says so (warpdem diagnose prints it)
    assert "no angle can be measured" in fm.dem_failures["baffle"]["first_error"]


def test_report_says_how_many_fills_gave_a_value():
    c = SimpleNamespace(replicates=2, n_ok=np.array([2, 1, 0]), mean=np.array([30.0, 11.5, np.nan]),
                        spread=np.array([0.5, np.nan, np.nan]))
    assert _dem_cell(c, 0) == "30 ± 0.5"
    assert _dem_cell(c, 1) == "11.5 (1 of 2 fills)"
    assert _dem_cell(c, 2) == "no value (0 of 2 fills)"


def test_the_verdict_names_an_observable_the_dem_could_not_measure_at_the_best_fit():
    """When every fill at the recalibrated best fit failed to measure one observable, the headline
    says so instead of counting it among those beyond 2 sigma."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from test_diagnosis_logic import BASE, FAST, ROLLING, TRUTHS, AnalyticGranularModel, lab_observables

    from validation import ForwardModel, diagnose

    obs = lab_observables(TRUTHS["rolling_resistance"], ("rolling_resistance",), seed=7)
    lost = obs[0].key

    class FailsAtConfirmations(ForwardModel):
        """The analytic model, but a single-set request with rolling resistance (a confirmation)
        measures nothing for the first observable."""

        def __init__(self):
            self.inner = AnalyticGranularModel(0)

        def evaluate(self, effects, parameter_sets, replicates, keys):
            out = self.inner.evaluate(effects, parameter_sets, replicates, keys)
            if len(parameter_sets) == 1 and "rolling_resistance" in effects and lost in keys:
                out[..., list(keys).index(lost)] = np.nan
            return out

    result = diagnose(obs, BASE, [ROLLING], FailsAtConfirmations(), FAST)
    name = obs[0].name
    assert f"the DEM gave no value for {name}" in result.headline, result.headline
    assert "remain beyond" not in result.headline
    assert not result.met
    f = result.forward
    assert 0 < f["missing_values"] < f["values"]  # counted, and the report's footer says it
    from validation.report import build_report

    assert f"{f['missing_values']} of {f['values']} values not measured" in build_report(result, {}).to_html()
