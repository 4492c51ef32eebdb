"""Batch checkpoints (issue 12, "lose nothing on interruption"): a batch of worlds saves its
simulation while it runs; a re-run of the same batch continues from the checkpoint and gives the
results of the uninterrupted run; a checkpoint of another batch or a damaged one is reported and
not used; a campaign killed with SIGKILL resumes mid-batch and ends with the records of an
uninterrupted campaign. CPU, tiny quick-scale batches (a few seconds each)."""
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

import calibration.campaign as cp
import warpdem as wd
from calibration.experiments import checkpoints, make_experiment
from calibration.experiments.checkpoints import BatchCheckpoints
from calibration.experiments.results_json import jsonable

ROOT = Path(__file__).parents[1]
# ~55 spheres of 14-18 mm per world in the quick cylinder (about 5 s per batch of 2 worlds; both measure a pile)
TINY_CYL = dict(fill_mass=1.5, lift_speed=0.5, max_time_after_lift=0.2, min_pile_layers=0.0, fill_per_world=True)
# a quick drum, one revolution recorded, 20 % full (about 10 s per batch of 2 worlds)
SMALL_DRUM = dict(fill_fraction=0.2, discard=0, record=1, fill_per_world=True)
SETS = [dict(mu_s_pp=0.3, mu_s_pw=0.3), dict(mu_s_pp=0.6, mu_s_pw=0.5)]


class Killed(BaseException):
    """Stands for a kill: raised right after a checkpoint was written."""


def kill_after_save(monkeypatch, n: int) -> list:
    """Make the ``n``-th checkpoint save of the next run raise :class:`Killed` once the files are
    written; returns the list of (protocol step label or None, steps) of every save."""
    saves = []
    plain_save = checkpoints.BatchCheckpoint.save

    def save(self, ctx, inner):
        plain_save(self, ctx, inner)
        saves.append(((inner or {}).get("label"), ctx.sim.steps))
        if len(saves) == n:
            raise Killed()

    monkeypatch.setattr(checkpoints.BatchCheckpoint, "save", save)
    return saves


def count_steps(monkeypatch) -> list:
    """Count the steps every ``Simulation.run`` advances (a hook independent of the runner)."""
    steps = [0]
    plain_run = wd.Simulation.run

    def run(self, n, *args, **kwargs):
        steps[0] += int(n)
        return plain_run(self, n, *args, **kwargs)

    monkeypatch.setattr(wd.Simulation, "run", run)
    return steps


def outcome(results) -> list:
    """What must not depend on an interruption: status, angle, observables, diagnostics (JSON)."""
    return [json.dumps(jsonable(dict(status=r.status, error=r.error, angle=r.angle_deg, obs=r.observables,
                                      diag=r.diagnostics, steps=r.timing["steps"],
                                      phases=r.timing["phases_s"])), sort_keys=True) for r in results]


@pytest.mark.parametrize("name, settings, kill_at", [("drum", SMALL_DRUM, 50), ("cylinder", TINY_CYL, 25)])
def test_interrupted_batch_continues_from_its_checkpoint(tmp_path, monkeypatch, name, settings, kill_at):
    """Killed right after a checkpoint, the batch continues from it (fewer steps simulated) and
    its results equal the uninterrupted run's bitwise on the CPU (the engine's checkpoint restarts
    bitwise; the runner restores every protocol state the rest of the run reads)."""
    exp = make_experiment(name, "quick", **settings)
    reference = exp.run(SETS, device="cpu")
    folder = tmp_path / "ck"
    saves = kill_after_save(monkeypatch, kill_at)
    with pytest.raises(Killed):
        make_experiment(name, "quick", **settings).run(SETS, device="cpu", checkpoints=BatchCheckpoints(folder, 1e-9))  # every opportunity: kill point in steps, not wall time
    label, saved_at = saves[-1]
    assert label is not None  # mid-phase (drum: in the rotation, after frames were taken)
    assert sorted(p.suffix for p in folder.iterdir()) == [".json", ".npz"]
    monkeypatch.undo()
    steps = count_steps(monkeypatch)
    resumed = make_experiment(name, "quick", **settings).run(SETS, device="cpu",
                                                             checkpoints=BatchCheckpoints(folder, 1e9))
    total = reference[0].timing["steps"]
    assert steps[0] == total - saved_at and resumed[0].timing["steps_this_run"] == total - saved_at
    ck = resumed[0].timing["checkpoint"]
    assert ck["resumed"]["step"] == saved_at and ck["resumed"]["in_step"] == label
    assert outcome(resumed) == outcome(reference)
    assert all(r.ok for r in resumed) and all(np.isfinite(r.angle_deg) for r in resumed)
    assert list(folder.iterdir()) == []  # removed once the results were returned


