"""The modal assurance criterion (MAC), written once.

For complex vectors ``a`` and ``b`` (mode shapes, residue columns, FRF vectors at one line)::

    MAC(a, b) = |a^H b|^2 / ((a^H a) (b^H b))

It lies in [0, 1], is 1 when ``b`` is a complex multiple of ``a`` (scaling and phase do not count),
0 for orthogonal vectors, and is set to 0 when either vector is zero (no shape to compare).
"""
from __future__ import annotations

import numpy as np

__all__ = ["mac", "mac_matrix"]


def mac(a: np.ndarray, b: np.ndarray) -> float:
    """MAC of two vectors of the same length (dimensionless, 0..1)."""
    a = np.asarray(a).ravel()
    b = np.asarray(b).ravel()
    den = float(np.vdot(a, a).real * np.vdot(b, b).real)
    return float(abs(np.vdot(a, b)) ** 2 / den) if den > 0 else 0.0


def mac_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """MAC between the columns of ``a`` (N, p) and ``b`` (N, q): a (p, q) matrix, 0 where a column
    is zero."""
    num = np.abs(a.conj().T @ b) ** 2
    den = np.outer(np.sum(np.abs(a) ** 2, axis=0), np.sum(np.abs(b) ** 2, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
