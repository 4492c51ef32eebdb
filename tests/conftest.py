import os

from warpdem.warp_output import quiet_warp

quiet_warp()
os.environ.setdefault("MPLBACKEND", "Agg")
