"""Outputs of a pump run: VTK for ParaView, figures (the seed paper's Figs. 15-18), results
files and the report (HTML via ``calibration.reporting`` when present, and Markdown).

VTK: ``vtk/particles.pvd`` (member spheres with body id, radius, velocity, speed, world),
``vtk/impeller.pvd`` and ``vtk/casing.pvd`` (surfaces in their current pose with per-cell
cumulative wear fields and component ids), and ``wear_impeller.vtp`` / ``wear_casing.vtp`` at
the end (rest pose; fields per cell: energy_n, energy_t [J], their values per area [J/m^2],
cumulative force sum |F| [N], Archard and Finnie depths [m], impacts, component, blade zone).
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from .geometry import COMPONENTS, REGIONS

COMP_COLOURS = {"shroud": "tab:green", "blade": "tab:orange", "hub": "tab:blue", "volute": "tab:red",
                "tongue": "tab:purple", "inlet": "tab:gray", "outlet": "tab:brown"}


def _pvd(path: Path, entries: list[tuple[float, str]]) -> None:
    lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
             "  <Collection>"]
    lines += [f'    <DataSet timestep="{t:.9g}" group="" part="0" file={quoteattr(f)}/>' for t, f in entries]
    lines += ["  </Collection>", "</VTKFile>"]
    path.write_text("\n".join(lines) + "\n")


def wall_cell_data(case, wall: int, world: int | None = None) -> dict[str, np.ndarray]:
    """Per-triangle wear fields of one pump wall (see the module docstring)."""
    rec = case.recorder
    cfg = case.config["wear"]
    areas = rec.areas()[wall]
    out = {}
    for f in ("energy_n", "energy_t"):
        v = rec.per_triangle(f, world)[wall]
        out[f] = v
        out[f + "_per_area"] = v / areas
    dt = case.sim.dt
    out["cumulative_force_n"] = rec.per_triangle("impulse_n", world)[wall] / dt
    out["cumulative_force_t"] = rec.per_triangle("impulse_t", world)[wall] / dt
    out["archard_depth"] = rec.archard_volume(float(cfg["archard_k"]), float(cfg["hardness"]), world)[wall] / areas
    out["finnie_depth"] = rec.per_triangle("erosion", world)[wall] / areas
    out["impacts"] = rec.per_triangle("impacts", world)[wall]
    w = case.sim.model.walls[wall]
    out["component"] = np.asarray(w.triangle_labels, dtype=np.int32)
    if wall == case.impeller_wall:
        out["blade_zone"] = case.geometry.impeller.zone.astype(np.int32)
    return out


def _polydata(points: np.ndarray, faces: np.ndarray):
    import pyvista as pv

    return pv.PolyData(np.asarray(points, dtype=np.float64), np.hstack([np.full((len(faces), 1), 3), faces]).ravel())


_VTK_TYPES = {np.dtype(np.float32): "Float32", np.dtype(np.float64): "Float64", np.dtype(np.int32): "Int32",
              np.dtype(np.int64): "Int64", np.dtype(np.uint8): "UInt8"}


def _data_array(name: str, a: np.ndarray) -> str:
    """One inline binary (base64, UInt32 byte-count header) VTK XML DataArray."""
    import base64
    import struct

    a = np.ascontiguousarray(a)
    if a.dtype not in _VTK_TYPES:
        a = a.astype(np.float64 if a.dtype.kind == "f" else np.int64)
    comps = 1 if a.ndim == 1 else a.shape[1]
    raw = a.astype(a.dtype.newbyteorder("<")).tobytes()
    payload = base64.b64encode(struct.pack("<I", len(raw)) + raw).decode("ascii")
    return (f'<DataArray type="{_VTK_TYPES[a.dtype]}" Name="{name}" NumberOfComponents="{comps}" '
            f'format="binary">{payload}</DataArray>')


def write_vtp(path: Path, points: np.ndarray, triangles: np.ndarray | None = None,
              point_data: dict | None = None, cell_data: dict | None = None) -> Path:
    """Write a VTK XML PolyData file (.vtp) without VTK: triangles as polys, or the points as
    vertices when ``triangles`` is None; fields per point / per cell (1 or 3 components)."""
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    n = len(pts)
    if triangles is None:
        conn, offs, kind, ncell = np.arange(n, dtype=np.int64), np.arange(1, n + 1, dtype=np.int64), "Verts", n
    else:
        tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        conn, offs, kind, ncell = tri.ravel(), 3 * np.arange(1, len(tri) + 1, dtype=np.int64), "Polys", len(tri)
    counts = {"Verts": 0, "Polys": 0}
    counts[kind] = ncell
    out = ['<?xml version="1.0"?>',
           '<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian" header_type="UInt32">', "<PolyData>",
           f'<Piece NumberOfPoints="{n}" NumberOfVerts="{counts["Verts"]}" NumberOfLines="0" NumberOfStrips="0" '
           f'NumberOfPolys="{counts["Polys"]}">']
    out += ["<PointData>"] + [_data_array(k, np.asarray(v)) for k, v in (point_data or {}).items()] + ["</PointData>"]
    out += ["<CellData>"] + [_data_array(k, np.asarray(v)) for k, v in (cell_data or {}).items()] + ["</CellData>"]
    out += ["<Points>", _data_array("Points", pts), "</Points>"]
    for section in ("Verts", "Lines", "Strips", "Polys"):
        if section == kind:
            out += [f"<{section}>", _data_array("connectivity", conn), _data_array("offsets", offs), f"</{section}>"]
    out += ["</Piece>", "</PolyData>", "</VTKFile>"]
    Path(path).write_text("\n".join(out) + "\n")
    return Path(path)


class VTKWriter:
    """Writes particle and wall frames and the ``.pvd`` collections."""

    def __init__(self, case, directory: Path) -> None:
        self.case = case
        self.dir = Path(directory)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.frames: dict[str, list[tuple[float, str]]] = {"particles": [], "impeller": [], "casing": []}
        self.k = 0

    def write_frame(self, t: float) -> None:
        case = self.case
        sim = case.sim
        m = sim.model
        x = sim.sphere_positions()
        body = m.host["sphere_body"]
        act = sim.state.body_active.numpy()[body] != 0
        v = sim.state.body_v.numpy()[body].astype(np.float32)
        name = f"particles_{self.k:05d}.vtp"
        write_vtp(self.dir / name, x[act], point_data={
            "id": body[act].astype(np.int32), "radius": m.host["sphere_radius"][act].astype(np.float32),
            "velocity": v[act], "speed": np.linalg.norm(v[act], axis=1).astype(np.float32),
            "world": m.host["sphere_world"][act].astype(np.int32)})
        self.frames["particles"].append((t, name))
        for wi, key in ((case.impeller_wall, "impeller"), (case.casing_wall, "casing")):
            w = m.walls[wi]
            name = f"{key}_{self.k:05d}.vtp"
            write_vtp(self.dir / name, w.points_at(t).astype(np.float32), w.faces, cell_data=_float32(wall_cell_data(case, wi)))
            self.frames[key].append((t, name))
        self.k += 1

    def close(self) -> None:
        for key, entries in self.frames.items():
            if entries:
                _pvd(self.dir / f"{key}.pvd", entries)


def write_wear_surfaces(case, out: Path) -> list[Path]:
    paths = []
    for wi, key, tm in ((case.impeller_wall, "impeller", case.geometry.impeller),
                        (case.casing_wall, "casing", case.geometry.casing)):
        paths.append(write_vtp(out / f"wear_{key}.vtp", tm.vertices, tm.faces, cell_data=wall_cell_data(case, wi)))
    return paths


def _float32(d: dict) -> dict:
    return {k: (v.astype(np.float32) if v.dtype.kind == "f" else v) for k, v in d.items()}


# ----------------------------------------------------------------------------- figures
def _plt():
    import matplotlib

    if os.environ.get("MPLBACKEND") is None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _log_field(v: np.ndarray) -> tuple[np.ndarray, float, float]:
    pos = v[v > 0]
    if pos.size == 0:
        return np.full_like(v, np.nan), 0.0, 1.0
    lo, hi = np.percentile(np.log10(pos), [5, 100])
    return np.where(v > 0, np.log10(np.maximum(v, 1e-300)), np.nan), float(lo), float(max(hi, lo + 1e-6))


def figure_wear(case, out: Path) -> Path:
    """Fig. 17 analogue: normal and tangential contact energy per area on the impeller (hub and
    blades, shroud removed) and the volute (front wall removed), log colour scale. pyvista
    off-screen, matplotlib projections if that fails."""
    path = out / "wear_energy.png"
    try:
        _figure_wear_pyvista(case, path)
    except Exception as exc:  # no OpenGL context: fall back to flat projections
        print(f"pump: pyvista off-screen rendering failed ({exc}); drawing projections with matplotlib")
        _figure_wear_matplotlib(case, path)
    return path


def _wear_views(case):
    geo = case.geometry
    imp, cas = geo.impeller, geo.casing
    keep_imp = imp.component != COMPONENTS.index("shroud")
    cen = cas.centroids()
    keep_cas = (cen[:, 2] < geo.z_front - 1e-4) & (cas.component != COMPONENTS.index("inlet"))
    return ((imp, keep_imp, wall_cell_data(case, case.impeller_wall), "impeller (shroud removed)"),
            (cas, keep_cas, wall_cell_data(case, case.casing_wall), "volute casing (front wall removed)"))


def _figure_wear_pyvista(case, path: Path) -> None:
    import pyvista as pv

    pv.OFF_SCREEN = True
    p = pv.Plotter(shape=(2, 2), off_screen=True, window_size=(1500, 1200))
    for row, (tm, keep, data, title) in enumerate(_wear_views(case)):
        for col, f in enumerate(("energy_n_per_area", "energy_t_per_area")):
            p.subplot(row, col)
            faces = tm.faces[keep]
            mesh = _polydata(tm.vertices, faces)
            vals, lo, hi = _log_field(data[f][keep])
            kind = "normal" if col == 0 else "tangential"
            label = f"log10 {kind} energy [J/m^2], {title.split()[0]}"
            mesh.cell_data[label] = np.nan_to_num(vals, nan=lo - 1.0)
            p.add_mesh(mesh, scalars=label, clim=(lo, hi), cmap="inferno", below_color="lightgrey",
                       show_edges=False, scalar_bar_args={"title": label, "vertical": False})
            p.add_text(f"{title}: {kind} energy", font_size=10)
            p.view_vector((0.35, -0.55, 1.0), viewup=(0, 1, 0))
            p.camera.zoom(1.25)
    p.screenshot(str(path))
    p.close()


def _figure_wear_matplotlib(case, path: Path) -> None:
    """Top views: flat faces (hub, back wall) as coloured triangles, vertical walls (blades,
    spiral, duct) as coloured dots at their triangle centres (zero energy in grey)."""
    import matplotlib
    from matplotlib.collections import PolyCollection

    plt = _plt()
    cmap = matplotlib.colormaps["inferno"].with_extremes(under="lightgrey")
    fig, axs = plt.subplots(2, 2, figsize=(12, 11), constrained_layout=True)
    for row, (tm, keep, data, title) in enumerate(_wear_views(case)):
        tri3 = tm.vertices[tm.faces]
        nz = np.abs(np.cross(tri3[:, 1] - tri3[:, 0], tri3[:, 2] - tri3[:, 0])[:, 2])
        flat = nz > 0.5 * 2 * tm.areas()
        for col, f in enumerate(("energy_n_per_area", "energy_t_per_area")):
            ax = axs[row, col]
            vals, lo, hi = _log_field(data[f])
            vals = np.nan_to_num(vals, nan=lo - 1)
            sel = keep & flat
            pc = PolyCollection(tri3[sel][:, :, :2], array=vals[sel], cmap=cmap, clim=(lo, hi), edgecolors="face",
                                linewidths=0.2)
            ax.add_collection(pc)
            vert = keep & ~flat
            cen = tm.centroids()[vert]
            order = np.argsort(vals[vert])
            ax.scatter(cen[order, 0], cen[order, 1], c=vals[vert][order], cmap=cmap, vmin=lo, vmax=hi, s=6,
                       linewidths=0)
            ax.autoscale()
            ax.set_aspect("equal")
            ax.set_title(f"{title}\n{'normal' if col == 0 else 'tangential'} energy, log10 J/m^2 (top view; "
                         f"dots: vertical walls)")
            fig.colorbar(pc, ax=ax, shrink=0.8)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def figure_wear_maps(case, out: Path) -> Path:
    """Unrolled wear maps: one blade (the three summed) seen on its pressure side and its suction
    side, (r - r1) / (r2 - r1) against z, and the volute's outer (spiral) wall, angle from the
    tongue against z; normal energy per area (top row) and tangential (bottom row), log scale."""
    from matplotlib.collections import PolyCollection

    plt = _plt()
    path = out / "wear_maps.png"
    geo, d = case.geometry, case.design
    imp, cas = geo.impeller, geo.casing
    data_i = wall_cell_data(case, case.impeller_wall)
    data_c = wall_cell_data(case, case.casing_wall)
    blade_sel = np.flatnonzero(imp.component == COMPONENTS.index("blade"))
    per = len(blade_sel) // d.blades
    first = blade_sel[:per]
    v = imp.vertices[imp.faces[first]]
    xi = (np.hypot(v[..., 0], v[..., 1]) - d.r1) / (d.r2 - d.r1)
    poly_b = np.stack([xi, v[..., 2] * 1e3], -1)
    zone = imp.zone[first]
    cen = cas.centroids()
    th_c = np.mod(np.arctan2(cen[:, 1], cen[:, 0]), 2 * np.pi)
    spiral = (np.abs(np.hypot(cen[:, 0], cen[:, 1]) - geo.spiral_radius(th_c)) < 2e-3) & \
        (cen[:, 2] > geo.z_back + 1e-4) & (cen[:, 2] < geo.z_front - 1e-4)
    vs = cas.vertices[cas.faces[spiral]]
    th_v = np.mod(np.arctan2(vs[..., 1], vs[..., 0]), 2 * np.pi)
    th_v = np.where(th_v - th_c[spiral][:, None] > np.pi, th_v - 2 * np.pi, th_v)
    th_v = np.where(th_c[spiral][:, None] - th_v > np.pi, th_v + 2 * np.pi, th_v)
    poly_s = np.stack([np.degrees(th_v), vs[..., 2] * 1e3], -1)
    fig, axs = plt.subplots(2, 3, figsize=(17, 8.5), gridspec_kw={"width_ratios": [1, 1, 2.2]},
                            constrained_layout=True)
    for row, f in enumerate(("energy_n_per_area", "energy_t_per_area")):
        blade_vals = data_i[f][blade_sel].reshape(d.blades, per).sum(axis=0) / d.blades
        spiral_vals = data_c[f][spiral]
        _, lo, hi = _log_field(np.concatenate([blade_vals, spiral_vals]))
        panels = (
            (axs[row, 0], poly_b, blade_vals, (zone == 1) | (zone == 2) | (zone == 4),
             "blade, pressure side (mean of the blades)"),
            (axs[row, 1], poly_b, blade_vals, (zone == 1) | (zone == 3) | (zone == 4), "blade, suction side"),
            (axs[row, 2], poly_s, spiral_vals, np.ones(len(spiral_vals), bool), "volute outer wall (unrolled)"),
        )
        for ax, poly, vals, sel, title in panels:
            lv = np.where(vals[sel] > 0, np.log10(np.maximum(vals[sel], 1e-300)), lo - 1)
            import matplotlib

            cmap = matplotlib.colormaps["inferno"].with_extremes(under="lightgrey")
            pc = PolyCollection(poly[sel], array=lv, cmap=cmap, clim=(lo, hi), edgecolors="none")
            ax.add_collection(pc)
            ax.autoscale()
            kind = "normal" if row == 0 else "tangential"
            ax.set_title(f"{title}\n{kind} energy, log10 J/m^2")
            ax.set_ylabel("z [mm]")
            ax.set_xlabel("(r - r1) / (r2 - r1): leading edge left" if ax is not axs[row, 2]
                          else "angle from the tongue [deg] (throat at 360)")
        fig.colorbar(pc, ax=axs[row, :].tolist(), shrink=0.9, label="log10 J/m^2")
    fig.savefig(path, dpi=95)
    plt.close(fig)
    return path


def _outline(ax, case, plane: str = "xy", blades: bool = True, casing: bool = True) -> None:
    geo = case.geometry
    d = geo.design
    th = np.linspace(0, 2 * np.pi, 400)
    if plane == "xy":
        ax.plot(d.r2 * np.cos(th), d.r2 * np.sin(th), "k:", lw=0.6)
        ax.plot(d.r_inlet * np.cos(th), d.r_inlet * np.sin(th), "k--", lw=0.6)
        if casing:
            ro = geo.spiral_radius(th)
            ax.plot(ro * np.cos(th), ro * np.sin(th), "k-", lw=0.8)
            ax.plot([d.r3, d.r3], [0, geo.outlet_y], "k-", lw=0.8)
            ax.plot([d.r_throat, d.r_throat], [0, geo.outlet_y], "k-", lw=0.8)
        from .geometry import blade_camber

        for k in range(d.blades if blades else 0):
            r, t = blade_camber(d, 60, 2 * np.pi * k / d.blades)
            ax.plot(r * np.cos(t), r * np.sin(t), color="0.5", lw=1.5)


def figure_trajectories(case, rec, out: Path) -> Path:
    """Fig. 15 analogue: trajectories of one world's particles coloured by speed, in the
    stationary frame (top and side views) and in the impeller's frame (top view, blades drawn;
    rotation is counter-clockwise, so each blade's pressure side is the one facing
    counter-clockwise)."""
    from matplotlib.collections import LineCollection

    plt = _plt()
    path = out / "trajectories.png"
    d = case.design
    geo = case.geometry
    x = np.asarray(rec.traj_x)  # (k, n, 3)
    s = np.asarray(rec.traj_speed)
    t = np.asarray(rec.time)
    fig, axs = plt.subplots(1, 3, figsize=(19, 6.2), gridspec_kw={"width_ratios": [1.1, 1.1, 1]},
                            constrained_layout=True)
    vmax = float(np.nanpercentile(s, 99)) if s.size and np.isfinite(s).any() else 1.0
    xr = x.copy()
    if x.ndim == 3:
        ang = -d.omega * t[:, None]
        c, sn = np.cos(ang), np.sin(ang)
        xr[..., 0] = c * x[..., 0] - sn * x[..., 1]
        xr[..., 1] = sn * x[..., 0] + c * x[..., 1]
    lc = None
    for ax, pts, (i, j), title in ((axs[0], x, (0, 1), "stationary frame, top view"),
                                   (axs[1], xr, (0, 1), "impeller frame, top view"),
                                   (axs[2], x, (0, 2), "stationary frame, side view")):
        segs, cols = [], []
        if pts.ndim == 3:
            for b in range(pts.shape[1]):
                p = pts[:, b, :]
                ok = np.isfinite(p[:, 0])
                if ax is axs[1]:
                    ok &= np.hypot(p[:, 0], p[:, 1]) < d.r2 * 1.02
                for k in np.flatnonzero(ok[:-1] & ok[1:]):
                    segs.append([p[k, [i, j]], p[k + 1, [i, j]]])
                    cols.append(0.5 * (s[k, b] + s[k + 1, b]))
        lc = LineCollection(segs, array=np.asarray(cols), cmap="jet", clim=(0, vmax), linewidths=1.1)
        ax.add_collection(lc)
        if j == 1:
            _outline(ax, case, blades=ax is axs[1], casing=ax is not axs[1])
        else:
            ax.add_patch(plt.Rectangle((-geo.spiral_radius(np.pi), geo.z_back), geo.spiral_radius(np.pi) + d.r_throat,
                                       d.b3, fill=False, lw=0.8))
            ax.add_patch(plt.Rectangle((-d.r_inlet, geo.z_front), 2 * d.r_inlet, d.inlet_length, fill=False, lw=0.8))
        ax.autoscale()
        ax.set_aspect("equal")
        ax.set_title(f"{title} (world {case.config['run']['trajectory_world']})")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]" if j == 1 else "z [m]")
    axs[1].set_xlim(-d.r2 * 1.05, d.r2 * 1.05)
    axs[1].set_ylim(-d.r2 * 1.05, d.r2 * 1.05)
    fig.colorbar(lc, ax=axs.tolist(), label="particle speed [m/s]", shrink=0.8)
    fig.savefig(path, dpi=95)
    plt.close(fig)
    return path


def figure_flow(case, out: Path) -> Path:
    """Fig. 16 analogue: the prescribed flow on the mid-plane z = b2 / 2 (speed with arrows,
    piezometric pressure) and on the meridional plane y = 0 (speed)."""
    plt = _plt()
    path = out / "flow_field.png"
    grid, geo, d = case.grid, case.geometry, case.design
    ax_ = [grid.origin[k] + grid.spacing * np.arange(grid.shape[k]) for k in range(3)]
    k = int(np.argmin(np.abs(ax_[2] - 0.5 * d.b2)))
    X, Y = np.meshgrid(ax_[0], ax_[1], indexing="ij")
    inside = geo.region_of(np.stack([X.ravel(), Y.ravel(), np.full(X.size, ax_[2][k])], -1)).reshape(X.shape) > 0
    vel = grid.velocity[:, :, k]
    spd = np.where(inside, np.linalg.norm(vel, axis=-1), np.nan)
    pres = np.where(inside, grid.pressure[:, :, k] / 1e3, np.nan)
    j = int(np.argmin(np.abs(ax_[1])))
    XZ, ZZ = np.meshgrid(ax_[0], ax_[2], indexing="ij")
    inside_m = geo.region_of(np.stack([XZ.ravel(), np.zeros(XZ.size), ZZ.ravel()], -1)).reshape(XZ.shape) > 0
    spd_m = np.where(inside_m, np.linalg.norm(grid.velocity[:, j, :], axis=-1), np.nan)
    fig, axs = plt.subplots(1, 3, figsize=(19, 6.2))
    c0 = axs[0].pcolormesh(X, Y, spd, shading="auto", cmap="viridis")
    st = 5
    m = inside[::st, ::st]
    axs[0].quiver(X[::st, ::st][m], Y[::st, ::st][m], vel[::st, ::st, 0][m], vel[::st, ::st, 1][m], color="w",
                  scale=400, width=0.002)
    fig.colorbar(c0, ax=axs[0], label="speed [m/s]")
    axs[0].set_title(f"absolute velocity, mid-plane z = {ax_[2][k] * 1e3:.0f} mm")
    c1 = axs[1].pcolormesh(X, Y, pres, shading="auto", cmap="coolwarm")
    fig.colorbar(c1, ax=axs[1], label="p* [kPa] (rel. to the suction pipe)")
    axs[1].set_title("piezometric pressure, mid-plane")
    for a in axs[:2]:
        _outline(a, case)
        a.set_aspect("equal")
        a.set_xlabel("x [m]")
        a.set_ylabel("y [m]")
    c2 = axs[2].pcolormesh(XZ, ZZ, spd_m, shading="auto", cmap="viridis")
    fig.colorbar(c2, ax=axs[2], label="speed [m/s]")
    axs[2].set_title("speed, meridional plane y = 0 (suction pipe above)")
    axs[2].set_aspect("equal")
    axs[2].set_xlabel("x [m]")
    axs[2].set_ylabel("z [m]")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def figure_force_vs_time(case, out: Path) -> Path:
    """Fig. 18 analogue: average cumulative contact force (normal and tangential) per component
    against time (sum over steps of |F| divided by the component's triangles, worlds summed)."""
    plt = _plt()
    path = out / "force_vs_time.png"
    t, totals = case.recorder.series.as_arrays()
    n_tri = case.recorder.triangles_per_component()
    dt = case.sim.dt
    fig, axs = plt.subplots(1, 2, figsize=(13, 5), sharex=True)
    for ax, fld, kind in ((axs[0], "impulse_n", "normal"), (axs[1], "impulse_t", "tangential")):
        for c in ("shroud", "blade", "hub", "volute", "tongue"):
            if c in totals.get(fld, {}):
                ax.plot(t, totals[fld][c] / dt / n_tri[c], label=c, color=COMP_COLOURS[c], lw=1.8)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"average cumulative {kind} contact force [N]")
        ax.set_title(f"{kind}: sum over steps of |F|, per triangle")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def figure_counts(case, rec, out: Path) -> Path:
    plt = _plt()
    path = out / "particle_counts.png"
    t = np.asarray(rec.time)
    c = np.asarray(rec.region_counts)  # (k, worlds, regions)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    if c.size:
        tot = c.sum(axis=1)
        for k in range(1, len(REGIONS)):
            ax.plot(t, tot[:, k], label=REGIONS[k])
        out_n = np.asarray(rec.removed_outlet).sum(axis=1)
        ax.plot(t, out_n, "k--", label="left through the outlet (cumulative)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"particles (all {case.sim.model.num_worlds} world(s))")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def figure_passage(case, rec, out: Path) -> Path:
    """Where particles sit across the blade passage (0: pressure side, 1: suction side)."""
    plt = _plt()
    path = out / "passage_position.png"
    ph = np.concatenate(rec.passage_phase) if rec.passage_phase else np.zeros(0)
    rr = np.concatenate(rec.passage_radius) if rec.passage_radius else np.zeros(0)
    d = case.design
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.5))
    axs[0].hist(ph, bins=20, range=(0, 1), color="tab:blue", alpha=0.8)
    axs[0].set_xlabel("position across the passage (0 = pressure side, 1 = suction side)")
    axs[0].set_ylabel("particle samples")
    axs[0].set_title("particles in the blade passages (all records)")
    if ph.size:
        axs[1].scatter((rr - d.r1) / (d.r2 - d.r1), ph, s=4, alpha=0.5)
    axs[1].set_xlabel("(r - r1) / (r2 - r1)")
    axs[1].set_ylabel("position across the passage")
    axs[1].set_title("along the blade: entry (left) to outlet (right)")
    for a in axs:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


