"""DEM solver (``step(state_in, state_out, dt)``) and a thin ``Simulation`` driver."""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import warp as wp

from . import contact_rows, kernels, layouts, stages
from .errors import ConfigError, ContactOverflowError, StabilityError, StabilityWarning
from .model import Model, State
from .stages.cell_list import CellList, build_neighbour_list_from_cells_kernel
from .stages.launch import resolve_register_cap
from .timestep import TimeStepLimits, check_time_step, speed_bound

UNSTABLE_MODES = ("raise", "freeze")
# how the Verlet list finds its candidates (DEMSolver's neighbour_search)
NEIGHBOUR_SEARCHES = ("cell_list", "hash_grid")
DEFAULT_NEIGHBOUR_SEARCH = "cell_list"
# how the wall contacts are computed (DEMSolver's wall_stage): collection and forces as two
# kernels, or both in one kernel (one thread per sphere); the same body states, bit for bit
# (wear sums on a GPU agree to float rounding: their atomic adds are unordered)
WALL_STAGES = ("split", "fused")
DEFAULT_WALL_STAGE = "split"
# where entry k of sphere i lies in the Verlet list (DEMSolver's neighbour_layout) and in the
# contact slots (history_layout): i * capacity + k, or k * num_spheres + i (warpdem.layouts);
# the same results, bit for bit. "auto" (the default) picks by device (resolve_performance_options).
SLOT_LAYOUTS = layouts.SLOT_LAYOUTS
DEFAULT_NEIGHBOUR_LAYOUT = "auto"
DEFAULT_HISTORY_LAYOUT = "auto"
# whether the integrator places the member spheres (DEMSolver's fused_placement); "auto" picks by device
DEFAULT_FUSED_PLACEMENT = "auto"
# how sphere-sphere pairs are evaluated (DEMSolver's pair_evaluation); "auto" picks by device and law
DEFAULT_PAIR_EVALUATION = "auto"
# slots per sphere for the triangles of moving walls it may touch (DEMSolver's wall_candidates);
# 0: query the moving walls' BVHs every step
DEFAULT_WALL_CANDIDATES = 32


def wall_reach(wall) -> float:
    """Largest distance [m] of a wall's rest-mesh vertex from its motion's origin c0 (bounds how
    far the wall's rotation carries a touching sphere, :func:`~warpdem.stages.wall_contacts.wall_drift`)."""
    v = np.asarray(wall.vertices, dtype=np.float64) - np.asarray(wall.motion.origin, dtype=np.float64)
    return float(np.sqrt((v * v).sum(axis=1).max())) if len(v) else 0.0


def resolve_performance_options(on_gpu: bool, neighbour_layout: str = "auto", history_layout: str = "auto",
                                fused_placement: bool | str = "auto") -> tuple[str, str, bool]:
    """The layouts and placement a solver uses for ``"auto"`` (``on_gpu``: its device is CUDA): on a
    GPU the slot-major layouts and the fused placement (one settled bed of 1e6 spheres, H200,
    2026-11-27: 6.5e8 -> 8.9e8 sphere-steps/s; 200k spheres in drum worlds +11 %; small models
    unchanged; ``benchmarks/levers_gpu.sh``), on the CPU
    the sphere-major layouts and a placement launch (slot-major contact slots cost 6-11 % there).
    Every choice gives the same results, bit for bit (``tests/test_layout_levers.py``).
    Explicit values pass through, checked."""
    cuda = bool(on_gpu)
    out = []
    for name, value in (("neighbour_layout", neighbour_layout), ("history_layout", history_layout)):
        if value == "auto":
            value = "slot_major" if cuda else "sphere_major"
        if value not in SLOT_LAYOUTS:
            raise ConfigError(f"{name} must be one of {SLOT_LAYOUTS + ('auto',)}, got {value!r}")
        out.append(value)
    if isinstance(fused_placement, str):
        choices = {"auto": cuda, "on": True, "off": False}
        if fused_placement not in choices:
            raise ConfigError(f"fused_placement must be True, False or one of {tuple(choices)}, "
                              f"got {fused_placement!r}")
        fused_placement = choices[fused_placement]
    return out[0], out[1], bool(fused_placement)


def resolve_pair_evaluation(on_gpu: bool, law, pair_evaluation: str = "auto") -> str:
    """``"full"`` or ``"half"`` for a solver's ``pair_evaluation``. ``"auto"``: ``"half"`` on the CPU
    when the law allows it (:attr:`ContactLaw.pair_antisymmetric`), else ``"full"``. ``"half"`` is
    refused on a GPU (its per-sphere rows without atomics keep results bitwise reproducible there)
    and for a law that does not allow it."""
    if pair_evaluation == "auto":
        return "half" if (not on_gpu and law.pair_antisymmetric) else "full"
    if pair_evaluation not in stages.PAIR_EVALUATIONS:
        raise ConfigError(f"pair_evaluation must be one of {stages.PAIR_EVALUATIONS + ('auto',)}, "
                          f"got {pair_evaluation!r}")
    if pair_evaluation == "half" and on_gpu:
        raise ConfigError("pair_evaluation='half' runs on the CPU only (on a GPU every sphere sums its own row: "
                          "no atomics, bitwise reproducible); use 'full' or 'auto'")
    if pair_evaluation == "half" and not law.pair_antisymmetric:
        odd = [f"{k}:{s.name}" for k, s in law.submodels.items() if not getattr(s, "pair_antisymmetric", False)]
        raise ConfigError(f"pair_evaluation='half' needs sub-models whose pair force is antisymmetric; "
                          f"{', '.join(odd)} do not declare it (pair_antisymmetric); use 'full' or 'auto'")
    return pair_evaluation


def body_states(state: State) -> kernels.BodyStates:
    """The bodies of ``state`` packed for the integrator and the placement kernels."""
    bodies = kernels.BodyStates()
    bodies.active, bodies.q, bodies.rot = state.body_active, state.body_q, state.body_rot
    bodies.v, bodies.w = state.body_v, state.body_w
    return bodies


# names of the State arrays that hold per-sphere contact slots
HISTORY_ARRAYS = ("contact_partner", "contact_spring", "contact_roll", "contact_wnormal")


#: copies of the wall accumulators on a GPU (``WallStats(lanes="auto")``) and the most entries per
#: field they may take together
WEAR_LANES = 32
WEAR_LANE_BUDGET = 1 << 21


def wear_lane_count(lanes: int | str, entries: int, on_gpu: bool) -> int:
    """Copies of the wall accumulators: ``"auto"``: :data:`WEAR_LANES` (halved until ``entries``
    times it fits in :data:`WEAR_LANE_BUDGET`) on a GPU, 1 on the CPU; an explicit power of two in
    1..64 passes through."""
    if lanes == "auto":
        if not on_gpu:
            return 1
        k = WEAR_LANES
        while k > 1 and entries * k > WEAR_LANE_BUDGET:
            k //= 2
        return k
    if isinstance(lanes, bool) or not isinstance(lanes, (int, np.integer)) or not 1 <= lanes <= 64 \
            or lanes & (lanes - 1):
        raise ConfigError(f"wear_lanes must be 'auto' or a power of two in 1..64, got {lanes!r}")
    return int(lanes)


