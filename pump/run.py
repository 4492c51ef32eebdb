"""Run the slurry-pump wear prototype from a YAML config: ``pump_main([CONFIG, ...])``.

    warpdem pump pump/configs/quick_pump.yaml            # CPU, minutes
    warpdem pump pump/configs/paper_pump.yaml            # GPU, the seed paper's conditions

Pipeline: :class:`~pump.design.PumpDesign` -> meshes (:mod:`pump.geometry`) -> analytic flow
sampled on a grid (:mod:`pump.flow`) -> DEM model with the rotating impeller, the static
casing, reserve particles (:mod:`pump.inlet`), fluid forces (:mod:`pump.coupling`) and an
impact recorder (:mod:`pump.wear`) -> run for N revolutions with injection/removal between
chunks -> ``results.json``, ``series.npz``, VTK (:mod:`pump.outputs`), figures and a report.

Config keys (SI units; every section optional except what a case needs):

    name, device (cpu | cuda), output (folder), seed
    design: PumpDesign fields (flow_rate_m3h, speed_rpm, head, inlet_length, ...)
    geometry: {resolution: 1.0, meshes: {component: path}, mesh_scale: 1.0}
    fluid: {density, viscosity, grid_spacing, drag: di_felice|schiller_naumann, added_mass,
            pressure_gradient, buoyancy, voidage_cell}
    coupling: {two_way: false (one-way, default) | true (the particles' drag corrects the fluid
               velocity per coarse cell, pump.coupling), relaxation: 1.0 (factor on |u0| / cell)}
    particles: {material: (calibration.materials.BulkMaterial config), volume_fraction | rate,
                inject_from, inject_until}
    contact: {rolling: none|epsd|cdt, <contact parameter>: value, ...}
    wall: {youngs_modulus, poisson_ratio, density}
    run: {revolutions, dt, worlds, update_every, record_every, vtk_every, max_contacts,
          steps_per_graph}
    wear: {archard_k, hardness, finnie_k}
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from warpdem.errors import ConfigError, WarpDEMError

from .design import PumpDesign
from .geometry import BLADE_ZONES, COMPONENTS, REGIONS, PumpGeometry, blade_camber, build_pump, passage_clearances

SECTIONS = {
    "name": None, "device": None, "output": None, "seed": None, "design": None, "geometry": None, "fluid": None,
    "coupling": None, "particles": None, "contact": None, "wall": None, "run": None, "wear": None, "gravity": None, "notes": None,
}
DEFAULTS = {
    "geometry": {"resolution": 1.0, "meshes": {}, "mesh_scale": 1.0},
    "fluid": {"density": 998.2, "viscosity": 1.002e-3, "grid_spacing": 0.003, "drag": "di_felice",
              "added_mass": 0.5, "pressure_gradient": 1.0, "buoyancy": 1.0, "voidage_cell": 0.05},
    "coupling": {"two_way": False, "relaxation": 1.0},
    "particles": {"material": {"type": "spheres", "diameter": [0.010, 0.025]}, "volume_fraction": 0.01,
                  "rate": None, "inject_from": 0.0, "inject_until": None},
    # seed paper Sec. 4.2 optimum (friction) and Table 6 (restitution 0.6)
    "contact": {"rolling": "epsd", "mu_s_pp": 0.323, "mu_r_pp": 0.061, "mu_s_pw": 0.316, "mu_r_pw": 0.441,
                "restitution_pp": 0.6, "restitution_pw": 0.6},
    "wall": {"youngs_modulus": 2.0e11, "poisson_ratio": 0.3, "density": 7850.0},
    "run": {"revolutions": 15.0, "dt": 1.0e-5, "worlds": 1, "update_every": 5.0e-4, "record_every": 2.0e-3,
            "vtk_every": 0.02, "max_contacts": 16, "steps_per_graph": 50, "trajectory_world": 0},
    "wear": {"archard_k": 1.0e-4, "hardness": 2.0e9, "finnie_k": 5.0e-10},
}


def load_config(path_or_dict: str | Path | dict) -> dict:
    """Read and validate a pump config (YAML path or mapping); fills defaults, names bad keys."""
    if isinstance(path_or_dict, dict):
        raw = dict(path_or_dict)
        where = "config"
    else:
        import yaml

        p = Path(path_or_dict)
        if not p.exists():
            raise ConfigError(f"pump config not found: {p}")
        with open(p) as fh:
            raw = yaml.safe_load(fh) or {}
        if not isinstance(raw, dict):
            raise ConfigError(f"{p}: a pump config must be a mapping of sections")
        where = str(p)
    problems: list[str] = []  # every problem of the file, reported together
    unknown = sorted(set(raw) - set(SECTIONS))
    if unknown:
        problems.append(f"unknown section(s) {unknown}; valid: {sorted(SECTIONS)}")
    try:
        seed = int(raw.get("seed", 0))
    except (TypeError, ValueError):
        problems.append(f"seed must be an integer, got {raw.get('seed')!r}")
        seed = 0
    cfg: dict[str, Any] = {"name": raw.get("name", "pump"), "device": raw.get("device", "cpu"),
                           "output": raw.get("output", "results/pump"), "seed": seed,
                           "design": dict(raw.get("design") or {}), "gravity": raw.get("gravity", [0.0, -9.81, 0.0]),
                           "notes": raw.get("notes", "")}
    for sec, defaults in DEFAULTS.items():
        given = raw.get(sec) or {}
        if not isinstance(given, dict):
            problems.append(f"section '{sec}' must be a mapping")
            given = {}
        if sec != "contact":  # contact takes any contact-parameter name (checked by the builder)
            bad = sorted(set(given) - set(defaults))
            if bad:
                problems.append(f"unknown key(s) {bad} in '{sec}'; valid: {sorted(defaults)}")
        cfg[sec] = {**defaults, **given}
    run = cfg["run"]
    for k in ("revolutions", "dt", "update_every", "record_every", "vtk_every"):
        if not (isinstance(run[k], (int, float)) and not isinstance(run[k], bool) and run[k] > 0):
            problems.append(f"run.{k} must be > 0, got {run[k]!r}")
    cp = cfg["coupling"]
    if not isinstance(cp["two_way"], bool):
        problems.append(f"coupling.two_way must be true or false, got {cp['two_way']!r}")
    if isinstance(cp["relaxation"], bool) or not isinstance(cp["relaxation"], (int, float)) \
            or not (math.isfinite(cp["relaxation"]) and 0 <= cp["relaxation"] <= 100):
        problems.append(f"coupling.relaxation must be a number in [0, 100] (factor on the flow-through rate "
                        f"|u0| / voidage_cell; 0: no decay), got {cp['relaxation']!r}")
    if isinstance(run["worlds"], bool) or not isinstance(run["worlds"], int) or run["worlds"] < 1:
        problems.append(f"run.worlds must be an integer >= 1, got {run['worlds']!r}")
    if cfg["device"] not in ("cpu", "cuda") and not str(cfg["device"]).startswith("cuda:"):
        problems.append(f"device must be 'cpu' or 'cuda', got {cfg['device']!r}")
    try:
        g_ok = np.asarray(cfg["gravity"], dtype=float).shape == (3,)
    except (TypeError, ValueError):
        g_ok = False
    if not g_ok:
        problems.append(f"gravity must be 3 numbers [m/s^2], got {cfg['gravity']!r}")
    if len(problems) == 1:
        raise ConfigError(f"{where}: {problems[0]}")
    if problems:
        raise ConfigError(f"{where}: {len(problems)} problems:\n" + "\n".join(f"  - {m}" for m in problems))
    return cfg


# ----------------------------------------------------------------------------- the case
@dataclass
class PumpCase:
    """Everything a run needs, built from a config by :func:`build_case`."""

    config: dict
    design: PumpDesign
    geometry: PumpGeometry
    flow: Any
    grid: Any
    material: Any
    plan: Any
    inlet: Any
    sim: Any
    fluid: Any
    impacts: Any
    recorder: Any
    impeller_wall: int = 0
    casing_wall: int = 1
    timings: dict = field(default_factory=dict)


def build_case(cfg: dict) -> PumpCase:
    """Design, meshes, flow grid and the DEM model of one config (see the module docstring)."""
    import warp as wp

    import warpdem as wd
    from calibration.materials import BulkMaterial, sample_particles

    from .coupling import GridFluidForces
    from .flow import PumpFlow
    from .inlet import ParticleInlet, injection_rate, plan_injection
    from .wear import ImpactRecorder, WearRecorder

    t0 = _time.perf_counter()
    wp.config.quiet = True
    wp.init()
    design = PumpDesign.from_config(cfg["design"])
    gcfg = cfg["geometry"]
    geo = build_pump(design, float(gcfg["resolution"]), gcfg["meshes"] or None, float(gcfg["mesh_scale"]))
    fl = cfg["fluid"]
    flow = PumpFlow(geo, float(fl["density"]), float(fl["viscosity"]))
    grid = flow.sample(float(fl["grid_spacing"]))
    t_grid = _time.perf_counter()

    pc = cfg["particles"]
    material = BulkMaterial.from_config(pc["material"])
    run = cfg["run"]
    t_end = float(run["revolutions"]) * design.revolution_time
    mean_volume = material.mean_particle_mass / material.particle.density
    if pc["rate"] is not None:
        rate = float(pc["rate"])
    else:
        rate = injection_rate(float(pc["volume_fraction"]), design.flow_rate, mean_volume)
    inject_until = t_end if pc["inject_until"] is None else min(float(pc["inject_until"]), t_end)
    worlds = int(run["worlds"])
    plan = plan_injection(geo, rate, inject_until, material.max_bounding_radius, worlds=worlds,
                          t_start=float(pc["inject_from"]), seed=cfg["seed"])
    if plan.count == 0:
        raise ConfigError(f"the run injects no particle: {rate:.3g} particles/s from t = {pc['inject_from']} s to "
                          f"{inject_until:.3g} s; run more revolutions or raise particles.volume_fraction")
    samples = [sample_particles(material, n=max(1, int((plan.world == w).sum())), rng=cfg["seed"] * 1000 + w)
               for w in range(worlds)]

    cc = dict(cfg["contact"])
    law = wd.ContactLaw(rolling=cc.pop("rolling"))
    b = wd.ModelBuilder(num_worlds=worlds, contact_law=law, gravity=cfg["gravity"],
                        max_contacts=int(run["max_contacts"]))
    b.add_material(material.particle)
    wc = cfg["wall"]
    wall_mat = wd.Material("pump_wall", float(wc["youngs_modulus"]), float(wc["poisson_ratio"]), float(wc["density"]))
    b.add_material(wall_mat)
    imp, cas = geo.impeller, geo.casing
    b.add_wall((imp.vertices, imp.faces), wall_mat, name="impeller",
               motion=wd.WallMotion.rotation((0.0, 0.0, 1.0), design.speed_rpm),
               triangle_labels=imp.component, label_names=COMPONENTS)
    b.add_wall((cas.vertices, cas.faces), wall_mat, name="casing", triangle_labels=cas.component,
               label_names=COMPONENTS)
    inlet = ParticleInlet(geo, plan, samples)
    inlet.add_to_builder(b, material.particle.name)
    b.set_contact_parameters(**cc)
    fluid = GridFluidForces(grid, drag=fl["drag"], added_mass=fl["added_mass"],
                            pressure_gradient=fl["pressure_gradient"], buoyancy=fl["buoyancy"],
                            voidage_cell=fl["voidage_cell"], two_way=cfg["coupling"]["two_way"],
                            relaxation=float(cfg["coupling"]["relaxation"]))
    b.add_body_force(fluid)
    impacts = ImpactRecorder(finnie_k=float(cfg["wear"]["finnie_k"]))
    b.add_body_force(impacts)
    model = b.finalize(cfg["device"], check_overlaps=False)  # reserve bodies are parked apart
    v_ref = design.u2 + design.inlet_velocity
    sim = wd.Simulation(model, float(run["dt"]), v_ref=v_ref, steps_per_graph=int(run["steps_per_graph"]))
    inlet.attach(sim)
    recorder = WearRecorder(sim, [0, 1], impacts=impacts, zones={0: imp.zone})
    case = PumpCase(cfg, design, geo, flow, grid, material, plan, inlet, sim, fluid, impacts, recorder)
    case.timings = {"build_grid_s": t_grid - t0, "build_model_s": _time.perf_counter() - t_grid}
    return case


# ----------------------------------------------------------------------------- running
@dataclass
class RunRecord:
    """What a run records (world-summed unless noted)."""

    time: list = field(default_factory=list)
    region_counts: list = field(default_factory=list)  # (worlds, regions) per record
    removed_outlet: list = field(default_factory=list)
    removed_lost: list = field(default_factory=list)
    traj_x: list = field(default_factory=list)  # trajectory world: (n_bodies, 3) per record, NaN inactive
    traj_speed: list = field(default_factory=list)
    passage_phase: list = field(default_factory=list)  # per record: arrays of passage fractions
    passage_radius: list = field(default_factory=list)
    max_overlap: float = 0.0


def passage_position(design: PumpDesign, x: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For points x (n, 3) at time t: mask of points in a blade passage (r1 < r < r2, 0 < z < b2),
    their radius, and their place across the passage in [0, 1): 0 at the pressure side of the
    blade behind, 1 at the suction side of the blade ahead (rotating frame, rotation about +z)."""
    r = np.hypot(x[:, 0], x[:, 1])
    inside = (r > design.r1) & (r < design.r2) & (x[:, 2] > 0.0) & (x[:, 2] < design.b2)
    rc, thc = blade_camber(design, 400, 0.0)
    th = np.arctan2(x[:, 1], x[:, 0]) - design.omega * t  # angle in the impeller frame
    pitch = 2.0 * np.pi / design.blades
    rel = np.mod(th - np.interp(np.clip(r, design.r1, design.r2), rc, thc), pitch)
    return inside, r, rel / pitch


