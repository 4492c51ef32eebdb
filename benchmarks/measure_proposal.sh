#!/usr/bin/env bash
# Close the loop of a tie: the lab measures the condition a diagnosis proposed, and the case is
# diagnosed again with that measurement added (the same 20-minute settings, from a DEM cache).
#
#   SRC=docs/results/four_cases_local_noise_h200_2026-11-27 CASE=cohesion benchmarks/measure_proposal.sh OUT
#
# measures what SRC/diagnosis_<case>/diagnosis.json recommended (MEASURE='drum 60rpm {"rpm": 60.0,
# "discard": 1, "record": 2}' names a condition yourself).
#
# SRC holds the case's lab file, truth, diagnosis config and DEM cache (four_cases_from_cache.sh
# writes them). The lab (validation.hidden_effects --measure, fresh fills) is the only reader of the
# truth until the diagnosis has finished; the diagnosis reads OUT/lab_<case>.yaml alone. Then
# benchmarks/score_hidden_effects.py scores it. Run it again to resume (the cache keeps every world;
# CHUNK_S, default 540 s, stops a sitting). Env: DEVICE (cuda), PYTHON (python3), DT (8.2599588e-05,
# the paper lab's step; empty: the recommended one), REPEATS (the lab's fills per condition), EXPORT (a folder to copy the results to).
set -u
out=${1:?usage: measure_proposal.sh OUT}
py=${PYTHON:-python3}
case_=${CASE:?CASE names the case, e.g. cohesion}
src=${SRC:?SRC names the folder of the first diagnosis}
if [ -n "${MEASURE:-}" ]; then  # 'EXPERIMENT CONDITION SETTINGS_JSON'
  read -r experiment condition settings <<< "$MEASURE"
  what=(--measure "$experiment" "$condition" "$settings")
else  # what the first diagnosis recommended (its tie's proposal)
  what=(--measure-recommended "$src/diagnosis_$case_/diagnosis.json")
fi
repo=$(cd "$(dirname "$0")/.." && pwd)
export PYTHONPATH="$repo${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
dt=${DT-8.2599588e-05}  # DT= (empty): each launch's recommended step
mkdir -p "$out/lab" && out=$(cd "$out" && pwd)
if [ ! -f "$out/lab_$case_.yaml" ]; then  # the lab: the only step that reads the truth
  $py -m validation.hidden_effects "${what[@]}" --truth "$src/truth_$case_.json" \
      --lab "$src/lab_$case_.yaml" --into "$out/lab/lab_$case_.yaml" --device "${DEVICE:-cuda}" ${dt:+--dt "$dt"} \
      ${REPEATS:+--repeats "$REPEATS"} > "$out/lab/measure.log" 2>&1 || { tail -3 "$out/lab/measure.log"; exit 2; }
  cp "$out/lab/lab_$case_.yaml" "$out/lab_$case_.yaml"
  cat "$src/dem_cache.jsonl" > "$out/dem_cache.jsonl"
  $py - "$src/diagnose_$case_.yaml" "$out" "$case_" <<'EOF' || exit 2
import sys
from pathlib import Path

import yaml

src, out, case = sys.argv[1], Path(sys.argv[2]), sys.argv[3]
doc = yaml.safe_load(Path(src).read_text())
doc.update(measurements=f"lab_{case}.yaml", cache=str(out / "dem_cache.jsonl"), output=str(out / f"diagnosis_{case}"))
(out / f"diagnose_{case}.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
EOF
fi
t0=$(date +%s)
n=$(ls "$out"/diagnose_run*.log 2>/dev/null | wc -l)
log=$out/diagnose_run$((n + 1)).log
(cd "$out" && timeout -s INT -k 20 "${CHUNK_S:-540}" $py -m validation.cli "diagnose_$case_.yaml" --device "${DEVICE:-cuda}") > "$log" 2>&1
rc=$?
echo "{\"run\": $((n + 1)), \"rc\": $rc, \"wall_s\": $(( $(date +%s) - t0 )), \"date\": \"$(date -u +%FT%TZ)\"}" >> "$out/runs.jsonl"
if [ "$rc" -eq 0 ]; then  # only now does the truth join the diagnosis, for the score
  cp "$src/truth_$case_.json" "$out/"
  $py "$repo/benchmarks/score_hidden_effects.py" "$out" --cases "$case_" --json "$out/score.json" --markdown "$out/score.md"
fi
if [ -n "${EXPORT:-}" ]; then
  mkdir -p "$EXPORT/diagnosis_$case_"
  cp "$out"/*.yaml "$out"/*.jsonl "$out"/*.log "$out/lab/measure.log" "$EXPORT/"
  cp "$out"/score.* "$out"/truth_*.json "$EXPORT/" 2>/dev/null
  cp "$out/diagnosis_$case_"/*.json "$out/diagnosis_$case_"/*.html "$EXPORT/diagnosis_$case_/" 2>/dev/null
fi
[ "$rc" -eq 0 ] && { echo "measure_proposal: diagnosis finished in $(( $(date +%s) - t0 )) s"; exit 0; }
echo "measure_proposal: stopped (rc $rc) after $(( $(date +%s) - t0 )) s: run it again to resume; log $log"
exit 3
