"""``warpdem doctor``: versions, devices, packages, LIGGGHTS and where results go (issue 30)."""
from __future__ import annotations

import json
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

from validation.doctor import PACKAGES, doctor_report, doctor_text
from warpdem.cli import commands


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> dict:
    return doctor_report(tmp_path_factory.mktemp("doctor_cwd"))


def test_doctor_is_a_registered_command():
    assert "doctor" in commands(), "reinstall the package (pip install -e .) to register the entry point"


def test_versions_devices_and_packages(report):
    import warp as wp

    assert report["warp"]["version"] == wp.__version__
    aliases = [d["alias"] for d in report["warp"]["devices"]]
    assert "cpu" in aliases
    assert report["warp"]["cuda_available"] == any(a.startswith("cuda") for a in aliases)
    assert list(report["packages"]) == list(PACKAGES)
    assert report["packages"]["numpy"] == metadata.version("numpy")
    assert report["packages"]["scikit-learn"] == metadata.version("scikit-learn")


def test_results_go_under_the_working_directory(report):
    where = Path(report["results"]["working_directory"])
    jobs = {j["command"]: j["output"] for j in report["results"]["jobs"]}
    assert jobs["warpdem diagnose validation/configs/first_diagnosis.yaml"] == str(where / "results/diagnosis_first")
    assert jobs["warpdem calibrate calibration/configs/quick_calibration.yaml"] == str(where / "results/calibration_quick")
    assert report["results"]["writable"] is True


def test_liggghts_is_reported_or_its_install_named(monkeypatch, tmp_path):
    monkeypatch.setenv("WARPDEM_LIGGGHTS", str(tmp_path / "no_such_liggghts"))
    missing = doctor_report(tmp_path)
    assert missing["liggghts"]["executable"] is None and "install_liggghts.sh" in missing["liggghts"]["hint"]
    assert "LIGGGHTS (reference code, docs/liggghts_reference.md): not found" in doctor_text(missing)


def test_text_names_what_a_cpu_machine_cannot_run(report):
    text = doctor_text(report)
    assert text.startswith("warpdem ") and f"Warp {report['warp']['version']}" in text
    assert ("no CUDA device" in text) is (not report["warp"]["cuda_available"])
    assert "results/diagnosis_first" in text


def test_command_prints_clean_json(tmp_path):
    """In a fresh process Warp's start-up output (its banner, a missing CUDA driver's warning) does not
    reach stdout: the command's output is one JSON object."""
    r = subprocess.run([sys.executable, "-m", "warpdem.cli", "doctor", "--json"], capture_output=True, text=True,
                       cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    parsed = json.loads(r.stdout)
    assert parsed["results"]["working_directory"] == str(tmp_path.resolve())
    assert parsed["warpdem"]["version"]
