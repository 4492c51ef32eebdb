"""Plain JSON from results: the one converter of numpy values and non-finite numbers, for every
layer (the engine, calibration, validation, pump and the scripts import it from here).

- :func:`jsonable`: ``obj`` as plain JSON values: mapping keys become strings, tuples lists,
  numpy arrays nested lists, numpy scalars Python numbers and booleans, and a non-finite float
  ``null`` (strict JSON has no NaN); anything else is returned as it is.
- :func:`json_default`: the ``default=`` hook of :func:`json.dumps` for what it cannot write:
  numpy scalars and arrays, paths; anything else is a ``TypeError``, as without a hook.
- :func:`write_json`: ``obj`` through both, written whole (:func:`warpdem.config_io.write_atomic`).
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .config_io import write_atomic

__all__ = ["json_default", "jsonable", "write_json"]


def jsonable(obj: Any) -> Any:
    """``obj`` as plain JSON values (see the module docstring)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def json_default(o: Any) -> Any:
    """``default=`` hook of :func:`json.dumps`: numpy scalars -> Python, arrays -> lists, paths -> str."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_json(path: str | os.PathLike, obj: Any, indent: int | None = 1) -> Path:
    """Write ``obj`` as strict JSON (:func:`jsonable`, then :func:`json_default`) to ``path``,
    whole or not at all."""
    return write_atomic(path, json.dumps(jsonable(obj), indent=indent, default=json_default, allow_nan=False))
