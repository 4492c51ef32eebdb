"""Provenance digests: the one place where a record's identity is hashed, for every layer (the
engine's record files, calibration's campaign records, the diagnosis's DEM-cache world ids).

- :func:`json_digest`: SHA-256 of the JSON of a value with sorted keys, first ``length`` hex
  digits; ``default`` and ``separators`` as in :func:`json.dumps`.
- :func:`plain` and :func:`fingerprint`: a campaign record's canonical JSON values and its
  fingerprint (:mod:`calibration.campaign_records`).
- :func:`sha256_file`: a file's digest.

The digests name files already written (DEM caches, campaign records): a change here that
changes a digest orphans them (tests/test_provenance_pins.py pins a few). Not here: the version
of the engine's sources (:func:`calibration.campaign_records.code_version`, which reads the
calibration package too) and a model's fingerprint for checkpoints (:func:`warpdem.model.model_fingerprint`).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any, Callable, Mapping

__all__ = ["fingerprint", "json_digest", "plain", "sha256_file"]


def json_digest(obj: Any, length: int = 20, default: Callable[[Any], Any] | None = None,
                separators: tuple[str, str] | None = None) -> str:
    """SHA-256 of ``json.dumps(obj, sort_keys=True, default=default, separators=separators)``,
    its first ``length`` hex digits."""
    text = json.dumps(obj, sort_keys=True, default=default, separators=separators)
    return hashlib.sha256(text.encode()).hexdigest()[:length]


def sha256_file(path: str | os.PathLike) -> str:
    """SHA-256 of the file's bytes (64 hex digits)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def plain(x: Any, numbers_as_float: bool = False) -> Any:
    """``x`` as plain JSON values (tuples -> lists, numpy -> Python; with ``numbers_as_float`` an
    integer becomes a float, so ``30`` and ``30.0`` in a config are the same setting)."""
    if isinstance(x, Mapping):
        return {str(k): plain(v, numbers_as_float) for k, v in sorted(x.items(), key=lambda kv: str(kv[0]))}
    if isinstance(x, (list, tuple)):
        return [plain(v, numbers_as_float) for v in x]
    if hasattr(x, "tolist") and not isinstance(x, (str, bytes)):  # numpy scalars and arrays
        return plain(x.tolist(), numbers_as_float)
    if isinstance(x, bool) or x is None or isinstance(x, str):
        return x
    if isinstance(x, int):
        return float(x) if numbers_as_float else x
    if isinstance(x, float):
        return x if math.isfinite(x) else str(x)
    return str(x)


def fingerprint(determined_by: Mapping[str, Any]) -> str:
    """SHA-256 of the canonical JSON of ``determined_by`` (first 20 hex digits)."""
    return json_digest(plain(determined_by), separators=(",", ":"))
