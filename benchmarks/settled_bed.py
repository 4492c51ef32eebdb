"""Settled-bed engine benchmark (``warpdem bench``): one JSON line; see :mod:`warpdem.bench_settled_bed`.

    python benchmarks/settled_bed.py --spheres 1000000 --device cuda
"""
from warpdem.bench_settled_bed import *  # noqa: F401,F403  (build, loose_fill, ... for the other benchmarks)
from warpdem.bench_settled_bed import main

if __name__ == "__main__":
    main()
