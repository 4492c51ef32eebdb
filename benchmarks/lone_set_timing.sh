#!/usr/bin/env bash
# Time ONE paper-scale measurement set's diagnosis alone (issue 11's target: <= 20 min on one H100),
# from an empty DEM cache, with designs_up_front on: the base model's and the three candidates'
# designs go into one launch per experiment before the base study starts.
#
#   benchmarks/lone_set_timing.sh OUT [all | designs | diagnose | total]     (default: all)
#
# One call of this script is one chunk; it stops itself after CHUNK_S seconds (default 540, so a
# 10-minute GPU call keeps time to start and copy back), and the next call resumes from the DEM
# cache in OUT (a launch cut in the middle is lost and runs again). Run the same command in 2-3
# calls until it prints "diagnosis finished"; every call prints the wall time of its chunk and the
# totals so far.
#   designs   the up-front designs (validation.diagnose.run_planned_designs, the diagnosis's own
#             up-front call, here via `--prefetch`), as two merged calls that each end inside a
#             chunk: baffle + cylinder (156 + 156 worlds), then the drum (468 worlds)
#   diagnose  the diagnosis itself (designs_up_front: true: its up-front call finds the designs
#             in the cache, or runs them if `designs` was skipped)
#   all       designs (the steps not done yet), then diagnose, while the chunk lasts
#   total     only print the totals (no GPU)
# The first call sets OUT up: lab_$CASE.yaml and diagnose_$CASE.yaml copied from SRC, the config's
# cache pointed at OUT/dem_cache.jsonl (refused if that file exists: the timing starts from an
# empty cache), never at SRC's dem_cache.jsonl.
#
# Env: CASE (rolling | base | cohesion | shape; default rolling), DEVICE (default cuda),
#      REPLICATED_FRACTION (diagnosis.replicated_fraction of the timed config, e.g. 0.34; default: the
#      source config's, 1.0: every design set replicated), DESIGN_POINTS (diagnosis.
#      design_points_per_parameter of the timed config, e.g. 4; default: the source config's, 6),
#      PYTHON (default python3), CHUNK_S (default 540), MIN_STEP_S (a step is not started with less
#      left, default 60), SRC (default docs/results/hidden_effects_paper), EXPORT (a folder to copy
#      the results to at the end of each call: chunks.jsonl, summary.json, logs.txt, the cache,
#      diagnosis.json and dem_timing.json; 6 files), SEED_CACHE (a DEM cache of an earlier run of the
#      same settings, copied in at set-up: a re-diagnosis that re-runs only what that cache lacks, e.g.
#      after a change to the statistics; NOT an empty-cache timing, and summary.json says
#      "seeded_from").
# On the device machine keep OUT in an ignored folder of the repository (e.g. results/lone_set) so
# a warm machine keeps it between calls, and pass EXPORT=$OUT; if the machine went back, put the
# exported files into that folder again and carry it.
set -u
out=${1:?usage: lone_set_timing.sh OUT [all|designs|diagnose|total]}
phase=${2:-all}
case_=${CASE:-rolling}
device=${DEVICE:-cuda}
py=${PYTHON:-python3}
chunk_s=${CHUNK_S:-540}
min_step_s=${MIN_STEP_S:-60}
repo=$(cd "$(dirname "$0")/.." && pwd)
src=${SRC:-$repo/docs/results/hidden_effects_paper}
case "$phase" in all|designs|diagnose|total) ;; *) echo "unknown phase $phase" >&2; exit 2 ;; esac
export PYTHONPATH="$repo${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
mkdir -p "$out/logs"
out=$(cd "$out" && pwd)
cfg=$out/diagnose_$case_.yaml
t0=$(date +%s)
chunk=$(( $(cat "$out/chunk_count" 2>/dev/null || echo 0) + 1 ))
[ "$phase" = total ] || echo "$chunk" > "$out/chunk_count"