def test_checkpoint_of_another_batch_is_not_used(tmp_path, monkeypatch, capsys):
    folder = tmp_path / "ck"
    kill_after_save(monkeypatch, 2)
    with pytest.raises(Killed):
        make_experiment("cylinder", "quick", **TINY_CYL).run(SETS, device="cpu", checkpoints=BatchCheckpoints(folder, 0.2))
    monkeypatch.undo()
    other = [dict(mu_s_pp=0.4, mu_s_pw=0.3), dict(mu_s_pp=0.6, mu_s_pw=0.5)]  # other parameters, same slot
    res = make_experiment("cylinder", "quick", **TINY_CYL).run(other, device="cpu", checkpoints=BatchCheckpoints(folder, 1e9))
    err = capsys.readouterr().err
    assert "belongs to another batch" in err and "not used, removed" in err
    assert res[0].timing["checkpoint"]["resumed"] is None
    assert res[0].timing["steps_this_run"] == res[0].timing["steps"]  # started over
    assert outcome(res) == outcome(make_experiment("cylinder", "quick", **TINY_CYL).run(other, device="cpu"))


@pytest.mark.parametrize("damage", ["truncated npz", "garbled sidecar", "npz missing"])
def test_damaged_checkpoint_is_reported_and_the_batch_starts_over(tmp_path, monkeypatch, capsys, damage):
    folder = tmp_path / "ck"
    kill_after_save(monkeypatch, 2)
    with pytest.raises(Killed):
        make_experiment("cylinder", "quick", **TINY_CYL).run(SETS, device="cpu", checkpoints=BatchCheckpoints(folder, 0.2))
    monkeypatch.undo()
    npz, = folder.glob("*.npz")
    sidecar, = folder.glob("*.json")
    if damage == "truncated npz":
        npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])
    elif damage == "garbled sidecar":
        sidecar.write_text(sidecar.read_text()[:100])
    else:
        npz.unlink()
    res = make_experiment("cylinder", "quick", **TINY_CYL).run(SETS, device="cpu", checkpoints=BatchCheckpoints(folder, 1e9))
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert ("is damaged" in err) if damage == "garbled sidecar" else ("cannot be resumed" in err and "damaged" in err)
    assert "the batch starts over" in err
    assert res[0].timing["checkpoint"]["resumed"] is None and res[0].timing["steps_this_run"] == res[0].timing["steps"]
    assert all(r.ok for r in res)


def test_checkpoints_config_section_is_checked():
    base = {"name": "c", "parameters": {"mu_s_pp": [0.2, 0.7]}, "design": {"samples": 4, "held_out": 0},
            "responses": [{"name": "g", "experiment": "cylinder", "target": 30.0}]}
    cfg = cp.parse_config(base)
    assert cfg.checkpoints.enabled and cfg.checkpoints.every_s == 120.0
    assert cp.parse_config({**base, "checkpoints": {"every_s": 5, "enabled": False}}).checkpoints.every_s == 5.0
    with pytest.raises(wd.ConfigError, match=r"checkpoints.every_s must be >= 0, got -1"):
        cp.parse_config({**base, "checkpoints": {"every_s": -1}})
    with pytest.raises(wd.ConfigError, match=r"checkpoints.evry_s: unknown key"):
        cp.parse_config({**base, "checkpoints": {"evry_s": 10}})


# ----------------------------------------------------------------------------- campaign
CAMPAIGN = {
    "name": "ck", "device": "cpu", "processes": 2,
    "parameters": {"mu_s_pp": [0.3, 0.7], "mu_s_pw": [0.3, 0.7]}, "fixed": {"mu_r_pp": 0.1, "mu_r_pw": 0.1},
    "design": {"samples": 5, "held_out": 0, "seed": 0}, "batch_worlds": 5,
    "responses": [{"name": "gamma", "experiment": "cylinder", "scale": "quick", "target": 20.0,
                   "settings": {k: v for k, v in TINY_CYL.items() if k != "fill_per_world"}}],
    "optimisation": {"pop_size": 8, "n_generations": 3, "tolerance_deg": 5.0, "n_dense": 200},
    "confirmation": {"runs": 1, "refine_rounds": 0},
    "surrogate": {"n_splits": 2, "n_repeats": 1},
    "sensitivity": {"n": 16},
    "checkpoints": {"every_s": 0},
}
VOLATILE = {"wall_s", "dem_wall_share_s", "sitting"}


