"""DEM batches on a Ray cluster (calibration.executor): a local 2-CPU cluster runs a tiny hollow-cylinder
batch, a tiny diagnosis forward model and a tiny campaign part with the same numbers as local processes;
a worker killed mid-batch loses only its task (Ray runs it again); a failure in the experiment code
reaches the caller as the same exception. Skipped where Ray is not installed (``pip install ray``)."""
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

import pytest

ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'warpdem[ray]')")
psutil = pytest.importorskip("psutil")

sys.path.insert(0, str(Path(__file__).parent))
from test_batch_checkpoint import SETS, TINY_CYL  # noqa: E402

from calibration.executor import LocalExecutor, RayExecutor, executor_from_config  # noqa: E402
from calibration.experiments import make_experiment  # noqa: E402
from calibration.model_description import ModelDescription  # noqa: E402
from validation.dem_forward import DEMForwardModel, ObservableSpec  # noqa: E402
from warpdem import ConfigError  # noqa: E402

RAY = RayExecutor(address="local", num_cpus=2, gpus_per_task=0, tasks=2, max_retries=2)
SETS4 = SETS + [dict(mu_s_pp=0.4, mu_s_pw=0.4), dict(mu_s_pp=0.8, mu_s_pw=0.3)]


@pytest.fixture(scope="module", autouse=True)
def cluster():
    RAY.connect()
    yield
    ray.shutdown()


def cylinder():
    return make_experiment("cylinder", "quick", **TINY_CYL)


def observables(results):
    return [(r.status, r.observables) for r in results]


def test_executor_config_is_checked_at_load():
    assert executor_from_config(None, 2) == LocalExecutor(2)
    assert executor_from_config({"kind": "ray", "address": "auto", "tasks": 4}).tasks == 4
    for bad, key in [({"kind": "slurm"}, "kind"), ({"kind": "ray", "gpu": 1}, "gpu"),
                     ({"kind": "ray", "tasks": 0}, "tasks"), ({"kind": "ray", "gpus_per_task": -1}, "gpus_per_task"),
                     ({"kind": "ray", "max_retries": "3"}, "max_retries"), ({"kind": "local", "address": "x"}, "address"),
                     ("ray", "executor")]:
        with pytest.raises(ConfigError, match=key):
            executor_from_config(bad)


def test_a_batch_on_ray_equals_the_same_split_in_local_processes():
    exp = cylinder()
    local = exp.run(SETS4, device="cpu", processes=2)
    on_ray = exp.run(SETS4, device="cpu", executor=RAY)
    assert observables(on_ray) == observables(local)  # bitwise: same fills, same split, same time step
    assert [r.world for r in on_ray] == list(range(4))
    assert on_ray[0].timing["ray_tasks"] == 2
    assert any(r.observables.get("pile_angle") is not None for r in on_ray)


def _kill_one_task_worker(stop: threading.Event, killed: list) -> None:
    """SIGKILL the first Ray worker process found running one of our tasks (title ``ray::_call``)."""
    while not stop.is_set() and not killed:
        for p in psutil.process_iter(["pid", "cmdline", "name"]):
            title = " ".join(p.info.get("cmdline") or []) + " " + (p.info.get("name") or "")
            if "ray::_call" in title:
                time.sleep(1.0)  # mid-batch: the task has started its DEM
                try:
                    os.kill(p.info["pid"], signal.SIGKILL)
                    killed.append(p.info["pid"])
                except ProcessLookupError:
                    continue
                return
        time.sleep(0.1)


def test_a_worker_killed_mid_batch_loses_only_its_task():
    exp = cylinder()
    reference = exp.run(SETS4, device="cpu", processes=2)
    stop, killed = threading.Event(), []
    killer = threading.Thread(target=_kill_one_task_worker, args=(stop, killed))
    killer.start()
    try:
        again = exp.run(SETS4, device="cpu", executor=RAY)
    finally:
        stop.set()
        killer.join()
    assert killed, "no Ray worker was found running a task (the test did not kill anything)"
    assert observables(again) == observables(reference)