class WallStats:
    """Per-triangle, per-world wall accumulators (relative wear model).

    ``energy_n``/``energy_t``: accumulated normal / tangential contact energy
    sum |F_n . v_n| dt, sum |F_t . v_t| dt [J]; ``impulse_n``/``impulse_t``: sum |F| dt [N s].

    Layout (``entries`` per field): a wall present in every world (``world = -1``) has one entry
    per triangle and world, the walls of one world (one drum per world at its own speed) one per
    triangle, so the size grows with the number of walls, never with worlds x walls:
    entry = ``wall_base[k] + world * wall_stride[k] + triangle``, the shared walls world-major first
    (stride = their triangle count ``shared_triangles``), then each one-world wall (stride 0).
    :meth:`per_triangle` gives any wall as (num_worlds, triangles) with zeros in the worlds it is
    not in.

    The wall stage adds into ``lanes`` copies of every entry (sphere i into copy i % lanes), so
    that the thousands of spheres resting on one floor triangle do not queue their atomic adds on
    one address; reading a field sums the copies in a fixed order (one small launch). ``lanes``:
    ``"auto"`` gives :data:`WEAR_LANES` copies on a GPU where they fit in
    :data:`WEAR_LANE_BUDGET` entries per field, 1 otherwise and on the CPU (one thread: nothing
    queues), or an explicit count (a power of two, 1-64).
    """

    FIELDS = ("energy_n", "energy_t", "impulse_n", "impulse_t")

    def __init__(self, model: Model, lanes: int | str = "auto") -> None:
        self.model = model
        walls, worlds = model.walls, model.num_worlds
        shared = [w.world == -1 for w in walls]
        self.shared_triangles = int(sum(w.num_triangles for w, s in zip(walls, shared) if s))
        base, shared_at, own_at = [], 0, worlds * self.shared_triangles
        for w, s in zip(walls, shared):
            base.append(shared_at if s else own_at)
            shared_at, own_at = (shared_at + w.num_triangles, own_at) if s else (shared_at, own_at + w.num_triangles)
        self.wall_base = np.asarray(base, dtype=np.int64)
        self.wall_stride = np.asarray([self.shared_triangles if s else 0 for s in shared], dtype=np.int64)
        self.entries = max(own_at, 1)
        if self.entries >= 2 ** 31:
            raise ConfigError(f"the wall accumulators need {self.entries} entries per field, more than a 32-bit "
                              "index reaches: fewer worlds, or walls shared by every world")
        self.lanes = wear_lane_count(lanes, self.entries, model.device.is_cuda)
        if self.entries * self.lanes >= 2 ** 31:
            raise ConfigError(f"wear_lanes={self.lanes} x {self.entries} wall accumulator entries exceed a 32-bit "
                              "index: choose fewer lanes ('auto' does)")
        d = model.device
        self.wall_base_array = wp.array(self.wall_base if len(walls) else np.zeros(1, np.int64), dtype=int, device=d)
        self.wall_stride_array = wp.array(self.wall_stride if len(walls) else np.zeros(1, np.int64), dtype=int,
                                          device=d)
        self._lane_arrays = {f: wp.zeros(self.entries * self.lanes, dtype=float, device=model.device)
                             for f in self.FIELDS}

    def wall_entries(self, wall: int) -> np.ndarray:
        """Entry of every (world, triangle) of one wall, shape (num_worlds, triangles); -1 in the
        worlds the wall is not in."""
        w = self.model.walls[wall]
        worlds = np.arange(self.model.num_worlds)[:, None]
        idx = self.wall_base[wall] + worlds * self.wall_stride[wall] + np.arange(w.num_triangles)[None, :]
        if w.world != -1:
            idx = np.where(worlds == w.world, idx, -1)
        return idx

    def world_major_index(self) -> np.ndarray:
        """For each entry, its index in the layout of checkpoints before the compact one
        (``world * total_triangles + tri_offset[wall] + triangle`` for every world and wall)."""
        m = self.model
        out = np.zeros(self.entries, dtype=np.int64)
        for k, w in enumerate(m.walls):
            idx = self.wall_entries(k)
            world, tri = np.nonzero(idx >= 0)
            out[idx[world, tri]] = world * m.total_triangles + w.tri_offset + tri
        return out

    def lane_array(self, field: str) -> wp.array:
        """The accumulator copies of one field (``lanes * entries``; what the wall stage adds into)."""
        return self._lane_arrays[field]

    def summed(self, name: str) -> wp.array:
        """One accumulator (``name`` in :attr:`FIELDS`), the copies summed: shape (entries,) in the
        layout of the class docstring (:meth:`per_triangle` gives it per wall and world)."""
        lanes = self._lane_arrays[name]
        if self.lanes == 1:
            return lanes
        out = wp.empty(self.entries, dtype=float, device=self.model.device)
        wp.launch(kernels.sum_wear_lanes, dim=self.entries, inputs=[lanes, self.lanes, self.entries, out],
                  device=self.model.device)
        return out

    energy_n = property(lambda self: self.summed("energy_n"))
    energy_t = property(lambda self: self.summed("energy_t"))
    impulse_n = property(lambda self: self.summed("impulse_n"))
    impulse_t = property(lambda self: self.summed("impulse_t"))

    def zero(self) -> None:
        for a in self._lane_arrays.values():
            a.zero_()

    def export_lanes(self) -> dict[str, np.ndarray]:
        """Every copy of every field, shape (lanes, entries) (for a checkpoint)."""
        return {f: a.numpy().reshape(self.lanes, self.entries) for f, a in self._lane_arrays.items()}

    def load(self, field: str, values: np.ndarray, world_major: bool = False) -> None:
        """Set one field: ``values`` of shape (entries,) (into the first copy, the others zeroed) or
        (lanes, entries) as :meth:`export_lanes` gave them (copied as they are). ``world_major``:
        the values are in the layout of checkpoints written before the compact one (one entry per
        world and triangle of every wall); they are moved into this layout first."""
        values = np.asarray(values, dtype=np.float32)
        if world_major:
            m = self.model
            size = max(m.num_worlds * m.total_triangles, 1)
            if values.shape[-1:] != (size,):
                raise ConfigError(f"wall accumulator {field}: {values.shape} values for {size} entries")
            values = values[..., self.world_major_index()] if m.walls else values[..., :1]
        if values.shape == (self.lanes, self.entries):
            self._lane_arrays[field].assign(values.reshape(-1))
            return
        if values.shape[-1:] != (self.entries,):
            raise ConfigError(f"wall accumulator {field}: {values.shape} values for {self.entries} entries")
        full = np.zeros((self.lanes, self.entries), dtype=np.float32)
        full[0] = values.reshape(-1, self.entries).sum(axis=0)
        self._lane_arrays[field].assign(full.reshape(-1))

    def per_triangle(self, field: str, wall: int | None = None) -> np.ndarray:
        """(num_worlds, T_wall) array of one accumulator for one wall (zeros in the worlds it is not
        in), or (num_worlds, total_triangles) of all walls in wall order."""
        m = self.model
        a = getattr(self, field).numpy()
        walls = range(len(m.walls)) if wall is None else [wall]
        parts = []
        for k in walls:
            idx = self.wall_entries(k)
            parts.append(np.where(idx >= 0, a[np.maximum(idx, 0)], 0.0).astype(a.dtype))
        if not parts:
            return np.zeros((m.num_worlds, 0), dtype=np.float32)
        return parts[0] if wall is not None else np.concatenate(parts, axis=1)

    def wall_triangles(self, values: np.ndarray, wall: int, world: int | None = None) -> np.ndarray:
        """One wall's triangles, shape (T_wall,), from ``values`` (a field as :meth:`summed` gives it,
        on the host): in ``world``, or summed over every world (None). Reads only that wall's
        entries, so a model of thousands of one-world walls writes its VTK frames without building
        a worlds x triangles array per wall."""
        w = self.model.walls[wall]
        t = np.arange(w.num_triangles)
        base, stride = int(self.wall_base[wall]), int(self.wall_stride[wall])
        if w.world != -1:  # one world: its entries only
            inside = world is None or world == w.world
            return values[base + t] if inside else np.zeros(w.num_triangles, dtype=values.dtype)
        if world is not None:
            return values[base + world * stride + t]
        return values[base + np.arange(self.model.num_worlds)[:, None] * stride + t[None, :]].sum(axis=0)

    def per_component(self, field: str, wall: int) -> dict[str, np.ndarray]:
        """Sum of one accumulator over each labelled component of a wall, per world."""
        w = self.model.walls[wall]
        tri = self.per_triangle(field, wall)
        if w.triangle_labels is None:
            return {w.name: tri.sum(axis=1)}
        out = {}
        for lab in np.unique(w.triangle_labels):
            name = w.label_names[lab] if lab < len(w.label_names) else f"{w.name}:{lab}"
            out[name] = tri[:, w.triangle_labels == lab].sum(axis=1)
        return out


