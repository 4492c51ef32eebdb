"""Pour spheres into a box, lift its baffle, measure the slope, write VTK (``warpdem pour``).

    python examples/pour_box.py [--spheres 20000 --device cuda --out out/pour]

The job lives in :mod:`calibration.pour_demo` so that ``warpdem pour`` works from an installed wheel.
"""
from calibration.pour_demo import main

if __name__ == "__main__":
    main()