if [ ! -f "$cfg" ] && [ "$phase" != total ]; then
  if [ -e "$out/dem_cache.jsonl" ]; then
    echo "lone_set_timing: $out/dem_cache.jsonl exists: the timing starts from an empty DEM cache; use a fresh OUT" >&2
    exit 2
  fi
  cp "$src/lab_$case_.yaml" "$out/" || exit 2
  $py - "$src/diagnose_$case_.yaml" "$cfg" "$out" "$case_" "${REPLICATED_FRACTION:-}" "${DESIGN_POINTS:-}" <<'EOF' || exit 2
import sys
from pathlib import Path

import yaml

src, dst, out, case, fraction, points = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[4], sys.argv[5], sys.argv[6]
doc = yaml.safe_load(Path(src).read_text())
doc["cache"] = str(out / "dem_cache.jsonl")  # a fresh cache, never the one beside the source config
doc["output"] = str(out / f"diagnosis_{case}")
doc.setdefault("diagnosis", {})["designs_up_front"] = True
if fraction:  # REPLICATED_FRACTION: the share of design sets with replicates (validation.design.design_replicates)
    doc["diagnosis"]["replicated_fraction"] = float(fraction)
if points:  # DESIGN_POINTS: Latin-hypercube sets per parameter of every model version's design
    doc["diagnosis"]["design_points_per_parameter"] = int(points)
assert Path(doc["cache"]).resolve() != (Path(src).parent / "dem_cache.jsonl").resolve()
dst.write_text(yaml.safe_dump(doc, sort_keys=False))
from validation.config import load_diagnosis_config  # noqa: E402  (checks the config, runs nothing)

load_diagnosis_config(dst)
print(f"lone_set_timing: set up {dst} (cache {doc['cache']}, designs_up_front: true, "
      f"replicated_fraction: {doc['diagnosis'].get('replicated_fraction', 1.0)}, "
      f"design_points_per_parameter: {doc['diagnosis'].get('design_points_per_parameter')})")
EOF
  if [ -n "${SEED_CACHE:-}" ]; then
    [ -f "$SEED_CACHE" ] || { echo "lone_set_timing: SEED_CACHE $SEED_CACHE is not a file" >&2; exit 2; }
    cat "$SEED_CACHE" > "$out/dem_cache.jsonl" && echo "$SEED_CACHE" > "$out/seeded_from"
    echo "lone_set_timing: DEM cache seeded from $SEED_CACHE ($(wc -l < "$out/dem_cache.jsonl") runs): not an empty-cache timing"
  fi
fi

left() { echo $(( chunk_s - ($(date +%s) - t0) )); }
status=cut
# step NAME ARGS...: one python process of the chunk, stopped (INT, then KILL) when the chunk ends
step() {
  local name=$1; shift
  [ -f "$out/done_$name" ] && return 0
  local budget; budget=$(left)
  if [ "$budget" -lt "$min_step_s" ]; then
    echo "lone_set_timing: $budget s left in this chunk: $name waits for the next call"; return 1
  fi
  local log="$out/logs/chunk$(printf %02d "$chunk")_$name.log" s0 rc
  s0=$(date +%s)
  echo "lone_set_timing: chunk $chunk: $name (at most $budget s) ..."
  (cd "$out" && timeout -s INT -k 20 "$budget" $py -m validation.cli "$cfg" --device "$device" "$@") > "$log" 2>&1
  rc=$?
  grep -E '^DEM: [a-z]+: [0-9]+ world' "$log" | sed 's/^/    /'
  echo "{\"chunk\": $chunk, \"step\": \"$name\", \"rc\": $rc, \"wall_s\": $(( $(date +%s) - s0 )), \"date\": \"$(date -u +%FT%TZ)\"}" >> "$out/chunks.jsonl"
  if [ "$rc" -eq 0 ]; then
    touch "$out/done_$name"; echo "lone_set_timing: $name done in $(( $(date +%s) - s0 )) s"; return 0
  fi
  echo "lone_set_timing: $name stopped (rc $rc) after $(( $(date +%s) - s0 )) s: run the same command again (the DEM cache resumes); log $log"
  return 1
}

