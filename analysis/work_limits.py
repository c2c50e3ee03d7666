"""Bounds on the work a command may ask for, checked before anything large is allocated.

Each bound comes from the data (a model cannot have more unknowns than the lines give equations)
or from the machine (the arrays must fit in the memory that is free now). A request beyond them is
refused with :class:`WorkLimitError` naming the largest value that would be accepted.
"""
from __future__ import annotations

import os
from collections.abc import Callable

from .errors import WorkLimitError

__all__ = ["WorkLimitError", "available_memory_bytes", "memory_budget_bytes", "largest_within", "check_model_order",
           "lscf_work_bytes"]

#: the share of the free memory one computation may take
MEMORY_SHARE = 0.5


def available_memory_bytes() -> int:
    """Memory free for new allocations now (``MemAvailable`` on Linux, else physical memory)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def memory_budget_bytes() -> int:
    """The memory one computation may use: :data:`MEMORY_SHARE` of what is free now."""
    return int(MEMORY_SHARE * available_memory_bytes())


def largest_within(cost: Callable[[int], float], budget: float, hi: int) -> int:
    """The largest n in 0..hi with ``cost(n) <= budget`` (``cost`` increasing in n)."""
    lo = 0
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if cost(mid) <= budget:
            lo = mid
        else:
            hi = mid - 1
    return lo


def lscf_work_bytes(n_frfs: int, max_modes: int) -> float:
    """Bytes of the frequency-domain (LSCF) normal equations up to ``max_modes`` modes: the
    (2n+1)^2 blocks per FRF and the cumulative (2n+1)^3 products, float64."""
    q = 2 * max_modes + 1
    return 8.0 * q * q * (3.0 * q + 2.0 * n_frfs)


def check_model_order(max_modes: int, n_lines: int, n_frfs: int, what: str = "model order",
                      band_hz: tuple[float, float] | None = None) -> None:
    """Refuse a model of ``max_modes`` modes that the ``n_lines`` lines of ``n_frfs`` FRFs cannot
    determine (2n+1 denominator coefficients need as many lines) or whose normal equations do not
    fit in memory; the message gives the largest accepted order (and the band ``band_hz`` in Hz the
    lines are counted in, when given)."""
    by_data = max(0, (n_lines - 1) // 2)
    by_memory = largest_within(lambda n: lscf_work_bytes(n_frfs, n), memory_budget_bytes(), max(by_data, 1))
    largest = min(by_data, by_memory)
    if max_modes > largest:
        band = f" in the band {band_hz[0]:.6g}..{band_hz[1]:.6g} Hz" if band_hz is not None else ""
        why = (f"the band holds {n_lines} lines" if largest == by_data else
               f"its equations need {lscf_work_bytes(n_frfs, max_modes) / 2**30:.3g} GiB and "
               f"{memory_budget_bytes() / 2**30:.3g} GiB may be used now")
        raise WorkLimitError(f"{what} {max_modes} modes{band} is too large: {why}; the largest accepted here is {largest} "
                             "(or widen the band)")
