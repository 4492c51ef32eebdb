"""Campaign records that cannot lie: what determines a DEM result, and files that are never torn.

Every record a campaign writes (a design sample in ``samples.jsonl``; a DEM target, a
confirmation round or the validation in ``runs.jsonl``) carries

- ``determined_by``: every input that fixes its result, in two parts:

  ``setup`` (the same for every record of one response; a resume refuses any difference)
    ``format`` record format; ``experiment`` name, scale, settings and replicates (fills per
    sample); ``material`` the bulk material (or the experiment's scale default); ``contact_law``
    every sub-model; ``plugins`` hashes of the user files / packages that define sub-models or
    shape families; ``fixed`` parameters held constant; ``fills`` the fill mode; ``code`` the
    engine's version (:func:`code_version`).
  ``point`` (this record alone)
    ``parameters`` the parameter values [their units] and ``fills`` the loose-fill indices of
    its worlds (each seeded by the experiment's ``seed`` setting and the index).

- ``fingerprint``: a SHA-256 digest of ``determined_by`` (first 20 hex digits), so an edited or
  damaged record is detected too.

Not part of the fingerprint: the device (CPU and GPU runs of one model are the same experiment up
to round-off), the number of processes, and the composition of a batch (a batch's time step
follows its stiffest fill: see docs/known_limits.md).
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
import inspect
import json
import os
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from warpdem import ConfigError
from warpdem.config_io import write_atomic  # noqa: F401 - re-exported: campaign files written whole
from warpdem.provenance import fingerprint, plain, sha256_file  # noqa: F401 - fingerprint, plain re-exported

__all__ = ["RECORD_FORMAT", "SETUP_LABELS", "append_records", "code_version", "describe_differences",
           "fingerprint", "is_campaign_record", "plugin_hashes", "read_records", "write_atomic"]

RECORD_FORMAT = 2  # 1: records without a fingerprint (refused on resume)

# what a component is called in a refusal message
SETUP_LABELS = {"format": "record format", "experiment": "experiment", "material": "material",
                "contact_law": "contact law", "plugins": "plugin sources", "fixed": "fixed parameters",
                "fills": "fill mode", "code": "code version"}

# Source that determines a DEM angle: the engine, the experiments, fills, materials, the
# measurement of an angle from particles. Left out: command lines, reports, renderers, demos.
ENGINE_SOURCES: dict[str, tuple[str, ...]] = {
    "warpdem": ("**/*.py",),
    "calibration": ("experiments/*.py", "filling.py", "materials.py", "model_description.py", "measurement/*.py"),
}
SOURCES_LEFT_OUT = {"warpdem/cli.py", "warpdem/bench_settled_bed.py",
                    "warpdem/config_io.py", "warpdem/record_files.py", "warpdem/json_io.py", "warpdem/provenance.py",
                    "calibration/experiments/cli.py", "calibration/experiments/report.py",
                    "calibration/measurement/cli.py", "calibration/measurement/render.py"}


@functools.lru_cache(maxsize=1)
def code_version() -> dict[str, Any]:
    """The version of the code that produced a DEM result: ``{"warpdem": package version,
    "source_sha256": digest of the engine and experiment sources (16 hex digits), "files": n}``.

    A hash of the source files (:data:`ENGINE_SOURCES`, each file's path and bytes), not ``git
    describe``: an installed package has no ``.git``; ``git describe`` does not see uncommitted
    edits (``-dirty`` says only that something changed, anywhere); and in a repository where
    others commit all day it changes with every commit to a README or a test, which would refuse
    resumes that nothing physical separates. The hash changes exactly when a file that can change
    an angle changes (a refactoring that keeps every result refuses too: the hash cannot tell)."""
    import calibration
    import warpdem

    digest = hashlib.sha256()
    n = 0
    for package, patterns in ENGINE_SOURCES.items():
        root = Path((warpdem if package == "warpdem" else calibration).__file__).parent
        files = sorted({p for pat in patterns for p in root.glob(pat) if p.is_file()})
        for p in files:
            rel = f"{package}/{p.relative_to(root).as_posix()}"
            if rel in SOURCES_LEFT_OUT or "__pycache__" in rel:
                continue
            digest.update(rel.encode() + b"\0" + p.read_bytes() + b"\0")
            n += 1
    return {"warpdem": warpdem.__version__, "source_sha256": digest.hexdigest()[:16], "files": n}


def plugin_hashes(plugins: Sequence[str], contact_law: Any = None) -> dict[str, str]:
    """SHA-256 (16 hex digits) of every plugin file or module of a model description, and of the
    source file of each sub-model of ``contact_law`` that lives outside the engine (an
    entry-point package), by file or module name."""
    out: dict[str, str] = {}
    for p in plugins:
        path = Path(p)
        if not path.exists():
            spec = importlib.util.find_spec(p)
            path = Path(spec.origin) if spec is not None and spec.origin else None
        out[Path(p).name if p.endswith(".py") else p] = sha256_file(path)[:16] if path else "not found"
    for cls in getattr(contact_law, "implementation", ()):
        module = cls.__module__
        if module.startswith("warpdem.") or module in out:
            continue
        try:
            out[module] = sha256_file(inspect.getsourcefile(cls))[:16]
        except (TypeError, OSError):
            out[module] = "source not found"
    return dict(sorted(out.items()))


def _short(x: Any, limit: int = 160) -> str:
    s = x if isinstance(x, str) else json.dumps(x, sort_keys=True)
    return s if len(s) <= limit else s[: limit - 3] + "..."


def _leaf_differences(recorded: Any, now: Any, path: str) -> list[tuple[str, Any, Any]]:
    if isinstance(recorded, Mapping) and isinstance(now, Mapping):
        out = []
        for k in sorted(set(recorded) | set(now)):
            out += _leaf_differences(recorded.get(k, "(not set)"), now.get(k, "(not set)"), f"{path}.{k}" if path else k)
        return out
    return [] if recorded == now else [(path, recorded, now)]


def describe_differences(recorded: Mapping[str, Any], now: Mapping[str, Any], max_per_component: int = 4) -> list[str]:
    """One line per setup component that differs, e.g. ``contact law differs: recorded
    hertz+mindlin+rolling:epsd+cohesion:none, config hertz+mindlin+rolling:epsd2+cohesion:none``;
    mappings name the keys that differ (``experiment differs: settings.lift_speed recorded 0.1,
    config 0.05``)."""
    lines = []
    for key in sorted(set(recorded) | set(now), key=lambda k: list(SETUP_LABELS).index(k) if k in SETUP_LABELS else 99):
        r, n = recorded.get(key, "(not set)"), now.get(key, "(not set)")
        if r == n:
            continue
        label = SETUP_LABELS.get(key, key)
        differs = "differ" if label.endswith("s") else "differs"
        now_word = "this code" if key == "code" else "config"  # the code is not in the config
        if isinstance(r, Mapping) and isinstance(n, Mapping):
            leaves = _leaf_differences(r, n, "")
            parts = [f"{p} recorded {_short(a)}, {now_word} {_short(b)}" for p, a, b in leaves[:max_per_component]]
            more = f" (and {len(leaves) - max_per_component} more)" if len(leaves) > max_per_component else ""
            lines.append(f"{label} {differs}: " + "; ".join(parts) + more)
        else:
            lines.append(f"{label} {differs}: recorded {_short(r)}, {now_word} {_short(n)}")
    return lines


# ----------------------------------------------------------------------------- files
def append_records(path: str | os.PathLike, records: Iterable[Mapping[str, Any]]) -> None:
    """Append whole JSON lines in one write, then flush and fsync: after a kill the file ends in
    complete lines or in one torn last line, which :func:`read_records` cuts off. Read the file
    with :func:`read_records` first: it refuses a file that is not a record file."""
    text = "".join(json.dumps(plain(r)) + "\n" for r in records)
    if not text:
        return
    with open(path, "a") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())


def is_campaign_record(rec: Mapping[str, Any]) -> bool:
    """True for a line of ``samples.jsonl`` (``index`` and ``response``) or ``runs.jsonl``
    (``kind`` and ``response``), of any record format."""
    return "response" in rec and ("index" in rec or "kind" in rec)


def read_records(path: str | os.PathLike, log: Callable[[str], None] = print,
                 is_record: Callable[[Mapping[str, Any]], bool] | None = None,
                 key: str = "--out") -> list[tuple[int, dict[str, Any]]]:
    """``(line number, record)`` of every line of a JSON-lines record file (none if it does not
    exist). The file must prove it is a record file before anything in it is changed: every
    complete line a JSON object (and ``is_record`` of it, if given), at least one of them. Then a
    torn last line (an interrupted write) is reported through ``log``, kept in ``<file>.torn`` and
    cut off (the file is rewritten atomically), so its run happens again; a complete last line
    without its newline gets one. Any other file is a ConfigError naming the file, the line and
    ``key`` (what named the folder), and is left untouched."""
    path = Path(path)
    if not path.exists():
        return []
    hint = f"it was left untouched: move it away, or run into a new output folder ({key} DIR)"
    if not path.is_file():
        raise ConfigError(f"{path} is not a file: {hint}")
    data = path.read_bytes()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(f"{path} is not a record file (not UTF-8 text); {hint}") from None
    lines = text.splitlines()
    out: list[tuple[int, dict[str, Any]]] = []
    bad: list[int] = []  # 0-based indices of lines that are not a JSON object
    for k, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except ValueError:  # json.JSONDecodeError is a ValueError
            rec = None
        if not isinstance(rec, dict):
            bad.append(k)
        elif is_record is not None and not is_record(rec):
            raise ConfigError(f"{path}: line {k + 1} is not a record of this kind: this is not a record file a "
                              f"warpdem tool wrote; {hint}")
        else:
            out.append((k + 1, rec))
    if bad and not out:
        raise ConfigError(f"{path}: no line is a JSON record (line {bad[0] + 1} is not one): this is not a record file "
                          f"a warpdem tool wrote; {hint}")
    damaged = [k for k in bad if k != len(lines) - 1]
    if damaged:
        raise ConfigError(f"{path}: line {damaged[0] + 1} is not valid JSON (a record is one JSON object per line); the "
                          f"record file is damaged: {hint}")
    if bad:  # the last line only: a write cut by a kill
        k = bad[0]
        log(f"{path}: the last line (line {k + 1}) is incomplete: a write was interrupted; it is cut off "
            f"(kept in {path.name}.torn) and its run happens again")
        with open(path.with_name(path.name + ".torn"), "a") as fh:
            fh.write(lines[k] + "\n")
        write_atomic(path, "".join(ln + "\n" for ln in lines[:k]))
        return out
    if out and not text.endswith("\n"):  # complete last record, newline lost: the next append would join it
        write_atomic(path, text + "\n")
    return out
