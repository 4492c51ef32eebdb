"""The contact computation of one step, in stages with one job each.

==========================  ==============================================  ==========================
stage (module)              job                                             writes
==========================  ==============================================  ==========================
1 ``collect_wall_contacts`` wall candidates from each wall's rest-frame     wall slots (tag, normal,
  (wall_contacts)           BVH (moving walls: the sphere's kept            point, depth, triangle);
                            candidate triangles), merged so that one        kept candidates
                            physical contact is one slot
2 ``wall_forces``           wall forces with tangential/rolling history,    history springs, per-sphere
  (wall_contacts)           wall wear (relative wear model)                 force/torque, wear
3 ``particle_forces``       sphere-sphere forces over the Verlet list,      history, per-sphere
  (particle_contacts)       history; finishes each sphere's row (inactive,  force/torque (continued)
                            paused worlds)
==========================  ==============================================  ==========================

Every stage runs one thread per sphere and reads packed structs (:mod:`.structs`). Stages 2
and 3 are generated per :class:`~warpdem.contact.law.ContactLaw` from its sub-models'
``wp.func``s (:func:`.law.law_evaluator`), so a sub-model found by the package scan plugs in
with no edit. Forces: stage 2 writes the sum over a sphere's wall contacts, stage 3 starts
from it and adds the particle contacts in neighbour order, so every sphere's force is the
same float sum, in the same order, as in one fused kernel (deterministic, no atomics; a
per-stage output summed later would change the summation order and round differently).
With ``pair_evaluation="half"`` (the CPU's default) stage 3 evaluates each pair once and adds the
reaction to the partner (atomic adds, serial on the CPU): the sums start from
``start_half_pair_sums`` and differ from the full evaluation by float rounding.
Stages 1 and 2 are skipped without walls (``walls_on=False``, or a model without walls).
With the solver's ``wall_stage="fused"`` they run as one kernel,
``collect_wall_contacts_and_forces`` (both stages of a sphere in one thread, same results).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import warp as wp

from ..contact.law import ContactLaw
from ..layouts import DEFAULT_SLOT_LAYOUT
from .particle_contacts import PAIR_EVALUATIONS, check_half_row_slots, particle_forces_kernel, start_half_pair_sums
from .structs import (CANDIDATES_OVERFLOW, CANDIDATES_UNSET, ContactHistory, ContactParameters, MovingWallCandidates,
                      NeighbourList, SphereForces, SphereSet, StepInputs, WallSet, WallSlots, WearAccumulators)
from .wall_contacts import collect_wall_contacts_kernel, wall_stage_kernels

__all__ = ["ContactStages", "contact_stages", "PackedInputs", "PAIR_EVALUATIONS", "start_half_pair_sums", "check_half_row_slots", "CANDIDATES_OVERFLOW", "CANDIDATES_UNSET",
           "ContactHistory", "ContactParameters", "MovingWallCandidates", "NeighbourList",
           "SphereForces", "SphereSet", "StepInputs", "WallSet", "WallSlots", "WearAccumulators"]


@dataclass(frozen=True)
class ContactStages:
    """The contact kernels of one contact law: the three stages in launch order, and stages 1
    and 2 fused into one kernel (launched instead of the first two with ``wall_stage="fused"``)."""

    collect_wall_contacts: "wp.Kernel"
    wall_forces: "wp.Kernel"
    particle_forces: "wp.Kernel"
    collect_wall_contacts_and_forces: "wp.Kernel"


@dataclass
class PackedInputs:
    """The structs the stages read that do not change from step to step (packed once by
    :meth:`warpdem.solver.DEMSolver.pack_contact_inputs`)."""

    spheres: SphereSet
    neighbours: NeighbourList
    walls: WallSet
    params: ContactParameters
    found: WallSlots
    wear: WearAccumulators
    forces: SphereForces
    candidates: MovingWallCandidates


@functools.lru_cache(maxsize=None)
def contact_stages(law: ContactLaw, neighbour_layout: str = DEFAULT_SLOT_LAYOUT,
                   history_layout: str = DEFAULT_SLOT_LAYOUT, max_registers: int | None = None,
                   pairs: str = "full") -> ContactStages:
    """The stage kernels of ``law`` for the layouts of the neighbour list and of the contact
    slots (:mod:`warpdem.layouts`), the CUDA register cap of the force stages (:mod:`.launch`)
    and the pair evaluation of stage 3 (``"full"`` or ``"half"``, :func:`particle_forces_kernel`);
    built once per combination and cached."""
    walls = wall_stage_kernels(law, history_layout, max_registers)
    return ContactStages(collect_wall_contacts_kernel(history_layout), walls.wall_forces,
                         particle_forces_kernel(law, neighbour_layout, history_layout, max_registers, pairs),
                         walls.collect_wall_contacts_and_forces)
