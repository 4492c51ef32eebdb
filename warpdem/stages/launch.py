"""How the force stages are compiled for CUDA: an optional cap on the registers per thread.

A force kernel inlines the whole contact law inside its loop over contacts; the CUDA compiler then
gives each thread many registers, which limits how many warps an SM keeps resident to hide the
latency of the neighbour gathers. ``max_registers`` (CUDA ``__maxnreg__``, Warp's
``cuda_max_registers``) trades registers for occupancy; ``None`` leaves the choice to the compiler.
The CPU ignores it. Results do not depend on it (the same instructions, other register allocation):
``tests/test_gpu.py`` checks that on CUDA, bit for bit.
"""
from __future__ import annotations

from typing import Callable

import warp as wp

from ..errors import ConfigError

#: smallest and largest register cap accepted (CUDA allows 16 .. 255 per thread)
REGISTER_CAP_RANGE = (24, 255)


def check_register_cap(max_registers: int | None) -> int | None:
    """``max_registers`` as an int, or None; a ConfigError naming the problem otherwise."""
    if max_registers is None:
        return None
    lo, hi = REGISTER_CAP_RANGE
    if isinstance(max_registers, bool) or not isinstance(max_registers, int) or not lo <= max_registers <= hi:
        raise ConfigError(f"force_registers must be None or an integer in [{lo}, {hi}] (registers per CUDA "
                          f"thread), got {max_registers!r}")
    return int(max_registers)


def force_kernel(max_registers: int | None) -> Callable:
    """The ``wp.kernel`` decorator of a force stage: with ``cuda_max_registers=max_registers``, or
    plain when ``None``."""
    return wp.kernel if max_registers is None else wp.kernel(cuda_max_registers=int(max_registers))