# ----------------------------------------------------------------------------- report
def _fmt(v, digits: int = 3) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not math.isfinite(v):
            return "-"
        if v == 0:
            return "0"
        if 1e-3 <= abs(v) < 1e5:
            return f"{v:.{max(0, digits - 1 - int(math.floor(math.log10(abs(v)))))}f}"
        return f"{v:.{digits - 1}e}"
    return str(v)


def report_content(case, results: dict) -> dict:
    """Plain content shared by the HTML and Markdown reports: verdict, tables, findings text."""
    d = case.design
    cfg = case.config
    f = results["findings"]
    fc = results["fluid_checks"]
    w = results["wear"]
    p = results["particles"]
    n_rep = sum(bool(v["reproduced"]) for v in f.values())
    f1, f2, f3 = (f["volute_wears_most_by_tangential_force"], f["blade_head_highest_normal_energy"],
                  f["particles_enter_along_pressure_side"])
    comps = [c for c in ("shroud", "blade", "hub", "volute", "tongue") if c in w["energy_n_J"]]
    findings = [
        ("Volute wears most, through cumulative tangential force", f1["reproduced"],
         f"tangential contact energy: casing (volute + tongue) {_fmt(f1['casing_tangential_energy_J'])} J vs impeller "
         + ", ".join(f"{c} {_fmt(v)} J" for c, v in f1["impeller_tangential_energy_J"].items())
         + f"; cumulative tangential force (sum over steps and triangles): casing "
         f"{_fmt(f1['casing_cumulative_tangential_force_N'])} N vs "
         + ", ".join(f"{c} {_fmt(v)} N" for c, v in f1["impeller_cumulative_tangential_force_N"].items())
         + "; tangential share of the casing's contact energy "
         f"{_fmt(100 * f1['volute_tangential_share_of_energy'])} %."),
        ("Blade head (leading edge) has the highest normal energy", f2["reproduced"],
         "normal contact energy per area on the impeller: "
         + ", ".join(f"{z} {_fmt(v)} J/m^2" for z, v in f2["normal_energy_per_area_J_m2"].items())
         + f"; the triangle with the most normal energy per area is on {f2['max_triangle']}."),
        ("Particles enter along the blades' pressure side", f3["reproduced"],
         f"fraction of particle samples in the pressure half of the passage: {_fmt(f3['pressure_half_fraction_entry'])}"
         f" at entry (first 30 % of the blade, {f3['samples_at_entry']} samples), "
         f"{_fmt(f3['pressure_half_fraction_passage'])} over the whole passage ({f3['samples_in_passage']} samples); "
         f"blade contact energy pressure side {_fmt(f3['pressure_side_contact_energy_J'])} J vs suction side "
         f"{_fmt(f3['suction_side_contact_energy_J'])} J."),
    ]
    checks = [
        ["flow rate, suction pipe [m^3/h]", fc["flow_rate_grid_m3s"]["inlet"] * 3600, d.flow_rate_m3h,
         f"{100 * fc['flow_rate_error']['inlet']:+.2f} %"],
        ["flow rate, impeller outlet [m^3/h]", fc["flow_rate_grid_m3s"]["impeller_outlet"] * 3600, d.flow_rate_m3h,
         f"{100 * fc['flow_rate_error']['impeller_outlet']:+.2f} %"],
        ["flow rate, discharge [m^3/h]", fc["flow_rate_grid_m3s"]["discharge"] * 3600, d.flow_rate_m3h,
         f"{100 * fc['flow_rate_error']['discharge']:+.2f} %"],
        ["Euler head of the sampled field [m]", fc["euler_head_grid_m"], fc["euler_head_design_m"],
         f"{100 * (fc['euler_head_grid_m'] / fc['euler_head_design_m'] - 1):+.2f} % (design H = {d.head:g} m / eta_h "
         f"{d.hydraulic_efficiency:g})"],
    ]
    wear_rows = []
    for c in comps:
        wear_rows.append([c, w["triangles"][c], w["area_m2"][c], w["energy_n_J"][c], w["energy_t_J"][c],
                          w["cumulative_force_avg_N"]["normal"][c], w["cumulative_force_avg_N"]["tangential"][c],
                          w["impacts"].get(c, 0.0), w["erosion_finnie_m3"].get(c, 0.0)])
    run = cfg["run"]
    setup = [
        ["duty", f"{d.flow_rate_m3h:g} m^3/h at {d.speed_rpm:g} rpm ({d.inlet_velocity:.2f} m/s in the "
                 f"{d.inlet_diameter * 1e3:g} mm suction pipe)"],
        ["design head", f"{d.head:g} m (chosen; the paper gives none): n_q = {d.n_q:.1f}, Gulich psi_opt = "
                        f"{d.psi:.3f}, d2 = {d.d2 * 1e3:.1f} mm, u2 = {d.u2:.2f} m/s"],
        ["impeller", f"z = {d.blades}, b2 = {d.b2 * 1e3:g} mm, r1 = {d.r1 * 1e3:g} mm, beta1B = {d.beta1_deg:g} deg "
                     f"(incidence {d.incidence_deg:.1f} deg), beta2B = {d.beta2_blade_deg:.1f} deg (solved), "
                     f"Wiesner slip {d.slip_factor:.3f}"],
        ["volute", f"r3 = {d.r3 * 1e3:.1f} mm, width {d.b3 * 1e3:g} mm, throat {d.throat_height * 1e3:g} mm, "
                   f"K_v / K_2 = {d.k_volute / d.k_impeller:.2f} (mixing loss {d.volute_loss_head:.1f} m)"],
        ["particles", f"{case.material.name}, {p['rate_per_s_per_world']:.1f}/s per world, {p['injected']} injected in "
                      f"{p['worlds']} world(s), {p['left_outlet']} left through the outlet, {p['lost']} lost"],
        ["impacts", f"largest normal impact speed {p['max_normal_impact_speed_m_s']:.1f} m/s: Hertz overlap "
                    f"{100 * p['hertz_overlap_at_max_impact_fraction_of_radius']:.0f} % of a mean particle's radius "
                    f"(particle E = {case.material.particle.youngs_modulus:.3g} Pa)"],
        ["time step", f"{case.sim.dt:.3g} s ({case.timings.get('steps', 0)} steps, {run['revolutions']:g} revolutions "
                      f"of {d.revolution_time * 1e3:.1f} ms)"],
        ["wall time", f"{case.timings.get('run_s', 0):.1f} s on {cfg['device']} "
                      f"(+ {case.timings.get('build_grid_s', 0) + case.timings.get('build_model_s', 0):.1f} s set-up)"],
    ]
    return {"n_reproduced": n_rep, "findings": findings, "checks": checks, "wear_rows": wear_rows, "setup": setup}


