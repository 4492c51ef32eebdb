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
    fluid: {density, viscosity, grid_spacing, drag: di_felice|schiller_naumann,
            drag_velocity: centre|surface_average|volume_average (where the drag reads the fluid
            velocity, pump.coupling), side_room_rotation: 0.5 (the side rooms' core c_u / (omega r),
            pump.flow), added_mass, pressure_gradient, buoyancy, voidage_cell}
    coupling: {two_way: false (one-way, default) | true (the particles' drag corrects the fluid
               velocity per coarse cell, pump.coupling), relaxation: 1.0 (factor on |u0| / cell)}
    particles: {material: (calibration.materials.BulkMaterial config), volume_fraction | rate,
                inject_from, inject_until}
    contact: {rolling: none|epsd|cdt, <contact parameter>: value, ...}
    wall: {youngs_modulus, poisson_ratio, density}
    run: {revolutions, dt, worlds, update_every, record_every, vtk_every, max_contacts,
          steps_per_graph}
    wear: {dnv_K, dnv_n, target_density (DNV-RP-O501 steel: 2e-9, 2.6, 7800), archard_k, hardness
           (Archard: 1e-2, 1.18e9 Pa), finnie_k (0: off), spin_up_revolutions (2: statistics start),
           block_revolutions (1: one sample per world and revolution)}; see pump/erosion.py
