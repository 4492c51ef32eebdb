"""settled-bed benchmark (docs/benchmarks.md): the engine's reference case.

N monodisperse spheres d = 18 mm, rho = 2661, E = 1e7 Pa, nu = 0.3, e = 0.6, mu_s = 0.5,
mu_r = 0.1 (EPSD), dt = 5e-5 s, box 0.6 x 0.6 m (widened in x, y at the same depth for
larger N, or W worlds of N each). Pour from a loose lattice, settle until KE per particle
< 1e-6 J, then time 2000 steps after 200 warm-up steps. One JSON line per run.

    python benchmarks/settled_bed.py --spheres 20000 --device cpu
    python benchmarks/settled_bed.py --spheres 1000000 --device cuda
    python benchmarks/settled_bed.py --spheres 20000 --worlds 50 --device cuda
    python benchmarks/settled_bed.py --spheres 1000000 --device cuda --neighbour-search hash_grid
    python benchmarks/settled_bed.py --spheres 1000000 --device cuda --wall-stage fused
    python benchmarks/settled_bed.py --spheres 1000000 --device cuda --save-state /tmp/bed.npz
    python benchmarks/settled_bed.py --spheres 1000000 --device cuda --load-state /tmp/bed.npz \
        --neighbour-layout slot_major --history-layout slot_major --fused-placement

``--save-state`` writes the settled State (contact slots in the default layout) before the
warm-up; ``--load-state`` starts from such a file instead of settling (same --spheres, --worlds,
--rolling, --max-contacts and --order: the model's fingerprint must match), so that solver
variants are timed from one settled bed.
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import time

import numpy as np
import warp as wp

import warpdem as wd
from warpdem import geometry
from warpdem.config_io import (check_output_folder, check_sphere_memory, device_arg, existing_file_arg,
                               nonnegative_int_arg, positive_float_arg, positive_int_arg)
from warpdem.solver import (DEFAULT_FUSED_PLACEMENT, DEFAULT_HISTORY_LAYOUT, DEFAULT_NEIGHBOUR_LAYOUT,
                            DEFAULT_NEIGHBOUR_SEARCH, DEFAULT_PAIR_EVALUATION, DEFAULT_WALL_CANDIDATES,
                            DEFAULT_WALL_STAGE, NEIGHBOUR_SEARCHES, SLOT_LAYOUTS, WALL_STAGES)
from warpdem.stages import PAIR_EVALUATIONS

D = 0.018
R = D / 2


def option_value(text: str) -> int | str | None:
    """A solver option's value on the command line: ``none`` -> None, an integer -> int, else the
    text (``auto``; the solver checks what it gets and names a bad value)."""
    if text == "none":
        return None
    try:
        return int(text)
    except ValueError:
        return text


def add_solver_options(ap: argparse.ArgumentParser) -> None:
    """The solver's performance options as command-line flags (shared by the engine benchmarks)."""
    ap.add_argument("--neighbour-search", default=DEFAULT_NEIGHBOUR_SEARCH, choices=list(NEIGHBOUR_SEARCHES),
                    help=f"candidate search of the Verlet list (default {DEFAULT_NEIGHBOUR_SEARCH})")
    ap.add_argument("--wall-stage", default=DEFAULT_WALL_STAGE, choices=list(WALL_STAGES),
                    help=f"wall contacts and forces as two kernels or one (default {DEFAULT_WALL_STAGE})")
    ap.add_argument("--neighbour-layout", default=DEFAULT_NEIGHBOUR_LAYOUT, choices=["auto", *SLOT_LAYOUTS],
                    help="Verlet list entry k of sphere i at i * capacity + k (sphere_major) or k * n + i "
                         f"(slot_major; default {DEFAULT_NEIGHBOUR_LAYOUT}: slot_major on a GPU)")
    ap.add_argument("--history-layout", default=DEFAULT_HISTORY_LAYOUT, choices=["auto", *SLOT_LAYOUTS],
                    help=f"the same for the contact slots (default {DEFAULT_HISTORY_LAYOUT})")
    ap.add_argument("--fused-placement", nargs="?", const="on", default=DEFAULT_FUSED_PLACEMENT,
                    choices=["auto", "on", "off"],
                    help="the integrator places the member spheres, no placement launch per step (bare "
                         f"flag: on; default {DEFAULT_FUSED_PLACEMENT}: on on a GPU)")
    ap.add_argument("--wall-candidates", type=nonnegative_int_arg, default=DEFAULT_WALL_CANDIDATES,
                    help="slots per sphere for the moving walls' triangles it may touch, kept between "
                         f"gatherings (0: query the moving walls' BVHs every step; default {DEFAULT_WALL_CANDIDATES})")
    ap.add_argument("--force-registers", type=option_value, default="auto",
                    help="CUDA register cap per thread of the wall- and particle-force kernels: an integer, 'none' "
                         "(the compiler's choice) or 'auto' (default: 80 for models of more than 2 x SMs x 512 "
                         "spheres)")
    ap.add_argument("--pair-evaluation", default=DEFAULT_PAIR_EVALUATION, choices=["auto", *PAIR_EVALUATIONS],
                    help="sphere pairs evaluated from both sides or once with the reaction added to the partner "
                         "(default auto: half on the CPU where the law allows it, full on a GPU)")
    ap.add_argument("--wear-lanes", type=option_value, default="auto",
                    help="copies of the wall wear accumulators (default auto: 32 on a GPU, 1 on the CPU)")


