"""The rules for the user's files and the tools' own, in one place.

Reading (every config and measurement file of every command goes through :func:`load_config_file`
or :func:`parse_yaml`): a missing file, a file that is not UTF-8 text, invalid YAML/JSON and a key
given twice in one mapping (YAML or JSON) are a :class:`~warpdem.errors.ConfigError` naming the
file, and for a repeated key the key and its line. A repeated key is never "the last one wins":
a repeated observable or condition would otherwise replace the first without a word. A number
with an exponent is a number (``6.0e4``, ``1e-5``: YAML 1.2's rule; PyYAML's YAML 1.1 reads them
as text).

Writing: :func:`write_atomic` replaces a file whole (temporary file in the same folder, fsync,
rename), so a reader or a kill sees the old file or the new one, never a part.

Checks at load (before any DEM): :func:`check_output_folder` (created, a folder, writable),
:func:`check_device` (cpu, cuda, cuda:N that exists here), :func:`parse_processes`,
:func:`check_sphere_memory` (the spheres a run holds against this machine's memory), and the
``argparse`` types of counts and numbers (:func:`positive_int_arg`, :func:`nonnegative_int_arg`,
:func:`positive_float_arg`, :func:`nonnegative_float_arg`), so an option is refused naming it.
"""
from __future__ import annotations

import json
import math
import os
import re
import tempfile
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError

__all__ = ["DuplicateKeyError", "load_config_file", "parse_yaml", "parse_json", "read_text_file", "write_atomic",
           "check_output_folder", "check_device", "parse_processes", "processes_arg", "device_arg", "positive_int_arg",
           "nonnegative_int_arg", "positive_float_arg", "nonnegative_float_arg", "BYTES_PER_SPHERE", "machine_memory",
           "check_sphere_memory", "existing_file_arg"]


class DuplicateKeyError(ConfigError):
    """A key given twice in one mapping of a YAML or JSON file. ``file``, ``key``, ``line`` (of the
    repeat, 1-based; None for JSON) and ``first_line`` say where."""

    def __init__(self, file: str, key: Any, line: int | None, first_line: int | None) -> None:
        self.file, self.key, self.line, self.first_line = file, key, line, first_line
        where = f"line {line}: " if line is not None else ""
        first = f" (first on line {first_line})" if first_line is not None else ""
        super().__init__(f"{file}: {where}key '{key}' is given twice in one mapping{first}; the second would "
                         "silently replace the first: keep one")


class _RepeatedKey(Exception):
    """Raised inside the YAML loader; :func:`parse_yaml` adds the file name."""

    def __init__(self, key: Any, line: int, first_line: int) -> None:
        super().__init__(key)
        self.key, self.line, self.first_line = key, line, first_line


class UniqueKeyLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (merge keys ``<<`` may
    still be overridden, as YAML intends)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                hash(key)
            except TypeError:  # an unhashable key: SafeLoader reports it itself
                continue
            line = key_node.start_mark.line + 1
            if key in seen:
                raise _RepeatedKey(key, line, seen[key])
            seen[key] = line
        return super().construct_mapping(node, deep)


# YAML 1.1 (PyYAML) reads an exponent without a dot and a sign (1e-5, 6.0e4, 1.0e6) as text; YAML 1.2
# and every user read it as a number: so does this loader (1.0e+6 and 1.0e-5 were numbers already)
UniqueKeyLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"))


def parse_yaml(text: str, source: str) -> Any:
    """YAML ``text`` as Python data; invalid YAML or a repeated key is a ConfigError naming ``source``."""
    try:
        return yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except _RepeatedKey as exc:
        raise DuplicateKeyError(source, exc.key, exc.line, exc.first_line) from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}: not valid YAML: {' '.join(str(exc).split())}") from None


def _unique_pairs(source: str):
    def hook(pairs: list[tuple[str, Any]]) -> dict:
        out: dict[str, Any] = {}
        for k, v in pairs:
            if k in out:
                raise DuplicateKeyError(source, k, None, None)
            out[k] = v
        return out

    return hook


def parse_json(text: str, source: str) -> Any:
    """JSON ``text`` as Python data; invalid JSON or a repeated key is a ConfigError naming ``source``."""
    try:
        return json.loads(text, object_pairs_hook=_unique_pairs(source))
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{source}: not valid JSON: {exc}") from None


def read_text_file(path: str | os.PathLike, what: str = "file") -> str:
    """The text of a UTF-8 file (a byte-order mark is dropped). Missing, a folder, unreadable or
    not UTF-8: a ConfigError naming ``what`` and the file."""
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{what} not found: {p}")
    if not p.is_file():
        raise ConfigError(f"{what} {p} is not a file")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{what} {p}: cannot read it ({exc.strerror})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{what} {p}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}): "
                          "is it the right file? save it as UTF-8") from None


def load_config_file(path: str | os.PathLike, what: str = "config") -> Any:
    """A YAML config or measurement file (JSON when its name ends in ``.json``) as Python data,
    with the rules of this module (UTF-8, valid syntax, no repeated key)."""
    p = Path(path)
    text = read_text_file(p, what)
    return parse_json(text, str(p)) if p.suffix.lower() == ".json" else parse_yaml(text, str(p))


