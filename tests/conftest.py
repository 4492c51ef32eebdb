import os

import warp as wp

wp.config.quiet = True
os.environ.setdefault("MPLBACKEND", "Agg")
