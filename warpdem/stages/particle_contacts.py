"""Particle stage: sphere-sphere contact forces over the Verlet list, with tangential and
rolling history, added to the wall stages' per-sphere sums."""
from __future__ import annotations

import functools

import warp as wp

from ..contact.base import ContactInput
from ..contact.law import ContactLaw
from ..kernels import body_lever, damping_mass_function, effective_shear_modulus, effective_youngs_modulus
from ..layouts import DEFAULT_SLOT_LAYOUT, entry_function
from .launch import force_kernel
from .law import law_evaluator
from .structs import ContactHistory, ContactParameters, NeighbourList, SphereForces, SphereSet, StepInputs, WallSlots

wp.set_module_options({"enable_backward": False, "fast_math": True})

#: how sphere-sphere pairs are evaluated: from both sides (each sphere writes only its own row and
#: sums: no atomics, the GPU's choice) or once per pair with the reaction added to the partner
PAIR_EVALUATIONS = ("full", "half")


@functools.lru_cache(maxsize=None)
def particle_forces_kernel(law: ContactLaw, neighbour_layout: str = DEFAULT_SLOT_LAYOUT,
                           history_layout: str = DEFAULT_SLOT_LAYOUT,
                           max_registers: int | None = None, pairs: str = "full") -> "wp.Kernel":
    """Stage 3 of one contact law (built and cached per law, layouts of the neighbour list and
    the contact history, :mod:`warpdem.layouts`, and CUDA register cap, :mod:`.launch`), one
    thread per sphere.

    Full neighbour list (each pair is evaluated from both sides, so sphere i writes only its
    own row: no atomics, deterministic). For each neighbour j of another body within
    r_i + r_j: normal n = (x_i - x_j) / |x_i - x_j|, overlap delta = r_i + r_j - |x_i - x_j|,
    contact point p = x_i - (r_i - delta / 2) n; last step's history of partner j is taken;
    R* = r_i r_j / (r_i + r_j), m* = m_i m_j / (m_i + m_j) with the masses felt at p
    (:func:`warpdem.kernels.mass_felt_at`; the whole-body masses with
    ``law.clump_damping_mass == "body"``), I* = I_i I_j / (I_i + I_j); for a law with
    ``needs_body_kinematics`` also |p - x_body| (:func:`warpdem.kernels.body_lever`), the
    body's angular velocity and mean moment of inertia. The contacts are
    appended after the wall contacts of stage 1 (``found.count``) and the forces added, in
    neighbour order, to the sums of stage 2 (zero without wall contacts), so the result does
    not depend on the split into stages. Also the stage that finishes every sphere's row:
    inactive spheres get no contacts; a paused world keeps its history unchanged and feels no
    force.

    ``pairs="half"`` (the CPU's choice, :data:`PAIR_EVALUATIONS`): each pair is evaluated once,
    by its higher-index sphere i (the list is sorted by index, so the walk stops at the first
    j > i), which keeps the pair's history in its row and adds the reaction -F (and its torque,
    with the rolling torque -M) to sphere j's sums with atomic adds. Valid for a law whose
    sub-models are all ``pair_antisymmetric`` (:attr:`ContactLaw.pair_antisymmetric`). The sums
    must start from :func:`start_half_pair_sums` (the wall stages' sums or zero). On the CPU the
    threads run one after another, so the sums are deterministic; they differ from ``"full"``
    by float rounding (the other side's evaluation is replaced by the exact negation)."""
    if pairs not in PAIR_EVALUATIONS:
        raise ValueError(f"pairs must be one of {PAIR_EVALUATIONS}, got {pairs!r}")
    half = pairs == "half"
    evaluate = law_evaluator(law)
    damping_mass = damping_mass_function(law.clump_damping_mass)  # compiled in: mass_felt_at or whole_body_mass
    roll_hist = bool(law.needs_rolling_history)
    body_kin = bool(law.needs_body_kinematics)  # compiled in: the body's lever, spin and inertia
    nb_entry = entry_function(neighbour_layout)  # compiled in: where entry k of sphere i lies
    slot = entry_function(history_layout)

    @force_kernel(max_registers)
    def particle_forces(spheres: SphereSet, neighbours: NeighbourList, params: ContactParameters, step: StepInputs,
                        history: ContactHistory, contacts: ContactHistory, found: WallSlots, forces: SphereForces):
        i = wp.tid()
        rows = contacts.count.shape[0]
        slots = contacts.slots
        me = spheres.view[i]
        if me.r < 0.0:
            contacts.count[i] = 0
            forces.force[i] = wp.vec3(0.0)
            forces.torque[i] = wp.vec3(0.0)
            return
        world = spheres.world[i]
        if step.world_paused[world] != 0:
            # a paused world is held at rest: its contact history is carried over unchanged
            n_keep = history.count[i]
            contacts.count[i] = n_keep
            for s in range(n_keep):
                e = slot(i, s, rows, slots)
                contacts.partner[e] = history.partner[e]
                contacts.spring[e] = history.spring[e]
                if wp.static(roll_hist):
                    contacts.roll[e] = history.roll[e]
                contacts.wall_normal[e] = history.wall_normal[e]
            forces.force[i] = wp.vec3(0.0)
            forces.torque[i] = wp.vec3(0.0)
            return
        xi = me.x
        ri = me.r
        xb = me.xb
        vb = me.v
        wb = me.w
        ib_mean = me.i_mean
        e_i = params.youngs_modulus[me.mat]
        nu_i = params.poisson_ratio[me.mat]
        n_old = history.count[i]
        dt = step.dt
        n_new = int(0)
        f_sum = wp.vec3(0.0)
        t_sum = wp.vec3(0.0)
        if step.walls_on != 0:  # continue after the wall stages' contacts and sums
            n_new = found.count[i]
            if not wp.static(half):  # half: start_half_pair_sums put them in the sums already
                if n_new > 0:
                    f_sum = forces.force[i]
                    t_sum = forces.torque[i]
        nb_rows = neighbours.count.shape[0]
        for nb in range(neighbours.count[i]):
            j = neighbours.index[nb_entry(i, nb, nb_rows, neighbours.capacity)]
            if wp.static(half):
                if j > i:  # the row is sorted by index: the rest are evaluated by their own threads
                    break
            other = spheres.view[j]
            rj = other.r
            if rj < 0.0:
                continue
            d = xi - other.x
            rr = ri + rj
            dist2 = wp.dot(d, d)
            if dist2 >= rr * rr:
                continue
            if n_new >= contacts.slots:
                wp.atomic_add(step.overflow, 0, 1)
                continue
            dist = wp.sqrt(dist2)
            nrm = wp.vec3(0.0, 0.0, 1.0)
            if dist > 1.0e-12:
                nrm = d / dist
            overlap = rr - dist
            spring = wp.vec3(0.0)
            roll = wp.vec3(0.0)
            for o in range(n_old):
                e_old = slot(i, o, rows, slots)
                if history.partner[e_old] == j:
                    spring = history.spring[e_old]
                    if wp.static(roll_hist):
                        roll = history.roll[e_old]
            arm_i = ri - 0.5 * overlap
            cp = xi - arm_i * nrm
            xbj = other.xb
            ibj_mean = other.i_mean
            e_j = params.youngs_modulus[other.mat]
            nu_j = params.poisson_ratio[other.mat]
            c = ContactInput()
            c.normal = nrm
            c.overlap = overlap
            c.v_rel = (vb + wp.cross(wb, cp - xb)) - (other.v + wp.cross(other.w, cp - xbj))
            c.w_rel = wb - other.w
            c.r_eff = ri * rj / rr
            c.radius_i = ri
            c.radius_j = rj
            m_i = damping_mass(me.m, ib_mean, xi - xb, nrm)
            m_j = damping_mass(other.m, ibj_mean, other.x - xbj, nrm)
            c.m_eff = m_i * m_j / (m_i + m_j)
            c.e_eff = effective_youngs_modulus(e_i, nu_i, e_j, nu_j)
            c.g_eff = effective_shear_modulus(e_i, nu_i, e_j, nu_j)
            c.arm = arm_i
            c.i_eff = ib_mean * ibj_mean / (ib_mean + ibj_mean)
            c.dt = dt
            c.row = 2 * world
            if wp.static(body_kin):
                c.arm_body = body_lever(xi - xb, arm_i, nrm)
                c.w_body = wb
                c.i_body = ib_mean
            fn, ft, tr, spring_new, roll_new = evaluate(c, params.table, spring, roll)
            force = fn * nrm + ft
            f_sum = f_sum + force
            t_sum = t_sum + wp.cross(cp - xb, force) + tr
            if wp.static(half):  # the reaction on j at the same contact point
                wp.atomic_add(forces.force, j, -force)
                wp.atomic_add(forces.torque, j, wp.cross(cp - xbj, -force) - tr)
                wp.atomic_add(forces.reactions, j, 1)
            e_new = slot(i, n_new, rows, slots)
            contacts.partner[e_new] = j
            contacts.spring[e_new] = spring_new
            if wp.static(roll_hist):
                contacts.roll[e_new] = roll_new
            n_new += 1
        contacts.count[i] = n_new
        if wp.static(half):
            wp.atomic_add(forces.force, i, f_sum)
            wp.atomic_add(forces.torque, i, t_sum)
        else:
            forces.force[i] = f_sum
            forces.torque[i] = t_sum

    return particle_forces


@wp.kernel
def check_half_row_slots(step: StepInputs, contacts: ContactHistory, forces: SphereForces):
    """``pairs="half"``, after the particle stage: a sphere whose contacts (its row's entries plus
    the pairs its higher-index partners keep) exceed the contact slots counts the excess into
    ``step.overflow``, as the full evaluation would when its row overflows, so ``max_contacts``
    means the same in both; the reaction counts are cleared for the next step."""
    i = wp.tid()
    extra = contacts.count[i] + forces.reactions[i] - contacts.slots
    if extra > 0:
        wp.atomic_add(step.overflow, 0, extra)
    forces.reactions[i] = 0


@wp.kernel
def start_half_pair_sums(step: StepInputs, found: WallSlots, forces: SphereForces):
    """``pairs="half"``: every sphere's force and torque sums start from its wall contacts' (the
    wall stages' sums) or zero, before the particle stage adds to them from both sides of a pair."""
    i = wp.tid()
    if step.walls_on != 0:
        if found.count[i] > 0:
            return
    forces.force[i] = wp.vec3(0.0)
    forces.torque[i] = wp.vec3(0.0)
