"""Immutable ``Model`` (what does not change during a run) and ``State`` (what does).

A model holds many *worlds*: independent copies of an experiment whose bodies never touch
bodies or walls of another world. Contact parameters live in a per-world table, so one
kernel launch advances a whole calibration design.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from .contact.law import ContactLaw
from .errors import ConfigError
from .materials import Material


@dataclass(frozen=True)
class WallMotion:
    """Prescribed rigid motion of a wall between ``start`` and ``stop`` [s].

    Translation at ``velocity`` [m/s] and rotation at ``angular_velocity`` [rad/s] (vector
    along the axis, right-handed) about the point ``origin`` [m], which moves with the wall.
    Outside [start, stop) the wall rests where the motion left it.
    """

    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start: float = 0.0
    stop: float = math.inf

    def __post_init__(self) -> None:
        for name in ("velocity", "angular_velocity", "origin"):
            v = getattr(self, name)
            if len(v) != 3 or not all(math.isfinite(float(x)) for x in v):
                raise ConfigError(f"WallMotion.{name} must be 3 finite numbers, got {v}")
        if not (self.stop > self.start):
            raise ConfigError(f"WallMotion: stop ({self.stop}) must be after start ({self.start})")

    @classmethod
    def translation(cls, velocity, start: float = 0.0, stop: float = math.inf) -> "WallMotion":
        return cls(velocity=tuple(float(x) for x in velocity), start=start, stop=stop)

    @classmethod
    def rotation(cls, axis, rpm: float, origin=(0.0, 0.0, 0.0), start: float = 0.0, stop: float = math.inf) -> "WallMotion":
        """Rotation about ``axis`` through ``origin`` at ``rpm`` revolutions per minute."""
        a = np.asarray(axis, dtype=float)
        if a.shape != (3,) or np.linalg.norm(a) == 0:
            raise ConfigError(f"WallMotion.rotation: axis must be a non-zero 3-vector, got {axis}")
        w = a / np.linalg.norm(a) * rpm * 2.0 * math.pi / 60.0
        return cls(angular_velocity=tuple(w), origin=tuple(float(x) for x in origin), start=start, stop=stop)

    @property
    def is_static(self) -> bool:
        return not any(self.velocity) and not any(self.angular_velocity)


@dataclass
class Wall:
    """A triangle-mesh wall in a model. ``triangle_labels`` map triangles to components."""

    name: str
    vertices: np.ndarray  # (V, 3) rest vertices [m]
    faces: np.ndarray  # (T, 3) int
    material: int
    world: int  # -1: present in every world
    motion: WallMotion
    tri_offset: int
    triangle_labels: np.ndarray | None = None
    label_names: tuple[str, ...] = ()
    mesh: wp.Mesh | None = field(default=None, repr=False)  # the rest mesh; never moved

    @property
    def num_triangles(self) -> int:
        return int(self.faces.shape[0])

    def points_at(self, time: float) -> np.ndarray:
        """Vertex positions [m] at ``time`` [s]: x(t) = c(t) + R(w tau) (x0 - c0), with
        tau = clamp(t, start, stop) - start and c(t) = c0 + v tau (the engine's kernels query
        the rest mesh at the sphere mapped back by the inverse of this motion)."""
        m = self.motion
        x0 = np.asarray(self.vertices, dtype=np.float64)
        if m.is_static:
            return x0.copy()
        tau = min(max(float(time), m.start), m.stop) - m.start
        c0 = np.asarray(m.origin, dtype=np.float64)
        w = np.asarray(m.angular_velocity, dtype=np.float64)
        rel = x0 - c0
        angle = float(np.linalg.norm(w)) * tau
        if angle > 0.0:  # Rodrigues' rotation formula
            k = w / np.linalg.norm(w)
            rel = (rel * math.cos(angle) + np.cross(k, rel) * math.sin(angle)
                   + np.outer(rel @ k, k) * (1.0 - math.cos(angle)))
        return c0 + np.asarray(m.velocity, dtype=np.float64) * tau + rel


class Model:
    """Static description of a DEM system on one Warp device (built by ``ModelBuilder``).

    Per-sphere: body, radius [m], material, world, offset in the body frame [m].
    Per-body: mass [kg], principal inertia [kg m^2], world, first member sphere, member count.
    ``contact_params`` is a (2 * num_worlds, P) float table (row = 2 world + pair type).
    """

    def __init__(self, host: dict, walls: list[Wall], materials: list[Material], law: ContactLaw,
                 initial: dict, device: str | None = None, max_contacts: int = 16,
                 gravity=(0.0, 0.0, -9.81), body_forces=()) -> None:
        self.device = wp.get_device(device)
        # body-force models (warpdem.body_forces), launched by the solver before integration
        self.body_forces = tuple(body_forces)
        self.host = {k: np.ascontiguousarray(v) for k, v in host.items()}
        self.initial = {k: np.ascontiguousarray(v) for k, v in initial.items()}
        self.materials = list(materials)
        self.contact_law = law
        self.max_contacts = int(max_contacts)
        self.gravity = tuple(float(g) for g in gravity)
        self.num_worlds = int(np.asarray(host["num_worlds"]).ravel()[0])
        self.num_spheres = int(host["sphere_radius"].shape[0])
        self.num_bodies = int(host["body_mass"].shape[0])
        self.max_radius = float(host["sphere_radius"].max())
        self.min_radius = float(host["sphere_radius"].min())
        d = self.device
        vec = wp.vec3
        self.sphere_body = wp.array(host["sphere_body"], dtype=int, device=d)
        self.sphere_offset = wp.array(host["sphere_offset"], dtype=vec, device=d)
        self.sphere_radius = wp.array(host["sphere_radius"], dtype=float, device=d)
        self.sphere_material = wp.array(host["sphere_material"], dtype=int, device=d)
        self.sphere_world = wp.array(host["sphere_world"], dtype=int, device=d)
        self.body_mass = wp.array(host["body_mass"], dtype=float, device=d)
        self.body_inertia = wp.array(host["body_inertia"], dtype=vec, device=d)
        self.body_world = wp.array(host["body_world"], dtype=int, device=d)
        self.body_first = wp.array(host["body_first"], dtype=int, device=d)
        self.body_count = wp.array(host["body_count"], dtype=int, device=d)
        self.mat_e = wp.array(np.array([m.youngs_modulus for m in materials]), dtype=float, device=d)
        self.mat_nu = wp.array(np.array([m.poisson_ratio for m in materials]), dtype=float, device=d)
        self.contact_params = wp.array(host["contact_params"], dtype=float, device=d)
        self.walls = walls
        # walls move rigidly, so a mesh stays at rest and walls of equal geometry (one drum per
        # world, each at its own speed) share one BVH
        meshes: dict[tuple[bytes, bytes], wp.Mesh] = {}
        for w in walls:
            pts = np.ascontiguousarray(w.vertices, dtype=np.float32)
            idx = np.ascontiguousarray(w.faces, dtype=np.int32).ravel()
            key = (pts.tobytes(), idx.tobytes())
            if key not in meshes:
                meshes[key] = wp.Mesh(points=wp.array(pts, dtype=vec, device=d), indices=wp.array(idx, dtype=int, device=d))
            w.mesh = meshes[key]
        self.total_triangles = int(sum(w.num_triangles for w in walls))
        n_walls = max(len(walls), 1)
        self.wall_mesh = wp.array([w.mesh.id for w in walls] or [0], dtype=wp.uint64, device=d)
        # the walls of each world (CSR): walls of every world (world -1) and its own, in wall order
        per_world = [[k for k, w in enumerate(walls) if w.world in (-1, j)] for j in range(self.num_worlds)]
        self.world_wall_start = wp.array(np.cumsum([0] + [len(p) for p in per_world]), dtype=int, device=d)
        self.world_wall_index = wp.array(np.concatenate([np.asarray(p, dtype=np.int64) for p in per_world] + [np.zeros(1, np.int64)]),
                                         dtype=int, device=d)
        self.wall_material = wp.array([w.material for w in walls] or [0], dtype=int, device=d)
        self.wall_tri_offset = wp.array([w.tri_offset for w in walls] or [0], dtype=int, device=d)
        self.wall_lin_vel = wp.array([w.motion.velocity for w in walls] or [(0, 0, 0)], dtype=vec, device=d)
        self.wall_ang_vel = wp.array([w.motion.angular_velocity for w in walls] or [(0, 0, 0)], dtype=vec, device=d)
        self.wall_origin = wp.array([w.motion.origin for w in walls] or [(0, 0, 0)], dtype=vec, device=d)
        self.wall_t_start = wp.array([w.motion.start for w in walls] or [0.0], dtype=float, device=d)
        self.wall_t_stop = wp.array([w.motion.stop for w in walls] or [0.0], dtype=float, device=d)
        self._num_wall_slots = n_walls
        self.fingerprint: str = model_fingerprint(self.host, walls, materials, law, self.max_contacts, self.gravity)

    # ------------------------------------------------------------------ parameters
    @property
    def parameter_names(self) -> list[str]:
        """Calibratable contact parameters of this model's law (e.g. ``mu_s_pp``)."""
        return self.contact_law.parameter_names

    def get_contact_parameter(self, name: str) -> np.ndarray:
        """Per-world values of one contact parameter (e.g. ``'mu_s_pw'``)."""
        base, pt = self.contact_law.split_name(name)
        col = self.contact_law.column(base)
        return self.host["contact_params"][pt::2, col].copy()

    def set_contact_parameter(self, name: str, values) -> None:
        """Set one contact parameter for every world (scalar or one value per world)."""
        base, pt = self.contact_law.split_name(name)
        col = self.contact_law.column(base)
        vals = np.broadcast_to(np.asarray(values, dtype=np.float64), (self.num_worlds,))
        spec = self.contact_law.specs[base]
        for v in vals:
            spec.check(name, float(v))
        table = self.host["contact_params"]
        table[pt::2, col] = vals
        self.contact_params.assign(table.astype(np.float32))

    # ------------------------------------------------------------------ states
    def state(self) -> "State":
        """A new State holding the model's initial conditions."""
        return State(self)

    def sphere_mass(self) -> np.ndarray:
        """Mass attributed to each sphere [kg] (body mass split by member volume)."""
        r3 = self.host["sphere_radius"] ** 3
        body = self.host["sphere_body"]
        vol_sum = np.bincount(body, weights=r3, minlength=self.num_bodies)
        return self.host["body_mass"][body] * r3 / vol_sum[body]


