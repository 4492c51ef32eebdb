"""Output: particles and wall meshes to VTK (ParaView), checkpoint and restart."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .contact.law import ContactLaw
from .errors import ConfigError
from .materials import Material
from .model import Model, Wall, WallMotion


def write_vtk(directory: str | os.PathLike, sim, frame: int, world: int | None = None) -> list[Path]:
    """Write spheres (``particles_NNNNNN.vtp``: radius, velocity, body, world) and walls
    (``wall_<name>_NNNNNN.vtp`` with per-triangle wear accumulators) for one frame.

    Spheres of inactive (removed) bodies are skipped. ``world`` restricts output to one world.
    """
    import pyvista as pv

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    m: Model = sim.model
    x = sim.sphere_positions()
    body = m.host["sphere_body"]
    active = sim.state.body_active.numpy()[body].astype(bool)
    sel = active if world is None else active & (m.host["sphere_world"] == world)
    v = sim.state.body_v.numpy()[body]
    cloud = pv.PolyData(x[sel])
    cloud["radius"] = m.host["sphere_radius"][sel]
    cloud["diameter"] = 2.0 * m.host["sphere_radius"][sel]
    cloud["velocity"] = v[sel]
    cloud["body"] = body[sel]
    cloud["world"] = m.host["sphere_world"][sel]
    paths = [out / f"particles_{frame:06d}.vtp"]
    cloud.save(paths[0])
    for wi, w in enumerate(m.walls):
        pts = w.mesh.points.numpy()
        faces = np.hstack([np.full((w.num_triangles, 1), 3), w.faces]).ravel()
        mesh = pv.PolyData(pts, faces)
        for field in sim.solver.wall_stats.FIELDS:
            a = sim.solver.wall_stats.per_triangle(field, wi)
            mesh.cell_data[field] = a[world] if world is not None else a.sum(axis=0)
        if w.triangle_labels is not None:
            mesh.cell_data["component"] = w.triangle_labels
        p = out / f"wall_{w.name}_{frame:06d}.vtp"
        mesh.save(p)
        paths.append(p)
    return paths


# ----------------------------------------------------------------------------- checkpoints
def save_checkpoint(path: str | os.PathLike, sim) -> Path:
    """Save model, state, wall accumulators and step count to one ``.npz`` file."""
    m: Model = sim.model
    law = m.contact_law
    meta = dict(
        version=1, law=dict(normal=law.normal, tangential=law.tangential, rolling=law.rolling, cohesion=law.cohesion,
                            track_wear=law.track_wear),
        materials=[dict(name=x.name, youngs_modulus=x.youngs_modulus, poisson_ratio=x.poisson_ratio, density=x.density)
                   for x in m.materials],
        walls=[dict(name=w.name, material=w.material, world=w.world, tri_offset=w.tri_offset,
                    label_names=list(w.label_names),
                    motion=dict(velocity=list(w.motion.velocity), angular_velocity=list(w.motion.angular_velocity),
                                origin=list(w.motion.origin), start=w.motion.start,
                                stop=None if not np.isfinite(w.motion.stop) else w.motion.stop))
               for w in m.walls],
        max_contacts=m.max_contacts, gravity=list(m.gravity), dt=sim.dt, steps=sim.steps)
    arrays = {f"host/{k}": v for k, v in m.host.items()}
    arrays.update({f"initial/{k}": v for k, v in m.initial.items()})
    arrays.update({f"state/{k}": v for k, v in sim.state.to_numpy().items()})
    for f in sim.solver.wall_stats.FIELDS:
        arrays[f"wear/{f}"] = getattr(sim.solver.wall_stats, f).numpy()
    for i, w in enumerate(m.walls):
        arrays[f"wall{i}/vertices"] = w.vertices
        arrays[f"wall{i}/faces"] = w.faces
        if w.triangle_labels is not None:
            arrays[f"wall{i}/labels"] = w.triangle_labels
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, meta=np.array(json.dumps(meta)), **arrays)
    return path if path.suffix == ".npz" else path.with_suffix(path.suffix + ".npz")


def load_checkpoint(path: str | os.PathLike, device: str | None = None, **sim_kwargs):
    """Rebuild the Simulation saved by :func:`save_checkpoint`; continuing it gives the same
    results as the uninterrupted run."""
    from .solver import Simulation

    path = Path(path)
    if not path.exists():
        raise ConfigError(f"checkpoint file not found: {path}")
    data = np.load(path, allow_pickle=False)
    try:
        meta = json.loads(str(data["meta"]))
    except KeyError as exc:
        raise ConfigError(f"{path} is not a warpdem checkpoint (no 'meta' entry)") from exc
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
    model = Model(host, walls, materials, ContactLaw(**meta["law"]), initial, device=device,
                  max_contacts=meta["max_contacts"], gravity=meta["gravity"])
    sim = Simulation(model, meta["dt"], force=True, **sim_kwargs)
    state = {k[6:]: data[k] for k in data.files if k.startswith("state/")}
    sim.state.load_numpy(state)
    sim._next.load_numpy(state)
    for f in sim.solver.wall_stats.FIELDS:
        getattr(sim.solver.wall_stats, f).assign(data[f"wear/{f}"])
    sim.steps = int(meta["steps"])
    return sim