def run_case(case: PumpCase, progress: bool = True, vtk: bool = True, out_dir: Path | None = None) -> RunRecord:
    """Advance the case to its end time with injection/removal every ``update_every`` and
    records every ``record_every``; writes VTK frames every ``vtk_every`` if ``vtk``."""
    from .outputs import VTKWriter

    cfg = case.config
    run = cfg["run"]
    sim = case.sim
    d = case.design
    dt = sim.dt
    t_end = float(run["revolutions"]) * d.revolution_time
    total = int(round(t_end / dt))
    upd = max(1, int(round(float(run["update_every"]) / dt)))
    if sim.use_graph:  # whole graph replays between updates
        spg = sim.steps_per_graph
        upd = max(spg, int(round(upd / spg)) * spg)
    rec_every = max(upd, int(round(float(run["record_every"]) / dt / upd)) * upd)
    vtk_every = max(upd, int(round(float(run["vtk_every"]) / dt / upd)) * upd)
    rec = RunRecord()
    tw = int(run["trajectory_world"])
    traj_bodies = case.inlet.body_ids[case.plan.world == tw]
    writer = VTKWriter(case, Path(out_dir or cfg["output"]) / "vtk") if vtk else None
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="step", desc=f"pump {cfg['name']}", mininterval=2.0)
    t_start = _time.perf_counter()
    case.inlet.update(sim)
    done = 0
    while done < total:
        n = min(upd, total - done)
        sim.run(n, check_every=n)
        done += n
        case.inlet.update(sim)
        if bar is not None:
            bar.update(n)
        if done % rec_every == 0 or done == total:
            _record(case, rec, traj_bodies)
        if writer is not None and (done % vtk_every == 0 or done == total):
            writer.write_frame(sim.time)
    sim.solver.check()
    if bar is not None:
        bar.close()
    case.timings["run_s"] = _time.perf_counter() - t_start
    case.timings["steps"] = total
    if writer is not None:
        writer.close()
    return rec


