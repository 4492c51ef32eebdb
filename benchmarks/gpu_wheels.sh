#!/usr/bin/env bash
# The pure-Python and binary wheels the GPU machine lacks (it has numpy, scipy, scikit-learn, matplotlib,
# pyyaml, opencv, no package index): trimesh, pymoo and its needs, pydantic and its needs, for Python
# 3.12 on x86-64, into .whl/ (git-ignored; about 11 MB). Warp itself goes up in three parts
# (../shared/GPU.md); the third upload carries .whl too (part02 + .whl + the repo fit the 64 MiB limit):
#   python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site /root/wp/$(cat .gpu/WHEEL_NAME) .whl/*.whl
# Versions are those of this machine's environment (pip show), so the GPU runs the code tested here.
set -euo pipefail
cd "$(dirname "$0")/.."
rm -rf .whl
platforms=""
for p in manylinux_2_28_x86_64 manylinux_2_27_x86_64 manylinux_2_24_x86_64 manylinux_2_17_x86_64 \
         manylinux2014_x86_64 manylinux1_x86_64 manylinux_2_31_x86_64 manylinux_2_34_x86_64; do
  platforms="$platforms --platform $p"
done
pins() { for n in "$@"; do echo "$n==$(python3 -m pip show "$n" 2>/dev/null | sed -n 's/^Version: //p')"; done; }
# shellcheck disable=SC2046,SC2086
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp $platforms -d .whl \
  $(pins trimesh pymoo alive-progress about-time graphemeu Deprecated wrapt autograd cma moocore cffi pycparser \
         platformdirs pydantic pydantic-core annotated-types typing-inspection typing-extensions)
ls .whl && du -sh .whl