if [ "$phase" = designs ] || [ "$phase" = all ]; then
  step designs_baffle_cylinder --prefetch --experiments baffle cylinder && \
    step designs_drum --prefetch --experiments drum && status=designs_done
fi
if [ "$phase" = diagnose ] || { [ "$phase" = all ] && [ "$status" = designs_done ]; }; then
  step diagnose && status=finished
fi

# totals: every chunk's steps, the DEM launches of every log, the diagnosis's own timing record
$py - "$out" "$case_" "$phase" "$(( $(date +%s) - t0 ))" <<'EOF'
import json
import re
import sys
from pathlib import Path

out, case, phase, chunk_wall = Path(sys.argv[1]), sys.argv[2], sys.argv[3], int(sys.argv[4])
steps = [json.loads(line) for line in (out / "chunks.jsonl").read_text().splitlines()] if (out / "chunks.jsonl").exists() else []
launches = []
for log in sorted((out / "logs").glob("chunk*.log")):
    for m in re.finditer(r"^DEM: (\w+): (\d+) world\(s\) in ([\d.]+) s", log.read_text(), re.M):
        launches.append({"log": log.name, "experiment": m[1], "worlds": int(m[2]), "wall_s": float(m[3])})
timing_path = out / f"diagnosis_{case}" / "dem_timing.json"
finished = (out / "done_diagnose").exists()
timing = json.loads(timing_path.read_text()) if finished and timing_path.exists() else None
last = [s for s in steps if s["step"] == "diagnose"]
dem_all = sum(x["wall_s"] for x in launches)
summary = {
    "case": case, "finished": finished, "chunks": len({s["chunk"] for s in steps}),
    "this_chunk_wall_s": chunk_wall,
    "sum_of_step_walls_s": sum(s["wall_s"] for s in steps),
    "dem_launch_s": round(dem_all, 1), "dem_worlds": sum(x["worlds"] for x in launches),
    "launches": launches, "steps": steps,
    "designs_up_front": timing.get("designs_up_front") if timing else None,
    "seeded_from": (out / "seeded_from").read_text().strip() if (out / "seeded_from").exists() else None,
}
if finished and last:
    # one uninterrupted run: every launch once + the statistics of the last (complete) diagnose step
    last_log = out / "logs" / f"chunk{last[-1]['chunk']:02d}_diagnose.log"
    last_dem = sum(x["wall_s"] for x in launches if x["log"] == last_log.name)
    summary["estimate_uninterrupted_s"] = round(dem_all + last[-1]["wall_s"] - last_dem, 1)
(out / "summary.json").write_text(json.dumps(summary, indent=1))
print(f"lone_set_timing: this chunk {chunk_wall} s; {summary['chunks']} chunk(s): steps {summary['sum_of_step_walls_s']} s "
      f"in all, DEM launches {summary['dem_launch_s']} s for {summary['dem_worlds']} worlds")
if finished:
    print("lone_set_timing: diagnosis finished; one uninterrupted run would take about "
          f"{summary.get('estimate_uninterrupted_s')} s (every launch once + the last diagnose step's statistics; "
          "the sum of step walls also counts each resume's start-up and replay)")
    if timing:
        print(f"lone_set_timing: dem_timing.json: wall {timing['wall_s']} s of the last step, designs up front: "
              f"{json.dumps(timing.get('designs_up_front'))}")
else:
    print("lone_set_timing: not finished: run the same command again")
EOF

if [ -n "${EXPORT:-}" ]; then
  mkdir -p "$EXPORT"
  for f in chunks.jsonl summary.json dem_cache.jsonl "diagnosis_$case_/diagnosis.json" "diagnosis_$case_/dem_timing.json"; do
    [ -f "$out/$f" ] && cp "$out/$f" "$EXPORT/"
  done
  cat "$out"/logs/chunk*.log > "$EXPORT/logs.txt" 2>/dev/null
fi
# 0: this phase is complete; 3: run the same command again
if [ "$status" = finished ] || [ "$phase" = total ] || { [ "$phase" = designs ] && [ "$status" = designs_done ]; }; then
  exit 0
fi
exit 3
