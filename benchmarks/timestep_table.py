"""Pool the JSON lines of several ``timestep_convergence.py`` calls (different fills of the same cases)
and print one Markdown table: per case, experiment, drum speed and step, the mean angle over all fills
(± standard error), and the change of each step against the smallest one, paired by fill (the same fill
index run at both steps) with its standard error.

    python benchmarks/timestep_table.py docs/results/timestep_paper_history_h200_2026-11-27.jsonl

Calls are pooled only when their records name the same law and the same time step [s] for a given
fraction (a batch's step follows its smallest sphere, so a call whose batch held other particles would
not be the same experiment); a fill index seen twice for one step is an error, not averaged.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict

import numpy as np


def mean_sem(values) -> tuple[float, float | None, int]:
    """Mean, standard error (ddof=1; None for one value) and count of the non-None values."""
    v = np.array([x for x in values if x is not None], dtype=float)
    if v.size == 0:
        return float("nan"), None, 0
    return float(v.mean()), (float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else None), int(v.size)


def pooled_fills(lines: list[dict]) -> dict:
    """{(case, experiment, rpm, fraction): {"fills": {fill: (angle, density)}, "dt_s", "law"}} (records
    written before the law was logged count as law "not recorded")."""
    out: dict = {}
    for rec in lines:
        if "angles_deg" not in rec:  # change lines: recomputed here from the pooled fills
            continue
        key = (rec["case"], rec["experiment"], rec["rpm"], rec["dt_rayleigh_fraction"])
        law = rec.get("law", "not recorded")
        entry = out.setdefault(key, {"fills": {}, "dt_s": rec["dt_s"], "law": law})
        if not np.isclose(entry["dt_s"], rec["dt_s"], rtol=1e-6) or entry["law"] != law:
            raise SystemExit(f"timestep_table: {key} ran at {rec['dt_s']:.4g} s / {law} in one call and "
                             f"{entry['dt_s']:.4g} s / {entry['law']} in another: not the same experiment")
        densities = rec.get("bulk_densities") or [None] * len(rec["angles_deg"])
        for fill, angle, density in zip(rec["fill_indices"], rec["angles_deg"], densities):
            if fill in entry["fills"]:
                raise SystemExit(f"timestep_table: fill {fill} of {key} appears twice")
            entry["fills"][fill] = (angle, density)
    return out


def fmt(mean: float, sem: float | None, nd: int = 2) -> str:
    if not np.isfinite(mean):
        return "-"
    return f"{mean:.{nd}f}" + ("" if sem is None else f" ± {sem:.{nd}f}")


def table(pooled: dict) -> str:
    """The Markdown table of the pooled records."""
    rows = ["| case | experiment | rpm | dt / t_R | dt [s] | fills | angle [deg] | change vs smallest, paired [deg] "
            "(fills) | bulk density [kg/m^3] |",
            "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    groups = defaultdict(dict)
    for (case, exp, rpm, frac), entry in pooled.items():
        groups[(case, exp, rpm)][frac] = entry
    for (case, exp, rpm), by_frac in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2] or 0)):
        f_min = min(by_frac)
        ref = by_frac[f_min]["fills"]
        for frac in sorted(by_frac, reverse=True):
            fills = by_frac[frac]["fills"]
            m, se, n = mean_sem(a for a, _ in fills.values())
            dm, dse, dn = mean_sem(fills[f][0] - ref[f][0] for f in fills
                                   if f in ref and fills[f][0] is not None and ref[f][0] is not None)
            dens, dens_se, _ = mean_sem(d for _, d in fills.values())
            change = "(reference)" if frac == f_min else f"{fmt(dm, dse)} ({dn})"
            rows.append(f"| {case} | {exp} | {'' if rpm is None else f'{rpm:g}'} | {frac:g} | "
                        f"{by_frac[frac]['dt_s']:.3e} | {n} | {fmt(m, se)} | {change} | "
                        f"{fmt(dens, dens_se, 0) if np.isfinite(dens) else ''} |")
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("jsonl", nargs="+", help="timestep_convergence.py outputs (JSON lines)")
    args = ap.parse_args(argv)
    lines = []
    for path in args.jsonl:
        with open(path) as fh:
            lines += [json.loads(s) for s in fh if s.strip().startswith("{")]
    if not lines:
        print("timestep_table: no records in " + ", ".join(args.jsonl), file=sys.stderr)
        return 2
    print(table(pooled_fills(lines)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
