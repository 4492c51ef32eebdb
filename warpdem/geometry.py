"""Wall meshes for common set-ups (trimesh in, plain vertices/faces out), in metres."""
from __future__ import annotations

import numpy as np
import trimesh


def plane(center, size_x: float, size_y: float, normal=(0.0, 0.0, 1.0), subdivisions: int = 1) -> trimesh.Trimesh:
    """A rectangle (two triangles per cell) centred at ``center`` with the given normal."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    k = subdivisions
    u = np.linspace(-0.5, 0.5, k + 1)
    gx, gy = np.meshgrid(u * size_x, u * size_y, indexing="ij")
    verts = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    faces = []
    for i in range(k):
        for j in range(k):
            a = i * (k + 1) + j
            b, c, d = a + (k + 1), a + 1, a + k + 2
            faces += [[a, b, d], [a, d, c]]
    mesh = trimesh.Trimesh(verts, np.array(faces), process=False)
    rot = trimesh.geometry.align_vectors([0, 0, 1], n)
    mesh.apply_transform(rot)
    mesh.apply_translation(center)
    return mesh


def open_box(lower, upper, top: bool = False) -> trimesh.Trimesh:
    """Inward-facing box walls (floor and four sides; lid if ``top``) spanning [lower, upper]."""
    box = trimesh.creation.box(bounds=np.array([lower, upper], dtype=float))
    keep = box.face_normals[:, 2] < 0.5 if not top else np.ones(len(box.faces), bool)
    mesh = trimesh.Trimesh(box.vertices, box.faces[keep], process=False)
    mesh.invert()  # normals point inside, where the particles are
    return mesh


def cylinder_shell(radius: float, length: float, axis=(0.0, 1.0, 0.0), center=(0.0, 0.0, 0.0), sections: int = 64,
                   caps: bool = True) -> trimesh.Trimesh:
    """Inward-facing cylinder (a drum), optionally closed by end caps."""
    cyl = trimesh.creation.cylinder(radius=radius, height=length, sections=sections)
    if not caps:
        keep = np.abs(cyl.face_normals[:, 2]) < 0.5
        cyl = trimesh.Trimesh(cyl.vertices, cyl.faces[keep], process=False)
    cyl.invert()
    rot = trimesh.geometry.align_vectors([0, 0, 1], np.asarray(axis, float))
    cyl.apply_transform(rot)
    cyl.apply_translation(center)
    return cyl
