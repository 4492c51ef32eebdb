"""Score the diagnoses of the hidden-effects proof against the generator's truth (issue 11).

The diagnoses (``benchmarks/hidden_effects_proof.sh OUT diagnose``) read only their
``lab_<case>.yaml``; this script is the only reader of ``truth_<case>.json`` and it runs
afterwards. For each case it states what was hidden, what the diagnosis ranked first (with the
evidence gap to the runner-up), what it added, the error history (chi^2/dof and the largest DEM
|z| before and after) and the recalibrated parameters next to the true ones.

    python benchmarks/score_hidden_effects.py docs/results/hidden_effects_paper
    python benchmarks/score_hidden_effects.py OUT --json OUT/score.json --markdown OUT/score.md
    python benchmarks/score_hidden_effects.py OUT --cases base rolling shape   (a subset was diagnosed)

A case of the engine-as-lab generator (``validation.hidden_effects``) passes when the top-ranked
candidate is the hidden effect (for the base case: the verdict "no effect is needed"). A case whose
truth lists its ``hidden_effects`` (the LIGGGHTS lab, ``validation.reference.liggghts_labs``) is
judged on the verdict: right when the diagnosis added exactly those effects, in either order (two
hidden effects: both added), and did not disown them as "none of the candidates explains these
measurements"; none hidden: the base model adequate and nothing added; an effect outside the
candidates (``outside_candidates``): the diagnosis says none of its candidates explains the data
(whatever it studied on the way). That verdict is read from ``verdict.none_of_candidates`` when the
diagnosis writes it (validation/diagnose.py does since 2026-11-28: True also when effects were
added but an observable stays beyond the cut-off), else from the headline or the last round's
reason in the older words (:data:`NONE_OF_CANDIDATES_WORDS`).
The recalibration's agreement is reported separately, since a right effect with an imperfect
recalibration is a different failure from a wrong effect.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

CASES = ("base", "rolling", "cohesion", "shape")
#: how validation/diagnose.py words "none of the candidate effects explains the data" (headline,
#: or the reason of the round that chose nothing), compared in lower case
NONE_OF_CANDIDATES_WORDS = ("none of the candidate effects explains", "the missing effect is not among the candidates",
                            "none of my candidates")


def hidden_effect(truth: dict[str, Any]) -> str | None:
    """The candidate-effect name of what the generator hid (None: the base model is right)."""
    hidden = truth["hidden"]
    if hidden.get("shape"):
        return "shape"
    law = hidden.get("law", {})
    if law.get("cohesion", "none") != "none":
        return "cohesion"
    if law.get("rolling", "none") != "none":
        return "rolling_resistance"
    return None


def expected(truth: dict[str, Any]) -> tuple[frozenset[str], bool, str]:
    """(the hidden candidate effects, whether an effect outside the candidates is hidden, the rule:
    "top" for an engine-as-lab truth, "added" for a truth that lists its ``hidden_effects``)."""
    if "hidden_effects" in truth:
        return frozenset(truth["hidden_effects"]), bool(truth.get("outside_candidates")), "added"
    h = hidden_effect(truth)
    return frozenset([h] if h else []), False, "top"


def hidden_label(truth: dict[str, Any]) -> str | None:
    """What was hidden, in one short label: an effect, ``a+b``, ``outside`` or None (nothing)."""
    effects, outside, rule = expected(truth)
    if rule == "top":
        return hidden_effect(truth)
    if outside:
        return "outside the candidates"
    return "+".join(sorted(effects)) or None


def none_of_candidates(diag: dict[str, Any]) -> str | None:
    """Where a diagnosis says that none of its candidates explains the data: "verdict field" (its
    ``verdict.none_of_candidates``, which decides when present), "headline", "round reason", or None."""
    verdict = diag["verdict"]
    if "none_of_candidates" in verdict:
        return "verdict field" if verdict["none_of_candidates"] else None
    if any(w in (verdict.get("headline") or "").lower() for w in NONE_OF_CANDIDATES_WORDS):
        return "headline"
    rounds = diag.get("rounds") or []
    if rounds and rounds[-1].get("chosen") is None and any(
            w in (rounds[-1].get("reason") or "").lower() for w in NONE_OF_CANDIDATES_WORDS):
        return "round reason"
    return None


def case_found(truth: dict[str, Any], row: dict[str, Any], diag: dict[str, Any]) -> bool:
    """Whether the diagnosis got the case right (module docstring)."""
    effects, outside, rule = expected(truth)
    verdict = diag["verdict"]
    if rule == "top":
        hidden = hidden_effect(truth)
        return row["top"] == hidden if hidden else bool(verdict["base_adequate"] and not row["added"])
    if outside:
        return row["none_of_candidates"] is not None
    if not effects:
        return bool(verdict["base_adequate"] and not row["added"])
    return set(row["added"]) == set(effects) and row["none_of_candidates"] is None


def score_case(folder: Path, case: str) -> dict[str, Any]:
    """One case's row: hidden vs found, evidence, error history and parameters."""
    truth = json.loads((folder / f"truth_{case}.json").read_text())
    result_path = folder / f"diagnosis_{case}" / "diagnosis.json"
    hidden = hidden_label(truth)
    if not result_path.exists():
        return {"case": case, "hidden": hidden, "finished": False}
    diag = json.loads(result_path.read_text())
    effects, _, rule = expected(truth)
    verdict = diag["verdict"]
    versions = diag["error_history"]["versions"]
    row: dict[str, Any] = {
        "case": case, "finished": True, "hidden": hidden, "hidden_words": truth["words"], "rule": rule,
        "headline": verdict["headline"], "base_adequate": verdict["base_adequate"],
        "added": list(verdict["added_effects"]), "none_of_candidates": none_of_candidates(diag),
        "history": [{"version": v["version"], "chi2_per_dof": v["chi2_per_dof"], "max_abs_z": v["max_abs_z"],
                     "n_within": v["n_within"], "n_observables": v["n_observables"]} for v in versions],
        "dem_seconds": diag["forward_model"]["seconds"], "dem_runs": diag["forward_model"]["runs"],
    }
    if diag["rounds"]:
        ranked = sorted(diag["rounds"][0]["candidates"], key=lambda c: c["rank"])
        row["ranking"] = [{"effect": c["effect"]["name"], "ln_bayes": c["log_bayes_vs_current"],
                           "max_abs_z_dem": c["max_abs_z"]} for c in ranked]
        row["top"] = ranked[0]["effect"]["name"]
        row["ln_bayes_gap"] = (ranked[0]["log_bayes_vs_current"] - ranked[1]["log_bayes_vs_current"]
                               if len(ranked) > 1 else None)
    else:
        row["ranking"], row["top"], row["ln_bayes_gap"] = [], None, None
    row["found"] = case_found(truth, row, diag)
    # a hidden effect the diagnosis declared tied with the top one (it then proposes a measurement)
    tied = list(diag["rounds"][0].get("tied") or []) if diag["rounds"] else []
    row["tied"] = tied
    row["tied_not_first"] = bool(len(effects) == 1 and not row["found"] and set(effects) <= set(tied)
                                 and row["top"] in tied)
    final = versions[-1]
    row["final_within_2_sigma"] = final["n_within"] == final["n_observables"]
    conf = diag["versions"][-1].get("confirmation") or {}
    row["local_noise"] = [o["key"] for o, src in zip(diag["observables"], conf.get("noise_source") or []) if src == "local"]
    true_p = truth["parameters"]
    best = diag["versions"][-1].get("best_fit") or {}
    best_x = best.get("parameters") if isinstance(best, dict) and "parameters" in best else best
    row["parameters"] = {k: {"recalibrated": float(v), "true": true_p.get(k)} for k, v in (best_x or {}).items()
                         if isinstance(v, (int, float))}
    return row


