"""Packed inputs and outputs of the contact stages (:mod:`warpdem.stages`).

Each ``@wp.struct`` groups the arrays of one thing a stage reads or writes, so that a stage
kernel takes a handful of arguments instead of ~46 loose ones. A struct holds references to
arrays (no copies): the solver packs them once (:meth:`warpdem.solver.DEMSolver.pack_contact_inputs`)
and passes them by value at each launch. Units are SI.

:class:`NeighbourList` and :class:`WallSet` are defined in :mod:`warpdem.kernels` (the
neighbour-list build writes and reads them, and that module cannot import this one) and
re-exported here.
"""
from __future__ import annotations

import warp as wp

from ..kernels import NeighbourList, SphereView, WallSet

__all__ = ["ContactHistory", "ContactParameters", "MovingWallCandidates", "NeighbourList", "SphereForces",
           "SphereSet", "StepInputs", "WallSet", "WallSlots", "WearAccumulators"]


@wp.struct
class SphereSet:
    """What the stages read of the spheres this step (written by ``place_sphere_views``)."""

    view: wp.array(dtype=SphereView)  # packed sphere and body state; radius < 0: inactive body
    world: wp.array(dtype=int)  # world index of each sphere


@wp.struct
class ContactParameters:
    """Materials and the per-world contact-law parameter table."""

    youngs_modulus: wp.array(dtype=float)  # E per material [Pa]
    poisson_ratio: wp.array(dtype=float)  # nu per material [-]
    table: wp.array2d(dtype=float)  # p[2 world + pair type (0 pp, 1 pw), column of the law]


@wp.struct
class StepInputs:
    """The step's time and the per-world and global flags the stages share."""

    time: wp.array(dtype=wp.float64)  # simulated time t at the start of the step [s] (1 entry)
    dt: float  # time step [s]
    world_paused: wp.array(dtype=int)  # 1: the world is held at rest (contacts skipped, history kept)
    walls_on: int  # 0: no wall stage ran this step (profiling, or a model without walls)
    overflow: wp.array(dtype=int)  # [0]: contacts that did not fit the slots (counted, raised on check)


@wp.struct
class ContactHistory:
    """Per-sphere contact slots of one State: this step's (out) or last step's (in).

    Slot ``s`` of sphere ``i`` is entry ``i * slots + s`` (the default layout) or
    ``s * num_spheres + i`` (``history_layout="slot_major"``, :mod:`warpdem.layouts`); wall
    contacts come first, then particle contacts in neighbour-list order."""

    count: wp.array(dtype=int)  # used slots per sphere
    partner: wp.array(dtype=int)  # sphere index >= 0, or -(wall + 1) for a wall
    spring: wp.array(dtype=wp.vec3)  # tangential spring delta_t [m]
    roll: wp.array(dtype=wp.vec3)  # rolling history (torque [N m]); 1 entry if the law keeps none
    wall_normal: wp.array(dtype=wp.vec3)  # unit normal of a wall contact (matches history across steps)
    slots: int  # slots per sphere (``max_contacts``)


@wp.struct
class WallSlots:
    """This step's merged wall contacts, from the collection stage to the wall-force stage
    (same slot layout as :class:`ContactHistory`; partner and normal are written there)."""

    count: wp.array(dtype=int)  # wall contacts per sphere (slots 0 .. count - 1)
    point: wp.array(dtype=wp.vec3)  # contact point on the wall, world frame [m]
    depth: wp.array(dtype=float)  # overlap r_i - distance [m]
    triangle: wp.array(dtype=int)  # triangle of the wall (for wear)


#: ``MovingWallCandidates.count`` of a sphere whose candidates were never gathered
CANDIDATES_UNSET = wp.constant(-2)
#: ``MovingWallCandidates.count`` of a sphere with more candidates than slots (its moving walls'
#: BVHs are queried every step until the next gathering)
CANDIDATES_OVERFLOW = wp.constant(-1)


@wp.struct
class MovingWallCandidates:
    """Per sphere: the triangles of the moving walls of its world that it may touch before it or a
    wall has moved by more than ``margin / 2`` (the collection stage gathers them from the walls'
    BVHs and then tests only these, see :func:`~.wall_contacts.wall_collection_function`).

    Candidate ``s`` of sphere ``i`` is entry ``i * capacity + s``, grouped by wall in the world's
    wall order and in each wall's BVH order."""

    count: wp.array(dtype=int)  # candidates per sphere; CANDIDATES_UNSET or CANDIDATES_OVERFLOW
    wall: wp.array(dtype=int)  # wall index k of each candidate
    triangle: wp.array(dtype=int)  # triangle of that wall
    x_built: wp.array(dtype=wp.vec3)  # sphere centre when they were gathered [m]
    t_built: wp.array(dtype=wp.float64)  # simulated time then [s]
    capacity: int  # slots per sphere (0: no candidates are kept, every step queries the BVHs)
    margin: float  # triangles within r + margin of the sphere are gathered [m]


@wp.struct
class WearAccumulators:
    """Per-world, per-triangle wall accumulators (relative wear model, ``DEMSolver.wall_stats``);
    entry ``wall_base[wall] + world * wall_stride[wall] + triangle`` (stride 0 for a wall of one
    world, :class:`warpdem.solver.WallStats`), held in ``lanes`` copies
    (lane ``i % lanes`` of sphere i at ``lane * entries + entry``: many spheres on one floor
    triangle then spread their atomic adds over several addresses; :class:`warpdem.solver.WallStats`
    sums the lanes when read)."""

    energy_n: wp.array(dtype=float)  # sum |F_n v_n| dt [J]
    energy_t: wp.array(dtype=float)  # sum |F_t . v_t| dt [J]
    impulse_n: wp.array(dtype=float)  # sum |F_n| dt [N s]
    impulse_t: wp.array(dtype=float)  # sum |F_t| dt [N s]
    wall_base: wp.array(dtype=int)  # first entry of each wall
    wall_stride: wp.array(dtype=int)  # entries between worlds of each wall (0: a wall of one world)
    entries: int  # entries of one lane
    lanes: int  # copies of every entry (1: none)


@wp.struct
class SphereForces:
    """Contact force [N] and torque about the body's centre of mass [N m] on each sphere
    (summed per body by ``integrate_bodies``)."""

    force: wp.array(dtype=wp.vec3)
    torque: wp.array(dtype=wp.vec3)
    #: ``pair_evaluation="half"``: contacts a sphere's row does not hold (pairs kept by a
    #: higher-index partner), counted for the slot check; unused (one entry) with "full"
    reactions: wp.array(dtype=int)