def calibrate(config: Path, out: Path, log: Path, **popen) -> subprocess.Popen:
    """``warpdem calibrate CONFIG --out OUT`` in a subprocess, stdout and stderr into ``log``."""
    code = "import sys; from warpdem.cli import main; sys.exit(main(sys.argv[1:]))"
    with open(log, "w") as fh:
        return subprocess.Popen([sys.executable, "-c", code, "calibrate", str(config), "--out", str(out),
                                 "--no-progress"], cwd=ROOT, stdout=fh, stderr=subprocess.STDOUT, **popen)


def records(out: Path) -> list:
    """Every record of a campaign folder without what differs between sittings (times, sitting)."""
    def strip(x):
        if isinstance(x, dict):
            return {k: strip(v) for k, v in x.items() if k not in VOLATILE}
        if isinstance(x, list):
            return [strip(v) for v in x]
        return x
    lines = [json.loads(s) for f in ("samples.jsonl", "runs.jsonl") for s in (out / f).read_text().splitlines()]
    return [strip(r) for r in lines]


@pytest.mark.slow
def test_campaign_killed_mid_batch_resumes_from_its_checkpoints(tmp_path):
    """``warpdem calibrate`` is SIGKILLed at a random moment after the first batch checkpoint
    appeared, twice, and run again to the end: its records (angles, fingerprints, parameters,
    fills) equal those of an uninterrupted campaign, none lost or duplicated, and the resumed
    sitting continued a checkpoint (45-70 s on 2 cores)."""
    config = tmp_path / "ck.yaml"
    config.write_text(yaml.safe_dump(CAMPAIGN))
    reference = calibrate(config, tmp_path / "reference", tmp_path / "reference.log")
    assert reference.wait(timeout=300) == 0, (tmp_path / "reference.log").read_text()
    out = tmp_path / "killed"
    rng = random.Random(12)
    logs = []
    for attempt in range(2):
        logs.append(tmp_path / f"killed{attempt}.log")
        started = time.time()
        proc = calibrate(config, out, logs[-1], start_new_session=True)
        t_end = time.monotonic() + 120

        def saved_now() -> bool:  # a sidecar written by this sitting
            return any(p.stat().st_mtime > started for p in (out / "checkpoints").glob("*.json"))

        while not saved_now() and proc.poll() is None and time.monotonic() < t_end:
            time.sleep(0.05)
        assert proc.poll() is None, f"finished before a checkpoint appeared: {logs[-1].read_text()}"
        time.sleep(rng.uniform(0.0, 2.0))
        os.killpg(proc.pid, signal.SIGKILL)  # the campaign and its pool workers
        proc.wait(timeout=30)
    logs.append(tmp_path / "final.log")
    final = calibrate(config, out, logs[-1])
    assert final.wait(timeout=300) == 0, logs[-1].read_text()
    assert any("continuing from step" in log.read_text() for log in logs[1:]), "no sitting continued a checkpoint"
    assert records(out) == records(tmp_path / "reference")
    assert list((out / "checkpoints").iterdir()) == []
    assert json.loads((out / "results.json").read_text())["confirmation"] == \
        json.loads((tmp_path / "reference" / "results.json").read_text())["confirmation"]


def test_a_batch_that_grew_its_slots_resumes_from_its_checkpoint(tmp_path):
    """A batch whose neighbour slots overflowed (and grew) and whose checkpoint is kept after the run
    (``keep_until_recorded``, as a caller that records elsewhere keeps it) runs again from that
    checkpoint without failing (it raised UnboundLocalError on the build time) and gives the same
    observables."""
    exp = make_experiment("cylinder", "quick", **TINY_CYL, max_neighbours=6)
    ck = BatchCheckpoints(tmp_path / "ck", 0.5, keep_until_recorded=True)
    first = exp.run(SETS, device="cpu", checkpoints=ck)
    assert first[0].timing["retries"]  # the slots did overflow and grow
    again = exp.run(SETS, device="cpu", checkpoints=ck)
    assert [r.observables for r in again] == [r.observables for r in first]
