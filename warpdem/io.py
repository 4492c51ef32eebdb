"""Output: particles and wall meshes to VTK (ParaView), checkpoint and restart."""
from __future__ import annotations

import json
import os
import re
import zipfile
import zlib
from pathlib import Path
from xml.sax.saxutils import escape as xml_escape

import numpy as np

from .config_io import write_atomic
from .contact.law import ContactLaw
from .errors import ConfigError
from .materials import Material
from .model import Model, Wall, WallMotion


def _safe_name(name: str) -> str:
    """A wall name as a file-name part: characters other than letters, digits, ``-``, ``_`` become ``_``."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name).strip("_") or "wall"


def particle_cloud(sim, world: int | None = None):
    """The active spheres of ``sim`` (of one ``world``, or all) as a ``pyvista.PolyData`` point cloud.

    Point fields (SI units): ``radius``, ``diameter`` [m]; ``velocity`` [m/s] of the sphere centre
    (body velocity + angular velocity x arm, so clump members differ); ``angular_velocity``
    [rad/s] of the body; ``contact_force`` [N]: the sum of the contact forces (particles and
    walls) on the sphere in the last step (gravity not included); ``contacts``: contacts of the
    sphere; ``id``: body index (members of one clump share it); ``sphere``: sphere index;
    ``body`` (same as ``id``, kept for older files); ``world``.
    """
    import pyvista as pv

    m: Model = sim.model
    if world is not None and not 0 <= int(world) < m.num_worlds:
        raise ConfigError(f"VTK output: world {world} does not exist (the model has {m.num_worlds} world(s))")
    x = sim.sphere_positions()
    body = m.host["sphere_body"]
    state = sim.state
    active = state.body_active.numpy()[body].astype(bool)
    sel = active if world is None else active & (m.host["sphere_world"] == world)
    v_body = state.body_v.numpy()[body].astype(np.float64)
    w_body = state.body_w.numpy()[body].astype(np.float64)
    arm = x - state.body_q.numpy()[body].astype(np.float64)
    velocity = v_body + np.cross(w_body, arm)
    cloud = pv.PolyData(np.ascontiguousarray(x[sel]))
    radius = m.host["sphere_radius"][sel]
    cloud["radius"] = radius
    cloud["diameter"] = 2.0 * radius
    cloud["velocity"] = velocity[sel]
    cloud["angular_velocity"] = w_body[sel]
    cloud["contact_force"] = sim.solver.sphere_f.numpy()[sel].astype(np.float64)
    cloud["contacts"] = sim.solver.contact_counts(state)[sel]
    cloud["id"] = body[sel]
    cloud["sphere"] = np.flatnonzero(sel)
    cloud["body"] = body[sel]
    cloud["world"] = m.host["sphere_world"][sel]
    return cloud


def wall_surfaces(sim, world: int | None = None) -> list[tuple[str, object]]:
    """``(name, pyvista.PolyData)`` of every wall in its current position (walls of other worlds
    left out when ``world`` is given). Cell fields: the wear accumulators of
    :class:`warpdem.solver.WallStats` per triangle (``energy_n``, ``energy_t`` [J],
    ``impulse_n``, ``impulse_t`` [N s]) of ``world`` (or summed over worlds), and ``component``
    where the wall has labelled triangles."""
    import pyvista as pv

    m: Model = sim.model
    stats = sim.solver.wall_stats
    sums = {field: stats.summed(field).numpy() for field in stats.FIELDS}  # one copy to the host per field
    out = []
    for wi, w in enumerate(m.walls):
        if world is not None and w.world not in (-1, world):
            continue
        pts = w.points_at(sim.time)
        faces = np.hstack([np.full((w.num_triangles, 1), 3), w.faces]).ravel()
        mesh = pv.PolyData(pts, faces)
        for field in stats.FIELDS:
            mesh.cell_data[field] = stats.wall_triangles(sums[field], wi, world)
        if w.triangle_labels is not None:
            mesh.cell_data["component"] = w.triangle_labels
        out.append((w.name, mesh))
    return out


def write_vtk(directory: str | os.PathLike, sim, frame: int, world: int | None = None) -> list[Path]:
    """Write spheres (``particles_NNNNNN.vtp``, fields of :func:`particle_cloud`) and walls
    (``wall_<name>_NNNNNN.vtp`` with per-triangle wear accumulators) for one frame.

    Spheres of inactive (removed) bodies are skipped. ``world`` restricts output to one world.
    For a time series that ParaView opens as one object use :class:`VtkSeries`.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"particles_{frame:06d}.vtp"]
    particle_cloud(sim, world).save(paths[0])
    for name, mesh in wall_surfaces(sim, world):
        p = out / f"wall_{name}_{frame:06d}.vtp"
        mesh.save(p)
        paths.append(p)
    return paths


