"""Image pipeline (spec section "Images") on synthetic pictures with known slopes."""

import json
import math

import cv2
import numpy as np
import pytest

from calibration.measurement import (
    MeasurementError,
    measure_image,
    synthetic_slope_image,
    video_frame_indices,
    video_frames_for_revolutions,
)
from calibration.measurement.cli import measure_main

H, W = 480, 640
CREST, TOP, FLOOR = 120.0, 120.0, 420.0


def slope_window(angle):
    """Pixel window over the sloped part only (plateau and floor excluded)."""
    toe = CREST + (FLOOR - TOP) / math.tan(math.radians(angle))
    return (CREST + 12, min(toe, W) - 12, 60, H - 20)


def hard_image(angle, seed, gradient=0.6):
    """Noise, a strong lighting gradient (background 2.5x darker at the far
    corner), a textured background with dark specks."""
    return synthetic_slope_image(angle, size_px=(H, W), crest_col=CREST, top_row=TOP, floor_row=FLOOR,
                                 noise_std=12.0, gradient=gradient, texture=25.0, specks=2.0, rng=seed)


@pytest.mark.parametrize("angle", [20.0, 26.0, 33.0, 39.0, 45.0])
def test_known_slope_with_noise_lighting_and_texture(angle):
    img = hard_image(angle, seed=int(angle))
    res = measure_image(img, window=slope_window(angle), window_units="px")
    assert abs(res.angle_deg - angle) < 0.5
    assert res.slope < 0  # falls to the right, z up
    assert res.material == "dark"
    assert res.units == "px" and res.n_points == res.points.shape[0] > 100


def test_uneven_lighting_needs_the_correction():
    """The gradient above is strong enough that plain Otsu is off by > 0.5 deg,
    and the specks need the denoising (opening / largest region)."""
    errs = []
    for angle in (26.0, 33.0, 39.0):
        img = hard_image(angle, seed=int(angle))
        win = slope_window(angle)
        assert abs(measure_image(img, window=win, window_units="px").angle_deg - angle) < 0.5
        errs.append(abs(measure_image(img, window=win, window_units="px",
                                      illumination_degree=0).angle_deg - angle))
        raw = measure_image(img, window=win, window_units="px", open_px=0, keep_largest=False)
        assert abs(raw.angle_deg - angle) > 5.0
    assert max(errs) > 0.5


def test_each_difficulty_alone_and_colour_input():
    angle = 31.0
    for kw in (dict(noise_std=25.0), dict(gradient=0.6), dict(texture=35.0)):
        img = synthetic_slope_image(angle, rng=3, **kw)
        assert abs(measure_image(img, window=slope_window(angle), window_units="px").angle_deg - angle) < 0.5
    bgr = cv2.cvtColor(hard_image(angle, 4), cv2.COLOR_GRAY2BGR)
    assert abs(measure_image(bgr, window=slope_window(angle), window_units="px").angle_deg - angle) < 0.5


def test_mm_scale_origin_and_band():
    angle, scale = 35.0, 2.0  # px/mm
    img = hard_image(angle, 5)
    origin = (CREST, FLOOR)  # crest column, floor row -> x = 0 at the crest, z = 0 on the floor
    h_mm = (FLOOR - TOP) / scale
    res = measure_image(img, scale_px_per_mm=scale, origin_px=origin,
                        window=(-20, (W - CREST) / scale, -5, h_mm + 30), fit_band=(0.15, 0.85), h_ref=h_mm)
    assert res.units == "mm"
    assert abs(res.angle_deg - angle) < 0.5
    assert res.intercept == pytest.approx(h_mm, abs=2.0)  # line passes through the crest
    z = res.points[:, 1]
    assert z.min() >= 0.15 * h_mm - 1e-9 and z.max() <= 0.85 * h_mm + 1e-9
    # default h_ref: highest edge point (pile peak, spec C)
    res2 = measure_image(img, scale_px_per_mm=scale, origin_px=origin,
                         window=(-20, (W - CREST) / scale, -5, h_mm + 30), fit_band=(0.2, 0.8))
    assert abs(res2.angle_deg - angle) < 0.5


def test_bright_material_auto_and_flag_and_threshold():
    angle = 28.0
    inv = 255 - hard_image(angle, 6)
    win = slope_window(angle)
    auto = measure_image(inv, window=win, window_units="px")
    assert auto.material == "bright" and abs(auto.angle_deg - angle) < 0.5
    flag = measure_image(inv, window=win, window_units="px", material="bright")
    assert flag.angle_deg == pytest.approx(auto.angle_deg)
    clean = synthetic_slope_image(angle, noise_std=3.0, rng=7)
    fixed = measure_image(clean, window=win, window_units="px", threshold=125, material="dark")
    assert fixed.threshold == 125 and abs(fixed.angle_deg - angle) < 0.5


def test_no_material_raises():
    rng = np.random.default_rng(0)
    blank = synthetic_slope_image(30.0, top_row=H + 50, floor_row=H + 50, noise_std=12.0,
                                  gradient=0.5, texture=25.0, rng=8)  # background only
    with pytest.raises(MeasurementError, match="no material"):
        measure_image(blank)
    with pytest.raises(MeasurementError, match="no material"):
        measure_image(np.full((200, 300), 128, np.uint8))
    noise = np.clip(150 + rng.normal(0, 20, (300, 400)), 0, 255).astype(np.uint8)
    with pytest.raises(MeasurementError, match="no material"):
        measure_image(noise)
    # only stray dark specks (two-toned, but no pile), with the side given or not
    specks = synthetic_slope_image(30.0, top_row=H + 50, floor_row=H + 50, noise_std=12.0, specks=2.0, rng=8)
    for side in ("auto", "dark"):
        with pytest.raises(MeasurementError, match="no material"):
            measure_image(specks, material=side)


