"""Wall meshes for common set-ups (trimesh in, plain vertices/faces out), in metres."""
from __future__ import annotations

import numpy as np
import trimesh


def plane(center, size_u: float, size_v: float, normal=(0.0, 0.0, 1.0), subdivisions: int = 1) -> trimesh.Trimesh:
    """A rectangle centred at ``center`` [m] facing ``normal`` (the side particles touch).

    In-plane axes: u = the first world axis (x, then y) not parallel to the normal, projected
    onto the plane; v = normal x u. So a floor (normal z) spans x by y, a wall facing +-x
    spans y by z, and a wall facing +-y spans x by z. Each cell is split into two triangles.
    """
    n = np.asarray(normal, dtype=float)
    if n.shape != (3,) or np.linalg.norm(n) == 0:
        raise ValueError(f"plane normal must be a non-zero 3-vector, got {normal!r}")
    n = n / np.linalg.norm(n)
    for axis in np.eye(3):
        u = axis - np.dot(axis, n) * n
        if np.linalg.norm(u) > 1e-6:
            break
    u = u / np.linalg.norm(u)
    v = np.cross(n, u)
    k = int(subdivisions)
    s = np.linspace(-0.5, 0.5, k + 1)
    gu, gv = np.meshgrid(s * size_u, s * size_v, indexing="ij")
    verts = np.asarray(center, dtype=float) + gu.reshape(-1, 1) * u + gv.reshape(-1, 1) * v
    faces = []
    for i in range(k):
        for j in range(k):
            a = i * (k + 1) + j
            b, c, d = a + (k + 1), a + 1, a + k + 2
            faces += [[a, b, d], [a, d, c]]  # counter-clockwise seen from the normal side
    return trimesh.Trimesh(verts, np.array(faces), process=False)


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