def write_pvd(path: str | os.PathLike, entries: list[tuple[float, str]]) -> Path:
    """Write a ParaView collection file: ``entries`` are (time [s], file path relative to the
    ``.pvd``'s folder), in time order."""
    path = Path(path)
    times = [float(t) for t, _ in entries]
    if any(not np.isfinite(t) for t in times) or any(b < a for a, b in zip(times, times[1:])):
        raise ValueError(f"write_pvd: times must be finite and non-decreasing, got {times}")
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "  <Collection>"]
    lines += [f'    <DataSet timestep="{t:.9g}" group="" part="0" file="{xml_escape(f, {chr(34): "&quot;"})}"/>'
              for t, f in entries]
    lines += ["  </Collection>", "</VTKFile>", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, "\n".join(lines))  # rewritten at every frame: a kill leaves the last whole index
    return path


class VtkSeries:
    """A time series for ParaView: one ``.vtp`` file per frame and one ``.pvd`` collection per
    object in ``directory``: ``particles.pvd`` (fields of :func:`particle_cloud`) and
    ``wall_<name>.pvd`` per wall (fields of :func:`wall_surfaces`). Open a ``.pvd`` in ParaView
    (or ``pyvista.PVDReader``) and play it; the time axis is the simulation time [s].

    The ``.pvd`` files are rewritten after every frame, so the frames written so far stay
    readable when a run stops early. ``world``: the world to write (None: all worlds overlaid).
    """

    def __init__(self, directory: str | os.PathLike, world: int | None = 0) -> None:
        self.directory = Path(directory)
        self.world = None if world is None else int(world)
        self.frames = 0
        self._entries: dict[str, list[tuple[float, str]]] = {}

    def write(self, sim) -> list[Path]:
        """Write the current state of ``sim`` as the next frame; returns the ``.pvd`` files."""
        self.directory.mkdir(parents=True, exist_ok=True)
        t = float(sim.time)
        objects = [("particles", particle_cloud(sim, self.world))]
        objects += [(f"wall_{_safe_name(name)}", mesh) for name, mesh in wall_surfaces(sim, self.world)]
        pvds = []
        for stem, data in objects:
            entries = self._entries.setdefault(stem, [])
            if entries and t < entries[-1][0]:
                raise ValueError(f"VtkSeries: time {t} s is before the last frame's {entries[-1][0]} s")
            fname = f"{stem}_{self.frames:06d}.vtp"
            data.save(self.directory / fname)
            entries.append((t, fname))
            pvds.append(write_pvd(self.directory / f"{stem}.pvd", entries))
        self.frames += 1
        return pvds


# ----------------------------------------------------------------------------- checkpoints
def save_checkpoint(path: str | os.PathLike, sim) -> Path:
    """Save model, state, wall accumulators and step count to one ``.npz`` file, with the
    model's fingerprint (:attr:`Model.fingerprint`) and the solver's ``v_ref`` and ``force``. The
    contact slots are saved in the default layout whatever the solver's ``history_layout``, so a
    checkpoint loads into a solver of either layout."""
    m: Model = sim.model
    law = m.contact_law
    meta = dict(
        version=2, fingerprint=m.fingerprint, v_ref=sim.solver.v_ref, force=sim.solver.force, law=law.to_config(every_key=True),
        materials=[dict(name=x.name, youngs_modulus=x.youngs_modulus, poisson_ratio=x.poisson_ratio, density=x.density)
                   for x in m.materials],
        walls=[dict(name=w.name, material=w.material, world=w.world, tri_offset=w.tri_offset,
                    label_names=list(w.label_names),
                    motion=dict(velocity=list(w.motion.velocity), angular_velocity=list(w.motion.angular_velocity),
                                origin=list(w.motion.origin), start=w.motion.start,
                                stop=None if not np.isfinite(w.motion.stop) else w.motion.stop))
               for w in m.walls],
        max_contacts=m.max_contacts, gravity=list(m.gravity), dt=sim.dt, steps=sim.steps,
        wear_layout="compact")  # WallStats: one entry per triangle for a wall of one world
    arrays = {f"host/{k}": v for k, v in m.host.items()}
    arrays.update({f"initial/{k}": v for k, v in m.initial.items()})
    # contact slots in the default layout whatever the solver's history_layout (loadable by any solver)
    arrays.update({f"state/{k}": v for k, v in sim.solver.export_state(sim.state).items()})
    for f, lanes in sim.solver.wall_stats.export_lanes().items():
        arrays[f"wear/{f}"] = lanes  # (lanes, entries): a solver with as many copies continues bit for bit
    for i, w in enumerate(m.walls):
        arrays[f"wall{i}/vertices"] = w.vertices
        arrays[f"wall{i}/faces"] = w.faces
        if w.triangle_labels is not None:
            arrays[f"wall{i}/labels"] = w.triangle_labels
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, meta=np.array(json.dumps(meta)), **arrays)
    return path if path.suffix == ".npz" else path.with_suffix(path.suffix + ".npz")


