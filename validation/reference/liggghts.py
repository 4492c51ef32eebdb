"""LIGGGHTS-PUBLIC 3.8 as the project's reference code: find the binary, run a deck, read its output.

The binary comes from the Debian package ``liggghts`` (``scripts/install_liggghts.sh``); the
environment variable ``WARPDEM_LIGGGHTS`` names another executable. Decks are plain text written
by the case modules beside this one; every run happens in its own folder, which keeps the deck,
the log and the outputs together, so a stored reference result can name exactly what produced it.

Output formats read here (LIGGGHTS manual, ``dump custom`` and ``fix print``):

* ``dump custom``: blocks of ``ITEM: TIMESTEP`` / ``ITEM: NUMBER OF ATOMS`` / ``ITEM: BOX BOUNDS``
  / ``ITEM: ATOMS col col ...`` followed by one line per atom.
* ``fix print ... file F screen no title "# a b c"``: one whitespace-separated row per print.
"""
from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["LIGGGHTS_ENV", "LiggghtsNotFound", "LiggghtsFailed", "LiggghtsRun", "DumpFrame",
           "liggghts_executable", "liggghts_version", "run_deck", "read_dump", "read_print_file"]

#: environment variable naming the LIGGGHTS executable (default: ``liggghts`` on PATH)
LIGGGHTS_ENV = "WARPDEM_LIGGGHTS"
INSTALL_HINT = "install it with scripts/install_liggghts.sh (Debian package liggghts 3.8)"


class LiggghtsNotFound(RuntimeError):
    """No LIGGGHTS executable on this machine."""


class LiggghtsFailed(RuntimeError):
    """A LIGGGHTS run ended with an error; the message carries the log's last lines."""


def liggghts_executable() -> str | None:
    """Path of the LIGGGHTS executable, or None (``$WARPDEM_LIGGGHTS``, else ``liggghts`` on PATH)."""
    named = os.environ.get(LIGGGHTS_ENV)
    if named:
        return shutil.which(named) or (named if os.access(named, os.X_OK) else None)
    return shutil.which("liggghts")


def liggghts_version(executable: str | None = None) -> str:
    """Version line of the executable, e.g. ``LIGGGHTS-PUBLIC 3.8.0`` (asked once per executable)."""
    return _version_of(executable or _require_executable())


@functools.lru_cache(maxsize=None)
def _version_of(exe: str) -> str:
    out = subprocess.run([exe, "-h"], capture_output=True, text=True, timeout=60).stdout
    m = re.search(r"Version\s+([^,)]+)", out)
    return m.group(1).strip() if m else out.splitlines()[0] if out else "unknown"


def _require_executable() -> str:
    exe = liggghts_executable()
    if exe is None:
        raise LiggghtsNotFound(f"LIGGGHTS not found (${LIGGGHTS_ENV} unset and no 'liggghts' on PATH); {INSTALL_HINT}")
    return exe


@dataclass
class LiggghtsRun:
    """One finished run: its folder (deck ``in.deck``, ``log.liggghts``, outputs) and wall time [s]."""

    folder: Path
    wall_s: float
    version: str
    log: str = field(repr=False, default="")

    def path(self, name: str) -> Path:
        return self.folder / name


def run_deck(deck: str, folder: str | os.PathLike, files: dict[str, str | bytes] | None = None,
             timeout_s: float = 3600.0, executable: str | None = None, *,
             screen_file: str | None = None, processes: int = 1) -> LiggghtsRun:
    """Write ``deck`` (and ``files``: name -> text or bytes, e.g. STL meshes) into ``folder`` and
    run LIGGGHTS there on ``processes`` MPI processes (``mpirun -np``; 1: no MPI launcher), one
    thread each. Raises :class:`LiggghtsFailed` with the log's tail when the run reports an error
    or exits non-zero.

    screen_file: write the screen output to this file in ``folder`` (None: no screen output).
    Decks with ``fix mesh/surface`` need one: LIGGGHTS 3.8 prints the mesh import to the screen
    stream and crashes (segmentation fault) when there is none."""
    exe = executable or _require_executable()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for name, content in (files or {}).items():
        target = folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            target.write_bytes(content)
        else:
            target.write_text(content)
    (folder / "in.deck").write_text(deck)
    t0 = time.perf_counter()
    command = [exe, "-in", "in.deck", "-log", "log.liggghts", "-screen", screen_file or "none", "-nocite"]
    if processes > 1:
        command = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-np", str(int(processes)), *command]
    proc = subprocess.run(command, cwd=folder, capture_output=True, text=True, timeout=timeout_s,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    wall = time.perf_counter() - t0
    log_path = folder / "log.liggghts"
    log = log_path.read_text(errors="replace") if log_path.exists() else ""
    error_lines = [ln for ln in log.splitlines() if ln.startswith("ERROR")]
    if proc.returncode != 0 or error_lines:
        tail = "\n".join((log or proc.stdout + proc.stderr).splitlines()[-15:])
        raise LiggghtsFailed(f"LIGGGHTS failed in {folder} (rc {proc.returncode}):\n{tail}")
    return LiggghtsRun(folder, wall, liggghts_version(exe), log)


@dataclass
class DumpFrame:
    """One ``dump custom`` frame: its step, box bounds and columns by name (sorted by atom id)."""

    step: int
    box: np.ndarray
    columns: dict[str, np.ndarray]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def vectors(self, *names: str) -> np.ndarray:
        """Columns stacked as an (n, len(names)) array, e.g. ``frame.vectors("x", "y", "z")``."""
        return np.stack([self.columns[n] for n in names], axis=1)


def read_dump(path: str | os.PathLike) -> list[DumpFrame]:
    """Every frame of a ``dump custom`` text file (atoms sorted by ``id`` when it is a column)."""
    lines = Path(path).read_text().splitlines()
    frames: list[DumpFrame] = []
    i = 0
    while i < len(lines):
        if not lines[i].startswith("ITEM: TIMESTEP"):
            i += 1
            continue
        step = int(lines[i + 1])
        n = int(lines[i + 3])
        box = np.array([[float(v) for v in lines[i + 5 + k].split()[:2]] for k in range(3)])
        names = lines[i + 8].split()[2:]
        body = lines[i + 9:i + 9 + n]
        data = np.array([[float(v) for v in ln.split()] for ln in body]).reshape(n, len(names))
        if "id" in names:
            data = data[np.argsort(data[:, names.index("id")], kind="stable")]
        frames.append(DumpFrame(step, box, {name: data[:, k] for k, name in enumerate(names)}))
        i += 9 + n
    return frames


def read_print_file(path: str | os.PathLike) -> np.ndarray:
    """Rows of a ``fix print`` file as a 2-D float array (lines starting with ``#`` skipped)."""
    rows = [[float(v) for v in ln.split()] for ln in Path(path).read_text().splitlines()
            if ln.strip() and not ln.lstrip().startswith("#")]
    return np.array(rows, dtype=float)
