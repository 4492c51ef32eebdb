"""warpdem against LIGGGHTS-PUBLIC 3.8 on single contacts (issue 27, item 2).

Runs every case of :mod:`validation.reference.contact_cases` (or those whose name contains one
of ``--cases``) in LIGGGHTS and in warpdem on the CPU, prints the comparison table (case,
quantity, LIGGGHTS, warpdem, relative difference, tolerance, verdict) and writes it to ``--out``
(default ``docs/results/liggghts_contact/``):

* ``comparison.json``: every row, each case's settings and laws, the LIGGGHTS version, the
  warpdem version and source digest, the command, the date and the run times;
* ``comparison.md``: the table in markdown, the cases and the notes on known differences;
* ``decks/<case>/``: the LIGGGHTS deck, data file and STL of every case.

    python benchmarks/liggghts_contact.py                                  # all cases, ~25 s on 2 cores
    python benchmarks/liggghts_contact.py --cases pull_off --out /tmp/c    # a subset, written elsewhere
"""
from __future__ import annotations

import argparse
import dataclasses
import datetime as _dt
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

VERDICT = {True: "ok", False: "DIFFERS"}
DECK_FILES = ("in.deck", "spheres.data", "wall.stl")  # enough to rerun the LIGGGHTS side


def _git_commit() -> str | None:
    """HEAD of the working tree (its uncommitted edits are in ``warpdem.source_sha256``)."""
    import subprocess

    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              timeout=10).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def markdown(rows, cases, meta: dict) -> str:
    """The comparison as a markdown page (table, then the cases and the notes)."""
    lines = ["# warpdem vs LIGGGHTS-PUBLIC 3.8: single contacts", "",
             f"LIGGGHTS: {meta['liggghts_version']}; warpdem {meta['warpdem']['warpdem']} "
             f"(sources {meta['warpdem']['source_sha256']}, commit {meta['git_commit']}); {meta['date']}; "
             f"{meta['machine']}; {meta['wall_s']} s.", "",
             f"Command: `{meta['command']}`", "",
             "Relative difference = (warpdem - LIGGGHTS) / |LIGGGHTS|. Held: the case's definitions match "
             "and the figure must agree within the tolerance; *known*: the case runs a warpdem definition "
             "that differs from LIGGGHTS' on purpose (see the notes).", "",
             "| case | quantity | LIGGGHTS | warpdem | rel. diff. | tolerance | held / known | verdict |",
             "| --- | --- | ---: | ---: | ---: | ---: | --- | --- |"]
    for r in rows:
        lines.append(f"| {r.case} | {r.quantity} [{r.unit}] | {r.liggghts:.6g} | {r.warpdem:.6g} | "
                     f"{100 * r.rel_diff:+.4f} % | {100 * r.tolerance:.0f} % | "
                     f"{'held' if r.expect_agreement else 'known'} | {VERDICT[r.agrees]} |")
    lines += ["", "## Cases", "", "| case | pair | warpdem law | LIGGGHTS law | dt [s] | steps |",
              "| --- | --- | --- | --- | ---: | ---: |"]
    for c in cases:
        lines.append(f"| {c.name} | {'sphere-wall' if c.partner == 'wall' else 'sphere-sphere'} | "
                     f"{c.law_text('warpdem')} | {c.law_text('liggghts')} | {c.dt:g} | {c.steps} |")
    notes = sorted({c.note for c in cases if c.note})
    if notes:
        lines += ["", "## Notes on known differences", ""] + [f"- {n}" for n in notes]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="*", default=None, help="run the cases whose name contains one of these")
    ap.add_argument("--out", default=str(ROOT / "docs" / "results" / "liggghts_contact"),
                    help="folder of comparison.json, comparison.md and decks/")
    ap.add_argument("--jobs", type=int, default=4, help="LIGGGHTS runs at a time (threads)")
    args = ap.parse_args(argv)

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from warpdem.bench_settled_bed import quiet_warp

    quiet_warp()
    from calibration.campaign_records import code_version
    from validation.reference import contact_cases as cc
    from validation.reference.liggghts import liggghts_executable, liggghts_version

    if liggghts_executable() is None:
        print("LIGGGHTS 3.8 not found: install it with scripts/install_liggghts.sh", file=sys.stderr)
        return 2
    cases = [c for c in cc.CASES if not args.cases or any(s in c.name for s in args.cases)]
    if not cases:
        print(f"no case matches {args.cases}; known: {[c.name for c in cc.CASES]}", file=sys.stderr)
        return 2
    out = Path(args.out)
    shutil.rmtree(out / "decks", ignore_errors=True)  # only this run's decks stay
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="liggghts_contact_") as tmp:
        rows, histories = cc.compare_cases(cases, tmp, liggghts_workers=args.jobs)
        for c in cases:  # keep what produced each LIGGGHTS figure
            dst = out / "decks" / c.name
            dst.mkdir(parents=True, exist_ok=True)
            for name in DECK_FILES:
                src = Path(tmp) / c.name / name
                if src.exists():
                    shutil.copy(src, dst / name)
    wall = time.perf_counter() - t0

    width = max(len(r.case) for r in rows)
    print(f"{'case':{width}s}  {'quantity':28s} {'LIGGGHTS':>13s} {'warpdem':>13s} {'rel. diff':>10s}  verdict")
    for r in rows:
        kind = "" if r.expect_agreement else " (known difference)"
        print(f"{r.case:{width}s}  {r.quantity:28s} {r.liggghts:13.6g} {r.warpdem:13.6g} "
              f"{100 * r.rel_diff:+9.4f}%  {VERDICT[r.agrees]}{kind}")
    held = [r for r in rows if r.expect_agreement]
    failed = [r for r in held if not r.agrees]
    print(f"{len(held) - len(failed)}/{len(held)} held figures within tolerance; largest held |rel. diff| "
          f"{100 * max(abs(r.rel_diff) for r in held):.4f} %; {wall:.1f} s")

    meta = {
        "date": _dt.datetime.now().isoformat(timespec="seconds"),
        "command": " ".join(["python", os.path.relpath(__file__, ROOT), *(argv if argv is not None else sys.argv[1:])]),
        "liggghts_version": liggghts_version(),
        "liggghts_executable": liggghts_executable(),
        "warpdem": code_version(),
        "git_commit": _git_commit(),
        "machine": f"{platform.system()} {platform.machine()}, {os.cpu_count()} CPU cores",
        "wall_s": round(wall, 1),
    }
    out.mkdir(parents=True, exist_ok=True)
    record = {
        **meta,
        "tolerances": cc.TOLERANCES,
        "rows": [r.as_dict() for r in rows],
        "cases": [{**dataclasses.asdict(c), "warpdem_law": c.law_text("warpdem"),
                   "liggghts_law": c.law_text("liggghts"),
                   "liggghts_wall_s": round(histories[c.name]["liggghts"].wall_s, 3),
                   "warpdem_wall_s": round(histories[c.name]["warpdem"].wall_s, 3)} for c in cases],
    }
    (out / "comparison.json").write_text(json.dumps(record, indent=1) + "\n")
    (out / "comparison.md").write_text(markdown(rows, cases, meta))
    print(f"wrote {out / 'comparison.json'} and {out / 'comparison.md'}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
