#!/usr/bin/env bash
# Proof of the diagnosis on data with hidden effects (issue 11), in two phases that each fit a
# 10-minute GPU call:
#   benchmarks/hidden_effects_proof.sh OUT lab        # lab data (4 cases) + the designs, in parallel
#   benchmarks/hidden_effects_proof.sh OUT diagnose   # the four diagnoses, in one process (pooled launches)
# Env: SCALE (paper | quick | tiny, default paper), DEVICE (default cuda), PYTHON (default python3).
# Each diagnosis reads only its lab_<case>.yaml; the truth_<case>.json files are read afterwards by
# benchmarks/score_hidden_effects.py. DEM worlds are cached in OUT/dem_cache.jsonl (the designs do
# not depend on the data, so the four cases share them; the lab fills come from another block).
set -u
out=${1:?output folder}
phase=${2:?phase: lab or diagnose}
scale=${SCALE:-paper}
device=${DEVICE:-cuda}
py=${PYTHON:-python3}
mkdir -p "$out"
t0=$(date +%s)
if [ "$phase" = lab ]; then
  # all four cases in one launch per experiment, then every design (base and each candidate) in one
  # launch per experiment: the candidate effects nest in one superset model (validation.dem_forward)
  $py -m validation.hidden_effects --out "$out" --scale "$scale" --device "$device" > "$out/gen.log" 2>&1
  $py -m validation.cli "$out/diagnose_base.yaml" --device "$device" --prefetch > "$out/prefetch.log" 2>&1
elif [ "$phase" = diagnose ]; then
  # the four diagnoses in ONE process: their DEM requests are pooled into shared launches
  # (validation.pooled; four processes on one GPU time-slice it and ran small launches ~5x slower).
  # Interrupted (a 10-minute call)? Run it again: every finished world is in the cache.
  # (run inside OUT: the configs' output folders are relative to the working directory)
  (cd "$out" && $py -m validation.cli diagnose_{base,rolling,cohesion,shape}.yaml --device "$device" > diagnose.log 2>&1)
else
  echo "unknown phase $phase" >&2; exit 2
fi
echo "{\"phase\": \"$phase\", \"scale\": \"$scale\", \"wall_s\": $(( $(date +%s) - t0 ))}" | tee -a "$out/phases.jsonl"