# host arrays that define a model's bodies and spheres (per-world contact parameters are run
# settings, not part of the model's identity)
FINGERPRINT_ARRAYS = ("num_worlds", "sphere_radius", "sphere_body", "sphere_world", "sphere_offset", "sphere_material",
                      "body_mass", "body_inertia", "body_world", "body_first", "body_count")


def model_fingerprint(host: dict, walls: list[Wall], materials: list[Material], law: ContactLaw,
                      max_contacts: int, gravity) -> str:
    """16 hex digits of a SHA-256 over what defines a model: the sphere and body arrays
    (:data:`FINGERPRINT_ARRAYS`, values as float64/int64), each wall's vertices, faces, world,
    material and motion, the contact law, the materials, ``max_contacts`` and gravity. Not
    included: per-world contact parameters and body-force models."""
    h = hashlib.sha256()

    def add(name: str, a) -> None:
        a = np.asarray(a)
        a = a.astype(np.float64 if a.dtype.kind == "f" else np.int64)
        h.update(f"{name}:{a.shape}:".encode())
        h.update(np.ascontiguousarray(a).tobytes())

    for k in FINGERPRINT_ARRAYS:
        add(k, host[k])
    for i, w in enumerate(walls):
        add(f"wall{i}/vertices", w.vertices)
        add(f"wall{i}/faces", w.faces)
        mo = w.motion
        h.update(json.dumps([w.world, w.material, list(mo.velocity), list(mo.angular_velocity), list(mo.origin),
                             mo.start, None if math.isinf(mo.stop) else mo.stop]).encode())
    law_fields = list(law.to_config().values())  # a later setting listed only when set: earlier fingerprints stay valid
    h.update(json.dumps(dict(law=law_fields,
                             materials=[[m.name, m.youngs_modulus, m.poisson_ratio, m.density] for m in materials],
                             max_contacts=int(max_contacts), gravity=[float(g) for g in gravity])).encode())
    return h.hexdigest()[:16]


