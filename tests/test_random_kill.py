"""A kill at any moment loses at most one checkpoint interval (issue 29): a tiny campaign and a
tiny diagnosis are SIGKILLed (with their process group) at a random moment of their run, run
again to the end, and

- give the same result as an uninterrupted run (records, confirmation, verdict),
- keep every record written before the kill (the record files only grow),
- redo at most the DEM steps of one checkpoint interval: the steps of the killed sitting and the
  resumed one, less those of the uninterrupted run, are at most the most steps the killed sitting
  simulated in any window of one interval, plus the chunk that crosses it (a save waits for the
  end of a chunk).

Each command runs in a subprocess that logs every ``Simulation.run`` call (end time, steps), with
one process for the DEM so that every step is logged. CPU, cylinder piles of about 55 spheres:
the campaign about 40 s on 2 cores, the diagnosis (three DEM launches) 50-90 s, marked slow. The
kill moment is drawn from the test's seed (printed with the steps, and in a failure's message);
set WARPDEM_KILL_SEED to replay one.
"""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

sys.path.insert(0, str(Path(__file__).parent))
from test_batch_checkpoint import CAMPAIGN, TINY_CYL, records  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
INTERVAL_S = 1.0  # wall seconds between checkpoints of a batch (campaign: checkpoints.every_s)

# logs every Simulation.run of the command (monotonic end time, steps); the diagnosis config has no
# checkpoint setting, so its forward model's interval is set here
DRIVER = """
import os, sys, time
import warpdem as wd
log = open(os.environ["WARPDEM_STEP_LOG"], "a", buffering=1)
plain_run = wd.Simulation.run
def run(self, n, *args, **kwargs):
    out = plain_run(self, n, *args, **kwargs)
    log.write(f"{time.monotonic():.4f} {int(n)}\\n")
    return out
wd.Simulation.run = run
import validation.dem_forward as dem_forward
plain_init = dem_forward.DEMForwardModel.__init__
def init(self, *args, **kwargs):
    kwargs.setdefault("checkpoint_every_s", float(os.environ["WARPDEM_CHECKPOINT_S"]))
    plain_init(self, *args, **kwargs)
dem_forward.DEMForwardModel.__init__ = init
from warpdem.cli import main
sys.exit(main(sys.argv[1:]))
"""

LAB = {"format": "warpdem-measurements/2", "title": "tiny cylinder piles",
       "experiments": {"cylinder": {"conditions": {"small": {
           "settings": {k: v for k, v in TINY_CYL.items() if k != "fill_per_world"},
           "observables": {"pile_angle": {"unit": "deg", "repeats": [21.0, 24.5, 23.0], "resolution": 0.5}}}}}}}
DIAGNOSIS = {
    "name": "kill", "measurements": "lab.yaml", "device": "cpu", "processes": 1, "scale": "quick",
    "model": {"contact_law": {"rolling": "none"}}, "parameters": {"mu_s_pp": [0.2, 0.8]},
    "fixed": {"mu_s_pw": 0.5, "restitution_pp": 0.6, "restitution_pw": 0.6},
    "candidates": ["rolling_resistance"], "proposals": "none",
    "diagnosis": {"design_points_per_parameter": 1, "min_design_points": 4, "replicates": 2, "confirm_replicates": 1,
                  "confirm_extra_replicates": 0, "refine_points": 0, "max_refine_waves": 0, "scan_points": 64,
                  "evidence_samples": 256, "gp_restarts": 0, "cv_folds": 2}}