"""
from __future__ import annotations

import argparse
import math
import sys
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from warpdem.errors import ConfigError, WarpDEMError

# the config (its schema, defaults and loader) lives in pump.config_schema; its names stay importable here
from .config_schema import DEFAULTS, MAX_STEPS, SECTIONS, load_config  # noqa: F401 (DEFAULTS, MAX_STEPS, SECTIONS)
from .design import PumpDesign
from .geometry import (COMPONENTS, EYE_SEAL_CLEARANCE, REGIONS, PumpGeometry, blade_camber, build_pump,
                       passage_clearances)

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
    from .erosion import ArchardWear, DNVErosion
    from .regions import pump_regions
    from .wear import ImpactRecorder, WearRecorder

    t0 = _time.perf_counter()
    from warpdem.warp_output import quiet_warp

    quiet_warp()
    wp.init()
    design = PumpDesign.from_config(cfg["design"])
    gcfg = cfg["geometry"]
    geo = build_pump(design, float(gcfg["resolution"]), gcfg["meshes"] or None, float(gcfg["mesh_scale"]))
    fl = cfg["fluid"]
    flow = PumpFlow(geo, float(fl["density"]), float(fl["viscosity"]), float(fl["side_room_rotation"]))
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
    fluid = GridFluidForces(grid, drag=fl["drag"], drag_velocity=fl["drag_velocity"], added_mass=fl["added_mass"],
                            pressure_gradient=fl["pressure_gradient"], buoyancy=fl["buoyancy"],
                            voidage_cell=fl["voidage_cell"], two_way=cfg["coupling"]["two_way"],
                            relaxation=float(cfg["coupling"]["relaxation"]))
    b.add_body_force(fluid)
    wcfg = cfg["wear"]
    impacts = ImpactRecorder(dnv_K=float(wcfg["dnv_K"]), dnv_n=float(wcfg["dnv_n"]), finnie_k=float(wcfg["finnie_k"]))
    b.add_body_force(impacts)
    model = b.finalize(cfg["device"], check_overlaps=False)  # reserve bodies are parked apart
    v_ref = design.u2 + design.inlet_velocity
    sim = wd.Simulation(model, float(run["dt"]), v_ref=v_ref, steps_per_graph=int(run["steps_per_graph"]))
    inlet.attach(sim)
    regions = pump_regions(geo)
    dnv = DNVErosion(K=float(wcfg["dnv_K"]), n=float(wcfg["dnv_n"]), density=float(wcfg["target_density"]))
    archard = ArchardWear(float(wcfg["archard_k"]), float(wcfg["hardness"]))
    recorder = WearRecorder(sim, [0, 1], impacts=impacts,
                            regions={0: regions["impeller"], 1: regions["casing"]}, dnv=dnv, archard=archard,
                            t_start=sim.time)
    case = PumpCase(cfg, design, geo, flow, grid, material, plan, inlet, sim, fluid, impacts, recorder)
    case.timings = {"build_grid_s": t_grid - t0, "build_model_s": _time.perf_counter() - t_grid}
    return case


# ----------------------------------------------------------------------------- running
WEAR_SNAPSHOTS_PER_REVOLUTION = 16
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
    # wear snapshots (per world, component and region) 16 times a revolution: the statistics' blocks
    # end on the snapshot nearest to each revolution (pump.regions.BlockSeries.blocks)
    wear_every = max(upd, int(round(d.revolution_time / WEAR_SNAPSHOTS_PER_REVOLUTION / dt / upd)) * upd)
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
    case.recorder.sample()  # the series start at t = 0 (accumulators zero)
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
        if done % wear_every == 0 or done == total:
            case.recorder.sample()
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
def solids_loading(case: PumpCase) -> dict:
    """Delivered solids of the run: volume fraction phi = n_dot V_mean / Q and mass fraction
    phi rho_p / (phi rho_p + (1 - phi) rho_f) (the loading the wear rates are stated at)."""
    m = case.material
    v_mean = m.mean_particle_mass / m.particle.density
    phi = case.plan.rate * v_mean / case.design.flow_rate
    rho_p, rho_f = m.particle.density, float(case.config["fluid"]["density"])
    return {"volume_fraction": phi, "mass_fraction": phi * rho_p / (phi * rho_p + (1 - phi) * rho_f),
            "particles_per_s_per_world": case.plan.rate, "particle_density_kg_m3": rho_p}


def analyse_wear(case: PumpCase) -> dict:
    """Wear metrics with intervals per component and region, the paper's wear findings re-tested,
    the wear-life sanity check (:mod:`pump.findings`), and the run-end cumulative values."""
    from .erosion import SECONDS_PER_YEAR
    from .findings import CASING, REGION_MERGES, retest_findings, table, wear_life_check, window_stats
    from .wear import METRICS

    d = case.design
    r = case.recorder
    wc = case.config["wear"]
    t_from = float(wc["spin_up_revolutions"]) * d.revolution_time
    block = float(wc["block_revolutions"]) * d.revolution_time
    comp = window_stats(r, "component", t_from, block, merge={"casing": CASING})
    regs = window_stats(r, "region", t_from, block, merge=REGION_MERGES) if r.regions else None
    cumulative = {kind: {name: r.metric(name, kind) for name in (
        "impulse_n", "impulse_t", "energy_n", "energy_t", "energy_n_per_area", "energy_t_per_area", "impacts",
        "edem_cumulative_force_n", "edem_cumulative_force_t")} for kind in (("component", "region") if r.regions
                                                                         else ("component",))}
    # the impeller triangle with the most normal energy per area (world mean) and its impacts
    en = r.per_triangle("energy_n")[case.impeller_wall] / r.areas()[case.impeller_wall]
    top = int(np.argmax(en)) if en.size else 0
    top_impacts = r.per_triangle("impacts")[case.impeller_wall][top] * case.sim.model.num_worlds if en.size else 0.0
    from .regions import REGIONS as WEAR_REGIONS

    top_region = WEAR_REGIONS[r.regions[case.impeller_wall][top]] if r.regions and en.size else "none"
    return {
        "definitions": {k: {"unit": u, "definition": t} for k, (u, t) in METRICS.items()},
        "elapsed_s": r.elapsed, "seconds_per_year": SECONDS_PER_YEAR,
        "window": {"from_s": comp.t_from, "to_s": comp.t_to, "blocks": comp.blocks, "worlds": comp.worlds,
                   "samples": comp.blocks * comp.worlds, "spin_up_revolutions": float(wc["spin_up_revolutions"]),
                   "block_revolutions": float(wc["block_revolutions"])},
        "solids": solids_loading(case),
        "erosion_model": {"dnv": {"K": r.dnv.K, "n": r.dnv.n, "target_density": r.dnv.density, "source": r.dnv.source},
                          "archard": {"wear_coefficient": r.archard.wear_coefficient, "hardness_Pa": r.archard.hardness,
                                      "source": r.archard.source}},
        "components": table(comp), "regions": table(regs) if regs is not None else {},
        "cumulative": cumulative,
        "impeller_max_normal_energy_triangle": {"region": top_region, "J_per_m2": float(en[top]) if en.size else 0.0,
                                                "impacts_all_worlds": float(top_impacts)},
        "findings": retest_findings(comp, regs),
        "wear_life": wear_life_check(comp, regs, d.blade_thickness),
    }


def analyse(case: PumpCase, rec: RunRecord) -> dict:
    """Numbers for the report: checks of the fluid model, particle balance, wear metrics with
    intervals (:func:`analyse_wear`) and the seed paper's findings."""
    d = case.design
    flow, grid = case.flow, case.grid
    rates = flow.flow_rates(grid.interpolate_velocity)
    h_e = flow.euler_head(grid.interpolate_velocity)
    worlds = case.sim.model.num_worlds
    wear = analyse_wear(case)
    # finding 3: particles in the passage keep to the pressure side (entry: first 30 % of the blade)
    ph = np.concatenate(rec.passage_phase) if rec.passage_phase else np.zeros(0)
    rr = np.concatenate(rec.passage_radius) if rec.passage_radius else np.zeros(0)
    entry = rr < d.r1 + 0.3 * (d.r2 - d.r1)
    ps_all = float(np.mean(ph < 0.5)) if ph.size else float("nan")
    ps_entry = float(np.mean(ph[entry] < 0.5)) if entry.any() else float("nan")
    reg_en = wear["cumulative"].get("region", {}).get("energy_n", {})
    reg_et = wear["cumulative"].get("region", {}).get("energy_t", {})
    ps_contact = reg_en.get("blade_pressure_side", 0.0) + reg_et.get("blade_pressure_side", 0.0)
    ss_contact = reg_en.get("blade_suction_side", 0.0) + reg_et.get("blade_suction_side", 0.0)
    f3 = bool(ph.size) and ps_entry > 0.5 and ps_contact > ss_contact
    counts = np.asarray(rec.region_counts)
    side = REGIONS.index("side_rooms")
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
    findings = dict(wear["findings"])
    findings["particles_enter_along_pressure_side"] = {
        "verdict": "reproduced" if f3 else "not reproduced", "reproduced": bool(f3),
        "caveat": "follows from the passage-averaged kinematics of the prescribed analytic flow, so it cannot "
                  "test the paper's fluid mechanism",
        "pressure_half_fraction_entry": ps_entry, "pressure_half_fraction_passage": ps_all,
        "samples_in_passage": int(ph.size), "samples_at_entry": int(entry.sum()),
        "pressure_side_contact_energy_J": ps_contact, "suction_side_contact_energy_J": ss_contact}
    wear = {k: v for k, v in wear.items() if k != "findings"}
    return {
        "design": d.summary(),
        "clearances_m": passage_clearances(case.geometry),
        "side_rooms": {
            "side_gap_m": d.side_gap, "core_rotation_factor": float(case.flow.side_room_rotation),
            "eye_seal_clearance_m": EYE_SEAL_CLEARANCE,
            "mean_particles_per_world": float(counts[:, :, side].mean()) if counts.size else 0.0,
            "max_particles_all_worlds": int(counts[:, :, side].sum(axis=1).max()) if counts.size else 0},
        "drag": {"law": case.fluid.drag, "velocity": case.fluid.drag_velocity},
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
        "wear": wear,
        "findings": findings,
    }