class State:
    """Time-dependent quantities: body poses and velocities, contact history, time.

    Contact history uses ``max_contacts`` slots per sphere: partner (sphere index >= 0, or
    ``-(wall + 1)`` for a wall), tangential spring [m], rolling history, wall normal.
    ``model_fingerprint``: the :attr:`Model.fingerprint` of the model it belongs to. With a
    solver's ``pair_evaluation="half"`` (the CPU's default) a sphere pair is kept by its
    higher-index sphere only (``contact_rows``; :mod:`warpdem.contact_rows`);
    :meth:`~warpdem.solver.DEMSolver.contact_counts` counts each sphere's contacts either way.
    """

    def __init__(self, model: Model) -> None:
        self.model_fingerprint: str = model.fingerprint
        # the pair evaluation its contact rows were written with ("full", "half"; None: none yet or
        # unknown), set by the solver that steps it (warpdem.contact_rows)
        self.contact_rows: str | None = None
        d = model.device
        ini = model.initial
        k = model.max_contacts
        n = model.num_spheres
        self.body_q = wp.array(ini["body_q"], dtype=wp.vec3, device=d)
        self.body_rot = wp.array(ini["body_rot"], dtype=wp.quat, device=d)
        self.body_v = wp.array(ini["body_v"], dtype=wp.vec3, device=d)
        self.body_w = wp.array(ini["body_w"], dtype=wp.vec3, device=d)
        self.body_active = wp.array(ini["body_active"], dtype=int, device=d)
        self.sphere_x = wp.zeros(n, dtype=wp.vec3, device=d)
        self.contact_count = wp.zeros(n, dtype=int, device=d)
        self.contact_partner = wp.zeros(n * k, dtype=int, device=d)
        self.contact_spring = wp.zeros(n * k, dtype=wp.vec3, device=d)
        nr = n * k if model.contact_law.needs_rolling_history else 1
        self.contact_roll = wp.zeros(nr, dtype=wp.vec3, device=d)
        self.contact_wnormal = wp.zeros(n * k, dtype=wp.vec3, device=d)
        self.time = wp.zeros(1, dtype=wp.float64, device=d)

    ARRAYS = ("body_q", "body_rot", "body_v", "body_w", "body_active", "sphere_x", "contact_count",
              "contact_partner", "contact_spring", "contact_roll", "contact_wnormal", "time")

    def to_numpy(self) -> dict[str, np.ndarray]:
        """Every array of the State, and ``model_fingerprint`` (the model it belongs to)."""
        data = {name: getattr(self, name).numpy() for name in self.ARRAYS}
        data["model_fingerprint"] = np.array(self.model_fingerprint)
        return data

    def load_numpy(self, data: dict[str, np.ndarray], fingerprint: str | None = None) -> None:
        """Load arrays saved by :meth:`to_numpy`. The model they came from (``fingerprint``, else the
        ``model_fingerprint`` the arrays carry) must be this State's model: another model's state is
        refused with a ConfigError, even where the array sizes happen to agree."""
        for given in (fingerprint, str(data["model_fingerprint"]) if "model_fingerprint" in data else None):
            if given is not None and given != self.model_fingerprint:
                raise ConfigError(f"state was saved from model {given}, not from this model {self.model_fingerprint}")
        for name in self.ARRAYS:
            arr = getattr(self, name)
            src = np.asarray(data[name])
            if src.shape[0] != arr.shape[0]:
                raise ConfigError(f"state array '{name}' has {src.shape[0]} entries, model expects {arr.shape[0]}")
            arr.assign(src)

    def assign(self, other: "State") -> None:
        """Copy ``other`` (a State of the same model) into this State."""
        if other.model_fingerprint != self.model_fingerprint:
            raise ConfigError(f"State.assign: the state is of model {other.model_fingerprint}, "
                              f"this one of model {self.model_fingerprint}")
        for name in self.ARRAYS:
            wp.copy(getattr(self, name), getattr(other, name))
        self.contact_rows = other.contact_rows

    @property
    def sim_time(self) -> float:
        return float(self.time.numpy()[0])
