#!/usr/bin/env bash
# On the GPU machine of the device tool: assemble the wheels uploaded in parts into /root/wp and install
# them, with .whl/ and .ray_small/ (git-ignored, carried with the call), into /tmp/site. Then:
#   export PYTHONPATH=/tmp/site:$PWD PATH=/tmp/site/bin:$PATH PYTHONUNBUFFERED=1
# Uploads, one call each (the tracked tree is ~33 MB and one call carries at most 64 MiB):
#   mkdir -p /root/wp && cp .gpu/warp.whl.partNN /root/wp/      carry [".gpu/warp.whl.partNN"], NN = 00..04
#   mkdir -p /root/wp && cp .ray/ray.whl.partNN /root/wp/       carry [".ray/ray.whl.partNN"], NN = 00..02 (Ray only)
# then the run: `bash benchmarks/device_install.sh && ...` with carry [".whl", ".ray_small", ".gpu/WHEEL_NAME"].
# Write every log with `| tee $OUT/NAME.log`: a command stopped at its limit returns only what is under $OUT.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
[ -d /tmp/site/warp ] && { echo "device_install: /tmp/site already holds warp"; exit 0; }
cd /root/wp
warp_wheel=$(cat "$repo/.gpu/WHEEL_NAME")
[ -f "$warp_wheel" ] || cat warp.whl.part0? > "$warp_wheel"
ray_wheel=ray-2.60.0-cp312-cp312-manylinux2014_x86_64.whl
if ls ray.whl.part0? >/dev/null 2>&1 && [ ! -f "$ray_wheel" ]; then cat ray.whl.part0? > "$ray_wheel"; fi
extra=()
[ -d "$repo/.ray_small" ] && extra+=("$repo"/.ray_small/*.whl)
python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site /root/wp/*.whl "$repo"/.whl/*.whl "${extra[@]}"
echo "device_install: installed into /tmp/site: $(ls /tmp/site | grep -c dist-info) distributions"
