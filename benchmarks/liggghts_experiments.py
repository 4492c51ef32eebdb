"""warpdem against LIGGGHTS-PUBLIC 3.8 on the standard experiments, measured by the same code
(issue 27, items 1 and 3).

For every fill index i the experiment runs in warpdem (CPU, one world, ``fill_per_world`` with
``first_fill_index`` i, so its loose fill is seeded by (seed, i)) and in LIGGGHTS from a deck
written by :mod:`validation.reference.liggghts_experiments` (``identical``: the same fill i;
``poured``: LIGGGHTS inserts the same mass itself, seeds from i). Both are measured by
``calibration.measurement`` through the experiment's own settings
(:mod:`validation.reference.liggghts_readback`). Runs go to at most ``--jobs`` processes at a time
(warpdem CPU runs and LIGGGHTS runs are one process each).

    python benchmarks/liggghts_experiments.py --experiment baffle --law none --scale small --fills 3 \\
        --fill-mode identical poured --out docs/results/liggghts_experiments/baffle_small_none

Laws (sliding friction 0.45 particle-particle, 0.35 particle-wall, restitution 0.6 everywhere):
``none`` (no rolling resistance, no cohesion), ``epsd2`` (rolling friction 0.2 pp and pw) and
``sjkr`` (cohesion energy density 1e5 J/m^3 pp and pw); ``--param name=value`` overrides.
Scales: ``quick`` (the experiment's quick preset), ``small`` (:data:`SMALL`: fewer particles) and
``paper_spheres`` (the paper preset with 16-20 mm spheres, :data:`PAPER_SPHERES`).

Writes ``results.json`` (every run, the summary, deck, LIGGGHTS version, command, date),
``results.md`` (observable, warpdem mean +- sd, LIGGGHTS mean +- sd per fill mode, difference) and
``decks/`` (the deck of every LIGGGHTS run, the STL walls of the first).
``python benchmarks/liggghts_experiments.py --collect DIR...`` prints one table of stored results.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import datetime as _dt
import json
import math
import multiprocessing
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from warpdem.json_io import jsonable as _jsonable

#: contact laws of the comparison: sub-models and their parameters (on top of BASE_PARAMETERS)
LAWS: dict[str, tuple[dict[str, str], dict[str, float]]] = {
    "none": ({"rolling": "none"}, {}),
    "epsd2": ({"rolling": "epsd2"}, {"mu_r_pp": 0.2, "mu_r_pw": 0.2}),
    "sjkr": ({"rolling": "none", "cohesion": "sjkr"},
             {"cohesion_energy_density_pp": 1.0e5, "cohesion_energy_density_pw": 1.0e5}),
}
BASE_PARAMETERS = {"mu_s_pp": 0.45, "mu_s_pw": 0.35}
#: the reduced scale: the quick preset with less material (a LIGGGHTS run of a few minutes or less on one core)
SMALL: dict[str, dict[str, Any]] = {"baffle": {"fill_mass": 16.0}, "drum": {}, "cylinder": {"fill_mass": 3.0}}
#: scale "paper_spheres": the paper preset (protocol, fill mass) with spheres of 16-20 mm, the
#: material of validation.hidden_effects' paper-scale lab (about 2000 spheres in the baffle box)
PAPER_SPHERES = {"type": "spheres", "diameter": [0.016, 0.020]}
SCALES = ("quick", "small", "paper_spheres")


def make_experiment(name: str, scale: str, law: str, fill_index: int, overrides: dict[str, Any] | None = None):
    """The experiment at ``scale`` (:data:`SCALES`) with the law's sub-models, whose single
    world starts from loose fill ``fill_index``."""
    import warpdem as wd
    from calibration.experiments import make_experiment as make

    settings = {**(SMALL[name] if scale == "small" else {}), **(overrides or {})}
    preset = "quick"
    if scale == "paper_spheres":
        preset, settings = "paper", {"material": dict(PAPER_SPHERES), **settings}
    return make(name, preset, contact_law=wd.ContactLaw(**LAWS[law][0]), fill_per_world=True,
                first_fill_index=int(fill_index), **settings)


def _quiet() -> None:
    import warp as wp

    from warpdem.warp_output import quiet_warp

    quiet_warp()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def run_warpdem(name: str, scale: str, law: str, fill_index: int, parameters: dict[str, float],
                overrides: dict[str, Any]) -> dict[str, Any]:
    """One warpdem CPU run (one world) -> its record (observables, diagnostics, timing)."""
    _quiet()
    exp = make_experiment(name, scale, law, fill_index, overrides)
    t0 = time.perf_counter()
    r = exp.run([parameters], device="cpu")[0]
    wall = time.perf_counter() - t0
    if r.status == "failed" and "WarpCodegen" in (r.error or ""):
        # a kernel compiled while its source file was being edited (a shared working tree): the
        # caller runs it again in a fresh process
        raise RuntimeError(f"warp codegen failed, run again: {r.error[:200]}")
    d = r.diagnostics
    keep = {k: d[k] for k in ("h_fill_m", "particles_before_lift", "removed_total", "fill_settle_settled",
                              "after_lift_settle_settled", "peak_height_m", "snapshot_std_deg",
                              "snapshot_mean_deg", "fill_top_m", "lift_time_s") if k in d}
    keep["phases_s"] = r.timing["phases_s"]
    if isinstance(d.get("fit"), dict):  # the baffle's fitted bins (as the LIGGGHTS record's "fit")
        keep["fit"] = {k: d["fit"][k] for k in ("n_bins", "x_fit_m", "z_fit_m", "residual_rms_m", "profile_z_m")
                       if k in d["fit"]}
    keep["particles"] = r.protocol["fill"]["particles_per_world"]
    keep["particles_final"] = int(len(r.particles[1])) if r.particles is not None else None
    # the read-back check: warpdem's own final particles through the LIGGGHTS read-back path
    check = None
    if r.ok and r.particles is not None and name in ("baffle", "cylinder"):
        from validation.reference.liggghts_readback import measure_particles

        xs, rs = (np.asarray(a, dtype=float) for a in r.particles)
        try:
            if name == "baffle":
                obs, _ = measure_particles(exp, (xs, rs), h_fill=d["h_fill_m"])
                check = {"static_angle": obs["static_angle"]}
            else:
                obs, _ = measure_particles(exp, (xs, rs), mean_diameter=d["mean_diameter_m"])
                check = {"pile_angle": obs["pile_angle"], "pile_height": obs["pile_height"]}
        except Exception as exc:  # noqa: BLE001 - recorded, not fatal
            check = {"error": f"{type(exc).__name__}: {exc}"}
    return {"code": "warpdem", "fill_index": fill_index, "status": r.status, "error": r.error,
            "observables": r.observables, "diagnostics": keep, "readback_check": check,
            "timing": {"wall_s": round(wall, 2), "dt_s": r.timing["dt_s"], "steps": r.timing["steps"]},
            "contact_parameters": r.contact_parameters, "parameters": r.parameters}


def run_liggghts(name: str, scale: str, law: str, fill_index: int, parameters: dict[str, float],
                 overrides: dict[str, Any], fill_mode: str, folder: str, tangential_reduce: bool | None = None
                 ) -> dict[str, Any]:
    """One LIGGGHTS run (one process) of the deck written for this experiment -> its record
    (``tangential_reduce``: None as the law means it, True/False forced, see ``write_deck``)."""
    _quiet()
    from validation.reference.liggghts_experiments import fill_for_index, warpdem_time_step, write_deck
    from validation.reference.liggghts_readback import run_and_measure

    exp = make_experiment(name, scale, law, fill_index, overrides)
    t0 = time.perf_counter()
    fill = fill_for_index(exp, fill_index)
    dt = warpdem_time_step(exp, fill)
    deck = write_deck(exp, parameters, fill_mode=fill_mode, fill_index=fill_index, fill=fill, dt=dt,
                      tangential_reduce=tangential_reduce)
    deck_s = time.perf_counter() - t0
    m, run = run_and_measure(exp, deck, folder)
    return {"code": "liggghts", "fill_mode": fill_mode, "variant": _variant(tangential_reduce),
            "fill_index": fill_index, "status": m.status,
            "error": m.error, "observables": m.observables, "diagnostics": m.diagnostics,
            "timing": {**m.timing, "deck_s": round(deck_s, 2)}, "folder": str(folder),
            "deck_settings": {k: v for k, v in deck.settings.items() if k != "phases"},
            "deck_phases": deck.settings.get("phases"), "notes": deck.notes, "n_particles_deck": deck.n_particles}


def _variant(tangential_reduce: bool | None) -> str:
    """Label of a LIGGGHTS deck variant: "" (the warpdem law) or "tangential_reduce on|off" (forced)."""
    return "" if tangential_reduce is None else f"tangential_reduce {'on' if tangential_reduce else 'off'}"


def _stats(values: list[float]) -> dict[str, float | int | None]:
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if v.size == 0:
        return {"n": 0, "mean": None, "sd": None}
    return {"n": int(v.size), "mean": float(v.mean()), "sd": float(v.std(ddof=1)) if v.size > 1 else None}


def summarise(records: list[dict[str, Any]], observables: list[str], modes: list[tuple[str, str]],
              group_key: str | None = None) -> list[dict[str, Any]]:
    """Per (group, observable, (fill mode, deck variant)): warpdem and LIGGGHTS mean +- sd, the
    difference of the means (warpdem - LIGGGHTS), and for the identical mode the paired
    difference per fill."""
    rows = []
    groups = sorted({r.get(group_key) for r in records}) if group_key else [None]
    for g in groups:
        recs = [r for r in records if group_key is None or r.get(group_key) == g]
        wd_recs = {r["fill_index"]: r for r in recs if r["code"] == "warpdem" and r["status"] == "ok"}
        for obs in observables:
            w = _stats([r["observables"].get(obs) for r in wd_recs.values()])
            for mode, variant in modes:
                lg_recs = {r["fill_index"]: r for r in recs if r["code"] == "liggghts" and r["fill_mode"] == mode
                           and r.get("variant", "") == variant and r["status"] == "ok"}
                lstat = _stats([r["observables"].get(obs) for r in lg_recs.values()])
                diff = (w["mean"] - lstat["mean"]) if w["mean"] is not None and lstat["mean"] is not None else None
                row = {"group": g, "observable": obs, "fill_mode": mode, "variant": variant, "warpdem": w,
                       "liggghts": lstat, "difference": diff}
                if mode == "identical":
                    pairs = [wd_recs[i]["observables"].get(obs) - lg_recs[i]["observables"].get(obs)
                             for i in sorted(set(wd_recs) & set(lg_recs))
                             if wd_recs[i]["observables"].get(obs) is not None
                             and lg_recs[i]["observables"].get(obs) is not None]
                    row["paired_difference"] = _stats(pairs)
                rows.append(row)
    return rows


def _fmt(s: dict[str, Any], digits: int) -> str:
    if s["mean"] is None:
        return "n/a"
    sd = f" ± {s['sd']:.{digits}f}" if s["sd"] is not None else ""
    return f"{s['mean']:.{digits}f}{sd} (n={s['n']})"


def markdown(meta: dict[str, Any], rows: list[dict[str, Any]], records: list[dict[str, Any]]) -> str:
    units = meta["observable_units"]
    lines = [f"# warpdem vs LIGGGHTS: {meta['experiment']} ({meta['scale']}), law `{meta['law']}`", "",
             f"- date: {meta['date']}; LIGGGHTS: {meta['liggghts_version']}; warpdem on CPU",
             f"- command: `{meta['command']}`",
             f"- contact law: {meta['contact_law']}; parameters: {meta['parameters']}",
             f"- settings: {meta['settings']}",
             f"- fills: {meta['fills']}; time step {meta['dt_s']} s (warpdem's, used by both)", "",
             "| group | observable | fill mode | warpdem mean ± sd | LIGGGHTS mean ± sd | difference (warpdem − LIGGGHTS) "
             "| paired difference (same fill) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        digits = 1 if units.get(r["observable"]) == "kg/m^3" else 3 if units.get(r["observable"]) == "m" else 2
        diff = "n/a" if r["difference"] is None else f"{r['difference']:+.{digits}f}"
        paired = _fmt(r["paired_difference"], digits) if "paired_difference" in r else ""
        lines.append(f"| {r['group'] if r['group'] is not None else ''} | {r['observable']} [{units.get(r['observable'], '')}] "
                     f"| {r['fill_mode']}{', ' + r['variant'] if r['variant'] else ''} | {_fmt(r['warpdem'], digits)} | {_fmt(r['liggghts'], digits)} | {diff} | {paired} |")
    lines += ["", "## Runs", "", "| code | fill mode | group | fill | status | observables | particles (after fill → end) "
              "| fill settle [s] | wall [s] |", "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(records, key=lambda r: (r["code"], r.get("fill_mode") or "", r.get("variant") or "",
                                            str(r.get("group")), r["fill_index"])):
        d = r["diagnostics"]
        obs = ", ".join(f"{k} {v:.4g}" for k, v in r["observables"].items() if v is not None) or (r["error"] or "")
        if r["code"] == "warpdem":
            n0, n1 = d.get("particles"), d.get("particles_final")
            settle = d["phases_s"].get("fill_settle")
        else:
            n0, n1 = d.get("particles_after_fill"), d.get("particles_final")
            settle = d.get("fill_settle_s")
        mode = (r.get("fill_mode") or "") + (f", {r['variant']}" if r.get("variant") else "")
        lines.append(f"| {r['code']} | {mode} | {r.get('group') or ''} | {r['fill_index']} | {r['status']} "
                     f"| {obs} | {n0} → {n1} | {settle if settle is None else round(settle, 3)} | {r['timing']['wall_s']} |")
    notes = list(dict.fromkeys(n for r in records if r["code"] == "liggghts" for n in r.get("notes") or []))
    if notes:
        lines += ["", "## Where the LIGGGHTS deck cannot match warpdem exactly", ""] + [f"- {n}" for n in notes]
    return "\n".join(lines) + "\n"


def collect(folders: list[Path]) -> str:
    """One markdown table of the summaries of several result folders (``results.json``), with each
    run's LIGGGHTS and warpdem wall times [s] (median per run)."""
    lines = ["| experiment | scale | law | group | observable | fill mode | warpdem mean ± sd | LIGGGHTS mean ± sd "
             "| difference (warpdem − LIGGGHTS) | paired (same fill) | run wall [s] warpdem / LIGGGHTS |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for folder in folders:
        data = json.loads((folder / "results.json").read_text())
        meta, runs = data["meta"], data["runs"]
        units = meta["observable_units"]
        walls = {code: [r["timing"]["wall_s"] for r in runs if r["code"] == code and r["timing"].get("wall_s")]
                 for code in ("warpdem", "liggghts")}
        wall = " / ".join(f"{np.median(v):.0f}" if v else "n/a" for v in walls.values())
        for r in data["summary"]:
            if units.get(r["observable"]) == "1/0":
                continue
            digits = 1 if units.get(r["observable"]) == "kg/m^3" else 3 if units.get(r["observable"]) == "m" else 2
            diff = "n/a" if r["difference"] is None else f"{r['difference']:+.{digits}f}"
            paired = _fmt(r["paired_difference"], digits) if "paired_difference" in r else ""
            mode = r["fill_mode"] + (f", {r['variant']}" if r.get("variant") else "")
            lines.append(f"| {meta['experiment']} | {meta['scale']} | {meta['law']} | {r['group'] or ''} "
                         f"| {r['observable']} [{units.get(r['observable'], '')}] | {mode} | {_fmt(r['warpdem'], digits)} "
                         f"| {_fmt(r['liggghts'], digits)} | {diff} | {paired} | {wall} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    if argv is None:
        argv = sys.argv[1:]
    if argv and argv[0] == "--collect":
        # python benchmarks/liggghts_experiments.py --collect DIR...: one table of stored results
        print(collect([Path(a) for a in argv[1:]]), end="")
        return 0
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--experiment", choices=("baffle", "drum", "cylinder"), required=True)
    ap.add_argument("--law", choices=sorted(LAWS), default="none")
    ap.add_argument("--scale", choices=SCALES, default="small")
    ap.add_argument("--fills", type=int, default=2, help="fill indices 0 .. N-1 (plus --first-fill)")
    ap.add_argument("--first-fill", type=int, default=0)
    ap.add_argument("--fill-mode", nargs="+", choices=("identical", "poured"), default=["identical"])
    ap.add_argument("--rpm", type=float, nargs="+", default=None, help="drum speeds (default: the preset's)")
    ap.add_argument("--param", action="append", default=[], help="contact parameter override name=value")
    ap.add_argument("--set", action="append", default=[], dest="settings",
                    help="experiment setting override name=value (a number or JSON)")
    ap.add_argument("--tangential-reduce", nargs="+", choices=("law", "on", "off"), default=["law"],
                    help="LIGGGHTS decks: 'law' writes what the warpdem law means, 'on'/'off' force LIGGGHTS' "
                         "tangential_reduce (cohesion only; 'off' is LIGGGHTS 3.8's default)")
    ap.add_argument("--jobs", type=int, default=2, help="processes at a time (default 2)")
    ap.add_argument("--retries", type=int, default=2, help="reruns of a run that failed to start (not of a measurement)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--keep-dumps", action="store_true", help="keep the LIGGGHTS run folders with their dumps")
    args = ap.parse_args(argv)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    work = out / "runs"
    overrides: dict[str, Any] = {}
    for kv in args.settings:
        k, v = kv.split("=", 1)
        try:
            overrides[k] = json.loads(v)
        except json.JSONDecodeError:
            overrides[k] = v
    params = {**BASE_PARAMETERS, **LAWS[args.law][1]}
    for kv in args.param:
        k, v = kv.split("=", 1)
        params[k] = float(v)
    fills = list(range(args.first_fill, args.first_fill + args.fills))
    rpms = args.rpm if args.experiment == "drum" and args.rpm else [None]

    reduce_values = [None if v == "law" else v == "on" for v in args.tangential_reduce]
    variants = [(mode, _variant(tr)) for mode in args.fill_mode for tr in reduce_values]
    tasks = []
    for rpm in rpms:
        p = {**params, **({"rpm": rpm} if rpm is not None else {})}
        group = None if rpm is None else f"{rpm:g} rpm"
        for i in fills:
            tasks.append((group, "warpdem", None, None, i, p))
            for mode in args.fill_mode:
                for tr in reduce_values:
                    tasks.append((group, "liggghts", mode, tr, i, p))
    # LIGGGHTS first within a fill: those runs are the longer ones at the quick scale
    t_start = time.perf_counter()
    ctx = multiprocessing.get_context("spawn")
    records: list[dict[str, Any]] = []
    with concurrent.futures.ProcessPoolExecutor(max_workers=max(1, args.jobs), mp_context=ctx) as pool:
        futures = {}

        def submit(task, attempt: int = 0) -> None:
            group, code, mode, tr, i, p = task
            variant = _variant(tr).replace("tangential_reduce ", "tr_")
            tag = (f"{code}{'_' + mode if mode else ''}{'_' + variant if variant else ''}_fill{i}"
                   f"{'_' + group.replace(' ', '') if group else ''}")
            if code == "warpdem":
                f = pool.submit(run_warpdem, args.experiment, args.scale, args.law, i, p, overrides)
            else:
                folder = work / tag
                if folder.exists():
                    shutil.rmtree(folder)
                f = pool.submit(run_liggghts, args.experiment, args.scale, args.law, i, p, overrides, mode,
                                str(folder), tr)
            futures[f] = (task, tag, attempt)

        for task in tasks:
            submit(task)
        while futures:
            done, _ = concurrent.futures.wait(list(futures), return_when=concurrent.futures.FIRST_COMPLETED)
            for f in done:
                task, tag, attempt = futures.pop(f)
                group, code, mode, tr, i, _p = task
                try:
                    rec = f.result()
                except Exception as exc:  # noqa: BLE001 - a failed run is recorded, never dropped
                    if attempt < args.retries:
                        print(f"[{time.perf_counter() - t_start:7.1f} s] {tag}: {type(exc).__name__}: "
                              f"{str(exc)[:160]}; running it again", file=sys.stderr, flush=True)
                        submit(task, attempt + 1)
                        continue
                    rec = {"code": code, "fill_mode": mode, "variant": _variant(tr) if code == "liggghts" else None,
                           "fill_index": i, "status": "failed", "error": f"{type(exc).__name__}: {exc}",
                           "observables": {}, "diagnostics": {}, "timing": {"wall_s": None}}
                rec["group"] = group
                rec["tag"] = tag
                rec["attempts"] = attempt + 1
                records.append(rec)
                obs = ", ".join(f"{k}={v:.4g}" for k, v in (rec["observables"] or {}).items() if v is not None)
                print(f"[{time.perf_counter() - t_start:7.1f} s] {tag}: {rec['status']} {obs} {rec['error'] or ''} "
                      f"({rec['timing']['wall_s']} s)", file=sys.stderr, flush=True)

    exp0 = make_experiment(args.experiment, args.scale, args.law, fills[0], overrides)
    observables = list(exp0.OBSERVABLES)
    rows = summarise(records, observables, variants, "group" if rpms != [None] else None)
    from validation.reference.liggghts import liggghts_version

    decks = out / "decks"
    decks.mkdir(exist_ok=True)
    first = True
    for r in records:
        if r["code"] != "liggghts" or "folder" not in r:
            continue
        folder = Path(r["folder"])
        if (folder / "in.deck").exists():
            shutil.copy(folder / "in.deck", decks / f"{r['tag']}.deck")
            if first:
                for stl in folder.glob("*.stl"):
                    shutil.copy(stl, decks / stl.name)
                first = False
        if not args.keep_dumps:
            for dump in folder.glob("*.dump"):
                dump.unlink()
    if not args.keep_dumps:
        shutil.rmtree(work, ignore_errors=True)
        for r in records:
            r.pop("folder", None)
    dt = sorted({r["timing"].get("dt_s") for r in records if r["timing"].get("dt_s")})
    meta = {"experiment": args.experiment, "scale": args.scale, "law": args.law,
            "contact_law": exp0.contact_law.describe(), "parameters": params,
            "settings": {**(SMALL[args.experiment] if args.scale == "small" else {}),
                         **({"material": PAPER_SPHERES, "preset": "paper"} if args.scale == "paper_spheres" else {}),
                         **overrides},
            "fills": fills, "fill_modes": args.fill_mode, "liggghts_tangential_reduce": args.tangential_reduce,
            "rpm": rpms, "dt_s": dt,
            "observable_units": dict(exp0.OBSERVABLES), "liggghts_version": liggghts_version(),
            "command": "python " + " ".join([sys.argv[0], *argv]),
            "date": _dt.datetime.now().isoformat(timespec="seconds"),
            "wall_s": round(time.perf_counter() - t_start, 1), "jobs": args.jobs}
    (out / "results.json").write_text(json.dumps(_jsonable({"meta": meta, "summary": rows, "runs": records}), indent=1))
    (out / "results.md").write_text(markdown(meta, rows, records))
    print(markdown(meta, rows, records))
    return 0


if __name__ == "__main__":
    sys.exit(main())