def test_a_failure_in_the_experiment_reaches_the_caller_as_itself():
    with pytest.raises(ConfigError, match="unknown contact parameter 'mu_x_pp'"):
        cylinder().run([dict(mu_s_pp=0.3), dict(mu_x_pp=0.1)], device="cpu", executor=RAY)


def _forward(cache, executor):
    spec = ObservableSpec("pile", "cylinder", "pile_angle", {k: v for k, v in TINY_CYL.items() if k != "fill_per_world"})
    return DEMForwardModel(ModelDescription.from_config({"contact_law": {"rolling": "none"}}), None, [], [spec],
                           scale="quick", device="cpu", processes=2, cache=cache, executor=executor)


def test_the_diagnosis_forward_model_writes_the_same_records_on_ray(tmp_path):
    local = _forward(tmp_path / "local" / "dem_runs.jsonl", None)
    on_ray = _forward(tmp_path / "ray" / "dem_runs.jsonl", RAY)
    a = local.evaluate((), SETS, 2, ("pile",))
    b = on_ray.evaluate((), SETS, 2, ("pile",))
    assert a.tobytes() == b.tobytes()

    def records(path):
        return [{k: v for k, v in json.loads(line).items()} for line in path.read_text().splitlines()
                if line.strip().startswith("{") and '"id"' in line]

    assert records(tmp_path / "ray" / "dem_runs.jsonl") == records(tmp_path / "local" / "dem_runs.jsonl")
    # the driver killed and restarted resumes from the records: nothing runs again
    again = _forward(tmp_path / "ray" / "dem_runs.jsonl", RAY)
    assert again.evaluate((), SETS, 2, ("pile",)).tobytes() == b.tobytes()
    assert again.dem_worlds == 0


def test_a_campaign_part_records_the_same_samples_on_ray(tmp_path):
    """`warpdem calibrate CONFIG --max-samples 4 --ray ...`: the design samples a Ray cluster ran are the
    records local processes write (timings aside)."""
    import yaml

    import calibration.campaign as cp

    settings = {k: v for k, v in TINY_CYL.items() if k != "fill_per_world"}
    cfg = {"name": "ray-part", "device": "cpu", "processes": 2,
           "parameters": {"mu_s_pp": [0.2, 0.8], "mu_s_pw": [0.2, 0.8]},
           "design": {"samples": 8, "held_out": 2, "seed": 3}, "batch_worlds": 4,
           "responses": [{"name": "pile", "experiment": "cylinder", "scale": "quick", "settings": settings,
                          "target": 30.0}]}
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(cfg))
    outs = {}
    for label, extra in [("local", []), ("ray", ["--ray", "local"])]:
        outs[label] = tmp_path / label
        assert cp.calibrate_main([str(path), "--out", str(outs[label]), "--max-samples", "4", "--no-progress",
                                  *extra]) == 0

    def samples(folder):
        recs = [json.loads(line) for line in (folder / "samples.jsonl").read_text().splitlines() if line.strip()]
        return [{k: v for k, v in r.items() if k not in ("wall_s", "dem_wall_share_s", "sitting")} for r in recs
                if "index" in r]

    assert samples(outs["ray"]) == samples(outs["local"])
    assert len(samples(outs["ray"])) == 4


def test_a_gpu_task_gets_a_worker_of_its_own():
    """Ray names a task's GPU through CUDA_VISIBLE_DEVICES, which CUDA reads once per process: a
    GPU task must not run in a worker that already started CUDA for another GPU (max_calls=1),
    while CPU tasks keep reusing their workers."""
    declared: list[dict] = []

    class FakeRemote:
        def options(self, **kw):
            return ("options", kw)

    class FakeRay:
        def remote(self, *args, **kw):
            if args and callable(args[0]):  # @ray.remote without arguments
                declared.append({})
                return FakeRemote()
            declared.append(kw)
            return lambda fn: FakeRemote()

    ex = RayExecutor(address="local", gpus_per_task=1)
    _, opts = ex.remote_function(FakeRay(), print, on_gpu=True)
    assert declared[-1].get("max_calls") == 1 and declared[-1].get("num_gpus") == 1 and opts["num_gpus"] == 1
    _, opts = ex.remote_function(FakeRay(), print, on_gpu=False)
    assert declared[-1] == {} and opts["num_gpus"] == 0
