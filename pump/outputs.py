"""Outputs of a pump run: VTK for ParaView, figures (the seed paper's Figs. 15-18), results
files and the report (HTML via ``calibration.reporting`` when present, and Markdown).

VTK: ``vtk/particles.pvd`` (member spheres with body id, radius, velocity, speed, world),
``vtk/impeller.pvd`` and ``vtk/casing.pvd`` (surfaces in their current pose with per-cell
wear fields and component ids), and ``wear_impeller.vtp`` / ``wear_casing.vtp`` at the end (rest
pose; per cell, mean over the worlds: energy_n, energy_t [J] and per area [J/m^2], time-averaged
contact force per area pressure_n, pressure_t [Pa], DNV and Archard depth rates [mm/year],
impacts, region, component, blade zone; :func:`wall_cell_data`).
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from warpdem.io import write_pvd  # the .pvd collections: the engine's writer
from warpdem.json_io import write_json as save_json  # results.json, strict and whole

from .erosion import depth_rate_mm_per_year
from .geometry import COMPONENTS, REGIONS
from .regions import MAX_RELATIVE_HALF_WIDTH, MIN_IMPACTS
from .regions import REGIONS as WEAR_REGIONS

COMP_COLOURS = {"shroud": "tab:green", "blade": "tab:orange", "hub": "tab:blue", "volute": "tab:red",
                "tongue": "tab:purple", "inlet": "tab:gray", "outlet": "tab:brown"}


def wall_cell_data(case, wall: int, world: int | None = None) -> dict[str, np.ndarray]:
    """Per-triangle wear fields of one pump wall, the mean over the worlds (or one ``world``):
    accumulated energies [J] and per area [J/m^2], time-averaged contact force per area [Pa]
    (pressure_n / pressure_t), DNV and Archard depth rates [mm/year], impacts (all worlds when
    ``world`` is None), region / component / blade zone ids (:mod:`pump.wear` for the definitions)."""
    rec = case.recorder
    areas = rec.areas()[wall]
    T = rec.elapsed
    out = {}
    for f in ("energy_n", "energy_t"):
        v = rec.per_triangle(f, world)[wall]
        out[f] = v
        out[f + "_per_area"] = v / areas
    for kind in ("n", "t"):
        out["pressure_" + kind] = rec.per_triangle("impulse_" + kind, world)[wall] / areas / T if T > 0 else 0 * areas
    out["dnv_depth_rate_mm_y"] = depth_rate_mm_per_year(rec.per_triangle("erosion", world)[wall] / rec.dnv.density,
                                                        areas, T)
    out["archard_depth_rate_mm_y"] = depth_rate_mm_per_year(rec.archard_volume(world=world)[wall], areas, T)
    worlds = 1 if world is not None else case.sim.model.num_worlds
    out["impacts"] = rec.per_triangle("impacts", world)[wall] * worlds
    w = case.sim.model.walls[wall]
    out["component"] = np.asarray(w.triangle_labels, dtype=np.int32)
    if rec.regions:
        out["region"] = rec.regions[wall].astype(np.int32)
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
                write_pvd(self.dir / f"{key}.pvd", entries)


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


def converged_triangles(case, results: dict | None, wall: int) -> np.ndarray:
    """(T,) True where a triangle's wear region is converged (:mod:`pump.regions`); all True
    without results or regions."""
    rec = case.recorder
    n = case.sim.model.walls[wall].num_triangles
    regions = (results or {}).get("wear", {}).get("regions", {})
    if not regions or not rec.regions:
        return np.ones(n, dtype=bool)
    ok = np.array([bool(regions.get(name, {}).get("converged", False)) for name in WEAR_REGIONS])
    return ok[rec.regions[wall]]


def _log_values(v: np.ndarray, ok: np.ndarray, lo: float) -> np.ndarray:
    """log10 of v; zero -> below the colour range (under colour), not converged -> NaN (bad colour)."""
    lv = np.where(v > 0, np.log10(np.maximum(v, 1e-300)), lo - 1.0)
    return np.where(ok, lv, np.nan)


GREY_NOTE = (f"silver: region not converged (< {MIN_IMPACTS} impacts or 95 % CI wider than "
             f"{100 * MAX_RELATIVE_HALF_WIDTH:.0f} % of the mean); white: no contact")


def figure_wear(case, out: Path, results: dict | None = None) -> Path:
    """Fig. 17 analogue: normal and tangential contact energy per area (mean over the worlds) on
    the impeller (hub and blades, shroud removed) and the volute (front wall removed), log colour
    scale, triangles of unconverged regions in silver. pyvista off-screen, matplotlib projections
    if that fails."""
    path = out / "wear_energy.png"
    try:
        _figure_wear_pyvista(case, path, results)
    except Exception as exc:  # no OpenGL context: fall back to flat projections
        print(f"pump: pyvista off-screen rendering failed ({exc}); drawing projections with matplotlib")
        _figure_wear_matplotlib(case, path, results)
    return path


def _wear_views(case, results: dict | None = None):
    geo = case.geometry
    imp, cas = geo.impeller, geo.casing
    keep_imp = imp.component != COMPONENTS.index("shroud")
    cen = cas.centroids()
    keep_cas = (cen[:, 2] < geo.z_front - 1e-4) & (cas.component != COMPONENTS.index("inlet"))
    return ((imp, keep_imp, wall_cell_data(case, case.impeller_wall), "impeller (shroud removed)",
             converged_triangles(case, results, case.impeller_wall)),
            (cas, keep_cas, wall_cell_data(case, case.casing_wall), "volute casing (front wall removed)",
             converged_triangles(case, results, case.casing_wall)))


def _figure_wear_pyvista(case, path: Path, results: dict | None = None) -> None:
    import pyvista as pv

    pv.OFF_SCREEN = True
    p = pv.Plotter(shape=(2, 2), off_screen=True, window_size=(1500, 1200))
    for row, (tm, keep, data, title, ok) in enumerate(_wear_views(case, results)):
        for col, f in enumerate(("energy_n_per_area", "energy_t_per_area")):
            p.subplot(row, col)
            faces = tm.faces[keep]
            mesh = _polydata(tm.vertices, faces)
            _, lo, hi = _log_field(data[f][keep])
            kind = "normal" if col == 0 else "tangential"
            label = f"log10 {kind} energy [J/m^2], {title.split()[0]}"
            mesh.cell_data[label] = _log_values(data[f][keep], ok[keep], lo)
            p.add_mesh(mesh, scalars=label, clim=(lo, hi), cmap="inferno", below_color="white", nan_color="silver",
                       show_edges=False, scalar_bar_args={"title": label, "vertical": False})
            p.add_text(f"{title}: {kind} energy (world mean; silver: not converged)", font_size=10)
            p.view_vector((0.35, -0.55, 1.0), viewup=(0, 1, 0))
            p.camera.zoom(1.25)
    p.screenshot(str(path))
    p.close()


def _figure_wear_matplotlib(case, path: Path, results: dict | None = None) -> None:
    """Top views: flat faces (hub, back wall) as coloured triangles, vertical walls (blades,
    spiral, duct) as coloured dots at their triangle centres."""
    import matplotlib
    from matplotlib.collections import PolyCollection

    plt = _plt()
    cmap = matplotlib.colormaps["inferno"].with_extremes(under="white", bad="silver")
    fig, axs = plt.subplots(2, 2, figsize=(12, 11), constrained_layout=True)
    for row, (tm, keep, data, title, ok) in enumerate(_wear_views(case, results)):
        tri3 = tm.vertices[tm.faces]
        nz = np.abs(np.cross(tri3[:, 1] - tri3[:, 0], tri3[:, 2] - tri3[:, 0])[:, 2])
        flat = nz > 0.5 * 2 * tm.areas()
        for col, f in enumerate(("energy_n_per_area", "energy_t_per_area")):
            ax = axs[row, col]
            _, lo, hi = _log_field(data[f])
            vals = _log_values(data[f], ok, lo)
            sel = keep & flat
            pc = PolyCollection(tri3[sel][:, :, :2], array=vals[sel], cmap=cmap, clim=(lo, hi), edgecolors="face",
                                linewidths=0.2)
            ax.add_collection(pc)
            vert = keep & ~flat
            cen = tm.centroids()[vert]
            order = np.argsort(np.nan_to_num(vals[vert], nan=-np.inf))
            ax.scatter(cen[order, 0], cen[order, 1], c=vals[vert][order], cmap=cmap, vmin=lo, vmax=hi, s=6,
                       linewidths=0, plotnonfinite=True)
            ax.autoscale()
            ax.set_aspect("equal")
            ax.set_title(f"{title}\n{'normal' if col == 0 else 'tangential'} energy, log10 J/m^2, world mean "
                         f"(top view; dots: vertical walls)")
            fig.colorbar(pc, ax=ax, shrink=0.8)
    fig.suptitle(GREY_NOTE, fontsize=9)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def figure_wear_maps(case, out: Path, results: dict | None = None) -> Path:
    """Unrolled wear maps: one blade (the mean of the blades) seen on its pressure side and its
    suction side, (r - r1) / (r2 - r1) against z, and the volute's outer (spiral) wall, angle
    from the tongue against z; normal energy per area (top row) and tangential (bottom row), log
    scale, world mean; triangles of unconverged regions in silver; each panel says how many
    impacts (all worlds, whole run) its triangles hold."""
    import matplotlib
    from matplotlib.collections import PolyCollection

    plt = _plt()
    path = out / "wear_maps.png"
    geo, d = case.geometry, case.design
    imp, cas = geo.impeller, geo.casing
    data_i = wall_cell_data(case, case.impeller_wall)
    data_c = wall_cell_data(case, case.casing_wall)
    ok_i = converged_triangles(case, results, case.impeller_wall)
    ok_c = converged_triangles(case, results, case.casing_wall)
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
    blade_imp = data_i["impacts"][blade_sel].reshape(d.blades, per).sum(axis=0)
    spiral_imp = data_c["impacts"][spiral]
    cmap = matplotlib.colormaps["inferno"].with_extremes(under="white", bad="silver")
    fig, axs = plt.subplots(2, 3, figsize=(17, 9), gridspec_kw={"width_ratios": [1, 1, 2.2]},
                            constrained_layout=True)
    for row, f in enumerate(("energy_n_per_area", "energy_t_per_area")):
        blade_vals = data_i[f][blade_sel].reshape(d.blades, per).sum(axis=0) / d.blades
        spiral_vals = data_c[f][spiral]
        _, lo, hi = _log_field(np.concatenate([blade_vals, spiral_vals]))
        panels = (
            (axs[row, 0], poly_b, blade_vals, blade_imp, ok_i[first], (zone == 1) | (zone == 2) | (zone == 4),
             "blade pressure side"),
            (axs[row, 1], poly_b, blade_vals, blade_imp, ok_i[first], (zone == 1) | (zone == 3) | (zone == 4),
             "blade suction side"),
            (axs[row, 2], poly_s, spiral_vals, spiral_imp, ok_c[spiral], np.ones(len(spiral_vals), bool),
             "volute outer wall (unrolled)"),
        )
        pc = None
        for ax, poly, vals, impacts, ok, sel, title in panels:
            pc = PolyCollection(poly[sel], array=_log_values(vals[sel], ok[sel], lo), cmap=cmap, clim=(lo, hi),
                                edgecolors="none")
            ax.add_collection(pc)
            ax.autoscale()
            kind = "normal" if row == 0 else "tangential"
            where = f" on {d.blades} blades" if ax is not axs[row, 2] else ""
            ax.set_title(f"{title}: {impacts[sel].sum():.0f} impacts{where}\n{kind} energy, log10 J/m^2", fontsize=10)
            ax.set_ylabel("z [mm]")
            ax.set_xlabel("(r - r1) / (r2 - r1): leading edge left" if ax is not axs[row, 2]
                          else "angle from the tongue [deg] (throat at 360)")
        fig.colorbar(pc, ax=axs[row, :].tolist(), shrink=0.9, label="log10 J/m^2")
    fig.suptitle(f"Mean over {case.sim.model.num_worlds} world(s) (blades: mean of the {d.blades}); impacts: all "
                 f"worlds, whole run. " + GREY_NOTE, fontsize=10)
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
    """Fig. 18, honestly: the accumulated normal and tangential contact impulse J = sum |F| dt
    per component against time (mean over the worlds, band: +- one standard error across worlds),
    as a total [N s] (top) and per unit area [N s/m^2] (bottom). The slope of the top row is the
    time-averaged contact force [N]. EDEM's "average cumulative contact force" plotted in the
    paper is J / (dt n_elements): the same curves rescaled by 1 / (dt n_elements), so it grows
    when dt or the elements shrink."""
    plt = _plt()
    path = out / "force_vs_time.png"
    rec = case.recorder
    series = rec.series["component"]
    names, idx = rec.groups("component")
    area = np.bincount(idx, weights=np.concatenate([rec.areas()[w] for w in rec.walls]), minlength=len(names))
    t = np.asarray(series.time)
    groups = {c: [names.index(c)] for c in ("shroud", "blade", "hub") if c in names}
    cas = [names.index(c) for c in ("volute", "tongue") if c in names]
    if cas:
        groups["casing (volute + tongue)"] = cas
    colours = dict(COMP_COLOURS, **{"casing (volute + tongue)": "tab:red"})
    fig, axs = plt.subplots(2, 2, figsize=(13, 8.5), sharex=True)
    for col, (fld, kind) in enumerate((("impulse_n", "normal"), ("impulse_t", "tangential"))):
        if not t.size:
            break
        a = series.array(fld)  # (k, worlds, G)
        for label, ids in groups.items():
            v = a[:, :, ids].sum(axis=2)  # (k, worlds)
            mean = v.mean(axis=1)
            se = v.std(axis=1, ddof=1) / math.sqrt(v.shape[1]) if v.shape[1] > 1 else np.zeros_like(mean)
            for row, scale, unit in ((0, 1.0, "N s"), (1, 1.0 / area[ids].sum(), "N s/m^2")):
                ax = axs[row, col]
                ax.plot(t, mean * scale, label=label, color=colours.get(label), lw=1.8)
                ax.fill_between(t, (mean - se) * scale, (mean + se) * scale, color=colours.get(label), alpha=0.2, lw=0)
                ax.set_ylabel(f"accumulated {kind} impulse [{unit}]")
        axs[0, col].set_title(f"{kind}: J = sum |F| dt per component (slope: time-averaged force)")
        axs[1, col].set_title(f"{kind}: per unit area")
    for ax in axs.ravel():
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    for ax in axs[1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(f"Seed paper Fig. 18 without the time-step and mesh factors: mean of "
                 f"{case.sim.model.num_worlds} world(s), band +- 1 standard error across worlds", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def figure_wear_regions(case, results: dict, out: Path) -> Path:
    """Wear per region with 95 % intervals (samples: worlds x revolutions after the spin-up):
    DNV-RP-O501 erosion depth rate [mm/year] and normal contact energy per area and time [W/m^2];
    unconverged regions are drawn grey and hatched (not ranked), each bar labelled with its impacts."""
    plt = _plt()
    path = out / "wear_regions.png"
    regs = results["wear"]["regions"]
    names = [n for n in regs if regs[n]["area_m2"] > 0]
    fig, axs = plt.subplots(1, 2, figsize=(15, 0.34 * len(names) + 2.2), sharey=True)
    y = np.arange(len(names))[::-1]
    impeller = {"blade_leading_edge", "blade_pressure_side", "blade_suction_side", "blade_trailing_edge",
                "blade_unzoned", "hub", "shroud"}
    for ax, metric, label in ((axs[0], "dnv_depth_rate", "DNV-RP-O501 erosion depth rate [mm/year]"),
                              (axs[1], "power_n_per_area", "normal contact energy per area and time [W/m^2]")):
        vals = np.array([regs[n].get(metric, {}).get("mean") or 0.0 for n in names])
        lo = np.array([regs[n].get(metric, {}).get("ci95_low") for n in names], dtype=float)
        hi = np.array([regs[n].get(metric, {}).get("ci95_high") for n in names], dtype=float)
        conv = np.array([regs[n]["converged"] for n in names])
        pos = vals[vals > 0]
        floor = float(pos.min()) * 0.3 if pos.size else 1e-3
        colour = ["tab:orange" if n in impeller or n.startswith("blade") else "tab:red" for n in names]
        for k in range(len(names)):
            ax.barh(y[k], max(vals[k], floor), color=colour[k] if conv[k] else "lightgrey",
                    hatch=None if conv[k] else "//", edgecolor="0.4", lw=0.5)
            if conv[k] and np.isfinite(lo[k]) and np.isfinite(hi[k]):
                ax.plot([max(lo[k], floor), hi[k]], [y[k], y[k]], color="k", lw=1.2)
            right = max(vals[k], floor, hi[k] if conv[k] and np.isfinite(hi[k]) else 0.0)
            ax.text(right * 1.2, y[k], f"{regs[names[k]]['impacts']:.0f} imp."
                    + ("" if conv[k] else ", not converged"), va="center", fontsize=7)
        ax.set_xscale("log")
        top = float(np.nanmax(np.where(np.isfinite(hi), hi, vals))) if vals.size else 0.0
        ax.set_xlim(floor, max(top, 10 * floor) * 8)
        ax.set_xlabel(label)
        ax.grid(alpha=0.3, axis="x")
    axs[0].set_yticks(y)
    axs[0].set_yticklabels(names, fontsize=8)
    s = results["wear"]["solids"]
    w = results["wear"]["window"]
    fig.suptitle(f"Wear per region at {100 * s['volume_fraction']:.1f} % solids by volume "
                 f"({100 * s['mass_fraction']:.1f} % by mass): mean and 95 % CI of {w['samples']} samples "
                 f"({w['worlds']} world(s) x {w['blocks']} revolution(s) after {w['spin_up_revolutions']:g} of spin-up); "
                 f"orange impeller, red casing, grey hatched: not converged", fontsize=9)
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


def _est(e: dict | None, unit: str = "", digits: int = 3) -> str:
    """'mean ± half-width unit' of an estimate dict (Estimate.as_dict); one sample: no interval."""
    if not e or e.get("mean") is None:
        return "-"
    hw = e.get("half_width")
    u = f" {unit}" if unit else ""
    if hw is None or not math.isfinite(hw):
        return f"{_fmt(e['mean'], digits)}{u} (no interval: {e.get('samples', 0)} sample)"
    return f"{_fmt(e['mean'], digits)} ± {_fmt(hw, 2)}{u}"


FINDING_TITLES = {
    ("volute_wears_most", "total"): ("The volute (casing) wears most", "extensive total: time-averaged tangential "
                                     "contact force of the component"),
    ("volute_wears_most", "per_element"): ("The volute (casing) wears most", "the paper's own metric: EDEM "
                                           "'average cumulative contact force' per element (Fig. 18)"),
    ("volute_wears_most", "per_area"): ("The volute (casing) wears most", "per unit area: time-averaged tangential "
                                        "contact force per area"),
    ("volute_wears_most", "per_area_wetted_wall"): ("The volute (casing) wears most", "per unit area of the wetted "
                                                    "wall only: spiral wall + cutwater vs blade (all zones), hub, "
                                                    "shroud"),
    ("leading_edge_highest_normal_energy", "per_area"): ("The blade head (leading edge) has the highest normal "
                                                         "energy", "normal contact energy per area and time"),
}
FINDING_GROUPS = {"volute_wears_most", "leading_edge_highest_normal_energy"}
GROUP_LABELS = {"casing": "casing (volute + tongue)", "volute_wall_and_cutwater": "spiral wall + cutwater",
                "blade_leading_edge": "blade leading edge", "blade_all_zones": "blade (all zones)"}


def _finding_rows(results: dict) -> list[list]:
    rows = []
    f = results["findings"]
    for key, readings in f.items():
        if key not in FINDING_GROUPS:
            continue
        for reading, t in readings.items():
            title, what = FINDING_TITLES[(key, reading)]
            unit = t.get("unit", "")
            diffs = t.get("differences", {})
            crit = min(diffs, key=lambda r: diffs[r]["mean"]) if diffs else None
            rival = f"{GROUP_LABELS.get(crit, crit)}: {_est(t['rivals'][crit], unit)}" if crit else "-"
            diff = _est(diffs[crit], unit) if crit else "-"
            need = t.get("samples_needed")
            need_txt = "decided" if need is None else ("no estimate" if need < 0 else f"about {need}")
            group = GROUP_LABELS.get(t.get("group"), t.get("group"))
            rows.append([title, what, f"{group}: {_est(t.get('value'), unit)}", rival, diff,
                         t["verdict"], need_txt])
    return rows


FINDING_COLUMNS = ["finding (seed paper)", "reading (metric)", "paper's group", "closest rival",
                   "difference (paired, 95 % CI)", "verdict", "samples (world x revolution) to decide"]
REGION_METRICS = (("pressure_n", "Pa"), ("pressure_t", "Pa"), ("power_n_per_area", "W/m^2"),
                  ("dnv_depth_rate", "mm/year"), ("archard_depth_rate", "mm/year"))
REGION_COLUMNS = ["region", "area [m^2]", "impacts", "converged", "normal force / area [Pa]",
                  "tangential force / area [Pa]", "normal energy rate [W/m^2]", "DNV erosion [mm/year]",
                  "Archard sliding [mm/year]"]
COMPONENT_COLUMNS = ["component", "triangles", "area [m^2]", "impacts", "normal force [N]", "tangential force [N]",
                     "tangential force / area [Pa]", "EDEM cum. force per element, tangential [N] (Fig. 18; dt-, "
                     "mesh-dependent)", "DNV erosion [mm/year]"]
CHECK_COLUMNS = ["check", "prototype", "target", "deviation"]


def _paper_needs(results: dict) -> str:
    """What the undecided findings would need at the paper's conditions (1 % solids, 15 revolutions)."""
    w = results["wear"]
    phi = w["solids"]["volume_fraction"]
    needs = [t.get("samples_needed") for r in results["findings"].values() if isinstance(r, dict)
             for t in r.values() if isinstance(t, dict) and "samples_needed" in t]
    needs = [n for n in needs if n is not None]
    import yaml

    from .config_schema import load_config

    # the paper's config as data (its device, cuda, need not exist where this report is written)
    raw = yaml.safe_load((Path(__file__).parent / "configs" / "paper_pump.yaml").read_text())
    paper = load_config({**raw, "device": "cpu"})
    paper_phi = float(paper["particles"]["volume_fraction"])
    paper_revs = float(paper["run"]["revolutions"])
    paper_blocks = max(1, int((paper_revs - float(paper["wear"]["spin_up_revolutions"]))
                              / float(paper["wear"]["block_revolutions"])))
    scale, fewer, more = _loading_scale(phi, paper_phi)
    if not needs:
        worlds = max(1, math.ceil(w["window"]["samples"] * scale / paper_blocks))
        return (f"Every re-tested reading is decided at this scale ({w['window']['samples']} samples at "
                f"{100 * phi:.1f} % solids by volume). The paper's conditions (paper_pump.yaml: calibrated clumps, "
                f"{100 * paper_phi:g} % solids, {paper_revs:g} revolutions at dt = {paper['run']['dt']:.3g} s) {fewer}, "
                f"so intervals as narrow need {more}: at least {worlds} worlds of {paper_revs:g} "
                f"revolutions ({paper_blocks} after the spin-up), a GPU run; the tangential rule and the clump shapes "
                f"may also change the outcome (issue 34), which only that run can tell.")
    if any(n < 0 for n in needs):
        return ("Some readings rest on a single sample (one world, one revolution after the spin-up) and have no "
                "interval: run more revolutions or worlds (run.worlds) before reading them.")
    n = max(needs)
    worlds = max(1, math.ceil(n * scale / paper_blocks))
    return (f"The undecided readings need about {n} samples (world x revolution) at this run's loading "
            f"({100 * phi:.1f} % solids by volume). The paper's conditions ({100 * paper_phi:g} % solids of calibrated "
            f"clumps) {fewer}, so they need {more}: at least {worlds} worlds of the paper's "
            f"{paper_revs:g} revolutions ({paper_blocks} after the spin-up), i.e. a GPU run of paper_pump.yaml with "
            f"run.worlds >= {worlds}; the per-element reading stays mesh-dependent whatever the sample size.")