class DEMSolver:
    """Explicit DEM solver for a :class:`Model`.

    Each step: place member spheres from body poses (walls move rigidly and are looked up in
    their rest frame, so no wall mesh is moved or refitted); rebuild the Verlet neighbour list
    if a sphere moved more than skin / 2 (decided on the device); evaluate contacts (one
    thread per sphere, full neighbour list with per-sphere history slots); integrate bodies
    (semi-implicit Euler); isolate unstable worlds; advance time. Nothing is copied to the
    host inside a step.

    Unstable worlds: a body whose new state is NaN/inf, or faster than ``v_max``, is put back
    to its last pose at rest and its world is frozen (paused: bodies held, contacts skipped)
    with the first cause recorded on the device; other worlds go on unchanged.
    :meth:`check` raises :class:`StabilityError` naming them; :meth:`failed_worlds` lists them.

    Args:
        model: the model.
        dt: time step [s], checked against :func:`~warpdem.timestep.check_time_step`.
        v_ref: largest expected impact speed for the stability check [m/s].
        force: accept a step above the stability limit (with a :class:`StabilityWarning`).
        v_max: speed [m/s] above which a body marks its world unstable (default
            :func:`~warpdem.timestep.speed_bound`: 10 (v_ref + wall speed) + free-fall speed
            over the model's extent). Spin is not bounded (only NaN/inf).
        neighbour_skin: Verlet skin [m] (default 0.3 * max radius): the neighbour list holds
            pairs closer than r_i + r_j + skin and is rebuilt (decided on the device, no host
            sync) once any sphere has moved more than skin / 2.
        max_neighbours: list capacity per sphere (default 3 * max_contacts for free spheres of
            similar size, 6 x with r_max > 2 r_min, 8 x with clumps); overflow is an error that names
            the capacity needed.
        conditional_rebuild: put the neighbour search and list kernel behind a conditional graph
            node (``wp.capture_if``) so steps without a rebuild skip them (fails to instantiate
            with ``neighbour_search="hash_grid"`` on Warp 1.19: HashGrid.build allocates).
        neighbour_search: how the list finds candidates: ``"cell_list"`` (default;
            :class:`~warpdem.stages.cell_list.CellList`, plain kernel launches that return at
            once on steps without a rebuild) or ``"hash_grid"`` (Warp's ``wp.HashGrid``, rebuilt
            every step). Both give the same list, entry for entry.
        wall_stage: how the wall contacts are computed: ``"split"`` (default; wall-contact
            collection and wall forces as two kernels, the contacts passed through
            ``WallSlots``) or ``"fused"`` (one kernel per contact law doing both for a sphere in
            one thread). Both give the same body states, bit for bit (on a GPU the per-triangle
            wear sums agree to float rounding: atomic adds in no fixed order). Measured on an H100:
            "fused" is 2 % faster at 1e6 spheres and 4-5 % slower on small drum models.
        neighbour_layout: where entry k of sphere i lies in the Verlet list: ``"sphere_major"``
            (``i * max_neighbours + k``) or ``"slot_major"`` (``k * num_spheres + i``: the
            threads of a warp read consecutive addresses as they walk their lists); default
            ``"auto"``: slot-major on a GPU, sphere-major on the CPU
            (:func:`resolve_performance_options`, which gives the measured gains). Same results,
            bit for bit; :meth:`neighbour_rows` reads the list in either layout.
        history_layout: the same choice for the per-sphere contact slots (the States' contact
            history and this step's wall slots; default ``"auto"`` as above). Same results, bit for bit; checkpoints are saved
            in the default layout whatever the solver's (:meth:`export_state`, :meth:`import_state`).
        fused_placement: the integrator's thread per body writes its member spheres' positions
            and packed views right after it moved the body, so a step launches no placement kernel
            that reads every body again (True or ``"on"``; False or ``"off"``: a placement launch
            at the start of each step; default ``"auto"``: on on a GPU, off on the CPU). The views are then those of the State the last step wrote; the next step places
            them all itself (one early-exit launch otherwise) on the first step, when a step starts
            from another State, after :meth:`invalidate_views` (called by :meth:`pause_worlds`,
            :meth:`import_state`, ``Simulation.remove_outside`` and ``Simulation.invalidate_graph``)
            and when a list rebuild was requested before the step (:meth:`request_neighbour_rebuild`,
            or a kernel that sets ``rebuild[0]``). Code that changes a State's bodies between steps
            some other way must call :meth:`invalidate_views`. Same results, bit for bit.
        wall_candidates: slots per sphere for the triangles of the moving walls of its world that
            it may touch (default 32): each sphere gathers them from the walls' BVHs within
            r + skin and tests only these each step, until it has moved more than skin / 2 or a
            wall's motion has carried it more than skin / 2 through the wall's rest frame
            (:func:`~warpdem.stages.wall_contacts.moving_wall_candidates`); a sphere with more
            candidates queries the BVHs each step until its next gathering. 0: every sphere of a
            world with a moving wall queries its BVHs every step. Same results, bit for bit.
        force_registers: CUDA register cap per thread of the wall- and particle-force kernels, a
            trade of registers for resident warps (:mod:`warpdem.stages.launch`): an integer in
            24..255, ``None`` (the compiler's choice) or ``"auto"`` (the default: 80 on a GPU for
            models of more than 2 x SMs x 512 spheres, 135k on an H100; a 1e6-sphere bed +7.4 %,
            small models unchanged). Ignored on the CPU. Same results, bit for bit.
        wear_lanes: copies of the wall accumulators (:class:`WallStats`): ``"auto"`` (32 on a GPU
            where they fit, 1 on the CPU) or a power of two in 1..64. The forces do not depend on it;
            the accumulated wear only to float rounding (atomic adds are unordered on a GPU anyway).
    """

    def __init__(self, model: Model, dt: float, v_ref: float = 2.0, force: bool = False,
                 neighbour_skin: float | None = None, max_neighbours: int | None = None,
                 conditional_rebuild: bool = False, v_max: float | None = None,
                 neighbour_search: str = DEFAULT_NEIGHBOUR_SEARCH, wall_stage: str = DEFAULT_WALL_STAGE,
                 neighbour_layout: str = DEFAULT_NEIGHBOUR_LAYOUT, history_layout: str = DEFAULT_HISTORY_LAYOUT,
                 fused_placement: bool | str = DEFAULT_FUSED_PLACEMENT,
                 wall_candidates: int = DEFAULT_WALL_CANDIDATES, force_registers: int | str | None = "auto",
                 wear_lanes: int | str = "auto", pair_evaluation: str = DEFAULT_PAIR_EVALUATION) -> None:
        self.model = model
        self.conditional_rebuild = bool(conditional_rebuild)
        self.pair_evaluation = resolve_pair_evaluation(model.device.is_cuda, model.contact_law, pair_evaluation)
        if neighbour_search not in NEIGHBOUR_SEARCHES:
            raise ConfigError(f"neighbour_search must be one of {NEIGHBOUR_SEARCHES}, got {neighbour_search!r}")
        self.neighbour_search = neighbour_search
        if wall_stage not in WALL_STAGES:
            raise ConfigError(f"wall_stage must be one of {WALL_STAGES}, got {wall_stage!r}")
        self.wall_stage = wall_stage
        self.neighbour_layout, self.history_layout, self.fused_placement = resolve_performance_options(
            model.device.is_cuda, neighbour_layout, history_layout, fused_placement)
        neighbour_layout, history_layout = self.neighbour_layout, self.history_layout
        self.limits: TimeStepLimits = check_time_step(model, dt, v_ref, force)
        self.dt = float(dt)
        self.v_ref = float(v_ref)
        self.force = bool(force)
        self._dt_checked = {self.dt}
        self.v_max = speed_bound(model, v_ref) if v_max is None else float(v_max)
        if not self.v_max > 0:
            raise ConfigError(f"v_max must be > 0 m/s, got {v_max}")
        d = model.device
        n = model.num_spheres
        k = model.max_contacts
        self.sphere_f = wp.zeros(n, dtype=wp.vec3, device=d)
        self.sphere_t = wp.zeros(n, dtype=wp.vec3, device=d)
        self.half_reactions = wp.zeros(n if self.pair_evaluation == "half" else 1, dtype=int, device=d)
        # this step's wall contacts, from the wall-collection stage to the wall-force stage
        self.wall_count = wp.zeros(n, dtype=int, device=d)
        self.slot_point = wp.zeros(n * k, dtype=wp.vec3, device=d)
        self.slot_depth = wp.zeros(n * k, dtype=float, device=d)
        self.slot_tri = wp.zeros(n * k, dtype=int, device=d)
        self.overflow = wp.zeros(1, dtype=int, device=d)
        # per world: 0 stable, else the first cause of instability (kernels.UNSTABLE_*)
        self.world_fail = wp.zeros(max(model.num_worlds, 1), dtype=int, device=d)
        self._reported_unstable: set[int] = set()
        self.world_paused = wp.zeros(max(model.num_worlds, 1), dtype=int, device=d)
        self.external_force = wp.zeros(model.num_bodies, dtype=wp.vec3, device=d)
        # bumped by every change that alters what a step launches (a captured graph is then stale)
        self.graph_epoch = 0
        self._use_external_force = False
        self.wall_stats = WallStats(model, wear_lanes)
        self.skin = 0.3 * model.max_radius if neighbour_skin is None else float(neighbour_skin)
        if not self.skin > 0:
            raise ConfigError(f"neighbour_skin must be > 0 m, got {neighbour_skin}")
        if max_neighbours is None:
            # a Verlet list of near-monodisperse free spheres holds ~12-20 entries (more while a
            # loose fill is compressed by impacts); small members of
            # clumps or wide size distributions see many more neighbours within r_i + r_max + skin
            clumps = bool(np.any(model.host["body_count"] > 1))
            wide = model.max_radius > 2.0 * model.min_radius
            max_neighbours = (8 if clumps else 6 if wide else 3) * model.max_contacts
        self.max_neighbours = int(max_neighbours)
        if model.num_spheres * self.max_neighbours >= 2 ** 31:
            raise ConfigError(
                f"the neighbour list would need {model.num_spheres} spheres x {self.max_neighbours} slots = "
                f"{model.num_spheres * self.max_neighbours:.3g} entries, past Warp's array limit of 2^31: run fewer "
                f"worlds per launch (a campaign's batch_worlds) or pass a smaller max_neighbours")
        # side of a search cell [m]: every neighbour within r_i + r_j + skin lies in the 27 cells around
        self.cell_size = 2.0 * model.max_radius + self.skin
        self.grid: wp.HashGrid | None = None
        self.cell_list: CellList | None = None
        if neighbour_search == "hash_grid":
            dim = int(min(256, max(16, round((2.0 * n) ** (1.0 / 3.0)))))
            self.grid = wp.HashGrid(dim, dim, dim, device=d)
        else:
            self.cell_list = CellList(n, self.cell_size, d)
        self._list_kernel = (kernels.build_neighbour_list_kernel(neighbour_layout) if self.grid is not None
                             else build_neighbour_list_from_cells_kernel(neighbour_layout))
        self._integrate = kernels.integrate_bodies_kernel(self.fused_placement)
        self._isolate = kernels.isolate_unstable_bodies_kernel(self.fused_placement)
        # fused_placement: [0] != 0 asks the next step to place every sphere (cleared by the integrator)
        self.place_request = wp.ones(1, dtype=int, device=d)
        self._views_of: State | None = None  # the State whose spheres the views show (fused_placement)
        self.views = wp.zeros(n, dtype=kernels.SphereView, device=d)
        self.nb_count = wp.zeros(n, dtype=int, device=d)
        self.nb_index = wp.zeros(n * self.max_neighbours, dtype=int, device=d)
        self.near_wall = wp.zeros(n, dtype=int, device=d)
        self.x_at_build = wp.zeros(n, dtype=wp.vec3, device=d)
        self.rebuild = wp.ones(1, dtype=int, device=d)
        self.nb_overflow = wp.zeros(2, dtype=int, device=d)  # [dropped, largest list needed]
        self.list_builds = wp.zeros(1, dtype=int, device=d)
        self.moving_walls = [i for i, w in enumerate(model.walls) if not w.motion.is_static]
        self.wall_moving = wp.array([0 if w.motion.is_static else 1 for w in model.walls] or [0], dtype=int, device=d)
        self.wall_reach = wp.array([wall_reach(w) for w in model.walls] or [0.0], dtype=float, device=d)
        if isinstance(wall_candidates, bool) or not isinstance(wall_candidates, (int, np.integer)) or wall_candidates < 0:
            raise ConfigError(f"wall_candidates must be an integer >= 0 (slots per sphere), got {wall_candidates!r}")
        # slots only where a moving wall exists
        self.wall_candidates = int(wall_candidates) if self.moving_walls else 0
        cand_rows = n if self.wall_candidates else 1
        self.candidate_count = wp.full(cand_rows, int(stages.CANDIDATES_UNSET), dtype=int, device=d)
        self.candidate_wall = wp.zeros(max(cand_rows * self.wall_candidates, 1), dtype=int, device=d)
        self.candidate_triangle = wp.zeros(max(cand_rows * self.wall_candidates, 1), dtype=int, device=d)
        self.candidate_x = wp.zeros(cand_rows, dtype=wp.vec3, device=d)
        self.candidate_t = wp.zeros(cand_rows, dtype=wp.float64, device=d)
        self.force_registers = resolve_register_cap(force_registers, d, n)
        self.stages = stages.contact_stages(model.contact_law, neighbour_layout, history_layout, self.force_registers,
                                            self.pair_evaluation)
        self.pack_contact_inputs()
        # body-force models (warpdem.body_forces): launched after the contacts, summed into one
        # per-body force that the integrator adds (with the external force, if used)
        self.body_forces = tuple(getattr(model, "body_forces", ()))
        self.body_force_context = None
        if self.body_forces:
            from .body_forces import BodyForceContext

            self.body_force_context = BodyForceContext(self)
            for bf in self.body_forces:
                bf.bind(self.body_force_context)

    @property
    def use_external_force(self) -> bool:
        """Whether the integrator adds ``external_force`` [N per body] (read when a step is launched
        or captured: changing it makes a :class:`Simulation` capture its graph again)."""
        return self._use_external_force

    @use_external_force.setter
    def use_external_force(self, on: bool) -> None:
        if bool(on) != self._use_external_force:
            self._use_external_force = bool(on)
            self.graph_epoch += 1

    # ---------------------------------------------------------------- step
    def step(self, state_in: State, state_out: State, dt: float | None = None) -> None:
        """Advance ``state_in`` by ``dt`` [s] into ``state_out`` (distinct States of this model).

        A ``dt`` other than the solver's is checked against the same stability limit: above it
        is a ConfigError (a :class:`StabilityWarning` if the solver was built with ``force``)."""
        m = self.model
        if dt is None:
            dt = self.dt
        else:
            dt = float(dt)
            if dt not in self._dt_checked:
                self._check_step_dt(dt)
        fp = m.fingerprint
        if state_in.model_fingerprint != fp or state_out.model_fingerprint != fp:
            bad = state_in if state_in.model_fingerprint != fp else state_out
            raise ConfigError(f"step: a State of model {bad.model_fingerprint} was given to the solver of "
                              f"model {fp}; make States with this model's model.state()")
        if state_in.contact_rows not in (None, self.pair_evaluation):
            raise ConfigError(f"step: the State's contact rows were written with pair_evaluation="
                              f"'{state_in.contact_rows}', this solver uses '{self.pair_evaluation}'; move a State "
                              f"between such solvers with export_state / import_state")
        state_in.contact_rows = state_out.contact_rows = self.pair_evaluation
        d = m.device
        if self.fused_placement:
            self._place_spheres_on_request(state_in)
        else:
            self.place_spheres(state_in)
        wp.launch(kernels.flag_moved_spheres, dim=m.num_spheres,
                  inputs=[state_in.sphere_x, self.x_at_build, 0.5 * self.skin, self.rebuild], device=d)
        if self.conditional_rebuild:
            wp.capture_if(self.rebuild, on_true=self._build_neighbour_list, state=state_in)
        else:
            self._build_neighbour_list(state_in)
        self.launch_contacts(state_in, state_out, dt)
        f_ext, use_ext = self.external_force, self.use_external_force
        if self.body_forces:
            f_ext, use_ext = self.apply_body_forces(state_in, state_out, dt), True
        bodies_in, bodies_out = body_states(state_in), body_states(state_out)
        wp.launch(self._integrate, dim=m.num_bodies, inputs=[
            self._members, m.body_world, self.sphere_f, self.sphere_t, f_ext, int(use_ext), wp.vec3(*m.gravity), dt,
            bodies_in, bodies_out, self.world_paused, state_out.sphere_x], device=d)
        wp.launch(self._isolate, dim=m.num_bodies, inputs=[
            m.body_world, bodies_in, bodies_out, self.v_max, self.world_fail, self.world_paused, self._members,
            state_out.sphere_x], device=d)
        if self.fused_placement:
            self._views_of = state_out
        wp.launch(kernels.advance_time, dim=1, inputs=[state_in.time, dt, state_out.time], device=d)

    def _check_step_dt(self, dt: float) -> None:
        """Refuse (ConfigError) or, with ``force``, warn about a step ``dt`` [s] above the limit."""
        lim = self.limits.limit
        if not (dt > 0 and np.isfinite(dt)):
            raise ConfigError(f"step: dt must be a positive finite number of seconds, got {dt}")
        if dt > lim:
            msg = (f"step: dt = {dt:.3g} s exceeds the stability limit {lim:.3g} s this solver was checked for "
                   f"(v_ref = {self.v_ref} m/s; its dt is {self.dt:.3g} s)")
            if not self.force:
                raise ConfigError(msg + "; build the solver with force=True to accept it")
            warnings.warn(f"{msg}: {dt / lim:.2f} x the limit, accepted because force=True", StabilityWarning,
                          stacklevel=3)
        self._dt_checked.add(dt)

    def apply_body_forces(self, state_in: State, state_out: State, dt: float) -> wp.array:
        """Per-body force [N] of the body-force models for this step (device only, capturable):
        starts from the external force (if used) or zero, each model adds its part."""
        ctx = self.body_force_context
        if self.use_external_force:
            wp.copy(ctx.force, self.external_force)
        else:
            ctx.force.zero_()
        for bf in self.body_forces:
            bf.launch(ctx, state_in, state_out, dt)
        return ctx.force

    def place_spheres(self, state: State) -> None:
        """Sphere positions (``state.sphere_x``) and packed views from the body poses."""
        m = self.model
        wp.launch(kernels.place_sphere_views, dim=m.num_spheres, inputs=[self._members, body_states(state), state.sphere_x],
                  device=m.device)

    def _place_spheres_on_request(self, state: State) -> None:
        """``fused_placement``: the placement launch of a step, which returns at once unless the
        views are stale (``place_request``) or a list rebuild was asked for before the step; a
        step from a State other than the one the last step wrote sets the request first."""
        m = self.model
        if state is not self._views_of:
            self.place_request.fill_(1)
        threads = min(m.num_spheres, kernels.MAX_PLACEMENT_THREADS)
        wp.launch(kernels.place_sphere_views_on_request, dim=threads, inputs=[
            self.rebuild, m.num_spheres, threads, self._members, body_states(state), state.sphere_x], device=m.device)

    def invalidate_views(self) -> None:
        """With ``fused_placement``: place every sphere from its State at the start of the next
        step (call after changing a State's bodies between steps other than through the solver
        or the Simulation). Without it every step places them anyway: nothing to do."""
        if self.fused_placement:
            self.place_request.fill_(1)

    def _build_neighbour_list(self, state: State) -> None:
        """Rebuild the Verlet list if ``self.rebuild`` is set (decided on the device).

        ``neighbour_search="cell_list"``: the cell list's launches and the list kernel all return
        at once unless a sphere moved more than skin / 2, so a step without a rebuild costs a
        few empty launches. ``"hash_grid"``: Warp's hash grid is rebuilt every step (it
        allocates and sorts with CUB, so it cannot sit in a conditional CUDA-graph node); the
        list kernel returns at once unless a rebuild is due."""
        m = self.model
        spheres = self._list_spheres(state)
        walls, build = self._packed.walls, self._verlet_build
        if self.cell_list is not None:
            self.cell_list.build(state.sphere_x, m.sphere_world, m.sphere_body, state.body_active, self.rebuild)
            wp.launch(self._list_kernel, dim=m.num_spheres,
                      inputs=[self.cell_list.table, spheres, walls, build], device=m.device)
        else:
            self.grid.build(state.sphere_x, self.cell_size, groups=m.sphere_world)
            wp.launch(self._list_kernel, dim=m.num_spheres, inputs=[self.grid.id, spheres, walls, build],
                      device=m.device)
        wp.launch(kernels.finish_build, dim=1, inputs=[self.rebuild, self.list_builds], device=m.device)

    def pause_worlds(self, state: State, worlds) -> None:
        """Hold every body of ``worlds`` (indices or a boolean mask over worlds) at rest in its
        current pose until :meth:`resume_worlds`: their velocities are zeroed and the integrator
        leaves them in place, so a settled world waits unchanged while other worlds settle."""
        flags = self.world_paused.numpy().copy()
        sel = np.asarray(worlds)
        if sel.dtype == bool:
            if sel.shape != (self.model.num_worlds,):
                raise ConfigError(f"pause_worlds: mask needs {self.model.num_worlds} entries, got {sel.shape}")
            sel = np.flatnonzero(sel)
        if sel.size and (sel.min() < 0 or sel.max() >= self.model.num_worlds):
            raise ConfigError(f"pause_worlds: world index out of range 0..{self.model.num_worlds - 1}: {sel.tolist()}")
        flags[sel] = 1
        self.world_paused.assign(flags)
        m = self.model
        wp.launch(kernels.stop_paused_bodies, dim=m.num_bodies,
                  inputs=[m.body_world, self.world_paused, state.body_v, state.body_w], device=m.device)
        self.invalidate_views()

    def resume_worlds(self) -> None:
        """Release every paused world (it starts again from rest); worlds frozen as unstable
        stay frozen."""
        wp.launch(kernels.release_worlds, dim=self.world_paused.shape[0], inputs=[self.world_fail, self.world_paused],
                  device=self.model.device)

    @property
    def paused_worlds(self) -> np.ndarray:
        """Boolean mask of the paused worlds (those frozen as unstable included)."""
        return self.world_paused.numpy()[: self.model.num_worlds] != 0

    def failed_worlds(self) -> dict[int, str]:
        """{world: cause} of the worlds frozen as unstable so far (reads the device flags)."""
        codes = self.world_fail.numpy()[: self.model.num_worlds]
        causes = {int(kernels.UNSTABLE_NONFINITE): "NaN/inf in a body state",
                  int(kernels.UNSTABLE_SPEED): f"a body faster than v_max = {self.v_max:.3g} m/s"}
        return {int(w): causes.get(int(c), f"cause {int(c)}") for w, c in enumerate(codes) if c != 0}

    def request_neighbour_rebuild(self) -> None:
        """Force a list rebuild at the next step (after bodies were added, moved or removed; with
        ``fused_placement`` the step then also places every sphere first)."""
        self.rebuild.fill_(1)

    def neighbour_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """The Verlet list on the host, whatever its layout: entries per sphere (n,) and the
        entries (n, max_neighbours) (row i: sphere i's neighbours in its first count[i] columns)."""
        n, cap = self.model.num_spheres, self.max_neighbours
        index = layouts.to_sphere_major(self.nb_index.numpy(), self.neighbour_layout, n, cap)
        return self.nb_count.numpy().copy(), index.reshape(n, cap)

    def export_state(self, state: State) -> dict[str, np.ndarray]:
        """``state.to_numpy()`` with the contact slots in the default layout (what checkpoints
        hold, whatever this solver's ``history_layout``)."""
        data = state.to_numpy()
        n, k = self.model.num_spheres, self.model.max_contacts
        for name in HISTORY_ARRAYS:
            data[name] = layouts.to_sphere_major(data[name], self.history_layout, n, k)
        if self.pair_evaluation == "half":  # checkpoints hold full rows (warpdem.contact_rows)
            data = contact_rows.half_rows_to_full(data, n, k)
        return data

    def import_state(self, state: State, data: dict[str, np.ndarray], fingerprint: str | None = None) -> None:
        """Load arrays of :meth:`export_state` (default slot layout) into ``state`` in this
        solver's layout (``fingerprint``: as in :meth:`State.load_numpy`)."""
        n, k = self.model.num_spheres, self.model.max_contacts
        data = dict(data)
        if self.pair_evaluation == "half" and all(name in data for name in HISTORY_ARRAYS + ("contact_count",)):
            data = contact_rows.full_rows_to_half(data, n, k)
        for name in HISTORY_ARRAYS:
            if name in data:
                data[name] = layouts.from_sphere_major(data[name], self.history_layout, n, k)
        state.load_numpy(data, fingerprint=fingerprint)
        state.contact_rows = self.pair_evaluation
        self.invalidate_views()

    def contact_counts(self, state: State) -> np.ndarray:
        """Each sphere's contacts in ``state`` (walls and spheres, each pair counted for both of its
        spheres, whatever the pair evaluation; ``state.contact_count`` holds a row's entries)."""
        n, k = self.model.num_spheres, self.model.max_contacts
        partner = layouts.to_sphere_major(state.contact_partner.numpy(), self.history_layout, n, k)
        return contact_rows.contacts_per_sphere(state.contact_count.numpy(), partner, n, k, self.pair_evaluation)

    def pack_contact_inputs(self) -> None:
        """Pack the model's and the solver's arrays that the contact stages and the
        neighbour-list build read or write into their structs (:mod:`warpdem.stages.structs`,
        and :class:`~warpdem.kernels.VerletBuild` for the list build, which shares the
        neighbour list and walls with the stages; references, no copies). Done once at
        construction; call again after replacing any of those arrays (the per-State history,
        the per-State spheres of the list build and the step's time are packed at launch)."""
        m = self.model
        spheres = stages.SphereSet()
        spheres.view = self.views
        spheres.world = m.sphere_world
        neighbours = stages.NeighbourList()
        neighbours.count = self.nb_count
        neighbours.index = self.nb_index
        neighbours.capacity = self.max_neighbours
        neighbours.near_static_wall = self.near_wall
        walls = stages.WallSet()
        walls.mesh = m.wall_mesh
        walls.world_start = m.world_wall_start
        walls.world_index = m.world_wall_index
        walls.moving = self.wall_moving
        walls.material = m.wall_material
        walls.tri_offset = m.wall_tri_offset
        walls.lin_vel = m.wall_lin_vel
        walls.ang_vel = m.wall_ang_vel
        walls.origin = m.wall_origin
        walls.t_start = m.wall_t_start
        walls.t_stop = m.wall_t_stop
        walls.reach = self.wall_reach
        candidates = stages.MovingWallCandidates()
        candidates.count, candidates.wall, candidates.triangle = (self.candidate_count, self.candidate_wall,
                                                                  self.candidate_triangle)
        candidates.x_built, candidates.t_built = self.candidate_x, self.candidate_t
        candidates.capacity = self.wall_candidates
        candidates.margin = float(self.skin)
        params = stages.ContactParameters()
        params.youngs_modulus = m.mat_e
        params.poisson_ratio = m.mat_nu
        params.table = m.contact_params
        found = stages.WallSlots()
        found.count = self.wall_count
        found.point = self.slot_point
        found.depth = self.slot_depth
        found.triangle = self.slot_tri
        wear = stages.WearAccumulators()
        ws = self.wall_stats
        wear.energy_n, wear.energy_t = ws.lane_array("energy_n"), ws.lane_array("energy_t")
        wear.impulse_n, wear.impulse_t = ws.lane_array("impulse_n"), ws.lane_array("impulse_t")
        wear.wall_base, wear.wall_stride = ws.wall_base_array, ws.wall_stride_array
        wear.entries, wear.lanes = ws.entries, ws.lanes
        forces = stages.SphereForces()
        forces.force = self.sphere_f
        forces.torque = self.sphere_t
        forces.reactions = self.half_reactions
        self._packed = stages.PackedInputs(spheres, neighbours, walls, params, found, wear, forces, candidates)
        members = kernels.MemberPlacement()
        members.body, members.first, members.count = m.sphere_body, m.body_first, m.body_count
        members.mass, members.inertia = m.body_mass, m.body_inertia
        members.offset, members.radius, members.material = m.sphere_offset, m.sphere_radius, m.sphere_material
        members.views, members.request = self.views, self.place_request
        self._members = members
        build = kernels.VerletBuild()
        build.neighbours = neighbours  # a copy of the struct (its array references): pack it filled
        build.x_at_build = self.x_at_build
        build.overflow = self.nb_overflow
        build.rebuild = self.rebuild
        self._verlet_build = build
        self._packed_history: dict[int, tuple[tuple, stages.ContactHistory]] = {}
        self._packed_list_spheres: dict[int, tuple[tuple, tuple[float, float], kernels.ListSpheres]] = {}
        self._packed_step: dict[tuple, tuple[wp.array, stages.StepInputs]] = {}
        self.graph_epoch += 1  # the launches now read other arrays

    def _history(self, state: State) -> stages.ContactHistory:
        """The contact-history struct of ``state`` (packed once per State)."""
        arrays = (state.contact_count, state.contact_partner, state.contact_spring, state.contact_roll,
                  state.contact_wnormal)
        cached = self._packed_history.get(id(state))
        if cached is not None and all(a is b for a, b in zip(cached[0], arrays)):
            return cached[1]
        h = stages.ContactHistory()
        h.count, h.partner, h.spring, h.roll, h.wall_normal = arrays
        h.slots = self.model.max_contacts
        if len(self._packed_history) > 4:  # States of this solver: usually two
            self._packed_history.clear()
        self._packed_history[id(state)] = (arrays, h)
        return h

    def _list_spheres(self, state: State) -> kernels.ListSpheres:
        """What the list build reads of ``state``'s spheres (its positions and active flags,
        the model's radii, worlds and bodies, r_max and the skin [m]; packed once per State)."""
        m = self.model
        arrays = (state.sphere_x, m.sphere_radius, m.sphere_world, m.sphere_body, state.body_active)
        distances = (float(m.max_radius), float(self.skin))
        cached = self._packed_list_spheres.get(id(state))
        if cached is not None:
            cached_arrays, cached_distances, cached_spheres = cached
            if all(a is b for a, b in zip(cached_arrays, arrays)) and cached_distances == distances:
                return cached_spheres
        spheres = kernels.ListSpheres()
        spheres.position, spheres.radius, spheres.world, spheres.body, spheres.body_active = arrays
        spheres.max_radius, spheres.skin = distances
        if len(self._packed_list_spheres) > 4:  # States of this solver: usually two
            self._packed_list_spheres.clear()
        self._packed_list_spheres[id(state)] = (arrays, distances, spheres)
        return spheres

    def _step_inputs(self, state: State, dt: float, walls_on: bool) -> stages.StepInputs:
        """The step struct for ``state``'s time, ``dt`` [s] and whether the wall stages run."""
        key = (id(state.time), float(dt), bool(walls_on))
        cached = self._packed_step.get(key)
        if cached is not None and cached[0] is state.time:
            return cached[1]
        step = stages.StepInputs()
        step.time = state.time
        step.dt = float(dt)
        step.world_paused = self.world_paused
        step.walls_on = int(walls_on)
        step.overflow = self.overflow
        if len(self._packed_step) > 16:
            self._packed_step.clear()
        self._packed_step[key] = (state.time, step)
        return step

    def launch_contacts(self, state_in: State, state_out: State, dt: float, walls_on: bool = True) -> None:
        """The contact stages alone (the neighbour list must be built for ``state_in``):
        wall contacts, wall forces and wear, particle forces (:mod:`warpdem.stages`), from
        ``state_in``'s history into ``state_out``'s, forces into ``sphere_f``/``sphere_t``.
        ``walls_on=False`` leaves the walls out (profiling); a model without walls skips the
        wall stages too. The wall stages are two kernels or one (``wall_stage``). The stages read the
        packed sphere views: with ``fused_placement`` those of the State the last step wrote, so call
        :meth:`place_spheres` on ``state_in`` first when it is another State."""
        m = self.model
        d = m.device
        n = m.num_spheres
        p = self._packed
        st = self.stages
        walls_on = bool(walls_on) and len(m.walls) > 0
        step = self._step_inputs(state_in, dt, walls_on)
        history = self._history(state_in)
        contacts = self._history(state_out)
        if walls_on and self.wall_stage == "fused":
            wp.launch(st.collect_wall_contacts_and_forces, dim=n, inputs=[
                p.spheres, p.neighbours, p.walls, p.params, step, p.candidates, history, contacts, p.found, p.wear,
                p.forces], device=d)
        elif walls_on:
            wp.launch(st.collect_wall_contacts, dim=n,
                      inputs=[p.spheres, p.neighbours, p.walls, step, p.candidates, contacts, p.found], device=d)
            wp.launch(st.wall_forces, dim=n,
                      inputs=[p.spheres, p.walls, p.params, step, history, contacts, p.found, p.wear, p.forces],
                      device=d)
        if self.pair_evaluation == "half":
            wp.launch(stages.start_half_pair_sums, dim=n, inputs=[step, p.found, p.forces], device=d)
        wp.launch(st.particle_forces, dim=n,
                  inputs=[p.spheres, p.neighbours, p.params, step, history, contacts, p.found, p.forces], device=d)
        if self.pair_evaluation == "half":
            wp.launch(stages.check_half_row_slots, dim=n, inputs=[step, contacts, p.forces], device=d)

    # ---------------------------------------------------------------- checks
    def check(self, on_unstable: str = "raise") -> dict[int, str]:
        """Raise if worlds became unstable or a contact slot overflowed since the last check.

        Unstable worlds (already frozen on the device) come first: ``on_unstable="raise"``
        raises :class:`StabilityError` (``.worlds``: {world: cause}) when a world failed since
        the last check; ``"freeze"`` warns (:class:`StabilityWarning`) and goes on. Returns
        :meth:`failed_worlds`."""
        if on_unstable not in UNSTABLE_MODES:
            raise ConfigError(f"on_unstable must be one of {UNSTABLE_MODES}, got {on_unstable!r}")
        failed = self.failed_worlds()
        new = sorted(set(failed) - self._reported_unstable)
        if new:
            self._reported_unstable.update(new)
            listing = "; ".join(f"world {w}: {failed[w]}" for w in new)
            msg = (f"{len(new)} world(s) became unstable and were frozen ({listing}); the other worlds go on. "
                   f"Time step {self.dt:.3g} s (limit {self.limits.limit:.3g} s for impacts up to "
                   f"v_ref = {self.v_ref} m/s): a smaller step, a larger v_ref, or a start without huge overlaps "
                   f"or speeds")
            if on_unstable == "raise":
                raise StabilityError(msg, worlds={w: failed[w] for w in new})
            warnings.warn(msg, StabilityWarning, stacklevel=2)
        ov = int(self.overflow.numpy()[0])
        nb_ov, nb_needed = (int(v) for v in self.nb_overflow.numpy())
        if nb_ov:
            self.nb_overflow.zero_()
            raise ContactOverflowError(
                f"{nb_ov} neighbour(s) did not fit the {self.max_neighbours} neighbour-list slots per sphere "
                f"(a sphere needed {nb_needed}); pass max_neighbours >= {nb_needed} (or a smaller "
                f"neighbour_skin) to the solver", kind="neighbours", capacity=self.max_neighbours, needed=nb_needed)
        if ov:
            self.overflow.zero_()
            raise ContactOverflowError(
                f"{ov} contact(s) did not fit the {self.model.max_contacts} slots per sphere and would have been "
                f"dropped; build the model with a larger max_contacts", kind="contacts",
                capacity=self.model.max_contacts)
        return failed


