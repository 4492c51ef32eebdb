"""Every ``warpdem`` subcommand works from a non-editable install in a virtual environment outside the
checkout (the engine reaches the applications only through the ``warpdem.commands`` entry points)."""
import os
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
COMMANDS = ["experiment", "measure", "calibrate", "diagnose", "pump", "pour", "bench", "doctor"]


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    root = tmp_path_factory.mktemp("install")
    wheels = root / "wheels"
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w",
                        str(wheels), str(REPO)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot build the wheel here: {r.stderr[-500:]}")
    env_dir = root / "venv"
    # the dependencies come from the environment running the tests (a venv as in the README, or the
    # system): its site-packages joins the new venv's path as plain entries, after the venv's own, so
    # warpdem itself is imported from the wheel installed below and never from an editable checkout.
    # (system_site_packages=True would see the *base* interpreter's packages, not this venv's.)
    venv.create(env_dir, system_site_packages=False, with_pip=True)
    py = env_dir / "bin" / "python"
    own_site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                              capture_output=True, text=True, check=True).stdout.strip()
    # install the wheel first: with the parent's packages already on the path, pip would find the
    # parent's warpdem (the CI's non-editable install) "already satisfied" and install nothing
    whl = next(wheels.glob("warpdem-*.whl"))
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(whl)], check=True)
    parents = dict.fromkeys(sysconfig.get_paths()[k] for k in ("purelib", "platlib"))
    Path(own_site, "zz_test_parent_env.pth").write_text("".join(f"{p}\n" for p in parents))
    return env_dir


def run(env_dir, *args, cwd):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    return subprocess.run([str(env_dir / "bin" / "warpdem"), *args], capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=300)


def test_every_subcommand_runs_from_an_installed_wheel(installed, tmp_path):
    where = subprocess.run([str(installed / "bin" / "python"), "-c", "import warpdem, calibration, validation, pump; "
                            "print(warpdem.__file__, calibration.__file__, validation.__file__, pump.__file__)"],
                           capture_output=True, text=True, cwd=tmp_path, check=True).stdout.split()
    for f in where:
        assert str(REPO) not in f, f"imported from the checkout, not the install: {f}"
    r = run(installed, "--version", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.startswith("warpdem ")
    r = run(installed, "--help", cwd=tmp_path)
    assert r.returncode == 0
    for c in COMMANDS:
        assert c in r.stdout
    for c in COMMANDS:
        r = run(installed, c, "--help", cwd=tmp_path)
        assert r.returncode == 0, (c, r.stderr[-800:])
        assert "usage" in r.stdout.lower(), (c, r.stdout[:300])
    r = run(installed, "nope", cwd=tmp_path)
    assert r.returncode == 2 and "unknown command 'nope'" in r.stderr


def test_shipped_configs_are_in_the_wheel(installed, tmp_path):
    code = ("import importlib.resources as r; "
            "print(all(r.files(p).joinpath(f).is_file() for p, f in ["
            "('calibration', 'configs/quick_calibration.yaml'), ('validation', 'configs/tiny_diagnosis.yaml'), "
            "('validation', 'configs/tiny_lab.yaml'), ('validation', 'configs/first_diagnosis.yaml'), ('validation', 'configs/first_lab.yaml'), ('pump', 'configs/quick_pump.yaml')]))")
    out = subprocess.run([str(installed / "bin" / "python"), "-c", code], capture_output=True, text=True,
                         cwd=tmp_path, check=True).stdout.strip()
    assert out == "True"