def pump_main(argv: list[str] | None = None) -> int:
    """Command line: ``warpdem pump CONFIG [--output DIR] [--device cpu|cuda] [--revolutions N]
    [--worlds N] [--no-vtk] [--no-progress]``; returns a process exit code."""
    ap = argparse.ArgumentParser(prog="warpdem pump", description="Slurry-pump wear prototype (seed paper Sec. 4.4)")
    ap.add_argument("config", help="YAML config (pump/configs/quick_pump.yaml, pump/configs/paper_pump.yaml)")
    ap.add_argument("--output", help="output folder (default: the config's 'output')")
    ap.add_argument("--device", help="cpu or cuda (default: the config's)")
    ap.add_argument("--revolutions", type=float, help="override run.revolutions (> 0)")
    ap.add_argument("--worlds", type=int, help="override run.worlds (independent replicates, >= 1)")
    ap.add_argument("--no-vtk", action="store_true", help="skip the VTK time series")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)
    try:
        from warpdem.config_io import check_device, check_output_folder

        cfg = load_config(args.config)
        # the command line's values are checked as the file's are (0 revolutions is refused, not ignored)
        for section, key, value in ((None, "output", args.output), (None, "device", args.device),
                                    ("run", "revolutions", args.revolutions), ("run", "worlds", args.worlds)):
            if value is not None:
                (cfg[section] if section else cfg)[key] = value
        cfg = load_config(cfg, where=f"{args.config} (with the command line's options)")
        check_device(cfg["device"], "--device" if args.device is not None else f"{args.config}: device")
        check_output_folder(cfg["output"], "--output" if args.output is not None else "output")
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


if __name__ == "__main__":
    sys.exit(pump_main())