def load_checkpoint(path: str | os.PathLike, device: str | None = None, model: Model | None = None, **sim_kwargs):
    """Rebuild the Simulation saved by :func:`save_checkpoint`; continuing it gives the same
    results as the uninterrupted run.

    ``model``: continue on this model instead of the one rebuilt from the file (e.g. one with
    body forces, which a checkpoint does not hold; its own contact parameters are used); it
    must have the checkpoint's fingerprint. Raises ConfigError naming the file for a missing,
    damaged or incomplete file, and naming both fingerprints for a checkpoint of another model."""
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"checkpoint file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as data:
            if "meta" not in data.files:
                raise ConfigError(f"{path} is not a warpdem checkpoint (no 'meta' entry)")
            return _load_checkpoint(path, data, device, model, sim_kwargs)
    except ConfigError:
        raise
    except (zipfile.BadZipFile, zlib.error, KeyError, EOFError, OSError, ValueError, TypeError) as exc:
        raise ConfigError(f"checkpoint {path} is damaged or incomplete ({type(exc).__name__}: {exc})") from exc


def _load_checkpoint(path: Path, data, device: str | None, model: Model | None, sim_kwargs: dict):
    from .solver import Simulation

    meta = json.loads(str(data["meta"]))
    saved_fp = meta.get("fingerprint")
    if model is not None:
        if saved_fp is not None and saved_fp != model.fingerprint:
            raise ConfigError(f"checkpoint {path} was saved from model {saved_fp}, not from the given model "
                              f"{model.fingerprint}")
    else:
        model = _model_from_checkpoint(path, data, meta, device)
    kwargs = dict(v_ref=meta.get("v_ref", 2.0), force=meta.get("force", True))
    kwargs.update(sim_kwargs)
    sim = Simulation(model, meta["dt"], **kwargs)
    state = {k[6:]: data[k] for k in data.files if k.startswith("state/")}
    missing = [n for n in sim.state.ARRAYS if n not in state]
    if missing:
        raise ConfigError(f"checkpoint {path} is incomplete: state arrays {missing} are missing")
    fp = saved_fp if saved_fp is not None else model.fingerprint
    sim.solver.import_state(sim.state, state, fingerprint=fp)  # into the solver's slot layout
    sim.solver.import_state(sim._next, state, fingerprint=fp)
    world_major = meta.get("wear_layout") != "compact"  # checkpoints before the compact layout
    for f in sim.solver.wall_stats.FIELDS:
        sim.solver.wall_stats.load(f, data[f"wear/{f}"], world_major=world_major)
    sim.steps = int(meta["steps"])
    return sim


def _model_from_checkpoint(path: Path, data, meta: dict, device: str | None) -> Model:
    """The Model stored in a checkpoint; its fingerprint must match the stored one."""
    host = {k[5:]: data[k] for k in data.files if k.startswith("host/")}
    initial = {k[8:]: data[k] for k in data.files if k.startswith("initial/")}
    materials = [Material(**x) for x in meta["materials"]]
    walls = []
    for i, w in enumerate(meta["walls"]):
        mo = dict(w["motion"])
        mo["stop"] = np.inf if mo["stop"] is None else mo["stop"]
        mo = {k: tuple(v) if isinstance(v, list) else v for k, v in mo.items()}
        labels = data[f"wall{i}/labels"] if f"wall{i}/labels" in data.files else None
        walls.append(Wall(name=w["name"], vertices=data[f"wall{i}/vertices"], faces=data[f"wall{i}/faces"],
                          material=w["material"], world=w["world"], motion=WallMotion(**mo), tri_offset=w["tri_offset"],
                          triangle_labels=labels, label_names=tuple(w["label_names"])))
    model = Model(host, walls, materials, ContactLaw.from_config(meta["law"], f"checkpoint {path}: law"), initial, device=device,
                  max_contacts=meta["max_contacts"], gravity=meta["gravity"])
    saved = meta.get("fingerprint")
    if saved is not None and saved != model.fingerprint:
        raise ConfigError(f"checkpoint {path} records model {saved} but its arrays make model {model.fingerprint}: "
                          f"the file is damaged or inconsistent")
    return model