def _loading_scale(phi: float, paper_phi: float) -> tuple[float, str, str]:
    """Factor on the samples the paper's conditions need against this run's, how their particle
    rates compare and what that asks of the samples, from the solids loadings (by volume). The
    variance per sample grows about as 1 / (particles per revolution), and the solids ratio is a
    lower bound on the particle-count ratio when the paper's particles (clumps up to 25 mm) are the
    larger. Within a factor 1.5 of the paper's loading the run counts as at it (factor 1, said
    plainly); more dilute than the paper, the factor stays 1 (at most as many samples)."""
    ratio = phi / paper_phi
    if ratio >= 1.5:
        return (ratio, f"pass at least {_times(ratio)} fewer particles per revolution than this run",
                f"at least {_times(ratio)} the samples")
    if ratio > 1.0 / 1.5:
        return 1.0, f"are at about this run's solids loading ({100 * phi:.2g} %)", "about as many samples as here"
    return (1.0, f"are at a higher solids loading than this run ({100 * paper_phi:g} % against {100 * phi:.2g} %)",
            "at most about as many samples as here")


def _times(ratio: float) -> str:
    """'4x', '2.5x', '12x'."""
    return (f"{ratio:.0f}" if ratio >= 10 else f"{ratio:.1f}".rstrip("0").rstrip(".")) + "x"