#: the solver's layout levers (benchmarks/levers_gpu.sh, levers_ab.py, tests/test_layout_levers.py): every
#: one off, each alone on top of that, and all; the solver's own "auto" picks "all" on a GPU, "off" on the CPU
LEVERS_OFF = dict(neighbour_layout="sphere_major", history_layout="sphere_major", fused_placement=False)
LEVER_VARIANTS = {
    "off": LEVERS_OFF,
    "neighbour_slot_major": {**LEVERS_OFF, "neighbour_layout": "slot_major"},
    "history_slot_major": {**LEVERS_OFF, "history_layout": "slot_major"},
    "fused_placement": {**LEVERS_OFF, "fused_placement": True},
    "all": dict(neighbour_layout="slot_major", history_layout="slot_major", fused_placement=True),
}


def quiet_warp() -> None:
    """Keep Warp's banner and module-load messages off stdout, so that a benchmark's stdout carries
    only its JSON lines (always, whatever ``$WARPDEM_WARP_VERBOSE`` says)."""
    from .warp_output import quiet_warp as quiet

    quiet(always=True)


def kernel_resources(kernel: "wp.Kernel", device: str, block_dim: int = 256) -> dict | None:
    """Registers per thread, local (spilled) bytes per thread and resident warps per SM of a CUDA
    kernel already loaded on ``device`` (CUDA driver's ``cuFuncGetAttribute`` and
    ``cuOccupancyMaxActiveBlocksPerMultiprocessor`` at ``block_dim`` threads per block, Warp's
    default); None on the CPU or when the kernel is not loaded there."""
    import ctypes

    dev = wp.get_device(device)
    if not dev.is_cuda:
        return None
    try:
        forward = kernel.module.get_kernel_hooks(kernel, dev).forward
    except RuntimeError:  # module not loaded on this device
        return None
    if not forward:
        return None
    cuda = ctypes.CDLL("libcuda.so.1")
    fn = ctypes.c_void_p(forward)
    out = {}
    with wp.ScopedDevice(dev):
        for name, attribute in (("registers", 4), ("local_bytes", 3), ("max_threads_per_block", 0)):
            value = ctypes.c_int(0)
            if cuda.cuFuncGetAttribute(ctypes.byref(value), ctypes.c_int(attribute), fn) != 0:
                return None
            out[name] = value.value
        blocks = ctypes.c_int(0)
        if cuda.cuOccupancyMaxActiveBlocksPerMultiprocessor(ctypes.byref(blocks), fn, ctypes.c_int(block_dim),
                                                            ctypes.c_size_t(0)) == 0:
            out["resident_warps_per_sm"] = blocks.value * block_dim // 32
    return out


def force_kernel_resources(solver: wd.DEMSolver) -> dict:
    """:func:`kernel_resources` of the solver's wall- and particle-force kernels (empty on the CPU)."""
    out = {}
    for name in ("wall_forces", "particle_forces"):
        res = kernel_resources(getattr(solver.stages, name), str(solver.model.device))
        if res is not None:
            out[name] = res
    return out


def used_solver_options(solver: wd.DEMSolver) -> dict:
    """The solver options a run actually used (``"auto"`` resolved), for its JSON line."""
    return dict(neighbour_search=solver.neighbour_search, wall_stage=solver.wall_stage,
                neighbour_layout=solver.neighbour_layout, history_layout=solver.history_layout,
                fused_placement=solver.fused_placement, wall_candidates=solver.wall_candidates,
                force_registers=solver.force_registers, wear_lanes=solver.wall_stats.lanes,
                pair_evaluation=solver.pair_evaluation)


def solver_options(args: argparse.Namespace) -> dict:
    """The :class:`warpdem.Simulation` keyword arguments of :func:`add_solver_options`'s flags."""
    return dict(neighbour_search=args.neighbour_search, wall_stage=args.wall_stage,
                neighbour_layout=args.neighbour_layout, history_layout=args.history_layout,
                fused_placement=args.fused_placement, wall_candidates=args.wall_candidates,
                force_registers=args.force_registers, wear_lanes=args.wear_lanes,
                pair_evaluation=args.pair_evaluation)