WEAR_COLUMNS = ["component", "triangles", "area [m^2]", "E_n [J]", "E_t [J]", "avg cum. F_n [N]", "avg cum. F_t [N]",
                "impacts", "Finnie volume [m^3]"]
CHECK_COLUMNS = ["check", "prototype", "target", "deviation"]


def write_markdown(case, results: dict, figures: dict[str, Path], path: Path) -> Path:
    c = report_content(case, results)
    lines = [f"# Slurry-pump wear prototype: {case.config['name']}", "",
             f"**{c['n_reproduced']} of the seed paper's 3 findings reproduced.**", ""]
    for title, ok, text in c["findings"]:
        lines.append(f"- **{title}: {'reproduced' if ok else 'not reproduced'}.** {text}")
    lines += ["", "## Set-up", "", "| item | value |", "| --- | --- |"]
    lines += [f"| {a} | {b} |" for a, b in c["setup"]]
    if case.config.get("notes"):
        lines += ["", str(case.config["notes"]).strip()]
    lines += ["", "## Fluid model checks", "", "| " + " | ".join(CHECK_COLUMNS) + " |", "|" + " --- |" * 4]
    lines += ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in c["checks"]]
    lines += ["", "## Wear per component (all worlds)", "", "| " + " | ".join(WEAR_COLUMNS) + " |",
              "|" + " --- |" * len(WEAR_COLUMNS)]
    lines += ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in c["wear_rows"]]
    lines += ["", "## Figures", ""]
    for key, p in figures.items():
        lines += [f"![{key}]({p.name})", ""]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_html(case, results: dict, figures: dict[str, Path], path: Path) -> Path | None:
    try:
        from calibration.reporting import Figure, Report, Section, Table, Verdict
    except ImportError:
        return None
    c = report_content(case, results)
    captions = {
        "wear": "Cumulative normal (left) and tangential (right) contact energy per area, impeller and volute "
                "(seed paper Fig. 17).",
        "trajectories": "Particle trajectories coloured by speed (seed paper Fig. 15).",
        "flow": "The prescribed flow: velocity and pressure on the mid-plane, speed on a meridional plane "
                "(seed paper Fig. 16).",
        "force": "Average cumulative contact force per component against time (seed paper Fig. 18).",
        "counts": "Particles per region against time.",
        "wear_maps": "Unrolled wear maps: one blade's pressure and suction sides (leading edge left) and the "
                     "volute's outer wall (tongue at 0 deg).",
        "passage": "Particle positions across the blade passages (rotating frame).",
    }
    verdict = Verdict(met=c["n_reproduced"] == 3, headline=f"{c['n_reproduced']} of the seed paper's 3 findings "
                                                           f"reproduced",
                      details=[f"{t}: {'reproduced' if ok else 'not reproduced'}. {txt}"
                               for t, ok, txt in c["findings"]],
                      numbers=[("wall time", f"{case.timings.get('run_s', 0):.0f} s"),
                               ("particles injected", str(results["particles"]["injected"])),
                               ("Euler head", f"{results['fluid_checks']['euler_head_grid_m']:.2f} m")])
    sections = [
        Section("Set-up", [Table(["item", "value"], c["setup"])] + ([str(case.config["notes"])]
                                                                      if case.config.get("notes") else [])),
        Section("Fluid model checks", [Table(CHECK_COLUMNS, c["checks"])]),
        Section("Wear per component", [Table(WEAR_COLUMNS, c["wear_rows"], caption="all worlds summed")]),
        Section("Figures", [Figure.from_path(p, captions.get(k, k)) for k, p in figures.items()]),
    ]
    nxt = ["Open vtk/*.pvd and wear_*.vtp in ParaView for the time series and per-cell wear.",
           "Run more worlds (run.worlds) or revolutions where the findings rest on few particles."]
    Report(title=f"Slurry-pump wear prototype: {case.config['name']}", verdict=verdict, sections=sections,
           next_steps=nxt, subtitle="CFD-free CFD-DEM analogue of the seed paper's Sec. 4.4").write(path)
    return path


