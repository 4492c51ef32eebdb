"""The generic HTML report builder (calibration/reporting.py): structure, escaping, bad input,
and that a report renders in headless Chromium (skipped where no Chromium binary exists)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from calibration.reporting import Cell, Figure, Report, Section, Table, Verdict, format_value


def _figure() -> Figure:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3))
    rpm = np.array([15, 30, 45])
    ax.errorbar(rpm, [38.0, 40.5, 43.0], yerr=0.6, fmt="ko", capsize=3, label="measured")
    ax.plot(rpm, [37.5, 41.0, 42.2], "s-", color="tab:blue", label="model")
    ax.set_xlabel("drum speed (rpm)")
    ax.set_ylabel("dynamic angle (deg)")
    ax.set_title("Drum angle against speed")
    ax.legend()
    f = Figure.from_matplotlib(fig, caption="Measured (mean ± SE) and simulated drum angles.", alt="drum plot")
    plt.close(fig)
    return f


def _report(met: bool | None = True) -> Report:
    return Report(
        title="Diagnosis of <gravel> & friends",
        subtitle="quick scale, 3 repeats per condition",
        verdict=Verdict(met=met, headline="Every observable within 2 sigma",
                        details=["Rolling resistance was added."],
                        numbers=[("largest |z|", 1.234567), ("chi2 per observable", 0.41)]),
        sections=[
            Section("Comparison", [
                "Measured mean ± standard error against the simulated mean.",
                Table(["observable", "measured", "simulated", "z"],
                      [["static angle (deg)", 34.1, 33.72, Cell(0.8, "good")],
                       ["bulk density (kg/m3)", 1612.0, 1650.3, Cell(-3.4, "bad")]],
                      caption="Comparison at the best parameters"),
                _figure(),
            ]),
        ],
        next_steps=["Measure the drum at 60 rpm.", "Re-run with <add: rolling_resistance>."],
        footer="warpdem",
    )


def test_report_reads_top_down_and_is_self_contained():
    text = _report().to_html()
    # order: verdict, then the sections, then what to do next
    i_verdict, i_section, i_next = text.index('id="verdict"'), text.index("<h2>Comparison"), text.index('id="next"')
    assert i_verdict < i_section < i_next
    # user text is escaped, never interpreted as markup
    assert "&lt;gravel&gt; &amp; friends" in text and "<gravel>" not in text
    assert "&lt;add: rolling_resistance&gt;" in text
    # self-contained: the figure is a data URI, nothing is fetched from elsewhere
    assert text.count('src="data:image/png;base64,') == 1
    assert not re.search(r"""(src|href)=["']?(https?:|//)""", text)
    assert "<link" not in text and "@import" not in text and "url(" not in text
    # tones and numbers
    assert 'class="num good">0.800<' in text and 'class="num bad">-3.40<' in text
    assert "1.23" in text and 'class="verdict met"' in text
    assert 'class="verdict notmet"' in _report(met=False).to_html()


def test_format_value():
    assert format_value(None) == "–" and format_value(float("nan")) == "–"
    assert format_value(1612.0) == "1612" and format_value(0.012345) == "0.0123"
    assert format_value(2.5e-7) == "2.50e-07" and format_value(True) == "yes" and format_value("x") == "x"
    assert format_value(np.float64(33.456)) == "33.5"


def test_bad_input_names_the_problem():
    with pytest.raises(ValueError, match="row 0 has 2 cells but the table has 3 columns"):
        Table(["a", "b", "c"], [[1, 2]])
    with pytest.raises(ValueError, match="PNG"):
        Figure(b"GIF89a....")
    with pytest.raises(ValueError, match="tone"):
        Cell(1.0, "red")
    with pytest.raises(ValueError, match="met must be"):
        Verdict(met="yes", headline="x")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="blocks must be"):
        Section("s", [3.0])  # type: ignore[list-item]
    with pytest.raises(FileNotFoundError):
        Figure.from_path("/nonexistent/figure.png")


def chromium_binary() -> str | None:
    """A Chromium/Chrome executable on PATH, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def screenshot_html(html_path: Path, png_path: Path, width: int = 1200, height: int = 2000) -> None:
    """Render ``html_path`` in headless Chromium into ``png_path`` (raises on failure)."""
    binary = chromium_binary()
    if binary is None:
        pytest.skip("no Chromium/Chrome binary on PATH (apt-get install chromium)")
    cmd = [binary, "--headless", "--disable-gpu", "--hide-scrollbars", f"--screenshot={png_path}",
           f"--window-size={width},{height}", html_path.resolve().as_uri()]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        cmd.insert(1, "--no-sandbox")  # Chromium refuses to run as root inside its sandbox
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    if not png_path.is_file():
        raise AssertionError(f"Chromium wrote no screenshot (rc {proc.returncode}): {proc.stderr[-2000:]}")


def test_report_renders_in_headless_chromium(tmp_path):
    import matplotlib.image as mpimg

    html_path = _report().write(tmp_path / "sub" / "report.html")
    png_path = tmp_path / "report.png"
    screenshot_html(html_path, png_path)
    img = mpimg.imread(png_path)[..., :3]
    assert img.shape[0] >= 1000 and img.shape[1] >= 1000
    assert float(img.std()) > 0.05, "screenshot is blank"
    # the verdict block is drawn with its green border (#1a7f37): the style sheet was applied
    green = np.array([0x1A, 0x7F, 0x37]) / 255.0
    assert int(np.sum(np.all(np.abs(img - green) < 0.04, axis=-1))) > 500
    # the embedded figure is shown: the plot's blue line (tab:blue #1f77b4) appears
    blue = np.array([0x1F, 0x77, 0xB4]) / 255.0
    assert int(np.sum(np.all(np.abs(img - blue) < 0.06, axis=-1))) > 50
    keep = os.environ.get("WARPDEM_KEEP_SCREENSHOTS")
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        shutil.copy(png_path, Path(keep) / "test_report_screenshot.png")
