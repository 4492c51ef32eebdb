"""Campaign HTML report: verdict against the tolerance, plain-word warnings, embedded figures."""
from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from calibration.report_campaign import (WEAK_SURROGATE_R2, campaign_basis, campaign_verdict,
                                         write_campaign_report)
from calibration.sensitivity import SobolResult, plot_sensitivity


def fake_results(dem_static: float = 33.0, r2=(0.9, 0.95), spread: float = 0.3,
                 validation_dem: float | None = None) -> dict:
    """A campaign's results dict; ``validation_dem`` adds a validation against a measured 6.40 deg."""
    X = np.random.default_rng(0).uniform(0, 0.8, (20, 2))
    extra = {} if validation_dem is None else {"validation": {
        "experiment": "cylinder", "scale": "quick", "dem_deg": validation_dem, "measured_deg": 6.40,
        "relative_error_pct": abs(validation_dem - 6.40) / 6.40 * 100, "failed": []}}
    return {**extra,
        "name": "gravel", "parameters": ["mu_s_pp", "mu_r_pp"], "fixed": {}, "device": "cpu", "wall_s": 12.0,
        "model": {"material": {"name": "quick spheres d=24-30 mm", "density": 2661.0},
                  "contact_law": {"normal": "hertz", "rolling": "epsd"}},
        "design": {"samples": 20, "held_out": 4, "X": X.tolist(), "failed": []},
        "surrogate": {"held_out": {"n": 4, "r2": list(r2), "rmse_deg": [0.5, 0.6]}},
        "optimisation": {"tolerance_deg": {"alpha_static": 1.0, "beta_dynamic": 1.0},
                         "acceptable_ranges": {"mu_s_pp": [0.3, 0.3 + spread], "mu_r_pp": [0.05, 0.05 + spread]}},
        "confirmation": {"parameters": {"mu_s_pp": 0.32, "mu_r_pp": 0.06},
                         "responses": {"alpha_static": dict(target_deg=32.5, surrogate_deg=32.7, dem_deg=dem_static,
                                                            abs_error_deg=abs(dem_static - 32.5)),
                                       "beta_dynamic": dict(target_deg=49.1, surrogate_deg=49.0, dem_deg=49.3,
                                                            abs_error_deg=0.2)}},
    }


def test_met_when_every_confirmation_is_within_tolerance(tmp_path):
    text = write_campaign_report(fake_results(33.0), tmp_path).read_text()
    assert 'class="verdict met"' in text and "The surrogate for" not in text and "pin the" not in text
    assert "quick spheres d=24-30 mm" in text and "epsd" in text