def _side_room_text(side: dict | None) -> str:
    """The side rooms' clearance, flow and occupancy, for the report's set-up table."""
    if not side:
        return "-"
    g = 1e3 * side["side_gap_m"]
    return (f"side clearance {g:g} mm between each disc and its liner (particles smaller than {g:g} mm can enter; "
            f"the eye sealed to {1e3 * side['eye_seal_clearance_m']:g} mm), fluid core turning at "
            f"k = {side['core_rotation_factor']:g} of the impeller speed (Daily & Nece 1960; Gulich); "
            f"{side['mean_particles_per_world']:.2g} particles per world in the side rooms on average, at most "
            f"{side['max_particles_all_worlds']} (all worlds); wear on the suction and back liners: regions "
            f"suction_liner, back_liner")


def _drag_text(drag: dict | None) -> str:
    """The drag law and where it reads the fluid velocity, for the report's set-up table."""
    if not drag:
        return "-"
    where = {"centre": "at the particle's centre (point particle; no finite-size correction)",
             "surface_average": "averaged over the particle's sphere (Faxen: u + a^2/6 lap u)",
             "volume_average": "averaged over the particle's volume (u + a^2/10 lap u)"}[drag["velocity"]]
    law = {"di_felice": "Di Felice (1994)", "schiller_naumann": "Schiller-Naumann"}.get(drag["law"], drag["law"])
    return f"{law}, fluid velocity {where}; no wall (confinement) correction for particles comparable to the passage"


