"""Model error: how far a DEM code's answer may sit from another code's with the same named law.

The diagnosis compares one simulator with measurements as if the simulator were exact. It is not:
LIGGGHTS-PUBLIC 3.8 and warpdem, given the same experiment, fill, parameters and named contact law,
differ by 1-2 deg on a repose angle and about 1 % on a bulk density (``docs/liggghts_reference.md``).
A real material's lab data differ from any one code at least that much for reasons no candidate
effect names. Following Kennedy & O'Hagan (J. R. Stat. Soc. B 63:425, 2001) the measured value is

    y_i = f_i(x) + delta_i + e_i,   delta_i ~ N(0, sd_disc,i^2),

and ``sd_disc,i`` enters every z, the adequacy, the evidence and the confirmation through
:class:`validation.misfit.Misfit`. Its default comes from the fidelity suite's residuals
(:func:`fidelity_table`): per quantity, cases c (experiment, scale, law) each give a paired
warpdem - LIGGGHTS difference ``d_c`` (mean over fills that start from the same positions) with
standard error ``se_c``; the true code-to-code bias b_c has

    E[d_c^2] = b_c^2 + se_c^2   =>   sd_disc^2 = max(0, mean_c(d_c^2 - se_c^2))

(the method-of-moments estimate of the mean squared bias, DerSimonian & Laird, Control. Clin.
Trials 7:177, 1986, without the weights). Angles of repose are one family (the same profile fit on
the same particles), so a quantity with fewer than :data:`MIN_CASES` cases takes the pooled estimate
of its family; bulk density is relative (a fraction of the measured mean).

A setting ``model_discrepancy`` of a diagnosis is ``"fidelity"`` (the default: this table),
``"none"`` (the simulator treated as exact, as before) or a mapping observable key -> sd in the
observable's unit (keys not named get 0).
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

__all__ = ["FIDELITY_TABLE", "MIN_CASES", "DiscrepancyTerm", "fidelity_table", "collect_fidelity_cases",
           "resolve_model_discrepancy", "main"]

#: the shipped table, written by ``python -m validation.model_error --collect docs/results/liggghts_experiments/*/``
FIDELITY_TABLE = Path(__file__).with_name("reference") / "model_discrepancy.json"

#: fewer cases than this and a quantity takes its family's pooled estimate
MIN_CASES = 3

#: quantities whose discrepancy is relative to the measured mean (fraction)
RELATIVE = frozenset({"bulk_density"})

#: quantities that share one estimate when they have too few cases of their own
FAMILIES = {"static_angle": "angle", "dynamic_angle": "angle", "pile_angle": "angle"}

#: observables with no code-to-code meaning of a "sd" (a yes/no outcome)
NOT_CONTINUOUS = frozenset({"pile_formed"})


@dataclass(frozen=True)
class DiscrepancyTerm:
    """The model-error sd given to one observable, and where it came from."""

    key: str
    sd: float
    source: str

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "sd": self.sd, "source": self.source}


def collect_fidelity_cases(folders: Iterable[str | Path]) -> list[dict[str, Any]]:
    """One record per (folder, observable, drum speed) of the fidelity suite's ``results.json`` files:
    same-fill paired warpdem - LIGGGHTS differences of the SAME named law (rows comparing different
    physics, e.g. ``tangential_reduce`` forced off, are left out), at least 2 fills, continuous
    observables, and a pile that formed in both codes. Bulk density as a fraction of LIGGGHTS' mean."""
    cases: list[dict[str, Any]] = []
    seen: set[tuple] = set()
    for folder in folders:
        path = Path(folder) / "results.json"
        if not path.is_file():
            continue
        doc = json.loads(path.read_text(encoding="utf-8"))
        meta = doc.get("meta", {})
        for row in doc.get("summary", []):
            paired = row.get("paired_difference")
            q = row.get("observable")
            if not paired or row.get("variant") or q in NOT_CONTINUOUS or int(paired.get("n", 0)) < 2:
                continue
            ref = float(row["liggghts"]["mean"])
            if q == "pile_angle" and ref == 0.0:
                continue  # no pile in either code: nothing to compare
            d = float(paired["mean"])
            se = float(paired.get("sd") or 0.0) / math.sqrt(int(paired["n"]))
            if q in RELATIVE:
                d, se = d / ref, se / ref
            same_runs = (q, row.get("group"), meta.get("law"), round(d, 12), round(se, 12))
            if same_runs in seen:
                continue  # one set of runs summarised in two folders counts once
            seen.add(same_runs)
            cases.append({"folder": Path(folder).name, "observable": q, "group": row.get("group"),
                          "experiment": meta.get("experiment"), "scale": meta.get("scale"),
                          "law": meta.get("law"), "fills": int(paired["n"]), "difference": d,
                          "standard_error": se, "relative": q in RELATIVE})
    return cases


def _moment_sd(cases: list[dict[str, Any]]) -> float:
    """sqrt(max(0, mean(d^2 - se^2))) over ``cases`` (module docstring)."""
    return math.sqrt(max(0.0, sum(c["difference"] ** 2 - c["standard_error"] ** 2 for c in cases) / len(cases)))