def _record(case: PumpCase, rec: RunRecord, traj_bodies: np.ndarray) -> None:
    sim = case.sim
    t = sim.time
    rec.time.append(t)
    rec.region_counts.append(case.inlet.region_counts(sim))
    out, lost = case.inlet.removed_per_world()
    rec.removed_outlet.append(out)
    rec.removed_lost.append(lost)
    case.recorder.sample()
    q = sim.state.body_q.numpy().astype(np.float64)
    v = sim.state.body_v.numpy().astype(np.float64)
    act = sim.state.body_active.numpy() != 0
    x = np.where(act[traj_bodies, None], q[traj_bodies], np.nan)
    rec.traj_x.append(x)
    rec.traj_speed.append(np.where(act[traj_bodies], np.linalg.norm(v[traj_bodies], axis=1), np.nan))
    ids = case.inlet.body_ids[act[case.inlet.body_ids]]
    inside, r, phase = passage_position(case.design, q[ids], t)
    rec.passage_phase.append(phase[inside])
    rec.passage_radius.append(r[inside])


# ----------------------------------------------------------------------------- analysis
def analyse(case: PumpCase, rec: RunRecord) -> dict:
    """Numbers for the report: checks of the fluid model, particle balance, wear per component
    and the three findings of the seed paper."""
    d = case.design
    flow, grid = case.flow, case.grid
    rates = flow.flow_rates(grid.interpolate_velocity)
    h_e = flow.euler_head(grid.interpolate_velocity)
    r = case.recorder
    worlds = case.sim.model.num_worlds
    comp_en = r.per_component("energy_n")
    comp_et = r.per_component("energy_t")
    cf_avg = r.cumulative_force(average=True)
    cf_tot = r.cumulative_force(average=False)
    erosion = r.per_component("erosion")
    impacts = r.per_component("impacts")
    n_tri = r.triangles_per_component()
    areas = r.areas()
    labs = r.labels()
    area_comp = {c: float(sum(areas[w][labs[w] == COMPONENTS.index(c)].sum() for w in labs)) for c in n_tri}
    zone_en = r.blade_zone_totals("energy_n")
    zone_et = r.blade_zone_totals("energy_t")
    zone_imp = r.blade_zone_totals("impacts")
    # impeller: normal energy per area of each zone (blade zones, hub, shroud)
    density_n = {z: zone_en[z] / zone_en[z + "_area"] for z in BLADE_ZONES[1:] if zone_en.get(z + "_area", 0) > 0}
    for c in ("hub", "shroud"):
        density_n[c] = comp_en.get(c, 0.0) / area_comp[c] if area_comp.get(c) else 0.0
    # where is the impeller's highest normal energy per area (triangle)?
    en_imp = r.per_triangle("energy_n")[0]
    dens_tri = en_imp / areas[0]
    top = int(np.argmax(dens_tri)) if dens_tri.size else 0
    top_zone = BLADE_ZONES[case.geometry.impeller.zone[top]] if dens_tri.size else "none"
    top_comp = COMPONENTS[case.geometry.impeller.component[top]] if dens_tri.size else "none"
    # finding 1: the volute (with its tongue) carries the largest cumulative tangential contact
    # energy and force (totals over the component: independent of the triangle size)
    casing_t = comp_et.get("volute", 0.0) + comp_et.get("tongue", 0.0)
    casing_n = comp_en.get("volute", 0.0) + comp_en.get("tongue", 0.0)
    imp_t = {c: comp_et.get(c, 0.0) for c in ("shroud", "blade", "hub")}
    f1_energy = casing_t > max(imp_t.values())
    ft_tot = cf_tot["tangential"]
    casing_ft = ft_tot.get("volute", 0.0) + ft_tot.get("tongue", 0.0)
    f1_force = casing_ft > max(ft_tot.get(c, 0.0) for c in ("shroud", "blade", "hub"))
    vol_avg_t = cf_avg["tangential"].get("volute", 0.0)
    tang_share = casing_t / max(casing_t + casing_n, 1e-300)
    # finding 2: the blade head (leading edge) has the highest normal energy (per area)
    f2 = bool(density_n) and max(density_n.values()) > 0 and max(density_n, key=density_n.get) == "leading_edge"
    # finding 3: particles in the passage keep to the pressure side (entry: first 30 % of the blade)
    ph = np.concatenate(rec.passage_phase) if rec.passage_phase else np.zeros(0)
    rr = np.concatenate(rec.passage_radius) if rec.passage_radius else np.zeros(0)
    entry = rr < d.r1 + 0.3 * (d.r2 - d.r1)
    ps_all = float(np.mean(ph < 0.5)) if ph.size else float("nan")
    ps_entry = float(np.mean(ph[entry] < 0.5)) if entry.any() else float("nan")
    ps_contact = zone_en.get("pressure_side", 0.0) + zone_et.get("pressure_side", 0.0)
    ss_contact = zone_en.get("suction_side", 0.0) + zone_et.get("suction_side", 0.0)
    f3 = bool(ph.size) and ps_entry > 0.5 and ps_contact > ss_contact
    counts = np.asarray(rec.region_counts)
    out_w, lost_w = case.inlet.removed_per_world()
    # largest normal impact speed and the Hertz overlap it gives a mean particle on the wall
    # (Johnson 1985: delta = (15 m v^2 / (16 E* sqrt(R)))^(2/5))
    v_max = float(case.impacts.max_normal_speed.numpy()[0])
    mats = case.sim.model.materials
    pm, wm = case.material.particle, next(x for x in mats if x.name == "pump_wall")
    e_star = 1.0 / ((1 - pm.poisson_ratio**2) / pm.youngs_modulus + (1 - wm.poisson_ratio**2) / wm.youngs_modulus)
    m_mean = case.material.mean_particle_mass
    r_mean = (3 * m_mean / (4 * math.pi * pm.density)) ** (1 / 3)
    overlap = (15 * m_mean * v_max**2 / (16 * e_star * math.sqrt(r_mean))) ** 0.4
    injected = case.inlet.injected
    return {
        "design": d.summary(),
        "clearances_m": passage_clearances(case.geometry),
        "fluid_checks": {
            "flow_rate_duty_m3s": d.flow_rate,
            "flow_rate_grid_m3s": rates,
            "flow_rate_error": {k: v / d.flow_rate - 1.0 for k, v in rates.items() if k != "volute_throat"},
            "euler_head_grid_m": h_e, "euler_head_design_m": d.head / d.hydraulic_efficiency,
            "design_head_m": d.head, "volute_loss_head_m": d.volute_loss_head,
        },
        "particles": {
            "injected": injected, "scheduled": case.plan.count, "rate_per_s_per_world": case.plan.rate,
            "left_outlet": int(out_w.sum()), "lost": int(lost_w.sum()),
            "in_pump_end": int(counts[-1].sum() - counts[-1][:, 0].sum()) if counts.size else 0,
            "mean_in_region_per_world": {REGIONS[k]: float(counts[:, :, k].mean()) for k in range(1, len(REGIONS))}
            if counts.size else {},
            "worlds": worlds,
            "max_normal_impact_speed_m_s": v_max,
            "hertz_overlap_at_max_impact_fraction_of_radius": overlap / r_mean,
        },
        "wear": {
            "energy_n_J": comp_en, "energy_t_J": comp_et, "erosion_finnie_m3": erosion, "impacts": impacts,
            "cumulative_force_avg_N": cf_avg, "cumulative_force_total_N": cf_tot, "triangles": n_tri,
            "area_m2": area_comp, "impeller_normal_energy_per_area_J_m2": density_n,
            "blade_zone_energy_n_J": {z: zone_en.get(z, 0.0) for z in BLADE_ZONES[1:]},
            "blade_zone_energy_t_J": {z: zone_et.get(z, 0.0) for z in BLADE_ZONES[1:]},
            "blade_zone_impacts": {z: zone_imp.get(z, 0.0) for z in BLADE_ZONES[1:]},
            "impeller_max_normal_energy_triangle": {"component": top_comp, "zone": top_zone,
                                                    "J_per_m2": float(dens_tri[top]) if dens_tri.size else 0.0},
        },
        "findings": {
            "volute_wears_most_by_tangential_force": {
                "reproduced": bool(f1_energy and f1_force),
                "casing_tangential_energy_J": casing_t, "casing_normal_energy_J": casing_n,
                "impeller_tangential_energy_J": imp_t,
                "casing_cumulative_tangential_force_N": casing_ft,
                "impeller_cumulative_tangential_force_N": {c: ft_tot.get(c, 0.0) for c in ("shroud", "blade", "hub")},
                "volute_tangential_share_of_energy": tang_share,
                "volute_avg_cumulative_tangential_force_N": vol_avg_t,
                "energy_criterion": bool(f1_energy), "force_criterion": bool(f1_force)},
            "blade_head_highest_normal_energy": {
                "reproduced": bool(f2), "normal_energy_per_area_J_m2": density_n,
                "max_triangle": f"{top_comp}/{top_zone}"},
            "particles_enter_along_pressure_side": {
                "reproduced": bool(f3), "pressure_half_fraction_entry": ps_entry,
                "pressure_half_fraction_passage": ps_all, "samples_in_passage": int(ph.size),
                "samples_at_entry": int(entry.sum()), "pressure_side_contact_energy_J": ps_contact,
                "suction_side_contact_energy_J": ss_contact},
        },
    }