def report_content(case, results: dict) -> dict:
    """Plain content shared by the HTML and Markdown reports: verdict, numbers, tables, text."""
    d = case.design
    cfg = case.config
    f = results["findings"]
    fc = results["fluid_checks"]
    w = results["wear"]
    p = results["particles"]
    sol, win = w["solids"], w["window"]
    finding_rows = _finding_rows(results)
    f3 = f["particles_enter_along_pressure_side"]
    headline_parts = []
    for key, readings in f.items():
        if key in FINDING_GROUPS:
            name = FINDING_TITLES[(key, next(iter(readings)))][0]
            headline_parts.append(f"{name}: " + "; ".join(f"{r.replace('_', ' ')} {t['verdict']}"
                                                          for r, t in readings.items()))
    headline = " | ".join(headline_parts)
    life = w["wear_life"]
    bm = life.get("blade_mean", {})
    numbers = [
        ("solids", f"{100 * sol['volume_fraction']:.2g} % by volume ({100 * sol['mass_fraction']:.2g} % by mass)"),
        ("blade erosion (DNV, mean)", _est(bm.get("depth_rate_mm_y"), "mm/year")),
        ("8 mm blade life", f"{bm['life_h']:.0f} h" if bm.get("life_h") is not None and math.isfinite(bm["life_h"])
         else "-"),
        ("samples", f"{win['samples']} ({win['worlds']} world(s) x {win['blocks']} revolution(s))"),
        ("wall time", f"{case.timings.get('run_s', 0):.0f} s"),
    ]
    details = [f"{r[0]} — {r[1]}: {r[5]} ({r[2]}; closest rival {r[3]}; difference {r[4]})." for r in finding_rows]
    details.append(f"Particles enter along the blades' pressure side: {f3['verdict']} "
                   f"({_fmt(f3['pressure_half_fraction_entry'])} of {f3['samples_at_entry']} entry samples in the "
                   f"pressure half), but {f3['caveat']}.")
    text_f3 = (f"fraction of particle samples in the pressure half of the passage: "
               f"{_fmt(f3['pressure_half_fraction_entry'])} at entry (first 30 % of the blade, {f3['samples_at_entry']} "
               f"samples), {_fmt(f3['pressure_half_fraction_passage'])} over the whole passage "
               f"({f3['samples_in_passage']} samples); blade contact energy pressure side "
               f"{_fmt(f3['pressure_side_contact_energy_J'])} J vs suction side "
               f"{_fmt(f3['suction_side_contact_energy_J'])} J (world mean). It {f3['caveat']}.")
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
    region_rows = []
    for n, r in w["regions"].items():
        ok = r["converged"]
        region_rows.append([n, r["area_m2"], int(round(r["impacts"])), "yes" if ok else "not converged"]
                           + [_est(r.get(m), "") for m, _ in REGION_METRICS])
    comp_rows = []
    for n, r in w["components"].items():
        if n in ("inlet", "outlet"):
            continue
        comp_rows.append([n, r["triangles"], r["area_m2"], int(round(r["impacts"])), _est(r.get("force_n")),
                          _est(r.get("force_t")),
                          _est(r.get("pressure_t")), _est(r.get("edem_cumulative_force_t")),
                          _est(r.get("dnv_depth_rate"))])
    definitions = [[k, v["unit"], v["definition"]] for k, v in w["definitions"].items()]
    em = w["erosion_model"]
    erosion_rows = [
        ["DNV-RP-O501 impact erosion", f"E_m = K U^n F(alpha), K = {em['dnv']['K']:.3g} (m/s)^-n, n = {em['dnv']['n']:g}, "
                                       f"rho_t = {em['dnv']['target_density']:g} kg/m^3; F: eq. 3.3, ductile",
         em["dnv"]["source"]],
        ["Archard sliding wear", f"V = (K_a / H) F_n s, K_a = {em['archard']['wear_coefficient']:.3g}, "
                                 f"H = {em['archard']['hardness_Pa']:.3g} Pa", em["archard"]["source"]],
    ]
    life_txt = [f"Wear-life check (order of magnitude; {life['sources']}): published wear lives lie between "
                f"{life['band_h'][0]:g} h and {life['band_h'][1]:.3g} h."]
    for key, label in (("blade_mean", "the blade's mean DNV rate"), ("fastest_converged_region", "the fastest "
                                                                                                   "converged region")):
        x = life.get(key)
        if x:
            where = f" ({x['region']})" if "region" in x else ""
            life_txt.append(f"At {label}{where}, {_est(x['depth_rate_mm_y'], 'mm/year')}, the {life['thickness_mm']:g} mm "
                            f"blade lasts {x['life_h']:.0f} h of continuous operation: "
                            f"{'inside' if x['plausible'] else 'OUTSIDE'} the published band.")
    life_txt.append(f"Rates are at {100 * sol['volume_fraction']:.2g} % solids by volume "
                    f"({100 * sol['mass_fraction']:.2g} % by mass, particles of {sol['particle_density_kg_m3']:g} kg/m^3) "
                    f"and scale about linearly with the loading in the dilute limit. DNV-RP-O501 is validated for sand of "
                    f"0.02-5 mm; these particles are larger, so the rates are an order-of-magnitude estimate. DNV (impact) "
                    f"and Archard (sliding) are separate estimates, not to be added: the DNV constants already include the "
                    f"cutting during an impact, and E_t counts the sliding within impacts too.")
    method = (f"Every metric is a mean over the {win['worlds']} world(s) (independent replicates). Intervals: the run "
              f"after {win['spin_up_revolutions']:g} revolution(s) of spin-up is cut into blocks of "
              f"{win['block_revolutions']:g} revolution; each (world, block) is one sample ({win['samples']} samples, "
              f"{_fmt(win['from_s'])} s to {_fmt(win['to_s'])} s); 95 % CI mean ± t s / sqrt(n), treating the blocks "
              f"as independent (consecutive revolutions of one world are mildly correlated, so with few worlds the "
              f"intervals are somewhat optimistic). A region is ranked only "
              f"with at least {MIN_IMPACTS} impacts and a CI half-width at most {100 * MAX_RELATIVE_HALF_WIDTH:.0f} % of "
              f"its mean; otherwise it is marked 'not converged' (grey in the figures). A finding holds when every "
              f"paired difference (same world and block) to its rivals has a CI above zero (reproduced), fails when "
              f"one lies below zero (not reproduced), and is 'cannot tell' otherwise.")
    run = cfg["run"]
    setup = [
        ["duty", f"{d.flow_rate_m3h:g} m^3/h at {d.speed_rpm:g} rpm ({d.inlet_velocity:.2f} m/s in the "
                 f"{d.inlet_diameter * 1e3:g} mm suction pipe)"],
        ["design head", f"{d.head:g} m (chosen; the paper gives none): n_q = {d.n_q:.1f}, Gulich psi_opt = "
                        f"{d.psi:.3f}, d2 = {d.d2 * 1e3:.1f} mm, u2 = {d.u2:.2f} m/s"],
        ["impeller", f"z = {d.blades}, b2 = {d.b2 * 1e3:g} mm, r1 = {d.r1 * 1e3:g} mm, beta1B = {d.beta1_deg:g} deg "
                     f"(incidence {d.incidence_deg:.1f} deg), beta2B = {d.beta2_blade_deg:.1f} deg (solved), "
                     f"Wiesner slip {d.slip_factor:.3f}, blades {d.blade_thickness * 1e3:g} mm thick"],
        ["volute", f"r3 = {d.r3 * 1e3:.1f} mm, width {d.b3 * 1e3:g} mm, throat {d.throat_height * 1e3:g} mm, "
                   f"K_v / K_2 = {d.k_volute / d.k_impeller:.2f} (mixing loss {d.volute_loss_head:.1f} m)"],
        ["side rooms", _side_room_text(results.get("side_rooms"))],
        ["drag", _drag_text(results.get("drag"))],
        ["particles", f"{case.material.name}, {p['rate_per_s_per_world']:.1f}/s per world "
                      f"({100 * sol['volume_fraction']:.2g} % solids by volume), {p['injected']} injected in "
                      f"{p['worlds']} world(s), {p['left_outlet']} left through the outlet, {p['lost']} lost"],
        ["impacts", f"largest normal impact speed {p['max_normal_impact_speed_m_s']:.1f} m/s: Hertz overlap "
                    f"{100 * p['hertz_overlap_at_max_impact_fraction_of_radius']:.0f} % of a mean particle's radius "
                    f"(particle E = {case.material.particle.youngs_modulus:.3g} Pa)"],
        ["time step", f"{case.sim.dt:.3g} s ({case.timings.get('steps', 0)} steps, {run['revolutions']:g} revolutions "
                      f"of {d.revolution_time * 1e3:.1f} ms)"],
        ["wall time", f"{case.timings.get('run_s', 0):.1f} s on {cfg['device']} "
                      f"(+ {case.timings.get('build_grid_s', 0) + case.timings.get('build_model_s', 0):.1f} s set-up)"],
    ]
    return {"headline": headline, "numbers": numbers, "details": details, "finding_rows": finding_rows,
            "finding3": text_f3, "paper_needs": _paper_needs(results), "method": method, "checks": checks,
            "region_rows": region_rows, "component_rows": comp_rows, "definitions": definitions,
            "erosion_rows": erosion_rows, "life": life_txt, "setup": setup}