def start(argv: list[str], folder: Path, step_log: Path) -> subprocess.Popen:
    """``warpdem ARGV`` in ``folder`` through the step-logging driver, in its own process group."""
    env = {**os.environ, "WARPDEM_STEP_LOG": str(step_log), "WARPDEM_CHECKPOINT_S": str(INTERVAL_S),
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    with open(step_log.with_suffix(".out"), "w") as out:
        return subprocess.Popen([sys.executable, "-c", DRIVER, *argv], cwd=folder, env=env, stdout=out,
                                stderr=subprocess.STDOUT, start_new_session=True)


def chunks(step_log: Path) -> list[tuple[float, int]]:
    """(end time, steps) of every Simulation.run a command logged (a line cut by the kill left out)."""
    out = []
    for line in step_log.read_text().splitlines() if step_log.exists() else []:
        parts = line.split()
        if len(parts) == 2:
            out.append((float(parts[0]), int(parts[1])))
    return out


def one_interval(logged: list[tuple[float, int]], interval: float) -> int:
    """The most steps simulated in any window of ``interval`` seconds, plus the largest chunk."""
    most = 0
    for end, _ in logged:
        most = max(most, sum(n for t, n in logged if end - interval < t <= end))
    return most + max((n for _, n in logged), default=0)


def run_killed_and_resumed(tmp_path: Path, argv: list[str], files: list[str], seed: int):
    """Run ``argv`` uninterrupted in ``reference/``; in ``killed/`` kill it at a random moment of
    the reference's duration and run it again to the end. Returns (reference folder, killed
    folder, steps: reference, killed sitting, resumed sitting, one interval of the killed sitting,
    the record files' text at the kill)."""
    folders = {}
    for name in ("reference", "killed"):
        folders[name] = tmp_path / name
        folders[name].mkdir()
        for f in files:
            (folders[name] / f).write_bytes((tmp_path / f).read_bytes())
    t0 = time.monotonic()
    ref = start(argv, folders["reference"], tmp_path / "reference.steps")
    assert ref.wait(timeout=600) == 0, (tmp_path / "reference.out").read_text()
    duration = time.monotonic() - t0
    kill_after = random.Random(seed).uniform(0.15, 0.85) * duration
    killed = start(argv, folders["killed"], tmp_path / "killed.steps")
    time.sleep(kill_after)
    finished_first = killed.poll() is not None
    if not finished_first:
        os.killpg(killed.pid, signal.SIGKILL)  # the command and any worker it started
    killed.wait(timeout=60)
    at_kill = {p.name: p.read_bytes() for p in folders["killed"].rglob("*.jsonl")}
    resumed = start(argv, folders["killed"], tmp_path / "resumed.steps")
    assert resumed.wait(timeout=600) == 0, (tmp_path / "resumed.out").read_text()
    logged = chunks(tmp_path / "killed.steps")
    steps = dict(reference=sum(n for _, n in chunks(tmp_path / "reference.steps")),
                 killed=sum(n for _, n in logged), resumed=sum(n for _, n in chunks(tmp_path / "resumed.steps")),
                 interval=one_interval(logged, INTERVAL_S), kill_after_s=round(kill_after, 2),
                 finished_before_the_kill=finished_first)
    return folders["reference"], folders["killed"], steps, at_kill


def check_steps_and_records(steps: dict, at_kill: dict[str, bytes], folder: Path, seed: int) -> None:
    redone = steps["killed"] + steps["resumed"] - steps["reference"]
    print(f"seed {seed}: {redone} steps redone; {steps}")
    assert steps["reference"] > 0, steps
    assert 0 <= redone <= steps["interval"], f"seed {seed}: {redone} steps redone, one interval {steps}"
    for name, before in at_kill.items():  # what was recorded before the kill is kept as it was
        whole = before[:before.rfind(b"\n") + 1]  # a line cut by the kill is the only part that may go
        after = next(folder.rglob(name)).read_bytes()
        assert after.startswith(whole), f"seed {seed}: {name} lost or changed records written before the kill"


def seed_of_this_run() -> int:
    return int(os.environ.get("WARPDEM_KILL_SEED", time.time_ns() % 1_000_000))


def test_a_campaign_killed_at_a_random_moment_resumes_losing_at_most_one_interval(tmp_path):
    seed = seed_of_this_run()
    doc = {**CAMPAIGN, "processes": 1, "output": "out", "checkpoints": {"every_s": INTERVAL_S}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(doc))
    ref, killed, steps, at_kill = run_killed_and_resumed(
        tmp_path, ["calibrate", "c.yaml", "--no-progress"], ["c.yaml"], seed)
    check_steps_and_records(steps, at_kill, killed, seed)
    assert records(killed / "out") == records(ref / "out"), f"seed {seed}: {steps}"
    result = [json.loads((f / "out/results.json").read_text())["confirmation"] for f in (ref, killed)]
    assert result[0] == result[1], f"seed {seed}"
    assert list((killed / "out/checkpoints").iterdir()) == []


@pytest.mark.slow
def test_a_diagnosis_killed_at_a_random_moment_resumes_losing_at_most_one_interval(tmp_path):
    seed = seed_of_this_run()
    (tmp_path / "lab.yaml").write_text(yaml.safe_dump(LAB, sort_keys=False))
    (tmp_path / "d.yaml").write_text(yaml.safe_dump({**DIAGNOSIS, "output": "out"}, sort_keys=False))
    ref, killed, steps, at_kill = run_killed_and_resumed(tmp_path, ["diagnose", "d.yaml"], ["lab.yaml", "d.yaml"],
                                                         seed)
    check_steps_and_records(steps, at_kill, killed, seed)
    cache = [(f / "out/dem_runs.jsonl").read_text().splitlines()[1:] for f in (ref, killed)]  # less the header
    assert sorted(cache[0]) == sorted(cache[1]), f"seed {seed}: {steps}"
    verdict = [json.loads((f / "out/diagnosis.json").read_text())["verdict"] for f in (ref, killed)]
    assert verdict[0] == verdict[1], f"seed {seed}"


@pytest.mark.parametrize("logged, expected", [([], 0), ([(0.0, 10)], 20), ([(0.0, 10), (0.5, 10), (2.0, 30)], 60)])
def test_one_interval_is_the_most_steps_in_a_window_plus_a_chunk(logged, expected):
    assert one_interval(logged, 1.0) == expected