# ----------------------------------------------------------------------------- writing
def _fsync_folder(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # e.g. a platform without directory handles
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_atomic(path: str | os.PathLike, data: str | bytes, encoding: str = "utf-8") -> Path:
    """Replace ``path`` by ``data`` so that a reader (or a kill) sees the old or the new file,
    never a part: write a temporary file in the same folder, flush, fsync, rename over ``path``."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data.encode(encoding) if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_folder(path.parent)
    return path


# ----------------------------------------------------------------------------- checks at load
def check_output_folder(path: str | os.PathLike, key: str = "output", what: str = "the output folder") -> Path:
    """Create the folder ``path`` if needed and check that it is a folder this process can write;
    otherwise a ConfigError naming ``key`` (``output``, ``--out``, ...) and ``what`` it is."""
    p = Path(path)
    for part in (p, *p.parents):
        if part.exists() and not part.is_dir():
            where = "is a file" if part == p else f"lies under {part}, which is a file"
            raise ConfigError(f"{key}: {what} {p} {where}, not a folder: name a folder")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{key}: cannot create {what} {p} ({exc.strerror}): name a folder you can write") from None
    try:
        fd, probe = tempfile.mkstemp(dir=p, prefix=".warpdem-write-check-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ConfigError(f"{key}: {what} {p} is not writable ({exc.strerror}): name a folder you can write") from None
    return p


_CUDA = re.compile(r"cuda(:(\d+))?")


def check_device(device: Any, key: str = "device", present: bool = True) -> str | None:
    """``device`` if it names one: None (Warp's choice), ``cpu``, ``cuda`` or ``cuda:N``; anything
    else is a ConfigError naming ``key``. ``present``: also refuse a CUDA device this machine does
    not have (False where a file is only read, e.g. a GPU config checked on a laptop)."""
    if device is None:
        return None
    name = str(device).strip() if isinstance(device, str) else None
    if name == "cpu":
        return name
    m = _CUDA.fullmatch(name or "")
    if m is None:
        raise ConfigError(f"{key}: {device!r} is not a device: give cpu, cuda or cuda:N")
    if not present:
        return name
    import warp as wp

    if not wp.is_cuda_available():
        raise ConfigError(f"{key}: {name}: no CUDA device here (Warp finds none): use cpu")
    if m.group(2) is not None and int(m.group(2)) >= wp.get_cuda_device_count():
        raise ConfigError(f"{key}: {name}: this machine has {wp.get_cuda_device_count()} CUDA device(s) "
                          f"(cuda:0 to cuda:{wp.get_cuda_device_count() - 1})")
    return name


def parse_processes(value: Any, key: str = "processes") -> int | str | None:
    """``processes``: None, ``"auto"`` or an integer >= 1 (an integer given as text too);
    anything else is a ConfigError naming ``key``."""
    if value is None or value == "auto":
        return value
    if isinstance(value, bool) or isinstance(value, float) and not value.is_integer():
        raise ConfigError(f"{key}: must be a whole number >= 1 or 'auto', got {value!r}")
    try:
        n = int(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{key}: must be a whole number >= 1 or 'auto', got {value!r}") from None
    if n < 1:
        raise ConfigError(f"{key}: must be >= 1 or 'auto', got {value!r}")
    return n


def processes_arg(text: str) -> int | str:
    """argparse ``type=`` of ``--processes``: ``auto`` or an integer >= 1."""
    import argparse

    try:
        return parse_processes(text, "--processes")
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--processes: ")) from None


def device_arg(text: str) -> str:
    """argparse ``type=`` of ``--device``: cpu, cuda or cuda:N present on this machine."""
    import argparse

    try:
        return check_device(text, "--device")
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--device: ")) from None


def positive_int_arg(text: str) -> int:
    """argparse ``type=`` of a count that must be a whole number >= 1."""
    import argparse

    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {n}")
    return n


def nonnegative_int_arg(text: str) -> int:
    """argparse ``type=`` of a count that may be 0: a whole number >= 0."""
    import argparse

    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {text!r}") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {n}")
    return n


def _finite_float(text: str) -> float:
    import argparse

    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return x


def positive_float_arg(text: str) -> float:
    """argparse ``type=`` of a finite number > 0 (a time, a speed, a rate)."""
    import argparse

    x = _finite_float(text)
    if not x > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return x


def nonnegative_float_arg(text: str) -> float:
    """argparse ``type=`` of a finite number >= 0 (a friction coefficient, a start time)."""
    import argparse

    x = _finite_float(text)
    if x < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return x


def existing_file_arg(text: str) -> str:
    """argparse ``type=`` of a file to read: it must exist and be a file."""
    import argparse

    if not Path(text).is_file():
        raise argparse.ArgumentTypeError(f"{text}: {'a folder, not a file' if Path(text).is_dir() else 'no such file'}")
    return text


# ----------------------------------------------------------------------------- resources
#: memory one sphere of a run takes at most, all buffers together [bytes] (state, contact and
#: neighbour slots, fill generation): with the sphere count, the memory estimate of a run
BYTES_PER_SPHERE = 4096


def machine_memory() -> int | None:
    """Physical memory of this machine [bytes] (None where the platform does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def check_sphere_memory(spheres: float, key: str, fix: str) -> float:
    """Refuse (ConfigError naming ``key``) a run of ``spheres`` spheres in all worlds whose memory
    estimate (:data:`BYTES_PER_SPHERE` each) exceeds this machine's memory; ``fix`` says what to
    lower. Returns the estimate [bytes]."""
    need = float(spheres) * BYTES_PER_SPHERE
    total = machine_memory()
    if total and need > total:
        raise ConfigError(f"{key}: {spheres:.3g} spheres need about {need / 1e9:.3g} GB ({BYTES_PER_SPHERE} bytes "
                          f"each); this machine has {total / 1e9:.3g} GB: {fix}")
    return need
