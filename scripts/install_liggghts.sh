#!/usr/bin/env bash
# Install LIGGGHTS-PUBLIC 3.8 (Debian package `liggghts`), the reference code of
# validation/reference/ and tests/test_liggghts_*.py. Needs apt-get and root; prints why not
# otherwise and exits 1 (the reference tests then skip, naming this script).
set -euo pipefail
if command -v liggghts >/dev/null 2>&1; then
  echo "liggghts: $(liggghts -h 2>/dev/null | head -1)"
  exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
  echo "install_liggghts: apt-get not found; install LIGGGHTS-PUBLIC 3.8 by hand and put 'liggghts' on PATH" >&2
  exit 1
fi
SUDO=""
if [ "$(id -u)" != 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo -n"; else
    echo "install_liggghts: needs root (or sudo) for apt-get install liggghts" >&2; exit 1; fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
# --no-install-recommends: the binary and its libraries only (no documentation, no GUI extras)
$SUDO apt-get install -y -qq --no-install-recommends liggghts >/dev/null
echo "liggghts: $(liggghts -h 2>/dev/null | head -1)"
