#!/usr/bin/env bash
# Diagnose the LIGGGHTS labs (validation/reference/liggghts_labs.py) on a GPU, one case after
# another, each timed, then score them (issue 28, item 5):
#
#   benchmarks/liggghts_labs_diagnose.sh OUT [LABS]
#
# LABS (default docs/results/liggghts_labs_quick) holds lab_<case>.yaml, diagnose_<case>.yaml and
# truth_<case>.json; LIGGGHTS is not needed here (the labs are files). The labs and configs are
# copied into OUT, so the DEM cache (the configs' `cache: dem_cache.jsonl`, relative to the config)
# is OUT/dem_cache.jsonl, shared by the cases (the designs do not depend on the data: the first case
# runs them, later cases find them there). Each diagnosis reads only OUT/lab_<case>.yaml; the truths
# are copied into OUT only after the diagnoses, for benchmarks/score_hidden_effects.py (their only
# reader), which writes OUT/score.md and OUT/score.json.
#
# A case whose OUT/diagnosis_<case>/diagnosis.json exists is skipped (FORCE=1 reruns it). A case is
# stopped after CHUNK_S seconds (default 560: one 10-minute GPU call); run the script again to resume
# it from the cache. Each attempt appends {"case", "rc", "wall_s", "date", "device"} to OUT/times.jsonl.
# Env: DEVICE (default cuda), PYTHON (default python3), CASES (default: every diagnose_<case>.yaml in
# LABS), CHUNK_S, FORCE, PROCESSES (CPU worker processes, passed as --processes; default the CLI's).
set -u
out=${1:?usage: liggghts_labs_diagnose.sh OUT [LABS]}
repo=$(cd "$(dirname "$0")/.." && pwd)
labs=${2:-$repo/docs/results/liggghts_labs_quick}
py=${PYTHON:-python3}
device=${DEVICE:-cuda}
chunk_s=${CHUNK_S:-560}
procs=()
[ -n "${PROCESSES:-}" ] && procs=(--processes "$PROCESSES")
export PYTHONPATH="$repo${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
[ -d "$labs" ] || { echo "liggghts_labs_diagnose: no lab folder $labs" >&2; exit 2; }
if [ -n "${CASES:-}" ]; then
  cases=${CASES//+/_}
else
  cases=$(cd "$labs" && ls diagnose_*.yaml 2>/dev/null | sed 's/^diagnose_//; s/\.yaml$//' | tr '\n' ' ')
fi
[ -n "$cases" ] || { echo "liggghts_labs_diagnose: no diagnose_<case>.yaml in $labs" >&2; exit 2; }
mkdir -p "$out"
out=$(cd "$out" && pwd)
for c in $cases; do
  [ -f "$labs/lab_$c.yaml" ] && [ -f "$labs/diagnose_$c.yaml" ] || {
    echo "liggghts_labs_diagnose: $labs lacks lab_$c.yaml or diagnose_$c.yaml" >&2; exit 2; }
  cp "$labs/lab_$c.yaml" "$labs/diagnose_$c.yaml" "$out/"
done
all_done=1
for c in $cases; do
  if [ -f "$out/diagnosis_$c/diagnosis.json" ] && [ -z "${FORCE:-}" ]; then
    echo "case $c: finished before (diagnosis_$c/diagnosis.json; FORCE=1 reruns it)"
    continue
  fi
  t0=$(date +%s)
  n=$(ls "$out"/diagnose_"$c"_run*.log 2>/dev/null | wc -l)
  log=$out/diagnose_${c}_run$((n + 1)).log
  # run inside OUT: the output folder is relative to the working directory, the cache to the config
  (cd "$out" && timeout -s INT -k 20 "$chunk_s" $py -m validation.cli "diagnose_$c.yaml" --device "$device" \
      --output "diagnosis_$c" ${procs[@]+"${procs[@]}"}) > "$log" 2>&1
  rc=$?
  wall=$(( $(date +%s) - t0 ))
  echo "{\"case\": \"$c\", \"rc\": $rc, \"wall_s\": $wall, \"date\": \"$(date -u +%FT%TZ)\", \"device\": \"$device\"}" \
    >> "$out/times.jsonl"
  if [ "$rc" -eq 0 ]; then
    echo "case $c: diagnosed in $wall s ($log)"
  else
    all_done=0
    echo "case $c: stopped (rc $rc) after $wall s: run the script again (the cache resumes); log $log"
    break
  fi
done
if [ "$all_done" -eq 1 ]; then  # the truths join the folder only now, after every diagnosis has finished
  for c in $cases; do cp "$labs/truth_$c.json" "$out/"; done
  $py "$repo/benchmarks/score_hidden_effects.py" "$out" --cases $cases --json "$out/score.json" --markdown "$out/score.md"
  exit 0
fi
exit 1
