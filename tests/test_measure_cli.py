"""``warpdem measure`` window and scale handling: --window is x right / z up from the origin
(px without a scale), a window beyond the image is an error naming its size, --scale must be > 0."""
from __future__ import annotations

import json
import math

import cv2
import pytest

from calibration.measurement.cli import measure_main
from calibration.measurement.render import synthetic_slope_image

ANGLE = 35.0
H, W = 480, 640  # synthetic_slope_image's default size: plateau at row 120 up to column 120, floor at row 420


@pytest.fixture
def pile(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cv2.imwrite("pile.png", synthetic_slope_image(ANGLE))
    return "pile.png"


def run(capsys, *argv: str) -> tuple[int, dict, str]:
    rc = measure_main([*argv, "--no-diagnostic"])
    cap = capsys.readouterr()
    return rc, (json.loads(cap.out) if cap.out.strip() else {}), cap.err


def test_window_without_scale_is_px_up_from_the_origin(pile, capsys):
    # x 360-540 px right of and z 20-200 px above the bottom-left pixel (row 479): rows 279-459,
    # where the slope runs (rows 288-414). Read as rows from the top (rows 20-200) it holds no material.
    rc, out, _ = run(capsys, pile, "--window", "360", "540", "20", "200")
    assert rc == 0, out
    assert abs(out["angle_deg"] - ANGLE) < 1.0
    rc_px, out_px, _ = run(capsys, pile, "--window-px", "360", "541", str(H - 1 - 200), str(H - 1 - 20 + 1))
    assert rc_px == 0 and out_px["angle_deg"] == pytest.approx(out["angle_deg"], abs=1e-9)


def test_window_px_counts_rows_from_the_top(pile, capsys):
    rc, out, _ = run(capsys, pile, "--window-px", "360", "541", "20", "200")
    assert rc == 1 and "no material" in out["error"]


@pytest.mark.parametrize("window", [
    ("--window-px", "0", "700", "0", "480"),
    ("--window-px", "0", "640", "0", "481"),
    ("--window", "0", "400", "0", "100", "--scale", "2"),  # 800 px wide at 2 px/mm
    ("--window", "300", "700", "0", "100"),  # px without a scale
])
def test_window_beyond_the_image_is_an_error_naming_its_size(pile, capsys, window):
    rc, out, err = run(capsys, pile, *window)
    assert rc == 1
    assert f"{W} x {H} px" in out["error"] and "beyond the image" in err


def test_window_of_the_whole_image_is_accepted(pile, capsys):
    rc, out, _ = run(capsys, pile, "--window-px", "0", str(W), "0", str(H))
    assert "beyond" not in out.get("error", "")


@pytest.mark.parametrize("scale", ["0", "-2", "nan", "inf", "two"])
def test_scale_must_be_positive(pile, capsys, scale):
    rc, _, err = run(capsys, pile, "--scale", scale)
    assert rc == 2 and "--scale must be" in err


def test_scale_and_window_in_mm(pile, capsys):
    # 2 px/mm, origin bottom-left: the same window as above in mm
    rc, out, _ = run(capsys, pile, "--scale", "2", "--window", "180", "270", "10", "100")
    assert rc == 0 and abs(out["angle_deg"] - ANGLE) < 1.0 and not math.isnan(out["angle_deg"])


def test_the_readme_photo_measures_its_known_slope(capsys, tmp_path, monkeypatch):
    """README: `warpdem measure examples/data/pile_photo.png --scale 2 --window 60 290 5 190 ...` on the
    shipped photo (examples/make_pile_photo.py: a 33 deg slope) gives 33 deg."""
    from pathlib import Path

    photo = Path(__file__).resolve().parents[1] / "examples" / "data" / "pile_photo.png"
    assert photo.is_file() and photo.stat().st_size < 200_000
    monkeypatch.chdir(tmp_path)
    rc, out, err = run(capsys, str(photo), "--scale", "2", "--window", "60", "290", "5", "190")
    assert rc == 0, err
    assert abs(out["angle_deg"] - 33.0) < 1.0
