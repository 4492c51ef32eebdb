"""Plain JSON values from experiment results: numpy scalars and arrays, materials and contact
laws become numbers, lists and dicts (non-finite numbers become null)."""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

import warpdem as wd

from ..materials import BulkMaterial

__all__ = ["jsonable"]


def jsonable(x: Any) -> Any:
    """``x`` as plain JSON values (see the module docstring)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.bool_,)):
        return bool(x)
    if isinstance(x, BulkMaterial):
        return jsonable(x.describe())
    if isinstance(x, wd.Material):
        return dataclasses.asdict(x)
    if isinstance(x, wd.ContactLaw):
        return jsonable(x.to_record())
    return x
