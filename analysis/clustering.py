"""Complete-linkage clustering cut at a distance: the flat clusters of a few hundred points.

Agglomerative complete linkage merges, again and again, the two clusters whose farthest pair of
points is the closest; cut at ``t`` it stops before the first merge above ``t``: every pair of
points in a cluster is then within ``t``. A cluster lies inside one connected component of the
graph "distance <= t" (single linkage at ``t``), so the merging runs per component, each a small
matrix (the stabilization diagram's poles of one resonance). The clusters are those of
``scipy.cluster.hierarchy.fcluster(linkage(D, "complete"), t, "distance")`` (up to ties of equal
distances), without importing ``scipy.cluster`` (a third of a second at the start of a command).
"""
from __future__ import annotations

import numpy as np

__all__ = ["complete_linkage_labels"]


def _components(close: np.ndarray) -> np.ndarray:
    """Connected component of every node of the boolean adjacency matrix ``close`` (n, n)."""
    n = close.shape[0]
    comp = np.full(n, -1)
    c = 0
    for start in range(n):
        if comp[start] >= 0:
            continue
        frontier = np.array([start])
        comp[start] = c
        while frontier.size:
            nxt = np.flatnonzero(np.any(close[frontier], axis=0) & (comp < 0))
            comp[nxt] = c
            frontier = nxt
        c += 1
    return comp


def complete_linkage_labels(D: np.ndarray, t: float) -> np.ndarray:
    """Flat cluster labels (1..K, one per point) of complete linkage on the symmetric distance
    matrix ``D`` (n, n) cut at distance ``t`` (module docstring). Labels are numbered in the order
    of each cluster's first point."""
    D = np.asarray(D, dtype=float)
    n = D.shape[0]
    if D.shape != (n, n):
        raise ValueError(f"D must be a square distance matrix; got shape {D.shape}")
    owner = np.arange(n)                      # the cluster (its lowest point) of every point
    comp = _components(D <= t)
    for c in np.unique(comp):
        idx = np.flatnonzero(comp == c)
        if idx.size < 2:
            continue
        C = D[np.ix_(idx, idx)].copy()
        np.fill_diagonal(C, np.inf)
        members = [[int(i)] for i in idx]
        while True:
            k = int(np.argmin(C))
            a, b = divmod(k, idx.size)
            if not C[a, b] <= t:
                break
            # merge b into a: the distance to the merged cluster is the larger of the two
            row = np.maximum(C[a], C[b])
            C[a], C[:, a] = row, row
            C[a, a] = np.inf
            C[b], C[:, b] = np.inf, np.inf
            members[a] += members[b]
            members[b] = []
        for m in members:
            if m:
                owner[m] = min(m)
    _, labels = np.unique(owner, return_inverse=True)
    return labels + 1
