"""Complete-linkage clustering (analysis.clustering) against scipy's own on random point sets."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.cluster.hierarchy import fcluster, linkage

from analysis.clustering import complete_linkage_labels


def _partition(labels: np.ndarray) -> set[frozenset[int]]:
    return {frozenset(np.flatnonzero(labels == lab).tolist()) for lab in np.unique(labels)}


@pytest.mark.parametrize("seed", range(6))
def test_same_clusters_as_scipy(seed):
    rng = np.random.default_rng(seed)
    # poles of a stabilization diagram: a few resonances seen at many orders, plus scatter
    centres = rng.uniform(10.0, 500.0, 8)
    f = np.concatenate([c * (1 + 0.004 * rng.standard_normal(25)) for c in centres] + [rng.uniform(10, 500, 30)])
    z = np.concatenate([rng.uniform(0.002, 0.03, 8).repeat(25) * (1 + 0.2 * rng.standard_normal(200)),
                        rng.uniform(0.001, 0.1, 30)])
    D = np.maximum(np.abs(f[:, None] - f[None, :]) / (0.01 * np.maximum(f[:, None], f[None, :])),
                   np.abs(z[:, None] - z[None, :]) / np.maximum(0.25 * np.maximum(z[:, None], z[None, :]), 1e-3))
    ours = complete_linkage_labels(D, 1.0)
    i, j = np.triu_indices(f.size, k=1)
    theirs = fcluster(linkage(D[i, j], method="complete"), t=1.0, criterion="distance")
    assert _partition(ours) == _partition(theirs)
    assert 8 <= len(_partition(ours)) < f.size


def test_every_pair_of_a_cluster_is_within_the_cut():
    rng = np.random.default_rng(1)
    x = np.sort(rng.uniform(0, 10, 60))
    D = np.abs(x[:, None] - x[None, :])
    labels = complete_linkage_labels(D, 0.5)
    for lab in np.unique(labels):
        k = labels == lab
        assert np.ptp(x[k]) <= 0.5
    assert labels.min() == 1 and set(np.unique(labels)) == set(range(1, labels.max() + 1))


def test_not_square_is_an_error():
    with pytest.raises(ValueError, match="square"):
        complete_linkage_labels(np.zeros((3, 2)), 1.0)