CAPTIONS = {
    "wear_regions": "Wear per region with 95 % intervals: DNV erosion depth rate and normal contact energy rate per "
                    "area; grey hatched bars are not converged and not ranked; each bar says how many impacts it holds.",
    "force": "Seed paper Fig. 18 without its time-step and mesh factors: accumulated contact impulse per component "
             "(slope = time-averaged contact force) and per unit area, mean over the worlds.",
    "wear": "Normal (left) and tangential (right) contact energy per area, mean over the worlds, impeller and volute "
            "(seed paper Fig. 17); silver: region not converged.",
    "wear_maps": "Unrolled wear maps: one blade's pressure and suction sides (leading edge left; the blades' mean) and "
                 "the volute's outer wall (tongue at 0 deg); each panel gives its impacts; silver: region not converged.",
    "trajectories": "Particle trajectories coloured by speed (seed paper Fig. 15).",
    "flow": "The prescribed flow: velocity and pressure on the mid-plane, speed on a meridional plane (seed paper "
            "Fig. 16).",
    "counts": "Particles per region against time.",
    "passage": "Particle positions across the blade passages (rotating frame).",
}


def _md_table(columns: list, rows: list) -> list[str]:
    return (["| " + " | ".join(columns) + " |", "|" + " --- |" * len(columns)]
            + ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in rows])