def truth_cases(folder: Path) -> list[str]:
    """Every case with a ``truth_<case>.json`` in ``folder``: the engine-as-lab four in their order, then the rest."""
    found = sorted(p.name[len("truth_"):-len(".json")] for p in folder.glob("truth_*.json"))
    return [c for c in CASES if c in found] + [c for c in found if c not in CASES]


def markdown(rows: list[dict[str, Any]]) -> str:
    """A table a person reads: one line per case, then the parameters."""
    out = ["| case (hidden) | ranked first (ln B) | runner-up (ln B) | found | added | chi2/dof before -> after "
           "| max DEM abs z before -> after | all within 2 sigma after |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if not r["finished"]:
            out.append(f"| {r['case']} ({r['hidden']}) | not finished | | | | | | |")
            continue
        rk = r["ranking"]
        first = f"{rk[0]['effect']} ({rk[0]['ln_bayes']:+.1f})" if rk else "- (base adequate)"
        second = f"{rk[1]['effect']} ({rk[1]['ln_bayes']:+.1f})" if len(rk) > 1 else "-"
        h = r["history"]
        chi = " -> ".join(f"{v['chi2_per_dof']:.2f}" for v in h)
        z = " -> ".join(f"{v['max_abs_z']:.1f}" for v in h)
        out.append(f"| {r['case']} ({r['hidden'] or 'none'}) | {first} | {second} | "
                   f"{'yes' if r['found'] else 'NO, tied with it' if r.get('tied_not_first') else 'NO'} | "
                   f"{', '.join(r['added']) or '-'}{' (none of the candidates explains it)' if r.get('none_of_candidates') else ''} "
                   f"| {chi} | {z} | "
                   f"{'yes' if r['final_within_2_sigma'] else 'no'}"
                   + (f" ({len(r['local_noise'])} judged with their own fills' scatter)" if r.get("local_noise") else "")
                   + " |")
    out.append("")
    for r in rows:
        if r.get("parameters"):
            pars = ", ".join(f"{k} {v['recalibrated']:.3g} (true {v['true']:.3g})"
                             for k, v in r["parameters"].items() if v["true"] is not None)
            out.append(f"- {r['case']}: {pars}")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="the proof's output folder (truth_*.json, diagnosis_*/)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows as JSON here")
    ap.add_argument("--markdown", type=Path, default=None, help="write the table as Markdown here")
    ap.add_argument("--cases", nargs="+", default=None,
                    help="score only these cases (default: every truth_<case>.json in the folder); the verdict "
                         "line names how many")
    args = ap.parse_args(argv)
    cases = [c.replace("+", "_") for c in args.cases] if args.cases else truth_cases(args.folder)
    if not cases:
        print(f"score_hidden_effects: no truth_<case>.json in {args.folder}", file=sys.stderr)
        return 2
    missing = [c for c in cases if not (args.folder / f"truth_{c}.json").exists()]
    if missing:
        print(f"score_hidden_effects: no truth file for {', '.join(missing)} in {args.folder}", file=sys.stderr)
        return 2
    rows = [score_case(args.folder, c) for c in cases]
    found = sum(bool(r.get("found")) for r in rows)
    tied = sum(bool(r.get("tied_not_first")) for r in rows)
    text = (f"Hidden effect found in {found} of {len(rows)} cases"
            + (f"; in {tied} more it tied with the top candidate (the diagnosis then proposes a measurement)"
               if tied else "") + ".\n\n" + markdown(rows))
    print(text)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    if args.markdown:
        args.markdown.write_text(text)
    return 0 if found == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