def test_not_met_and_warnings_in_plain_words(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    fig.savefig(tmp_path / "sensitivity.png")
    text = write_campaign_report(fake_results(35.0, r2=(-6.7, 0.9), spread=0.75), tmp_path).read_text()
    assert 'class="verdict notmet"' in text and "alpha_static outside the tolerance" in text
    assert "The surrogate for alpha_static predicts nothing" in text and "-6.70" in text
    assert "do not pin the" in text
    assert "data:image/png;base64," in text  # the figure is embedded, no external file


@pytest.mark.skipif(shutil.which("chromium") is None, reason="headless chromium not installed")
def test_renders_in_headless_chromium(tmp_path):
    path = write_campaign_report(fake_results(35.0, r2=(-6.7, 0.9), spread=0.75), tmp_path)
    shot = tmp_path / "shot.png"
    subprocess.run(["chromium", "--headless", "--no-sandbox", "--disable-gpu", f"--screenshot={shot}",
                    "--window-size=1100,1400", path.as_uri()], check=True, capture_output=True, timeout=120)
    from PIL import Image
    img = np.asarray(Image.open(shot).convert("L"), dtype=float)
    assert img.std() > 10  # not blank


def test_recorded_vtk_series_are_listed(tmp_path):
    res = fake_results(33.0)
    assert "ParaView" not in write_campaign_report(res, tmp_path).read_text()
    res["vtk_series"] = ["vtk/sample_003/alpha_static", "vtk/target/beta_dynamic"]
    text = write_campaign_report(res, tmp_path).read_text()
    assert "ParaView time series" in text and "vtk/sample_003/alpha_static" in text


def _sensitivity(results: dict) -> dict:
    """``results`` with Sobol indices as the campaign stores them (two responses, two parameters)."""
    return {**results, "sensitivity": {"first_order": [[0.6, 0.3], [0.2, 0.7]], "total_order": [[0.65, 0.35],
                                       [0.25, 0.75]], "n": 64, "parameters": ["mu_s_pp", "mu_r_pp"],
                                       "responses": ["alpha_static", "beta_dynamic"]}}


def test_a_met_verdict_states_its_basis_and_stays_green_when_it_is_strong(tmp_path):
    verdict, _ = campaign_verdict(fake_results(33.0, r2=(0.9, 0.95), validation_dem=6.9))
    assert verdict.met and verdict.tone == "met" and not verdict.caveats
    basis = [d for d in verdict.details if d.startswith("Basis of this verdict")]
    assert basis and "alpha_static 0.90" in basis[0] and "beta_dynamic 0.95" in basis[0] and "0.50 deg off" in basis[0]
    assert dict(verdict.numbers)["surrogate held-out R² (lowest)"] == "0.90 (alpha_static)"
    text = write_campaign_report(fake_results(33.0, validation_dem=6.9), tmp_path).read_text()
    assert 'class="verdict met"' in text and "Weak basis" not in text


def test_met_on_weak_surrogates_and_a_failed_validation_is_amber_with_the_reasons(tmp_path):
    """The quick calibration of issue 30: both targets met, held-out R² -0.97 and -1.05, validation 31.5 % off."""
    res = fake_results(33.0, r2=(-0.97, -1.05), validation_dem=6.40 * 1.315)
    verdict, _ = campaign_verdict(res)
    assert verdict.met is True and verdict.tone == "weak" and verdict.status_text == "Met on a weak basis"
    assert verdict.headline.startswith("Calibration met on a weak basis")
    for words in ("alpha_static predicts nothing (held-out R² -0.97)", "beta_dynamic predicts nothing (held-out R² -1.05)",
                  "31.5 % off"):
        assert words in verdict.headline
    assert len(verdict.caveats) == 3 and all(c in verdict.details for c in verdict.caveats)  # the CLI prints details
    text = write_campaign_report(res, tmp_path).read_text()
    assert 'class="verdict weak"' in text and 'class="verdict met"' not in text
    assert text.count("Weak basis:") == 3 and "Address the warnings above" in text


@pytest.mark.parametrize("r2, validation_dem, weak", [
    ((0.9, WEAK_SURROGATE_R2 - 0.01), None, True),   # one surrogate just below the bar
    ((0.9, WEAK_SURROGATE_R2), None, False),          # at the bar
    ((0.9, 0.95), 6.40 + 1.6, True),                  # validation beyond the 1.0 deg tolerance
    ((0.9, 0.95), 6.40 + 0.9, False),                 # within it
    ((0.9, 0.95), None, False),
])
def test_each_weakness_alone_turns_the_verdict_amber(r2, validation_dem, weak):
    res = fake_results(33.0, r2=r2, validation_dem=validation_dem)
    verdict, _ = campaign_verdict(res)
    assert (verdict.tone == "weak") is weak and bool(campaign_basis(res).weak) is weak
    assert verdict.met is True


def test_an_acceptable_set_over_the_whole_box_is_a_weak_basis_and_a_miss_stays_red():
    verdict, _ = campaign_verdict(fake_results(33.0, spread=0.75))
    assert verdict.tone == "weak" and "spans most of the box" in verdict.headline
    verdict, _ = campaign_verdict(fake_results(35.0, r2=(-6.7, 0.9), spread=0.75))
    assert verdict.tone == "notmet" and verdict.caveats  # red, and still says why the basis is weak


def test_a_failed_validation_is_a_weak_basis():
    res = fake_results(33.0)
    res["validation"] = {"experiment": "cylinder", "scale": "quick", "dem_deg": None, "measured_deg": 6.4,
                         "relative_error_pct": None, "failed": ["no pile"]}
    verdict, _ = campaign_verdict(res)
    assert verdict.tone == "weak" and "the validation on the cylinder failed" in verdict.headline


def test_sensitivity_plot_from_weak_surrogates_carries_a_warning(tmp_path):
    res = _sensitivity(fake_results(33.0, r2=(0.3, 0.95)))
    text = write_campaign_report(res, tmp_path).read_text()
    assert "Warning: drawn from surrogates that predict poorly (held-out R² alpha_static 0.30" in text
    assert (tmp_path / "sensitivity.png").is_file()  # redrawn with the warning on it
    strong = tmp_path / "strong"
    text = write_campaign_report(_sensitivity(fake_results(33.0)), strong).read_text()
    assert "Warning: drawn from" not in text and not (strong / "sensitivity.png").exists()


def test_plot_sensitivity_draws_the_warning_on_the_figure():
    import matplotlib.pyplot as plt

    sob = SobolResult(["a", "b"], ["y"], np.array([[0.5, 0.4]]), np.array([[0.6, 0.4]]), 64, 256)
    fig = plot_sensitivity(sob, warning="drawn from weak surrogates")
    assert fig._suptitle is not None and "Warning: drawn from weak surrogates" in fig._suptitle.get_text()
    plt.close(fig)
    fig = plot_sensitivity(sob)
    assert fig._suptitle is None
    plt.close(fig)