@dataclass(frozen=True)
class SettleReport:
    """Outcome of :meth:`Simulation.settle`: simulated time spent [s], whether every world met
    the criterion, kinetic energy per active body per world when it stopped [J], bodies removed,
    and the worlds frozen as unstable ({world: cause}; they did not settle)."""

    time: float
    settled: bool
    ke_per_particle: np.ndarray
    removed: int
    failed: dict = field(default_factory=dict)


@dataclass
class SettleProgress:
    """Where a :meth:`Simulation.settle` loop stands after a chunk: steps done, bodies removed,
    the last kinetic energy per active body per world [J], which worlds are paused and which met
    the criterion. Handed to ``after_chunk`` and taken back as ``start`` to continue the loop
    (e.g. from a checkpoint) exactly where it stood."""

    done: int
    removed: int
    ke_report: np.ndarray
    paused: np.ndarray
    met: np.ndarray

    @classmethod
    def fresh(cls, num_worlds: int) -> "SettleProgress":
        return cls(0, 0, np.zeros(num_worlds), np.zeros(num_worlds, dtype=bool), np.zeros(num_worlds, dtype=bool))


class Simulation:
    """Owns two States and a solver; runs many steps with periodic checks.

    The inner loop is captured once in a graph (``steps_per_graph`` steps, even so that the
    state parity is preserved) and replayed: a CUDA graph on a GPU, Warp's CPU graph on the CPU
    (``use_graph=None``: both, except on the CPU with ``neighbour_search="hash_grid"`` or
    ``conditional_rebuild``; the same results as stepping one by one, bit for bit). The solver options
    (``neighbour_skin``, ``max_neighbours``, ``conditional_rebuild``, ``v_max``,
    ``neighbour_search``, ``wall_stage``, ``neighbour_layout``, ``history_layout``,
    ``fused_placement``, ``wall_candidates``) are passed to :class:`DEMSolver`.
    """

    def __init__(self, model: Model, dt: float, v_ref: float = 2.0, force: bool = False,
                 use_graph: bool | None = None, steps_per_graph: int = 20, neighbour_skin: float | None = None,
                 max_neighbours: int | None = None, conditional_rebuild: bool = False,
                 v_max: float | None = None, neighbour_search: str = DEFAULT_NEIGHBOUR_SEARCH,
                 wall_stage: str = DEFAULT_WALL_STAGE, neighbour_layout: str = DEFAULT_NEIGHBOUR_LAYOUT,
                 history_layout: str = DEFAULT_HISTORY_LAYOUT,
                 fused_placement: bool | str = DEFAULT_FUSED_PLACEMENT,
                 wall_candidates: int = DEFAULT_WALL_CANDIDATES, force_registers: int | str | None = "auto",
                 wear_lanes: int | str = "auto", pair_evaluation: str = DEFAULT_PAIR_EVALUATION) -> None:
        self.model = model
        # what run() and settle() do when a world becomes unstable: "raise" (StabilityError) or
        # "freeze" (the world stays frozen and is listed, the others run on)
        self.on_unstable = "raise"
        self.solver = DEMSolver(model, dt, v_ref=v_ref, force=force, neighbour_skin=neighbour_skin,
                                max_neighbours=max_neighbours, conditional_rebuild=conditional_rebuild,
                                v_max=v_max, neighbour_search=neighbour_search, wall_stage=wall_stage,
                                neighbour_layout=neighbour_layout, history_layout=history_layout,
                                fused_placement=fused_placement, wall_candidates=wall_candidates,
                                force_registers=force_registers, wear_lanes=wear_lanes,
                                pair_evaluation=pair_evaluation)
        self.state = model.state()
        self._next = model.state()
        self.steps = 0
        if use_graph is None:
            # CUDA: a CUDA graph. CPU: Warp's CPU graph (recorded launches replayed in a native loop; a
            # 1,900-sphere drum step 1.39 -> 1.11 ms on one core, the same results bit for bit), except
            # where a step does host work that a CPU capture would not replay (Warp's HashGrid build,
            # conditional nodes)
            use_graph = model.device.is_cuda or (self.solver.neighbour_search == "cell_list"
                                                 and not self.solver.conditional_rebuild)
        self.use_graph = bool(use_graph)
        self.steps_per_graph = max(2, steps_per_graph + (steps_per_graph % 2))
        self._graph = None

    @property
    def dt(self) -> float:
        return self.solver.dt

    @property
    def time(self) -> float:
        return self.state.sim_time

    def _step_pair(self, n: int) -> None:
        for _ in range(n):
            self.solver.step(self.state, self._next)
            self.state, self._next = self._next, self.state

    def invalidate_graph(self) -> None:
        """Call after replacing model arrays that a captured graph refers to (also repacks the
        contact stages' structs; with ``fused_placement`` the next step places every sphere)."""
        self.solver.pack_contact_inputs()
        self.solver.invalidate_views()
        self._graph = None

    def failed_worlds(self) -> dict[int, str]:
        """{world: cause} of the worlds frozen as unstable (see :class:`DEMSolver`)."""
        return self.solver.failed_worlds()

    def run(self, steps: int, check_every: int = 1000, callback: Callable[["Simulation"], None] | None = None,
            callback_every: int = 0, progress: bool = False, on_unstable: str | None = None) -> dict[int, str]:
        """Advance ``steps`` steps. ``callback(sim)`` runs every ``callback_every`` steps.

        Every ``check_every`` steps :meth:`DEMSolver.check` looks at the device flags. A world
        that became unstable is frozen at once on the device; ``on_unstable="raise"`` then
        raises :class:`StabilityError` naming it, ``"freeze"`` warns and runs the other worlds
        to the end (None: the simulation's ``on_unstable`` attribute, "raise" unless set).
        Returns the failed worlds ({world: cause}, empty when all are stable)."""
        on_unstable = self.on_unstable if on_unstable is None else on_unstable
        if on_unstable not in UNSTABLE_MODES:
            raise ConfigError(f"on_unstable must be one of {UNSTABLE_MODES}, got {on_unstable!r}")
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
            raise ConfigError(f"run: steps must be a whole number of steps >= 0, got {steps!r} (for a duration in "
                              f"seconds use round(duration / sim.dt))")
        failed: dict[int, str] = {}
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=steps, unit="step", desc="DEM")
        done = 0
        chunk_limit = min(x for x in (check_every, callback_every or check_every) if x > 0)
        while done < steps:
            n = min(chunk_limit, steps - done)
            if callback_every:
                n = min(n, callback_every - (self.steps % callback_every))
            self._advance(n)
            done += n
            if bar is not None:
                bar.update(n)
            if self.steps % check_every == 0 or done == steps:
                failed = self.solver.check(on_unstable)
            if callback_every and self.steps % callback_every == 0 and callback is not None:
                callback(self)
        if bar is not None:
            bar.close()
        return failed

    def _advance(self, n: int) -> None:
        if not self.use_graph or n < self.steps_per_graph:
            self._step_pair(n)
            self.steps += n
            return
        if self._graph is not None and (self._graph_epoch != self.solver.graph_epoch
                                        or {id(self.state), id(self._next)} != {id(s) for s in self._graph[1:]}):
            # the solver changed what a step launches, or the States were replaced, since the capture
            self._graph = None
        if self._graph is None:
            self._step_pair(2)  # warm-up: allocations happen outside the capture
            self.steps += 2
            n -= 2
            a, b = self.state, self._next
            with wp.ScopedCapture(device=self.model.device) as cap:
                for _ in range(self.steps_per_graph // 2):
                    self.solver.step(a, b)
                    self.solver.step(b, a)
            self._graph = (cap.graph, a, b)
            self._graph_epoch = self.solver.graph_epoch
        graph, a, _ = self._graph
        if self.state is not a:  # keep parity with the captured buffers
            self._step_pair(1)
            self.steps += 1
            n -= 1
        reps, rest = divmod(n, self.steps_per_graph)
        for _ in range(reps):
            wp.capture_launch(graph)
        self.steps += reps * self.steps_per_graph
        self._step_pair(rest)
        self.steps += rest

    # ---------------------------------------------------------------- read-back
    def kinetic_energy(self) -> np.ndarray:
        """Kinetic energy per world [J]: each body's (float32, on the device), summed per world in
        body order in float64 on the host, so the same State always gives the same figure."""
        m = self.model
        ke = wp.empty(m.num_bodies, dtype=float, device=m.device)
        s = self.state
        wp.launch(kernels.kinetic_energy, dim=m.num_bodies,
                  inputs=[m.body_mass, m.body_inertia, s.body_active, s.body_rot, s.body_v, s.body_w, ke],
                  device=m.device)
        return np.bincount(m.host["body_world"], weights=ke.numpy().astype(np.float64), minlength=m.num_worlds)

    def sphere_positions(self) -> np.ndarray:
        """World positions of all spheres at the current state (n, 3) [m]."""
        self.solver.place_spheres(self.state)
        return self.state.sphere_x.numpy().astype(np.float64)

    def remove_outside(self, lower, upper, worlds=None) -> int:
        """Deactivate bodies whose centre is outside the box; returns how many were removed now.
        ``worlds``: only those of these worlds (indices or a boolean mask over worlds; None: all)."""
        m = self.model
        on = np.ones(m.num_worlds, dtype=np.int32)
        if worlds is not None:
            on[:] = 0
            on[np.asarray(worlds)] = 1
            if not on.any():
                return 0
        removed = wp.zeros(1, dtype=int, device=m.device)
        wp.launch(kernels.deactivate_outside, dim=m.num_bodies,
                  inputs=[self.state.body_q, wp.vec3(*lower), wp.vec3(*upper), self.state.body_active, m.body_world,
                          wp.array(on, dtype=int, device=m.device), removed],
                  device=m.device)
        self.solver.invalidate_views()
        return int(removed.numpy()[0])

    def pause_worlds(self, worlds) -> None:
        """Hold the bodies of ``worlds`` at rest (see :meth:`DEMSolver.pause_worlds`)."""
        self.solver.pause_worlds(self.state, worlds)

    def resume_worlds(self) -> None:
        self.solver.resume_worlds()

    def settle(self, ke_per_particle: float = 1.0e-6, max_time: float | np.ndarray = 1.5,
               check_interval: float = 0.01, min_time: float | np.ndarray = 0.0,
               remove_box: tuple | None = None, on_unstable: str | None = None,
               start: SettleProgress | None = None,
               after_chunk: Callable[[SettleProgress], None] | None = None) -> "SettleReport":
        """Run until the mean kinetic energy per active body of every world is below
        ``ke_per_particle`` [J] after ``min_time``, or ``max_time`` [s] passed (scalars or one
        value per world). Bodies leaving ``remove_box`` = (lower, upper) [m] are removed at each
        check (every ``check_interval`` s).

        Worlds are independent: a world that meets the criterion (or reaches its ``max_time``)
        is paused at rest (:meth:`pause_worlds`) while the others go on, and all are released at
        the end, so a world's settled state does not depend on the other worlds of its batch.
        ``on_unstable``: as in :meth:`run`; with ``"freeze"`` a world frozen as unstable stops
        (it does not count as settled) and is listed in the report's ``failed``.
        ``start``: continue a loop from this :class:`SettleProgress` (default: from the beginning);
        ``after_chunk``: called with the progress after every chunk that leaves a world running
        (a checkpoint hook)."""
        nw = self.model.num_worlds
        max_w = np.broadcast_to(np.asarray(max_time, dtype=float), (nw,))
        min_w = np.broadcast_to(np.asarray(min_time, dtype=float), (nw,))
        if np.any(max_w < 0) or np.any(min_w < 0):
            raise ConfigError(f"settle: times must be >= 0, got min {min_time}, max {max_time}")
        chunk = max(1, int(round(check_interval / self.dt)))
        n_max = np.round(max_w / self.dt).astype(int)
        pg = start if start is not None else SettleProgress.fresh(nw)
        done, removed = int(pg.done), int(pg.removed)
        ke_report = np.array(pg.ke_report, dtype=float)
        paused, met = np.array(pg.paused, dtype=bool), np.array(pg.met, dtype=bool)
        worlds = self.model.host["body_world"]
        failed: dict[int, str] = {}
        if paused.any():
            self.pause_worlds(paused)
        try:
            while not paused.all():
                # checks fall every ``chunk`` steps from the start; a world whose max_time ends
                # between two checks stops there, alone: its removal and kinetic energy are read
                # for it only, so the other worlds see the checks they would see without it
                # (and it ends as it would alone, where its end is the last chunk's)
                ends = n_max[~paused]
                if ends.min() <= done:  # a world's end is here already (max_time 0, or a resumed loop)
                    target = done
                else:
                    target = min((done // chunk + 1) * chunk, int(ends.max()))
                    between = ends[ends < target]
                    target = int(between.min()) if between.size else target
                k = target - done
                if k > 0:
                    # the option is passed only when set, so wrappers of run() without it still work
                    self.run(k, check_every=k, **({} if on_unstable is None else {"on_unstable": on_unstable}))
                    failed = self.solver.failed_worlds()
                    done += k
                every = (k > 0 and done % chunk == 0) or done >= ends.max()
                check = ~paused if every else ~paused & (done >= n_max)
                if remove_box is not None:
                    removed += self.remove_outside(*remove_box, worlds=None if every else check)
                bad = np.zeros(nw, dtype=bool)
                bad[list(failed)] = True
                active = np.bincount(worlds, weights=self.state.body_active.numpy(), minlength=nw)
                ke = self.kinetic_energy() / np.maximum(active, 1)
                ke_report[check] = ke[check]
                now_met = check & ~bad & (done * self.dt >= min_w - 1e-12) & (ke < ke_per_particle)
                met |= now_met
                stop = now_met | (check & ((done >= n_max) | bad))
                if stop.any():
                    paused |= stop
                    self.pause_worlds(paused)
                if after_chunk is not None and not paused.all():
                    after_chunk(SettleProgress(done, removed, ke_report.copy(), paused.copy(), met.copy()))
        finally:
            self.resume_worlds()
        return SettleReport(done * self.dt, bool(met.all()), ke_report, removed, failed)
