"""The solver's ``wall_stage="fused"`` (wall-contact collection and wall forces in one kernel)
gives the same results as ``"split"`` (two kernels), bit for bit: the five CPU scenes of
tests/test_contact_stages.py (and its contact launch with ``walls_on=False``) are run with each
option and their body states, contact counts, forces and wall wear compared with
``np.array_equal``. Both options call the same ``wp.func``s, so every float operation is the
same, in the same order. The same comparison runs on ``cuda`` where a GPU is present (skipped
otherwise): there the compiler inlines the functions into different kernels, so it also checks
that no floating-point contraction differs between them. One exception on CUDA: the per-triangle
wear accumulators are summed with atomic adds from many threads, in an order the GPU does not fix,
so run to run (even split against split) they agree only to float rounding (rtol 1e-5); on an
H100 the body states matched bit for bit and only ``wear_impulse_n`` differed.
"""
from __future__ import annotations

import functools
import sys
from pathlib import Path

import numpy as np
import pytest
import warp as wp

import warpdem as wd

sys.path.insert(0, str(Path(__file__).parent))
from test_contact_stages import SCENES, run_scene  # noqa: E402


DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no CUDA device"))]


def run_scene_with(name: str, wall_stage: str, device: str, monkeypatch: pytest.MonkeyPatch) -> dict[str, np.ndarray]:
    """:func:`test_contact_stages.run_scene` with every ``Simulation`` built with ``wall_stage``
    and every model on ``device`` (the scenes ask for ``"cpu"``)."""
    finalize = wd.ModelBuilder.finalize

    def finalize_on_device(builder: wd.ModelBuilder, _asked: str | None = None, **options) -> wd.Model:
        return finalize(builder, device, **options)

    with monkeypatch.context() as patch:
        patch.setattr(wd, "Simulation", functools.partial(wd.Simulation, wall_stage=wall_stage))
        patch.setattr(wd.ModelBuilder, "finalize", finalize_on_device)
        return run_scene(name)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", list(SCENES))
def test_fused_wall_stage_is_bitwise_identical_to_split(name, device, monkeypatch):
    split = run_scene_with(name, "split", device, monkeypatch)
    fused = run_scene_with(name, "fused", device, monkeypatch)
    assert int(split["contact_count"].sum()) > 0  # the scene has contacts
    assert split.keys() == fused.keys()
    for key, want in split.items():
        if device == "cuda" and key.startswith("wear_"):
            np.testing.assert_allclose(fused[key], want, rtol=1e-5, atol=1e-12, err_msg=f"{name}/{key}")
        else:
            assert np.array_equal(fused[key], want), f"{name}/{key}: fused differs from split"


def test_wall_stage_option_is_passed_to_the_solver(monkeypatch):
    with monkeypatch.context() as patch:
        patch.setattr(wd, "Simulation", functools.partial(wd.Simulation, wall_stage="fused"))
        sim = SCENES["wear"]()
    assert sim.solver.wall_stage == "fused"
    assert SCENES["wear"]().solver.wall_stage == "split"  # the default


def test_unknown_wall_stage_is_a_config_error():
    model = SCENES["wear"]().model
    with pytest.raises(wd.ConfigError, match=r"wall_stage must be one of \('split', 'fused'\)"):
        wd.DEMSolver(model, 1e-6, force=True, wall_stage="merged")
    with pytest.raises(wd.ConfigError, match="wall_stage"):
        wd.Simulation(model, 1e-6, force=True, use_graph=False, wall_stage="merged")
