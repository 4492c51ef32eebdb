"""Wall stages: collect the wall contacts of each sphere, then their forces and wall wear.

Each stage's per-sphere work is a ``wp.func`` (:func:`collect_sphere_wall_contacts`, and the
per-law ``wall_forces_of_sphere`` of :func:`wall_stage_kernels`); the kernels are thin
wrappers: stage 1 and stage 2 as two launches (``wall_stage="split"``), or both in one thread
(``"fused"``), with the same float operations in the same order.

A wall moves rigidly: a point x0 of its rest mesh is at x(t) = c(t) + R(w tau) (x0 - c0). The
mesh is never moved: a sphere at x is looked up in the rest mesh at x0 = c0 + R^T (x - c(t))
(:func:`warpdem.kernels.point_in_wall_rest_frame`) and the closest point and normal found
there are mapped back to the world frame.

Moving walls: each sphere keeps the triangles it may touch (:class:`~.structs.MovingWallCandidates`,
gathered from the BVHs within r + skin) and gathers them again only when it or a wall has moved
enough to make them stale (:func:`moving_wall_candidates`), so most steps test a few triangles
instead of traversing a BVH. The triangles come in the BVH's order either way: same results, bit
for bit (``DEMSolver(wall_candidates=0)`` queries every step).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import warp as wp

from ..contact.base import ContactInput
from ..contact.law import ContactLaw
from ..kernels import (SLOT_EMPTY, WALL_MATCH_COS, WALL_MERGE_COS, body_lever, closest_point_triangle,
                       damping_mass_function, effective_shear_modulus, effective_youngs_modulus,
                       point_in_wall_rest_frame, wall_is_moving, wall_motion_time, wall_point_velocity)
from ..layouts import DEFAULT_SLOT_LAYOUT, entry_function
from .launch import force_kernel
from .law import law_evaluator
from .structs import (CANDIDATES_OVERFLOW, CANDIDATES_UNSET, ContactHistory, ContactParameters, MovingWallCandidates,
                      NeighbourList, SphereForces, SphereSet, StepInputs, WallSet, WallSlots, WearAccumulators)

wp.set_module_options({"enable_backward": False, "fast_math": True})


@wp.func
def wall_drift(t_then: wp.float64, t_now: wp.float64, ri: float, world: int, walls: WallSet) -> float:
    """Bound on how far [m] a sphere of radius ``ri`` that touches a moving wall of ``world`` at
    ``t_now`` has moved in that wall's rest frame since ``t_then`` through the walls' motion alone
    (its own motion adds at most its displacement). A rigid wall turns by dtheta = |w| dtau and
    its centre moves by |v| dtau (dtau: elapsed motion time between the two instants); the rest
    point x0 = c0 + R^T (x - c(t)) then moves by at most dtheta (reach + r_i) + |v| dtau, since
    |x - c(t)| <= reach + r_i for a touching sphere and |R(a) - R(b)| <= |a - b| for rotations about one
    axis (reach: the wall's largest vertex distance from its centre)."""
    first = walls.world_start[world]
    drift = float(0.0)
    for kk in range(walls.world_start[world + 1] - first):
        k = walls.world_index[first + kk]
        if walls.moving[k] == 0:
            continue
        tau_now = wall_motion_time(t_now, walls.t_start[k], walls.t_stop[k])
        tau_then = wall_motion_time(t_then, walls.t_start[k], walls.t_stop[k])
        dtau = float(wp.abs(tau_now - tau_then))
        d = wp.length(walls.ang_vel[k]) * dtau * (walls.reach[k] + ri) + wp.length(walls.lin_vel[k]) * dtau
        drift = wp.max(drift, d)
    return drift


@wp.func
def gather_moving_wall_candidates(i: int, xi: wp.vec3, ri: float, world: int, t_now: wp.float64, walls: WallSet,
                                  candidates: MovingWallCandidates) -> int:
    """Gather the triangles of the moving walls of ``world`` whose bounds meet the box
    x0 +- (r_i + margin) around sphere i's rest-frame centre x0 at ``t_now`` (each wall's BVH, in
    the world's wall order); record the sphere's centre ``xi`` [m] and the time. Returns the count,
    or CANDIDATES_OVERFLOW if they do not fit the slots."""
    first = walls.world_start[world]
    cap = candidates.capacity
    half_box = ri + candidates.margin
    ext = wp.vec3(half_box, half_box, half_box)
    n = int(0)
    for kk in range(walls.world_start[world + 1] - first):
        k = walls.world_index[first + kk]
        if walls.moving[k] == 0:
            continue
        x_rest, rot, c_now = point_in_wall_rest_frame(xi, t_now, walls.t_start[k], walls.t_stop[k],
                                                      walls.origin[k], walls.lin_vel[k], walls.ang_vel[k])
        mquery = wp.mesh_query_aabb(walls.mesh[k], x_rest - ext, x_rest + ext)
        tri = int(0)
        while wp.mesh_query_aabb_next(mquery, tri):
            if n < cap:
                candidates.wall[i * cap + n] = k
                candidates.triangle[i * cap + n] = tri
            n += 1
    candidates.x_built[i] = xi
    candidates.t_built[i] = t_now
    if n > cap:
        n = CANDIDATES_OVERFLOW
    candidates.count[i] = n
    return n


@wp.func
def moving_wall_candidates(i: int, xi: wp.vec3, ri: float, world: int, t_now: wp.float64, walls: WallSet,
                           candidates: MovingWallCandidates) -> int:
    """Sphere i's candidate count for this step (gathered again first if it never was, or if the
    sphere moved more than margin / 2 since, or a moving wall of its world drifted more than
    margin / 2 in the rest frame (:func:`wall_drift`): together less than the margin, so every
    triangle within r_i of the sphere is among the candidates). CANDIDATES_OVERFLOW: query the
    BVHs. Capacity 0: always CANDIDATES_OVERFLOW, nothing kept."""
    if candidates.capacity == 0:
        return CANDIDATES_OVERFLOW
    n = candidates.count[i]
    half = 0.5 * candidates.margin
    stale = int(0)
    if n == CANDIDATES_UNSET:
        stale = 1
    else:
        d = xi - candidates.x_built[i]
        if wp.dot(d, d) > half * half:
            stale = 1
        elif wall_drift(candidates.t_built[i], t_now, ri, world, walls) > half:
            stale = 1
    if stale == 1:
        n = gather_moving_wall_candidates(i, xi, ri, world, t_now, walls, candidates)
    return n


@functools.lru_cache(maxsize=None)
def wall_collection_function(history_layout: str = DEFAULT_SLOT_LAYOUT) -> "wp.Function":
    """:func:`collect_sphere_wall_contacts` for the contact slots' ``history_layout``
    (:mod:`warpdem.layouts`), built once per layout."""
    entry = entry_function(history_layout)  # compiled in: where slot s of sphere i lies

    @wp.func
    def offer_wall_triangle(i: int, tri: int, mesh: wp.uint64, x_rest: wp.vec3, moving: int, rot: wp.quat,
                            c_now: wp.vec3, c_rest: wp.vec3, ri: float, tag: int, n_new: int, step: StepInputs,
                            contacts: ContactHistory, found: WallSlots) -> int:
        """Offer triangle ``tri`` of wall ``tag`` to sphere i's wall contacts (``n_new`` slots so
        far, returned updated): its closest point to the rest-frame centre ``x_rest``, if closer
        than r_i, is merged with the contacts already collected (see
        :func:`collect_sphere_wall_contacts`)."""
        rows = contacts.count.shape[0]
        max_contacts = contacts.slots
        m = wp.mesh_get(mesh)
        pa = m.points[m.indices[3 * tri + 0]]
        pb = m.points[m.indices[3 * tri + 1]]
        pc = m.points[m.indices[3 * tri + 2]]
        cp = closest_point_triangle(x_rest, pa, pb, pc)
        d = x_rest - cp
        dist = wp.length(d)
        if dist >= ri or dist < 1.0e-12:
            return n_new
        nrm = d / dist
        if moving != 0:  # back to the world frame
            nrm = wp.quat_rotate(rot, nrm)
            cp = c_now + wp.quat_rotate(rot, cp - c_rest)
        depth = ri - dist
        keep = int(1)
        tol = 1.0e-3 * ri
        for s in range(n_new):
            e = entry(i, s, rows, max_contacts)
            tag_s = contacts.partner[e]
            if tag_s == SLOT_EMPTY:
                continue
            n_s = contacts.wall_normal[e]
            p_s = found.point[e]
            d_s = found.depth[e]
            related = int(0)
            if wp.dot(n_s, nrm) > WALL_MERGE_COS:
                related = 1
            if d_s >= depth and wp.dot(cp - p_s, n_s) <= tol:
                related = 1
            if depth > d_s and wp.dot(p_s - cp, nrm) <= tol:
                related = 1
            if related == 1:
                if d_s >= depth:
                    keep = 0
                else:
                    contacts.partner[e] = SLOT_EMPTY
        n_out = n_new
        if keep == 1:
            # reuse a slot emptied above (many triangles meeting at a vertex must not
            # exhaust the slots with replaced candidates), else append
            slot = n_new
            for s in range(n_new):
                if slot == n_new and contacts.partner[entry(i, s, rows, max_contacts)] == SLOT_EMPTY:
                    slot = s
            if slot < max_contacts:
                e = entry(i, slot, rows, max_contacts)
                contacts.partner[e] = tag
                contacts.wall_normal[e] = nrm
                found.depth[e] = depth
                found.point[e] = cp
                found.triangle[e] = tri
                if slot == n_new:
                    n_out = n_new + 1
            else:
                wp.atomic_add(step.overflow, 0, 1)
        return n_out

    @wp.func
    def collect_sphere_wall_contacts(i: int, spheres: SphereSet, neighbours: NeighbourList, walls: WallSet,
                                     step: StepInputs, candidates: MovingWallCandidates,
                                     contacts: ContactHistory, found: WallSlots) -> int:
        """The wall contacts of sphere i at the step's time; returns how many (slots 0 .. n - 1).

        The closest feature of every triangle within the sphere's radius is a candidate: for a
        static wall from a rest-frame BVH query (if the list build found the wall near), for a
        moving wall from the sphere's kept candidates (:func:`moving_wall_candidates`; a BVH
        query if they overflowed), in the same order either way. A candidate and a collected
        contact describe one contact if their normals
        agree (cosine > WALL_MERGE_COS), or if the shallower one's contact point lies on (or
        behind) the deeper one's tangent plane: an edge/vertex of a neighbouring triangle touched
        "through" a face the sphere already presses on (coplanar or convex neighbours). The deeper
        one is kept. Concave corners (floor and side wall) stick out of each other's planes and
        stay two contacts. Writes the wall tag -(k + 1) and normal into this step's history
        (``contacts``: slots 0 .. n - 1) and the point, depth and triangle into ``found``; a
        contact beyond the slots counts into ``step.overflow``. Spheres of inactive bodies or
        paused worlds get none (the particle stage handles them); a sphere that is neither near a
        static wall (list build) nor in a world with a moving wall is decided without reading its
        state. ``found.count`` is left to the caller (the stage-1 kernel or the fused wall stage)."""
        world = spheres.world[i]
        close_to_static_wall = neighbours.near_static_wall[i]
        first_wall = walls.world_start[world]
        n_walls = walls.world_start[world + 1] - first_wall
        # most spheres of a bed are far from every static wall: decided without reading the sphere
        n_moving = int(0)
        for kk in range(n_walls):
            n_moving = n_moving + walls.moving[walls.world_index[first_wall + kk]]
        if close_to_static_wall + n_moving == 0 or step.world_paused[world] != 0:
            return 0
        me = spheres.view[i]
        if me.r < 0.0:
            return 0
        xi = me.x
        ri = me.r
        t_now = step.time[0]
        n_kept_candidates = int(CANDIDATES_OVERFLOW)
        if n_moving > 0:
            n_kept_candidates = moving_wall_candidates(i, xi, ri, world, t_now, walls, candidates)
        cap = candidates.capacity
        cursor = int(0)
        n_new = int(0)
        for kk in range(n_walls):
            k = walls.world_index[first_wall + kk]
            moving = walls.moving[k]
            if moving == 0 and close_to_static_wall == 0:
                continue
            from_candidates = moving != 0 and n_kept_candidates >= 0
            if from_candidates:
                # none of this wall's triangles is near: nothing to place in its frame
                if cursor >= n_kept_candidates:
                    continue
                if candidates.wall[i * cap + cursor] != k:
                    continue
            mesh = walls.mesh[k]
            tag = -(k + 1)
            # the sphere in the wall's rest frame (static walls: the same point)
            rot = wp.quat_identity()
            c_now = wp.vec3(0.0)
            c_rest = wp.vec3(0.0)
            x_rest = xi
            if moving != 0:
                c_rest = walls.origin[k]
                x_rest, rot, c_now = point_in_wall_rest_frame(xi, t_now, walls.t_start[k], walls.t_stop[k], c_rest,
                                                              walls.lin_vel[k], walls.ang_vel[k])
            if from_candidates:
                while cursor < n_kept_candidates:
                    if candidates.wall[i * cap + cursor] != k:
                        break
                    n_new = offer_wall_triangle(i, candidates.triangle[i * cap + cursor], mesh, x_rest, moving, rot,
                                                c_now, c_rest, ri, tag, n_new, step, contacts, found)
                    cursor += 1
            else:
                ext = wp.vec3(ri, ri, ri)
                mquery = wp.mesh_query_aabb(mesh, x_rest - ext, x_rest + ext)
                tri = int(0)
                while wp.mesh_query_aabb_next(mquery, tri):
                    n_new = offer_wall_triangle(i, tri, mesh, x_rest, moving, rot, c_now, c_rest, ri, tag, n_new,
                                                step, contacts, found)
        # compact the slots (drop the ones replaced by deeper related contacts)
        rows = contacts.count.shape[0]
        max_contacts = contacts.slots
        n_kept = int(0)
        for s in range(n_new):
            e = entry(i, s, rows, max_contacts)
            if contacts.partner[e] != SLOT_EMPTY:
                if n_kept != s:
                    e_kept = entry(i, n_kept, rows, max_contacts)
                    contacts.partner[e_kept] = contacts.partner[e]
                    contacts.wall_normal[e_kept] = contacts.wall_normal[e]
                    found.depth[e_kept] = found.depth[e]
                    found.point[e_kept] = found.point[e]
                    found.triangle[e_kept] = found.triangle[e]
                n_kept += 1
        return n_kept

    return collect_sphere_wall_contacts


@functools.lru_cache(maxsize=None)
def collect_wall_contacts_kernel(history_layout: str = DEFAULT_SLOT_LAYOUT) -> "wp.Kernel":
    """Stage 1 (:func:`collect_wall_contacts` below) for ``history_layout``, built once per layout."""
    collect_sphere_wall_contacts = wall_collection_function(history_layout)

    @wp.kernel
    def collect_wall_contacts(spheres: SphereSet, neighbours: NeighbourList, walls: WallSet, step: StepInputs,
                              candidates: MovingWallCandidates, contacts: ContactHistory, found: WallSlots):
        """Stage 1, one thread per sphere: :func:`collect_sphere_wall_contacts` of sphere i, its
        count into ``found.count`` (0 for spheres without wall contacts)."""
        i = wp.tid()
        found.count[i] = collect_sphere_wall_contacts(i, spheres, neighbours, walls, step, candidates, contacts,
                                                      found)

    return collect_wall_contacts


@wp.func
def accumulate_wear(wear: WearAccumulators, entry: int, fn: float, ft: wp.vec3, v_rel: wp.vec3, nrm: wp.vec3,
                    dt: float):
    """Relative wear model of one wall contact over one step, added to triangle ``entry``:
    |F_n v_n| dt and |F_t . v_t| dt [J], |F_n| dt and |F_t| dt [N s] (v_n = v_rel . n,
    v_t = v_rel - v_n n)."""
    v_n = wp.dot(v_rel, nrm)
    v_t = v_rel - v_n * nrm
    wp.atomic_add(wear.energy_n, entry, wp.abs(fn * v_n) * dt)
    wp.atomic_add(wear.energy_t, entry, wp.abs(wp.dot(ft, v_t)) * dt)
    wp.atomic_add(wear.impulse_n, entry, wp.abs(fn) * dt)
    wp.atomic_add(wear.impulse_t, entry, wp.length(ft) * dt)


@dataclass(frozen=True)
class WallStageKernels:
    """The wall kernels of one contact law: stage 2 alone (after :func:`collect_wall_contacts`)
    and stages 1 + 2 fused into one kernel (the same functions, in the same thread)."""

    wall_forces: "wp.Kernel"
    collect_wall_contacts_and_forces: "wp.Kernel"


@functools.lru_cache(maxsize=None)
def wall_stage_kernels(law: ContactLaw, history_layout: str = DEFAULT_SLOT_LAYOUT,
                       max_registers: int | None = None) -> WallStageKernels:
    """The wall-force kernels of one contact law (built and cached per law, layout of the
    contact slots, :mod:`warpdem.layouts`, and CUDA register cap, :mod:`.launch`), one thread
    per sphere.

    Both call ``wall_forces_of_sphere`` (compiled per law): for each wall contact that stage 1
    found: last step's history of the same wall is taken if its normal agrees (cosine >
    WALL_MATCH_COS); the wall material's velocity at the contact point (v + w x (p - c(t))
    while the wall moves) gives the relative motion; the contact point p is the closest point
    of the wall, r - delta from the sphere centre, or at r - delta / 2 for a normal sub-model
    with ``wall_contact_at_half_overlap`` (LIGGGHTS' convention); the law gives fn, ft and the rolling
    torque (damped for the mass of ``law.clump_damping_mass``). Writes the springs into this
    step's history, the summed force F = sum (fn n + ft) [N] and torque
    T = sum ((p - x_b) x F + torque) [N m] about the body's centre into ``forces`` (the particle
    stage adds on), and, if the law tracks wear, the per-triangle accumulators (atomic adds:
    many spheres touch one triangle). A sphere without wall contacts returns at once and writes
    nothing (the fused kernel writes its count 0)."""
    evaluate = law_evaluator(law)
    damping_mass = damping_mass_function(law.clump_damping_mass)  # compiled in: mass_felt_at or whole_body_mass
    # where the contact point lies (SubModel.wall_contact_at_half_overlap): on the wall, or r - delta/2
    half_overlap_point = bool(getattr(law.submodels["normal"], "wall_contact_at_half_overlap", False))
    track_wear = bool(law.track_wear)
    roll_hist = bool(law.needs_rolling_history)
    body_kin = bool(law.needs_body_kinematics)  # compiled in: the body's lever, spin and inertia
    entry = entry_function(history_layout)  # compiled in: where slot s of sphere i lies
    collect_sphere_wall_contacts = wall_collection_function(history_layout)

    @wp.func
    def wall_forces_of_sphere(i: int, n_found: int, spheres: SphereSet, walls: WallSet, params: ContactParameters,
                              step: StepInputs, history: ContactHistory, contacts: ContactHistory, found: WallSlots,
                              wear: WearAccumulators, forces: SphereForces):
        """Forces, torques and wear of the ``n_found`` (> 0) wall contacts of sphere i in slots
        0 .. n_found - 1 of ``contacts``/``found``."""
        me = spheres.view[i]
        world = spheres.world[i]
        rows = contacts.count.shape[0]
        slots = contacts.slots
        xi = me.x
        ri = me.r
        xb = me.xb
        vb = me.v
        wb = me.w
        e_i = params.youngs_modulus[me.mat]
        nu_i = params.poisson_ratio[me.mat]
        n_old = history.count[i]
        t_now = step.time[0]
        dt = step.dt
        f_sum = wp.vec3(0.0)
        t_sum = wp.vec3(0.0)
        for s in range(n_found):
            e = entry(i, s, rows, slots)
            tag = contacts.partner[e]
            kw = -tag - 1
            nrm = contacts.wall_normal[e]
            cp = found.point[e]
            depth = found.depth[e]
            arm = ri - depth
            if wp.static(half_overlap_point):
                # LIGGGHTS (src/surface_model_default.h, cri = radi - deltan/2): half the overlap
                arm = ri - 0.5 * depth
                cp = xi - arm * nrm
            spring = wp.vec3(0.0)
            roll = wp.vec3(0.0)
            for o in range(n_old):
                e_old = entry(i, o, rows, slots)
                if history.partner[e_old] == tag:
                    if wp.dot(history.wall_normal[e_old], nrm) > WALL_MATCH_COS:
                        spring = history.spring[e_old]
                        if wp.static(roll_hist):
                            roll = history.roll[e_old]
            # wall kinematics at the contact point
            v_wall = wall_point_velocity(t_now, walls.t_start[kw], walls.t_stop[kw], walls.origin[kw],
                                         walls.lin_vel[kw], walls.ang_vel[kw], cp)
            w_wall = wp.vec3(0.0)
            if wall_is_moving(t_now, walls.t_start[kw], walls.t_stop[kw]):
                w_wall = walls.ang_vel[kw]
            mw = walls.material[kw]
            e_w = params.youngs_modulus[mw]
            nu_w = params.poisson_ratio[mw]
            c = ContactInput()
            c.normal = nrm
            c.overlap = depth
            c.v_rel = vb + wp.cross(wb, cp - xb) - v_wall
            c.w_rel = wb - w_wall
            c.r_eff = ri
            c.radius_i = ri
            c.radius_j = 0.0  # a wall: flat partner (infinite radius)
            # lever x n: the contact point lies on the line through the sphere centre along n
            c.m_eff = damping_mass(me.m, me.i_mean, xi - xb, nrm)
            c.e_eff = effective_youngs_modulus(e_i, nu_i, e_w, nu_w)
            c.g_eff = effective_shear_modulus(e_i, nu_i, e_w, nu_w)
            c.arm = arm
            c.i_eff = me.i_mean
            c.dt = dt
            c.row = 2 * world + 1
            if wp.static(body_kin):
                c.arm_body = body_lever(xi - xb, arm, nrm)
                c.w_body = wb
                c.i_body = me.i_mean
            fn, ft, tr, spring_new, roll_new = evaluate(c, params.table, spring, roll)
            force = fn * nrm + ft
            f_sum = f_sum + force
            t_sum = t_sum + wp.cross(cp - xb, force) + tr
            contacts.spring[e] = spring_new
            if wp.static(roll_hist):
                contacts.roll[e] = roll_new
            if wp.static(track_wear):
                tri_entry = wear.wall_base[kw] + world * wear.wall_stride[kw] + found.triangle[e]
                accumulate_wear(wear, (i % wear.lanes) * wear.entries + tri_entry, fn, ft, c.v_rel, nrm, dt)
        forces.force[i] = f_sum
        forces.torque[i] = t_sum

    @force_kernel(max_registers)
    def wall_forces(spheres: SphereSet, walls: WallSet, params: ContactParameters, step: StepInputs,
                    history: ContactHistory, contacts: ContactHistory, found: WallSlots, wear: WearAccumulators,
                    forces: SphereForces):
        """Stage 2: the forces of the wall contacts stage 1 left in ``found``."""
        i = wp.tid()
        n_found = found.count[i]  # 0 for inactive spheres and paused worlds (stage 1)
        if n_found == 0:
            return
        wall_forces_of_sphere(i, n_found, spheres, walls, params, step, history, contacts, found, wear, forces)

    @force_kernel(max_registers)
    def collect_wall_contacts_and_forces(spheres: SphereSet, neighbours: NeighbourList, walls: WallSet,
                                         params: ContactParameters, step: StepInputs,
                                         candidates: MovingWallCandidates, history: ContactHistory,
                                         contacts: ContactHistory, found: WallSlots, wear: WearAccumulators,
                                         forces: SphereForces):
        """Stages 1 and 2 of sphere i in one thread (``wall_stage="fused"``): one launch, and the
        contacts just found are read back by the thread that wrote them."""
        i = wp.tid()
        n_found = collect_sphere_wall_contacts(i, spheres, neighbours, walls, step, candidates, contacts, found)
        found.count[i] = n_found  # the particle stage appends after these
        if n_found == 0:
            return
        wall_forces_of_sphere(i, n_found, spheres, walls, params, step, history, contacts, found, wear, forces)

    return WallStageKernels(wall_forces, collect_wall_contacts_and_forces)


def wall_forces_kernel(law: ContactLaw) -> "wp.Kernel":
    """Stage 2 of ``law`` alone (see :func:`wall_stage_kernels`)."""
    return wall_stage_kernels(law).wall_forces
