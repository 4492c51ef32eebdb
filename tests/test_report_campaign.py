"""Campaign HTML report: verdict against the tolerance, plain-word warnings, embedded figures."""
from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from calibration.report_campaign import write_campaign_report


def fake_results(dem_static: float = 33.0, r2=(0.9, 0.95), spread: float = 0.3) -> dict:
    X = np.random.default_rng(0).uniform(0, 0.8, (20, 2))
    return {
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
