"""Checks that measured values are finite numbers, used where files are parsed (importers, UFF,
SEP005, fit results): a NaN or an infinity is never stored, replaced by 0 or passed on to a fit.
Each check names where the first bad value is, so the user can find it in the file."""
from __future__ import annotations

import numpy as np

__all__ = ["first_nonfinite", "describe_nonfinite"]


def first_nonfinite(values: np.ndarray | list | tuple) -> tuple[int, ...] | None:
    """The index of the first non-finite value (NaN, +-inf; real or complex) in C order, or None."""
    a = np.asarray(values)
    if a.dtype.kind not in "fc":
        return None
    bad = ~np.isfinite(a)
    if not bad.any():
        return None
    return tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), a.shape))


def describe_nonfinite(values: np.ndarray | list | tuple) -> str | None:
    """``"sample 17 is nan (3 non-finite values in all)"`` for the first bad value of a 1-D array
    (last axis of an n-D one), or None when every value is finite."""
    idx = first_nonfinite(values)
    if idx is None:
        return None
    a = np.asarray(values)
    n_bad = int(np.count_nonzero(~np.isfinite(a)))
    return f"sample {idx[-1]} is {a[idx]} ({n_bad} non-finite value{'s' if n_bad != 1 else ''} in all)"
