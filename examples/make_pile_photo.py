"""Make ``examples/data/pile_photo.png``: the photograph ``warpdem measure`` is shown with in the README.

A camera-like side view (:func:`calibration.measurement.render.render_side_view`) of a synthetic
baffle-test pile whose slope is known: spheres of 8-10 mm below a plateau 150 mm high that falls
at ``--angle`` degrees (default 33) from x = 60 mm, seen through the spec's y band of 30-170 mm,
2 px/mm, with the image's bottom-left corner at x = z = 0 and a little sensor noise. Then::

    warpdem measure examples/data/pile_photo.png --scale 2 --window 60 300 0 200

measures the slope (within about a degree of ``--angle``; the fit, the window and the scale:
``docs/experiments.md``, "The same angles from images").
"""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2

from calibration.measurement.render import render_side_view, synthetic_pile

HERE = Path(__file__).resolve().parent
#: image scale [px/mm] and extent (x from, x to, z from, z to) [m]: the README's --scale and --window
SCALE_PX_PER_MM = 2.0
EXTENT_M = (0.0, 0.30, 0.0, 0.20)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--angle", type=float, default=33.0, help="slope of the synthetic pile [deg]")
    ap.add_argument("--out", default=str(HERE / "data" / "pile_photo.png"), help="PNG to write")
    args = ap.parse_args(argv)
    pos, radii = synthetic_pile(args.angle, height=0.15, crest_x=0.06, rng=7)
    view = render_side_view(pos, radii, slab=(0.030, 0.170), scale_px_per_mm=SCALE_PX_PER_MM, extent_m=EXTENT_M,
                            noise_std=4.0, rng=1)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), view.image, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"{out}: {view.image.shape[1]} x {view.image.shape[0]} px, {SCALE_PX_PER_MM:g} px/mm, slope {args.angle:g} deg, "
          f"{out.stat().st_size / 1024:.0f} kB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
