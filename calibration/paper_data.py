"""Data and reported numbers of the seed paper.

Zhang et al. (2023), "Calibration and Validation of Flow Parameters of Irregular
Gravel Particles Based on the Multi-Response Concept". The 140 LHS samples of
Appendix A are shipped as ``calibration/data/zhang2023_appendix_a.csv``: rows 1-100
are the RBF training set, rows 101-140 the validation set (Section 3.1), the latter
with the paper's RBF predictions.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .designs import ParameterSpace, paper_parameter_space

__all__ = [
    "PAPER_CSV",
    "PARAMETER_NAMES",
    "RESPONSE_NAMES",
    "PAPER_R2",
    "TARGETS_DEG",
    "PAPER_OPTIMUM",
    "TABLE9_DEM_AT_OPTIMUM_DEG",
    "TABLE9_RELATIVE_ERROR_PERCENT",
    "TABLE8_NSGA2",
    "PAPER_SENSITIVITY_PERCENT",
    "PAPER_TOLERANCE_FRACTION",
    "PaperData",
    "load_paper_data",
]

PAPER_CSV = Path(__file__).resolve().parent / "data" / "zhang2023_appendix_a.csv"

PARAMETER_NAMES = ("mu_s_pp", "mu_r_pp", "mu_s_pw", "mu_r_pw")
RESPONSE_NAMES = ("alpha_static_deg", "beta_dynamic_deg")

# Section 4.1, Figure 11: "R^2 ... 0.965 for the static ... and 0.958 for the dynamic
# angle of repose" (40 validation samples).  Note: recomputing Eq. (17) from the
# Appendix A predictions gives 0.9645 / 0.9549; the reported numbers match the squared
# Pearson correlation of the linear fit in Figure 11 (0.9652 / 0.9578).
PAPER_R2 = {"alpha_static_deg": 0.965, "beta_dynamic_deg": 0.958}

# Table 1 / Eq. (15): measured static (baffle lifting) and dynamic (rotary drum, 30 rpm)
# angles of repose in degrees.  (Section 4.2 misprints the static one as 32.054.)
TARGETS_DEG = {"alpha_static_deg": 32.534, "beta_dynamic_deg": 49.058}

# Section 4.2: NSGA-II optimum (dimensionless friction coefficients).
PAPER_OPTIMUM = {"mu_s_pp": 0.323, "mu_r_pp": 0.061, "mu_s_pw": 0.316, "mu_r_pw": 0.441}

# Table 9: DEM re-simulation at the optimum (degrees) and relative error to target (%).
TABLE9_DEM_AT_OPTIMUM_DEG = {"alpha_static_deg": 34.094, "beta_dynamic_deg": 48.838}
TABLE9_RELATIVE_ERROR_PERCENT = {"alpha_static_deg": 4.795, "beta_dynamic_deg": 0.448}

# Table 8: NSGA-II settings.
TABLE8_NSGA2 = {
    "pop_size": 500,
    "n_generations": 200,
    "crossover_prob": 0.9,
    "crossover_eta": 10.0,
    "mutation_eta": 20.0,
}

# Section 4.1 text on Figure 13 (only these two values are given in the text):
# mu_s_pw -> dynamic angle 54.10 %, mu_s_pp -> static angle 48.22 %.
PAPER_SENSITIVITY_PERCENT = {
    ("beta_dynamic_deg", "mu_s_pw"): 54.10,
    ("alpha_static_deg", "mu_s_pp"): 48.22,
}

# Section 4.2: "5% accuracy ... as a tolerance criterion".
PAPER_TOLERANCE_FRACTION = 0.05


@dataclass(frozen=True)
class PaperData:
    """Appendix A split into training (rows 1-100) and validation (rows 101-140).

    ``X_*`` are friction coefficients (dimensionless), ``Y_*`` angles in degrees with
    columns ``RESPONSE_NAMES``; ``Y_val_paper_pred`` holds the paper's RBF predictions.
    """

    X_train: np.ndarray
    Y_train: np.ndarray
    X_val: np.ndarray
    Y_val: np.ndarray
    Y_val_paper_pred: np.ndarray
    space: ParameterSpace
    parameter_names: tuple[str, ...] = PARAMETER_NAMES
    response_names: tuple[str, ...] = RESPONSE_NAMES


def load_paper_data(path: str | Path = PAPER_CSV) -> PaperData:
    """Read the Appendix A CSV; raises ValueError naming a missing column or bad role."""
    path = Path(path)
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise ValueError(f"{path}: no data rows")
    need = ("role",) + PARAMETER_NAMES + RESPONSE_NAMES + ("alpha_predicted_deg", "beta_predicted_deg")
    missing = [c for c in need if c not in rows[0]]
    if missing:
        raise ValueError(f"{path}: missing column(s) {missing}")
    roles = [r["role"].strip() for r in rows]
    bad = sorted(set(roles) - {"training", "validation"})
    if bad:
        raise ValueError(f"{path}: unknown role value(s) {bad}")

    def arr(sel, cols):
        return np.array([[float(r[c]) for c in cols] for r, ok in zip(rows, sel) if ok], dtype=float)

    tr = [r == "training" for r in roles]
    va = [r == "validation" for r in roles]
    return PaperData(
        X_train=arr(tr, PARAMETER_NAMES),
        Y_train=arr(tr, RESPONSE_NAMES),
        X_val=arr(va, PARAMETER_NAMES),
        Y_val=arr(va, RESPONSE_NAMES),
        Y_val_paper_pred=arr(va, ("alpha_predicted_deg", "beta_predicted_deg")),
        space=paper_parameter_space(),
    )
