"""The seed paper (Zhang et al. 2023) reproduced end to end with warpdem, in one command.

Our DEM (the model and protocols of calibration/configs/paper_gravel.yaml) runs at the paper's own
Appendix-A points, the surrogates are fitted on our angles, NSGA-II calibrates against the paper's
Table 1 lab values, the DEM confirms at the optimum, the hollow cylinder validates, and
reproduction.md / reproduction.html set the paper's tables beside ours (verdict first).

Usage (docs/reproduce_zhang2023.md)::

    python examples/reproduce_zhang2023.py --device cuda [--ray auto] [--points 140|N] [--out DIR]
    # in sittings of 10 minutes: repeat until it prints "complete:" (nothing already run is repeated)
    python examples/reproduce_zhang2023.py --device cuda --points 40 --time-limit 480
    # or in parts of your choosing, then the analysis:
    python examples/reproduce_zhang2023.py --device cuda --points 40 --max-samples 8 --only beta_dynamic
    python examples/reproduce_zhang2023.py --device cuda --points 40
    python examples/reproduce_zhang2023.py --points 40 --report-only          # the report from the records
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without install

from calibration.reproduction import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