def write_outputs(case, rec, results: dict, out: Path) -> dict[str, Path]:
    """results.json, series.npz, wear surfaces, figures, report.md (+ report.html)."""
    from .run import save_json

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    save_json(out / "results.json", results)
    t, totals = case.recorder.series.as_arrays()
    arrays = {"time": np.asarray(rec.time), "region_counts": np.asarray(rec.region_counts),
              "removed_outlet": np.asarray(rec.removed_outlet), "trajectory_x": np.asarray(rec.traj_x),
              "trajectory_speed": np.asarray(rec.traj_speed), "wear_time": t}
    for fld, per in totals.items():
        for comp, v in per.items():
            arrays[f"{fld}/{comp}"] = v
    np.savez_compressed(out / "series.npz", **arrays)
    paths = {"results": out / "results.json"}
    paths["surfaces"] = write_wear_surfaces(case, out)
    figs = {"wear": figure_wear(case, out), "wear_maps": figure_wear_maps(case, out),
            "trajectories": figure_trajectories(case, rec, out),
            "flow": figure_flow(case, out), "force": figure_force_vs_time(case, out),
            "counts": figure_counts(case, rec, out), "passage": figure_passage(case, rec, out)}
    paths["figures"] = figs
    paths["report_md"] = write_markdown(case, results, figs, out / "report.md")
    html = write_html(case, results, figs, out / "report.html")
    paths["report"] = html or paths["report_md"]
    return paths