def write_markdown(case, results: dict, figures: dict[str, Path], path: Path) -> Path:
    """report.md: verdict, numbers, tables, then the figures."""
    c = report_content(case, results)
    lines = [f"# Slurry-pump wear prototype: {case.config['name']}", "",
             f"**Verdict (the seed paper's wear findings on its own metrics, with 95 % intervals):** {c['headline']}", ""]
    lines += [f"- {t}" for t in c["details"]]
    lines += ["", "**Numbers:** " + "; ".join(f"{a}: {b}" for a, b in c["numbers"]) + ".", "",
              "## Findings re-tested", ""] + _md_table(FINDING_COLUMNS, c["finding_rows"])
    lines += ["", c["paper_needs"], "", f"Particles along the pressure side: {c['finding3']}", "", c["method"], "",
              "## Wear per region (mean over worlds, 95 % CI)", ""] + _md_table(REGION_COLUMNS, c["region_rows"])
    lines += ["", "## Wear per component", ""] + _md_table(COMPONENT_COLUMNS, c["component_rows"])
    lines += ["", "## Erosion constants and wear-life check", ""] + _md_table(["model", "law and constants", "source"],
                                                                               c["erosion_rows"])
    lines += [""] + c["life"]
    lines += ["", "## Metric definitions", ""] + _md_table(["metric", "unit", "definition"], c["definitions"])
    lines += ["", "## Set-up", "", "| item | value |", "| --- | --- |"] + [f"| {a} | {b} |" for a, b in c["setup"]]
    if case.config.get("notes"):
        lines += ["", str(case.config["notes"]).strip()]
    lines += ["", "## Fluid model checks", ""] + _md_table(CHECK_COLUMNS, c["checks"])
    lines += ["", "## Figures", ""]
    for key, p in figures.items():
        lines += [f"![{key}]({p.name})", "", f"*{CAPTIONS.get(key, key)}*", ""]
    from warpdem.config_io import write_atomic

    write_atomic(path, "\n".join(lines) + "\n")
    return path