def test_flat_surface_raises():
    flat = synthetic_slope_image(0.0, top_row=300, noise_std=12.0, gradient=0.5, texture=25.0, rng=9)
    with pytest.raises(MeasurementError, match="flat"):
        measure_image(flat)
    # the plateau of a real pile alone is flat as well
    img = hard_image(35.0, 10)
    with pytest.raises(MeasurementError, match="flat"):
        measure_image(img, window=(0, CREST - 10, 60, H - 20), window_units="px")


def test_too_few_edge_points_and_bad_window_raise():
    img = hard_image(35.0, 11)
    with pytest.raises(MeasurementError, match="too few edge points"):
        measure_image(img, window=(200, 205, 60, H - 20), window_units="px")
    with pytest.raises(MeasurementError, match="outside the image"):
        measure_image(img, window=(2000, 3000, 0, 10), window_units="px")
    with pytest.raises(MeasurementError, match="cannot read"):
        measure_image("/nonexistent/pile.png")


def test_diagnostic_picture(tmp_path):
    angle = 33.0
    out = tmp_path / "diag" / "pile.png"
    res = measure_image(hard_image(angle, 12), window=slope_window(angle), window_units="px",
                        diagnostic_path=out)
    pic = cv2.imread(str(out))
    assert pic is not None and pic.shape == (H, W, 3)
    # the fitted line is drawn in red somewhere inside the window
    red = (pic[:, :, 2] > 200) & (pic[:, :, 1] < 60) & (pic[:, :, 0] < 60)
    assert red.sum() > 100
    assert res.as_dict()["angle_deg"] == pytest.approx(res.angle_deg)


def drum_frame(angle, seed):
    """Drum crop: a straight surface through the frame centre (col 120, row 100),
    falling to the right; no plateau, no floor."""
    crest = 120.0 - 1100.0 / math.tan(math.radians(angle))
    return synthetic_slope_image(angle, size_px=(200, 240), crest_col=crest, top_row=-1000.0,
                                 floor_row=1000.0, noise_std=8.0, rng=seed)


def test_video_frame_indices():
    idx, t = video_frame_indices(10.0, 30.0, discard=1, record=2)  # 20 frames per revolution
    assert idx.tolist() == [20, 30, 39, 40, 50, 59]
    np.testing.assert_allclose(t, idx / 10.0)
    with pytest.raises(MeasurementError, match="frames"):
        video_frame_indices(10.0, 30.0, discard=1, record=2, n_frames=50)


def test_video_frames_for_revolutions_sequence():
    fps, rpm = 10.0, 30.0
    rng = np.random.default_rng(1)
    true = 47.0 + 3.0 * rng.random(60)
    frames = [drum_frame(a, i) for i, a in enumerate(true)]
    # only the picked frames are measured: make the others unmeasurable to prove it
    idx, _ = video_frame_indices(fps, rpm, 1, 2)
    frames = [f if i in set(idx.tolist()) else np.full_like(f, 128) for i, f in enumerate(frames)]
    res = video_frames_for_revolutions(frames, fps, rpm, 1, 2, window=(20, 220, 20, 180), window_units="px")
    assert res.frame_indices.tolist() == idx.tolist()
    picked = true[idx]
    assert np.all(np.abs(np.array([f.angle_deg for f in res.frames]) - picked) < 0.5)
    expect = math.degrees(math.atan(np.mean(np.tan(np.radians(picked)))))
    assert abs(res.angle_deg - expect) < 0.5
    assert res.std_deg == pytest.approx(np.std([f.angle_deg for f in res.frames], ddof=1))


def test_video_file_roundtrip(tmp_path):
    path = str(tmp_path / "drum.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (240, 200), False)
    if not writer.isOpened():
        pytest.skip("no MJPG writer in this OpenCV build")
    for i in range(60):
        writer.write(drum_frame(49.0, i))
    writer.release()
    res = video_frames_for_revolutions(path, None, 30.0, 1, 2, window=(20, 220, 20, 180), window_units="px")
    assert len(res.frames) == 6
    assert abs(res.angle_deg - 49.0) < 0.5
    with pytest.raises(MeasurementError, match="frame"):
        video_frames_for_revolutions(path, None, 30.0, 2, 2)


def test_cli_image(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    angle = 36.0
    cv2.imwrite("pile.png", hard_image(angle, 13))
    c0, c1, r0, r1 = slope_window(angle)
    rc = measure_main(["pile.png", "--window-px", str(c0), str(c1), str(r0), str(r1), "--json", "out.json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and abs(out["angle_deg"] - angle) < 0.5
    assert (tmp_path / "pile_measure.png").exists()
    assert json.loads((tmp_path / "out.json").read_text())["angle_deg"] == out["angle_deg"]
    cv2.imwrite("blank.png", np.full((100, 100), 200, np.uint8))
    assert measure_main(["blank.png"]) == 1
    assert "no material" in json.loads(capsys.readouterr().out)["error"]
    assert measure_main(["--bogus"]) == 2
