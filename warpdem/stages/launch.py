"""How the force stages are compiled for CUDA: an optional cap on the registers per thread.

A force kernel inlines the whole contact law inside its loop over contacts; the CUDA compiler then
gives each thread many registers (92 for the particle stage of a law with rolling resistance, H100,
Warp 1.19), so an SM keeps only 16 warps resident to hide the latency of the neighbour gathers.
``max_registers`` (CUDA ``__maxnreg__``, Warp's ``cuda_max_registers``) trades registers for
resident warps; ``None`` leaves the choice to the compiler. The CPU ignores it. Results do not
depend on it (the same instructions, other register allocation): ``tests/test_gpu.py`` checks that
on CUDA, bit for bit.

``"auto"`` (the solver's default) caps at :data:`OCCUPANCY_REGISTER_CAP` only where the occupancy
can pay: when the model has more spheres than twice the threads the GPU keeps resident at the
compiler's choice (16 warps of 32 threads per SM). Measured on an H100 (docs/notes/engine_speed.md,
2026-11-27): a settled bed of 1e6 spheres 1.154 -> 1.074 ms per step (+7.4 %), 200k spheres in
drum worlds -3.5 %, but 20k spheres +2 % and the 64-world paper-scale batches (52k-124k spheres)
+2-3 % (every thread is resident anyway; fewer registers cost instructions).
"""
from __future__ import annotations

from typing import Callable

import warp as wp

from ..errors import ConfigError

#: smallest and largest register cap accepted (CUDA allows 16 .. 255 per thread)
REGISTER_CAP_RANGE = (24, 255)

#: the largest cap that keeps 3 blocks of 256 threads (24 warps) per SM with a 64 K-register file:
#: 65536 / (3 x 256) = 85, rounded down to the allocation granularity of 8 registers. No law of the
#: engine spills at it (``benchmarks/force_kernel_registers.py``, H100: Hertz-Mindlin, EPSD, EPSD2,
#: EPSD2 + SJKR, CDT); 72 spills 16-48 B per thread, 64 spilled 80 B and ran 5 % slower.
OCCUPANCY_REGISTER_CAP = 80

#: resident threads per SM at the compiler's own register choice for the force kernels (16 warps)
RESIDENT_THREADS_PER_SM = 16 * 32


def check_register_cap(max_registers: int | str | None) -> int | str | None:
    """``max_registers`` checked: ``"auto"``, None or an int; a ConfigError naming the problem otherwise."""
    if max_registers is None or max_registers == "auto":
        return max_registers
    lo, hi = REGISTER_CAP_RANGE
    if isinstance(max_registers, bool) or not isinstance(max_registers, int) or not lo <= max_registers <= hi:
        raise ConfigError(f"force_registers must be 'auto', None or an integer in [{lo}, {hi}] (registers per "
                          f"CUDA thread), got {max_registers!r}")
    return int(max_registers)


def resolve_register_cap(max_registers: int | str | None, device: "wp.Device", num_spheres: int) -> int | None:
    """The cap the force kernels are compiled with: ``"auto"`` gives :data:`OCCUPANCY_REGISTER_CAP`
    on a CUDA device when ``num_spheres`` exceeds 2 x SMs x :data:`RESIDENT_THREADS_PER_SM` (135k
    spheres on a 132-SM H100), else None; explicit values pass through (checked)."""
    max_registers = check_register_cap(max_registers)
    if max_registers != "auto":
        return max_registers
    if not device.is_cuda:
        return None
    sms = int(getattr(device, "sm_count", 0) or 0)
    return OCCUPANCY_REGISTER_CAP if sms > 0 and num_spheres > 2 * sms * RESIDENT_THREADS_PER_SM else None


def force_kernel(max_registers: int | None) -> Callable:
    """The ``wp.kernel`` decorator of a force stage: with ``cuda_max_registers=max_registers``, or
    plain when ``None``."""
    return wp.kernel if max_registers is None else wp.kernel(cuda_max_registers=int(max_registers))