def build_table(cases: list[dict[str, Any]], sources: list[str]) -> dict[str, Any]:
    """The per-quantity table from :func:`collect_fidelity_cases` records."""
    by_q: dict[str, list[dict[str, Any]]] = {}
    for c in cases:
        by_q.setdefault(c["observable"], []).append(c)
    family_cases: dict[str, list[dict[str, Any]]] = {}
    for q, cs in by_q.items():
        if q in FAMILIES:
            family_cases.setdefault(FAMILIES[q], []).extend(cs)
    quantities = {}
    for q, cs in sorted(by_q.items()):
        own = _moment_sd(cs)
        fam = FAMILIES.get(q)
        pooled = fam is not None and len(cs) < MIN_CASES
        sd = _moment_sd(family_cases[fam]) if pooled else own
        quantities[q] = {"sd": sd, "relative": q in RELATIVE, "cases": len(cs), "own_estimate": own,
                         "rms_difference": math.sqrt(sum(c["difference"] ** 2 for c in cs) / len(cs)),
                         "estimate": (f"pooled over the {fam} family ({len(family_cases[fam])} cases): "
                                      f"fewer than {MIN_CASES} cases of its own") if pooled else "own cases"}
    return {"format": "warpdem-model-discrepancy/1",
            "what": "model-error sd per quantity: warpdem against LIGGGHTS-PUBLIC 3.8, same named law, same fills",
            "estimator": "sqrt(max(0, mean_c(d_c^2 - se_c^2))) over the cases c (validation/model_error.py)",
            "sources": sources, "quantities": quantities, "cases": cases}


def fidelity_table(path: str | Path | None = None) -> dict[str, Any]:
    """The shipped (or given) model-discrepancy table."""
    p = Path(path) if path is not None else FIDELITY_TABLE
    doc = json.loads(p.read_text(encoding="utf-8"))
    if doc.get("format") != "warpdem-model-discrepancy/1":
        raise ValueError(f"{p}: not a model-discrepancy table (format {doc.get('format')!r})")
    return doc


def resolve_model_discrepancy(spec: str | Mapping[str, float], observations: Any,
                              table: Mapping[str, Any] | None = None) -> tuple[dict[str, float], list[DiscrepancyTerm]]:
    """The model-error sd per observable key, and where each came from.

    spec : ``"fidelity"`` (the fidelity table by quantity), ``"none"`` (all 0) or a mapping key -> sd.
    observations : the measured observables (``validation.observables.Observations``); a relative
        quantity's sd is the table's fraction times the measured mean (the detection limit when censored).
    """
    if isinstance(spec, str):
        if spec not in ("fidelity", "none"):
            raise ValueError(f"model_discrepancy must be 'fidelity', 'none' or a mapping observable -> sd, got {spec!r}")
        if spec == "none":
            return {}, [DiscrepancyTerm(o.key, 0.0, "none (the simulator treated as exact)") for o in observations]
        quantities = (table or fidelity_table())["quantities"]
        sds: dict[str, float] = {}
        terms = []
        for o in observations:
            row = quantities.get(o.quantity)
            if row is None:
                terms.append(DiscrepancyTerm(o.key, 0.0, f"no fidelity case measures {o.quantity}: 0"))
                continue
            level = o.detection_limit if o.is_censored and o.detection_limit else o.mean
            sd = float(row["sd"]) * abs(float(level)) if row["relative"] else float(row["sd"])
            sds[o.key] = sd
            how = f"{row['sd']:.2%} of the measured mean" if row["relative"] else f"{row['sd']:.3g} {o.unit}"
            terms.append(DiscrepancyTerm(o.key, sd, f"fidelity suite, {o.quantity}: {how} ({row['estimate']}, "
                                                    f"{row['cases']} case(s))"))
        return sds, terms
    sds = {str(k): float(v) for k, v in dict(spec).items()}
    return sds, [DiscrepancyTerm(o.key, sds.get(o.key, 0.0), "set by the user" if o.key in sds else "not set: 0")
                 for o in observations]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m validation.model_error",
                                 description="Write the model-discrepancy table from the fidelity suite's results.")
    ap.add_argument("--collect", nargs="+", required=True, help="folders holding results.json (liggghts_experiments)")
    ap.add_argument("--out", default=str(FIDELITY_TABLE))
    args = ap.parse_args(argv)
    folders = sorted(args.collect)
    cases = collect_fidelity_cases(folders)
    if not cases:
        raise SystemExit("no same-law paired cases found in " + ", ".join(folders))
    table = build_table(cases, [Path(f).name for f in folders])
    from warpdem.config_io import write_atomic

    write_atomic(args.out, json.dumps(table, indent=1) + "\n")
    for q, row in table["quantities"].items():
        unit = "of the mean" if row["relative"] else ""
        print(f"{q:15s} sd {row['sd']:.4g} {unit} ({row['cases']} cases; {row['estimate']})")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