def write_html(case, results: dict, figures: dict[str, Path], path: Path) -> Path | None:
    """report.html (calibration.reporting): verdict and numbers, tables, figures."""
    try:
        from calibration.reporting import Cell, Figure, Report, Section, Table, Verdict
    except ImportError:
        return None
    c = report_content(case, results)
    tone = {"reproduced": "good", "not reproduced": "bad", "cannot tell": "warn"}
    finding_rows = [row[:5] + [Cell(row[5], tone.get(row[5], ""))] + row[6:] for row in c["finding_rows"]]
    region_rows = [[Cell(v, "" if row[3] == "yes" else "warn") if k in (0, 3) else
                    (v if row[3] == "yes" else Cell(v, "warn")) for k, v in enumerate(row)] for row in c["region_rows"]]
    verdict = Verdict(met=None, headline=c["headline"], details=c["details"], numbers=c["numbers"])
    sections = [
        Section("Findings re-tested on the paper's own metrics", [Table(FINDING_COLUMNS, finding_rows),
                                                                   c["paper_needs"],
                                                                   "Particles along the pressure side: " + c["finding3"],
                                                                   c["method"]]),
        Section("Wear per region", [Table(REGION_COLUMNS, region_rows, caption="mean over the worlds ± 95 % CI; "
                                                                                 "amber: not converged, not ranked")]),
        Section("Wear per component", [Table(COMPONENT_COLUMNS, c["component_rows"],
                                             caption="mean over the worlds ± 95 % CI")]),
        Section("Erosion constants and wear-life check", [Table(["model", "law and constants", "source"],
                                                                c["erosion_rows"])] + c["life"]),
        Section("Metric definitions", [Table(["metric", "unit", "definition"], c["definitions"])]),
        Section("Set-up", [Table(["item", "value"], c["setup"])] + ([str(case.config["notes"])]
                                                                      if case.config.get("notes") else [])),
        Section("Fluid model checks", [Table(CHECK_COLUMNS, c["checks"])]),
        Section("Figures", [Figure.from_path(p, CAPTIONS.get(k, k)) for k, p in figures.items()]),
    ]
    nxt = ["Open vtk/*.pvd and wear_*.vtp in ParaView for the time series and per-cell wear (pressure_n, "
           "dnv_depth_rate_mm_y, region).",
           "Regions marked 'not converged' and findings marked 'cannot tell' need more worlds (run.worlds) or "
           "revolutions: " + c["paper_needs"]]
    Report(title=f"Slurry-pump wear prototype: {case.config['name']}", verdict=verdict, sections=sections,
           next_steps=nxt, subtitle="CFD-free CFD-DEM analogue of the seed paper's Sec. 4.4").write(path)
    return path