def loose_fill(n: int, width: float, rng: np.random.Generator, spacing: float = 1.06 * D) -> np.ndarray:
    """Jittered cubic lattice of n centres filling a width x width column from the floor up."""
    per_row = int((width - D) // spacing)
    per_layer = per_row * per_row
    layers = math.ceil(n / per_layer)
    ix, iy, iz = np.meshgrid(np.arange(per_row), np.arange(per_row), np.arange(layers), indexing="ij")
    pts = np.stack([ix.ravel(), iy.ravel(), iz.ravel()], 1)
    pts = pts[np.lexsort((pts[:, 1], pts[:, 0], pts[:, 2]))][:n]
    pos = (pts + 0.5) * spacing + np.array([R, R, R])
    jitter = (spacing - D) / 2 * 0.9
    return pos + rng.uniform(-jitter, jitter, pos.shape)


def morton_order(pos: np.ndarray, cell: float) -> np.ndarray:
    """Indices sorting points along a Z-order (Morton) curve of cells of size ``cell``."""
    c = np.floor((pos - pos.min(0)) / cell).astype(np.uint64)
    code = np.zeros(len(pos), dtype=np.uint64)
    for bit in range(21):
        for axis in range(3):
            code |= ((c[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(code, kind="stable")


def build(n: int, worlds: int, rolling: str, device: str, max_contacts: int, order: str = "morton"):
    law = wd.ContactLaw(rolling=rolling)
    b = wd.ModelBuilder(num_worlds=worlds, contact_law=law, max_contacts=max_contacts)
    b.add_material(wd.Material("bed", 1.0e7, 0.3, 2661.0))
    width = 0.6 * max(1.0, math.sqrt(n / 20000.0))  # same depth as the 20k case
    rng = np.random.default_rng(0)
    pos = loose_fill(n, width, rng)
    if order == "morton":  # memory order follows space: neighbours share cache lines
        pos = pos[morton_order(pos, D)]
    for w in range(worlds):
        b.add_spheres(pos, R, "bed", world=w)
    b.add_wall(geometry.open_box((0, 0, 0), (width, width, pos[:, 2].max() + D)), "bed")
    params = dict(restitution_pp=0.6, restitution_pw=0.6, mu_s_pp=0.5, mu_s_pw=0.5)
    if rolling != "none":
        params.update(mu_r_pp=0.1, mu_r_pw=0.1)
    b.set_contact_parameters(**params)
    return b.finalize(device, check_overlaps=n * worlds <= 200_000), width


def min_bytes_per_sphere_step(contacts_per_sphere: float) -> float:
    """The traffic a step must at least move per sphere [B]: body state in and out (q, rot, v, w:
    52 B each way), sphere position (12 B written, read twice) and radius, and the contact slots in
    and out (count 4 B + per contact partner 4 B, spring 12 B, rolling history 12 B)."""
    return 2 * 52 + 12 * 3 + 8 + 2 * (4 + contacts_per_sphere * 28)


def save_settled_state(path: str, sim: wd.Simulation, settle_sim_time: float) -> None:
    """The settled State (contact slots in the default layout) with the model's fingerprint."""
    data = sim.solver.export_state(sim.state)
    np.savez(path, fingerprint=np.array(sim.model.fingerprint), settle_sim_time=np.array(settle_sim_time),
             **{f"state/{k}": v for k, v in data.items()})


def load_settled_state(path: str, sim: wd.Simulation) -> float:
    """Load a State of :func:`save_settled_state` into both of ``sim``'s States (in its solver's
    layout); returns the simulated settling time it took."""
    with np.load(path) as f:
        data = {k[6:]: f[k] for k in f.files if k.startswith("state/")}
        fingerprint, settle_sim_time = str(f["fingerprint"]), float(f["settle_sim_time"])
    for state in (sim.state, sim._next):
        sim.solver.import_state(state, data, fingerprint=fingerprint)
    sim.solver.request_neighbour_rebuild()
    return settle_sim_time


def time_steps(sim: wd.Simulation, device: str, warmup: int, steps: int) -> float:
    """Run ``warmup`` steps, then time ``steps`` steps [s]."""
    sim.run(warmup)
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    sim.run(steps, check_every=steps)
    wp.synchronize_device(device)
    return time.perf_counter() - t0


def settle_and_time(sim: wd.Simulation, device: str, settle_time: float, warmup: int, steps: int,
                    min_time: float = 0.3, on_settled=None) -> tuple[float, float, float]:
    """The case's protocol: settle (KE per body < 1e-6 J or ``settle_time`` simulated seconds), run
    ``warmup`` steps, time ``steps`` steps. Returns (settling sim time, settling wall s, timed wall s).
    ``on_settled(settle_sim_time)`` is called between settling and the warm-up."""
    t0 = time.perf_counter()
    settle_sim_time = sim.settle(ke_per_particle=1e-6, max_time=settle_time, check_interval=0.05,
                                 min_time=min(min_time, settle_time)).time
    t_settle = time.perf_counter() - t0
    if on_settled is not None:
        on_settled(settle_sim_time)
    return settle_sim_time, t_settle, time_steps(sim, device, warmup, steps)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="warpdem bench", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spheres", type=positive_int_arg, default=20000, help="spheres per world")
    ap.add_argument("--worlds", type=positive_int_arg, default=1)
    ap.add_argument("--device", type=device_arg, default=None, help="cpu or cuda (default: cuda if present)")
    ap.add_argument("--rolling", default="epsd", choices=["none", "cdt", "epsd"])
    ap.add_argument("--steps", type=positive_int_arg, default=2000)
    ap.add_argument("--warmup", type=nonnegative_int_arg, default=200)
    ap.add_argument("--settle-time", type=positive_float_arg, default=3.0, help="max simulated settling time [s]")
    ap.add_argument("--max-contacts", type=positive_int_arg, default=12)
    ap.add_argument("--no-graph", action="store_true")
    ap.add_argument("--conditional-rebuild", action="store_true", help="skip the grid build on steps without a list rebuild")
    ap.add_argument("--order", default="morton", choices=["morton", "lattice"], help="memory order of the spheres")
    add_solver_options(ap)
    ap.add_argument("--save-state", default=None, metavar="NPZ",
                    help="save the settled State here (before the warm-up)")
    ap.add_argument("--load-state", type=existing_file_arg, default=None, metavar="NPZ",
                    help="start from this settled State instead of settling")
    args = ap.parse_args(argv)
    check_sphere_memory(args.spheres * args.worlds, "--spheres x --worlds", "run fewer spheres or worlds")
    if args.save_state:
        from pathlib import Path

        check_output_folder(Path(args.save_state).parent, "--save-state", "the folder of the saved state")
    quiet_warp()
    device = args.device or ("cuda" if wp.is_cuda_available() else "cpu")
    t0 = time.perf_counter()
    model, width = build(args.spheres, args.worlds, args.rolling, device, args.max_contacts, args.order)
    sim = wd.Simulation(model, 5.0e-5, use_graph=None if not args.no_graph else False, steps_per_graph=50,
                        conditional_rebuild=args.conditional_rebuild, **solver_options(args))
    t_build = time.perf_counter() - t0
    if args.load_state:
        t0 = time.perf_counter()
        settle_sim_time = load_settled_state(args.load_state, sim)
        t_settle = time.perf_counter() - t0
        seconds = time_steps(sim, device, args.warmup, args.steps)
    else:
        save = (lambda t: save_settled_state(args.save_state, sim, t)) if args.save_state else None
        settle_sim_time, t_settle, seconds = settle_and_time(sim, device, args.settle_time, args.warmup, args.steps,
                                                             on_settled=save)
    ke = sim.kinetic_energy() / args.spheres
    counts = sim.solver.contact_counts(sim.state)
    n_total = args.spheres * args.worlds
    bytes_per_sphere = min_bytes_per_sphere_step(float(counts.mean()))
    result = dict(
        case="settled-bed", device=str(wp.get_device(device)), device_name=wp.get_device(device).name,
        host=platform.node(), spheres=args.spheres, worlds=args.worlds, total_spheres=n_total, steps=args.steps,
        seconds=round(seconds, 4), sphere_steps_per_s=float(f"{n_total * args.steps / seconds:.4g}"),
        contacts_per_sphere=round(float(counts.mean()), 3), rolling=args.rolling, dt=5e-5,
        box_width_m=round(width, 4), settle_sim_time_s=round(settle_sim_time, 3), settle_wall_s=round(t_settle, 1),
        ke_per_particle_J=float(f"{ke.max():.3g}"), build_s=round(t_build, 1), warp=wp.config.version,
        graph=sim.use_graph, order=args.order, conditional_rebuild=args.conditional_rebuild,
        **used_solver_options(sim.solver), state_from=args.load_state or "settled here",
        min_bytes_per_sphere_step=round(bytes_per_sphere),
        effective_GBps=round(n_total * args.steps * bytes_per_sphere / seconds / 1e9, 1),
        list_builds=int(sim.solver.list_builds.numpy()[0]), date=time.strftime("%Y-%m-%d"))
    print(json.dumps(result), flush=True)
    return result


def cli_main(argv: list[str] | None = None) -> int:
    """``warpdem bench``: run :func:`main`, exit code 0."""
    main(argv)
    return 0


if __name__ == "__main__":
    main()