def pump_main(argv: list[str] | None = None) -> int:
    """Command line: ``warpdem pump CONFIG [--output DIR] [--device cpu|cuda] [--revolutions N]
    [--worlds N] [--no-vtk] [--no-progress]``; returns a process exit code."""
    ap = argparse.ArgumentParser(prog="warpdem pump", description="Slurry-pump wear prototype (seed paper Sec. 4.4)")
    ap.add_argument("config", help="YAML config (pump/configs/quick_pump.yaml, pump/configs/paper_pump.yaml)")
    ap.add_argument("--output", help="output folder (default: the config's 'output')")
    ap.add_argument("--device", help="cpu or cuda (default: the config's)")
    ap.add_argument("--revolutions", type=float, help="override run.revolutions")
    ap.add_argument("--worlds", type=int, help="override run.worlds (independent replicates)")
    ap.add_argument("--no-vtk", action="store_true", help="skip the VTK time series")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)
    try:
        cfg = load_config(args.config)
        if args.output:
            cfg["output"] = args.output
        if args.device:
            cfg["device"] = args.device
        if args.revolutions:
            cfg["run"]["revolutions"] = args.revolutions
        if args.worlds:
            cfg["run"]["worlds"] = args.worlds
        return run_config(cfg, progress=not args.no_progress, vtk=not args.no_vtk)
    except (ConfigError, WarpDEMError) as exc:
        print(f"warpdem pump: {exc}", file=sys.stderr)
        return 2


