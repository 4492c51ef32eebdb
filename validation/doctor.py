"""``warpdem doctor``: what this installation runs on, and where its results go.

Prints the versions of warpdem, Python and Warp, the devices Warp sees (CPU, CUDA GPUs and the
CUDA driver and toolkit), the versions of the packages the jobs use (Ray is optional), the
LIGGGHTS reference binary if one is installed (:mod:`validation.reference.liggghts`), and the
folders the shipped jobs write into (their configs' ``output``, relative to the working
directory) with Warp's kernel cache. ``--json`` prints the same as one JSON object.

It lives in :mod:`validation`, the top layer, because it reports on every layer (the engine
never imports the applications); ``warpdem/cli.py`` finds it through the ``warpdem.commands``
entry point ``doctor``.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import sys
import tempfile
from importlib import metadata, resources
from pathlib import Path
from typing import Any, Iterator, Sequence

import yaml

__all__ = ["PACKAGES", "SHIPPED_JOBS", "doctor_report", "doctor_text", "doctor_main"]

#: distributions the jobs import, in the order they are printed; ``ray`` is optional
PACKAGES = ("warp-lang", "numpy", "scipy", "scikit-learn", "pymoo", "pydantic", "matplotlib",
            "opencv-python-headless", "trimesh", "pyvista", "pyyaml", "ray")
#: what each optional distribution is for, printed when it is missing
OPTIONAL = {"ray": 'optional, for executor: {kind: ray} (pip install ".[ray]")'}
#: shipped jobs whose output folder is reported: (command, package, config inside the package)
SHIPPED_JOBS = (
    ("warpdem diagnose validation/configs/first_diagnosis.yaml", "validation", "configs/first_diagnosis.yaml"),
    ("warpdem diagnose validation/configs/tiny_diagnosis.yaml", "validation", "configs/tiny_diagnosis.yaml"),
    ("warpdem calibrate calibration/configs/quick_calibration.yaml", "calibration", "configs/quick_calibration.yaml"),
    ("warpdem pump pump/configs/quick_pump.yaml", "pump", "configs/quick_pump.yaml"),
)


def package_versions() -> dict[str, str | None]:
    """Installed version of each of :data:`PACKAGES` (None: not installed)."""
    out: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


@contextlib.contextmanager
def _captured_native_output() -> Iterator[list[str]]:
    """Catch what native code writes to stdout and stderr (Warp's CUDA warnings) into a list of lines."""
    sys.stdout.flush()
    sys.stderr.flush()
    lines: list[str] = []
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile(mode="w+b") as sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            yield lines
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            sink.seek(0)
            lines += [ln.strip() for ln in sink.read().decode("utf-8", "replace").splitlines() if ln.strip()]


def warp_state() -> dict[str, Any]:
    """Warp's version, the CUDA toolkit and driver, the devices, the kernel cache and what Warp said
    while starting (its banner and warnings, caught instead of printed)."""
    import warp as wp

    if hasattr(wp, "LOG_ERROR"):
        wp.config.log_level = wp.LOG_ERROR
    with _captured_native_output() as said:
        wp.init()
    from warp._src import context  # the runtime's toolkit and driver versions

    runtime = getattr(context, "runtime", None)

    def version_text(v: Any) -> str | None:
        return ".".join(map(str, v)) if isinstance(v, tuple) else (None if v is None else str(v))

    devices = []
    for d in wp.get_devices():
        entry: dict[str, Any] = {"alias": d.alias, "name": d.name, "cuda": bool(d.is_cuda)}
        if d.is_cuda:
            entry["memory_gib"] = round(d.total_memory / 2**30, 1)
            entry["arch"] = getattr(d, "arch", None)
        devices.append(entry)
    return {"version": wp.__version__, "cuda_available": bool(wp.is_cuda_available()),
            "cuda_toolkit": version_text(getattr(runtime, "toolkit_version", None)),
            "cuda_driver": version_text(getattr(runtime, "driver_version", None)),
            "devices": devices, "kernel_cache": str(wp.config.kernel_cache_dir), "messages": said}


def liggghts_state() -> dict[str, Any]:
    """The LIGGGHTS reference binary: its path and version, or None and how to install it."""
    from validation.reference import liggghts

    exe = liggghts.liggghts_executable()
    if exe is None:
        return {"executable": None, "version": None, "hint": liggghts.INSTALL_HINT}
    try:
        version = liggghts.liggghts_version(exe)
    except (OSError, ValueError, RuntimeError) as exc:  # found but does not run
        version = f"does not run: {exc}"
    return {"executable": exe, "version": version}


def result_folders(cwd: Path) -> list[dict[str, str]]:
    """Each shipped job of :data:`SHIPPED_JOBS` and the folder it writes into from ``cwd`` (its config's ``output``)."""
    out = []
    for command, package, name in SHIPPED_JOBS:
        try:
            cfg = yaml.safe_load(resources.files(package).joinpath(name).read_text(encoding="utf-8")) or {}
        except (OSError, ModuleNotFoundError, yaml.YAMLError) as exc:
            out.append({"command": command, "output": f"config not readable: {exc}"})
            continue
        out.append({"command": command, "output": str(cwd / str(cfg.get("output", "results")))})
    return out


def doctor_report(cwd: str | os.PathLike | None = None) -> dict[str, Any]:
    """Everything ``warpdem doctor`` prints, as plain data."""
    import warpdem

    here = Path(cwd or os.getcwd()).resolve()
    return {
        "warpdem": {"version": warpdem.__version__, "location": str(Path(warpdem.__file__).resolve().parent)},
        "python": {"version": platform.python_version(), "executable": sys.executable},
        "platform": platform.platform(),
        "warp": warp_state(),
        "packages": package_versions(),
        "liggghts": liggghts_state(),
        "results": {"working_directory": str(here), "writable": os.access(here, os.W_OK),
                    "jobs": result_folders(here)},
    }


def doctor_text(report: dict[str, Any]) -> str:
    """The report as the lines ``warpdem doctor`` prints."""
    w, lig, res = report["warp"], report["liggghts"], report["results"]
    lines = [f"warpdem {report['warpdem']['version']} ({report['warpdem']['location']})",
             f"Python {report['python']['version']} ({report['python']['executable']}); {report['platform']}",
             f"Warp {w['version']}: CUDA toolkit {w['cuda_toolkit'] or 'none'}, "
             f"CUDA driver {w['cuda_driver'] or 'not found'}"]
    for d in w["devices"]:
        lines.append(f"  device {d['alias']}: {d['name']}"
                     + (f" ({d['memory_gib']} GiB, sm_{d['arch']})" if d["cuda"] else ""))
    if not w["cuda_available"]:
        lines.append("  no CUDA device: every job runs on the CPU; commands with --device cuda need a GPU")
    lines += [f"  Warp said: {m}" for m in w["messages"] if "warning" in m.lower() or "error" in m.lower()]
    lines.append("packages:")
    for name, version in report["packages"].items():
        lines.append(f"  {name:<24} {version or 'not installed' + (f', {OPTIONAL[name]}' if name in OPTIONAL else '')}")
    lines.append("LIGGGHTS (reference code, docs/liggghts_reference.md): " + (
        f"{lig['executable']} ({lig['version']})" if lig["executable"] else f"not found; {lig['hint']}"))
    lines.append(f"results go under the working directory {res['working_directory']}"
                 f" ({'writable' if res['writable'] else 'NOT writable: run the jobs from another folder'}):")
    for job in res["jobs"]:
        lines.append(f"  {job['command']:<62} -> {job['output']}")
    lines.append(f"Warp's compiled kernels: {w['kernel_cache']}")
    return "\n".join(lines)


def doctor_main(argv: Sequence[str] | None = None) -> int:
    """``warpdem doctor [--json]``."""
    p = argparse.ArgumentParser(prog="warpdem doctor",
                                description="Print the versions, devices and packages this installation runs on, "
                                            "the LIGGGHTS reference if installed, and where results go.")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    args = p.parse_args(list(argv) if argv is not None else None)
    report = doctor_report()
    print(json.dumps(report, indent=1) if args.json else doctor_text(report))
    return 0