def write_outputs(case, rec, results: dict, out: Path) -> dict[str, Path]:
    """results.json, series.npz, wear surfaces, figures, report.md (+ report.html)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    save_json(out / "results.json", results)
    arrays = {"time": np.asarray(rec.time), "region_counts": np.asarray(rec.region_counts),
              "removed_outlet": np.asarray(rec.removed_outlet), "trajectory_x": np.asarray(rec.traj_x),
              "trajectory_speed": np.asarray(rec.traj_speed)}
    # wear snapshots per group kind: time (k,) and per base field (k, worlds, groups), group names
    for kind, series in case.recorder.series.items():
        if not series.time:
            continue
        arrays[f"wear_{kind}/time"] = np.asarray(series.time)
        arrays[f"wear_{kind}/names"] = np.asarray(case.recorder.groups(kind)[0])
        for fld in series.totals:
            arrays[f"wear_{kind}/{fld}"] = series.array(fld)
    np.savez_compressed(out / "series.npz", **arrays)
    paths = {"results": out / "results.json"}
    paths["surfaces"] = write_wear_surfaces(case, out)
    figs = {"wear_regions": figure_wear_regions(case, results, out), "force": figure_force_vs_time(case, out),
            "wear": figure_wear(case, out, results), "wear_maps": figure_wear_maps(case, out, results),
            "trajectories": figure_trajectories(case, rec, out),
            "flow": figure_flow(case, out), "counts": figure_counts(case, rec, out),
            "passage": figure_passage(case, rec, out)}
    paths["figures"] = figs
    paths["report_md"] = write_markdown(case, results, figs, out / "report.md")
    html = write_html(case, results, figs, out / "report.html")
    paths["report"] = html or paths["report_md"]
    return paths