def run_config(cfg: dict, progress: bool = True, vtk: bool = True) -> int:
    """Build, run, analyse and write every output of one config; returns 0."""
    from .outputs import write_outputs

    out = Path(cfg["output"])
    out.mkdir(parents=True, exist_ok=True)
    case = build_case(cfg)
    print(f"pump: {case.design.describe()}")
    fd = case.fluid.describe()
    print(f"pump: fluid coupling {fd['coupling']} ({fd['drag']} drag"
          + (f", relaxation {fd['two_way_relaxation']:g})" if case.fluid.two_way else ")"))
    print(f"pump: {case.plan.count} particles scheduled ({case.plan.rate:.1f}/s per world, {case.plan.slots} inlet "
          f"slots), {case.sim.model.num_worlds} world(s), dt = {case.sim.dt:.3g} s, "
          f"{int(round(cfg['run']['revolutions'] * case.design.revolution_time / case.sim.dt))} steps on {cfg['device']}")
    rec = run_case(case, progress=progress, vtk=vtk, out_dir=out)
    results = analyse(case, rec)
    results["timings_s"] = case.timings
    results["config"] = cfg
    results["fluid_coupling"] = fluid_coupling_summary(case.fluid)
    paths = write_outputs(case, rec, results, out)
    fc = results["fluid_coupling"]
    if fc["mode"] == "two-way":
        print(f"pump: two-way coupling: largest cell fluid velocity change {fc['max_cell_velocity_change_m_s']:.3g} m/s "
              f"({fc['cells_changed']} cells changed)")
    print(f"pump: {case.timings['steps']} steps in {case.timings['run_s']:.1f} s "
          f"({case.timings['steps'] / max(case.timings['run_s'], 1e-9):.0f} steps/s); report: {paths['report']}")
    return 0


def fluid_coupling_summary(fluid) -> dict:
    """Which coupling ran and, for two-way, the largest cell slowdown at the end [m/s]."""
    out = {"mode": fluid.describe()["coupling"]}
    if fluid.two_way:
        du = fluid.fluid_velocity_change()
        out.update(relaxation=fluid.relaxation, max_cell_velocity_change_m_s=float(np.linalg.norm(du, axis=-1).max()),
                   cells_changed=int((np.linalg.norm(du, axis=-1) > 1e-6).sum()))
    return out


def save_json(path: Path, data: dict) -> None:
    def conv(o):
        if isinstance(o, (np.floating, np.integer)):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, Path):
            return str(o)
        if isinstance(o, float) and not math.isfinite(o):
            return None
        raise TypeError(f"not JSON serialisable: {type(o).__name__}")

    path.write_text(json.dumps(data, indent=1, default=conv))


if __name__ == "__main__":
    sys.exit(pump_main())
