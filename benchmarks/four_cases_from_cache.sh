#!/usr/bin/env bash
# Re-diagnose the four hidden-effect cases (base, rolling, cohesion, shape) at the 20-minute
# settings (design_points_per_parameter 4, replicated_fraction 0.34, designs up front) in ONE
# process (their DEM requests share launches, validation.pooled), from the DEM cache of an earlier
# run with the same settings: the designs do not depend on the data, so only what that cache lacks
# runs (confirmations, refinement waves and forecasts where the best fits moved). Use it after a
# change to the statistics; it is NOT a timing (lone_set_timing.sh is).
#
#   SEED_CACHE=docs/results/.../dem_cache.jsonl benchmarks/four_cases_from_cache.sh OUT
#
# Run it again until it prints "four diagnoses finished" (every finished world is in OUT's cache;
# stop it yourself with CHUNK_S, default 560 s). Each diagnosis reads only OUT/lab_<case>.yaml;
# once all have finished, benchmarks/score_hidden_effects.py (the only reader of the truth files,
# copied beside them) writes OUT/score.md and score.json. Env: KEEP_SETTINGS=1 (keep each config's own
# diagnosis settings instead of the 20-minute ones), SRC (default docs/results/hidden_effects_paper), DEVICE
# (default cuda), PYTHON (default python3), CASES (default "base rolling cohesion shape"), EXPORT (a
# folder to copy each case's diagnosis.json and report.html, the labs, truths, configs, log, cache and
# score to).
set -u
out=${1:?usage: four_cases_from_cache.sh OUT}
py=${PYTHON:-python3}
device=${DEVICE:-cuda}
chunk_s=${CHUNK_S:-560}
cases=${CASES:-base rolling cohesion shape}
repo=$(cd "$(dirname "$0")/.." && pwd)
src=${SRC:-$repo/docs/results/hidden_effects_paper}
export PYTHONPATH="$repo${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
mkdir -p "$out"
out=$(cd "$out" && pwd)
if [ -n "${SEED_CACHE:-}" ]; then  # every seed record OUT's cache lacks joins it (also on a resumed OUT)
  [ -f "$SEED_CACHE" ] || { echo "four_cases_from_cache: SEED_CACHE $SEED_CACHE is not a file" >&2; exit 2; }
  $py - "$SEED_CACHE" "$out/dem_cache.jsonl" <<'EOF' || exit 2
import json
import sys
from pathlib import Path

seed, cache = Path(sys.argv[1]), Path(sys.argv[2])
have = set()
if cache.exists():
    for line in cache.read_text().splitlines():
        try:
            have.add(json.loads(line)["id"])
        except (ValueError, KeyError):
            pass  # a torn line: the diagnosis reports and drops it
new = [line for line in seed.read_text().splitlines() if line.strip() and json.loads(line)["id"] not in have]
with open(cache, "a") as fh:
    fh.writelines(line + "\n" for line in new)
print(f"four_cases_from_cache: {len(new)} record(s) of {seed} joined {cache}")
EOF
  echo "$SEED_CACHE" >> "$out/seeded_from"
elif [ ! -f "$out/dem_cache.jsonl" ]; then
  echo "four_cases_from_cache: SEED_CACHE must name a DEM cache (jsonl) for a new OUT" >&2; exit 2
fi
configs=()
for c in $cases; do
  cfg=$out/diagnose_$c.yaml
  configs+=("diagnose_$c.yaml")
  [ -f "$cfg" ] && continue
  cp "$src/lab_$c.yaml" "$src/truth_$c.json" "$out/" || exit 2
  $py - "$src/diagnose_$c.yaml" "$cfg" "$out" "$c" <<'EOF' || exit 2
import os
import sys
from pathlib import Path

import yaml

src, dst, out, case = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[4]
doc = yaml.safe_load(Path(src).read_text())
doc["cache"] = str(out / "dem_cache.jsonl")
doc["output"] = str(out / f"diagnosis_{case}")
if os.environ.get("KEEP_SETTINGS") != "1":  # the 20-minute settings, unless the configs' own are kept
    doc.setdefault("diagnosis", {}).update(designs_up_front=True, replicated_fraction=0.34, design_points_per_parameter=4)
dst.write_text(yaml.safe_dump(doc, sort_keys=False))
from validation.config import load_diagnosis_config  # noqa: E402  (checks the config, runs nothing)

load_diagnosis_config(dst)
EOF
done
t0=$(date +%s)
n=$(ls "$out"/diagnose_run*.log 2>/dev/null | wc -l)
log=$out/diagnose_run$((n + 1)).log
(cd "$out" && timeout -s INT -k 20 "$chunk_s" $py -m validation.cli "${configs[@]}" --device "$device") > "$log" 2>&1
rc=$?
grep -E '^DEM: [a-z]+: [0-9]+ world' "$log" | sed 's/^/    /'
echo "{\"run\": $((n + 1)), \"rc\": $rc, \"wall_s\": $(( $(date +%s) - t0 )), \"date\": \"$(date -u +%FT%TZ)\"}" >> "$out/runs.jsonl"
if [ "$rc" -eq 0 ]; then  # the truths are read only now, after every diagnosis has finished
  $py "$repo/benchmarks/score_hidden_effects.py" "$out" --cases $cases --json "$out/score.json" --markdown "$out/score.md"
fi
if [ -n "${EXPORT:-}" ]; then
  mkdir -p "$EXPORT"
  cp "$out/dem_cache.jsonl" "$out/runs.jsonl" "$log" "$out"/lab_*.yaml "$out"/truth_*.json "$out"/diagnose_*.yaml "$EXPORT/"
  cp "$out/score.json" "$out/score.md" "$EXPORT/" 2>/dev/null
  for c in $cases; do
    [ -d "$out/diagnosis_$c" ] || continue
    mkdir -p "$EXPORT/diagnosis_$c"
    cp "$out/diagnosis_$c"/*.json "$out/diagnosis_$c"/*.html "$EXPORT/diagnosis_$c/" 2>/dev/null
  done
fi
if [ "$rc" -eq 0 ]; then echo "four_cases_from_cache: four diagnoses finished in $(( $(date +%s) - t0 )) s"; exit 0; fi
echo "four_cases_from_cache: stopped (rc $rc) after $(( $(date +%s) - t0 )) s: run it again (the cache resumes); log $log"
exit 3
