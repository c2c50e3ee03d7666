"""The modal assurance criterion (MAC), written once.

For complex vectors ``a`` and ``b`` (mode shapes, residue columns, FRF vectors at one line)::

    MAC(a, b) = |a^H b|^2 / ((a^H a) (b^H b))

It lies in [0, 1], is 1 when ``b`` is a complex multiple of ``a`` (scaling and phase do not count),
0 for orthogonal vectors, and is set to 0 when either vector is zero (no shape to compare).
"""
from __future__ import annotations

import numpy as np

__all__ = ["mac", "mac_matrix", "MacReference"]


def mac(a: np.ndarray, b: np.ndarray) -> float:
    """MAC of two vectors of the same length (dimensionless, 0..1)."""
    a = np.asarray(a).ravel()
    b = np.asarray(b).ravel()
    den = float(np.vdot(a, a).real * np.vdot(b, b).real)
    return float(abs(np.vdot(a, b)) ** 2 / den) if den > 0 else 0.0


def mac_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """MAC between the columns of ``a`` (N, p) and ``b`` (N, q): a (p, q) matrix, 0 where a column
    is zero."""
    return MacReference(a).against(b)


class MacReference:
    """The columns of ``a`` (N, p) held for MAC against many other sets of columns (a search that
    compares one measured set with thousands of candidates): its conjugate transpose and the columns'
    energies are computed once."""

    def __init__(self, a: np.ndarray) -> None:
        a = np.asarray(a)
        self.a_h = a.conj().T
        self.energy = np.sum(np.abs(a) ** 2, axis=0)

    def against(self, b: np.ndarray) -> np.ndarray:
        """MAC between the held columns and the columns of ``b`` (N, q): a (p, q) matrix, 0 where a
        column is zero."""
        num = np.abs(self.a_h @ b) ** 2
        den = np.outer(self.energy, np.sum(np.abs(b) ** 2, axis=0))
        if np.all(den > 0):
            return num / den
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
