"""Graphs of a Kuramoto group: who sees whom, as a dense matrix or as an edge list.

A *graph spec* names a graph of ``n`` participants:

* ``"ring"``: each participant sees its two neighbours (the deliverable's graph);
* ``"all"``: everyone sees everyone else;
* ``("random", p, seed)``: an undirected Erdős–Rényi graph G(n, p), drawn with ``seed``
  (not necessarily connected);
* a matrix (array_like or ``scipy.sparse``), ``a_ij`` the weight with which i sees j:
  weighted, possibly directed.

``a_ij`` multiplies ``sin(θ_j − θ_i)`` in participant i's coupling, so a weighted matrix is a
per-edge gain on top of the group's global gain.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from cogblocks.sim.params import positive_int

__all__ = [
    "adjacency_matrix",
    "complete_adjacency",
    "graph_edges",
    "is_random_graph",
    "random_adjacency",
    "random_graph_params",
    "ring_adjacency",
]


def _size(n: Any, owner: str = "graph") -> int:
    return positive_int(owner, "n", n, minimum=2)


def ring_adjacency(n: int) -> np.ndarray:
    """Adjacency matrix of a ring of ``n`` participants (each sees its two neighbours)."""
    n = _size(n, "ring_adjacency")
    a = np.zeros((n, n))
    for i in range(n):
        a[i, (i + 1) % n] = a[i, (i - 1) % n] = 1.0
    return a


def complete_adjacency(n: int) -> np.ndarray:
    """Adjacency matrix of an all-to-all group of ``n`` participants (zero diagonal)."""
    n = _size(n, "complete_adjacency")
    return np.ones((n, n)) - np.eye(n)


def random_adjacency(n: int, p: float, seed: int) -> np.ndarray:
    """Undirected Erdős–Rényi graph G(n, p): each pair is linked with probability ``p``, independently."""
    n = _size(n, "random_adjacency")
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"random graph: p must be in [0, 1], got {p!r}")
    upper = np.triu(np.random.default_rng(seed).random((n, n)) < p, k=1)
    return (upper | upper.T).astype(float)


def random_graph_params(spec: tuple) -> tuple[float, int]:
    """``(p, seed)`` of a ``("random", p, seed)`` spec, or ``ValueError``."""
    if len(spec) != 3 or not isinstance(spec[2], (int, np.integer)) or isinstance(spec[2], bool):
        raise ValueError(f"a random graph spec is ('random', p, seed) with an integer seed, got {spec!r}")
    return float(spec[1]), int(spec[2])


def is_random_graph(spec: Any) -> bool:
    """Whether ``spec`` is a ``("random", p, seed)`` graph spec."""
    return isinstance(spec, tuple) and len(spec) > 0 and isinstance(spec[0], str) and spec[0] == "random"


def graph_edges(spec: Any, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge list ``(rows, cols, weights)`` of a graph spec, sorted by row then column, without zero weights.

    A ring is listed without building its matrix, so it scales to any ``n``.
    """
    n = _size(n)
    if isinstance(spec, str) and spec == "ring":
        i = np.arange(n)
        rows = np.repeat(i, 2)
        cols = np.stack([(i - 1) % n, (i + 1) % n], axis=1).ravel()
        if n == 2:  # both neighbours are the same participant: one edge of weight 1, as in the matrix
            return i, i[::-1].copy(), np.ones(2)
        order = np.lexsort((cols, rows))
        return rows[order], cols[order], np.ones(2 * n)
    matrix = sp.coo_matrix(adjacency_matrix(spec, n, sparse=True)).tocsr()
    matrix.eliminate_zeros()
    matrix.sort_indices()
    rows = np.repeat(np.arange(n), np.diff(matrix.indptr))
    return rows, matrix.indices.astype(np.intp), matrix.data.astype(float)


def adjacency_matrix(spec: Any, n: int, *, sparse: bool = False) -> np.ndarray | sp.csr_matrix:
    """The ``n × n`` adjacency matrix of a graph spec, dense or as a CSR matrix.

    Raises
    ------
    ValueError
        For an unknown spec, a matrix of the wrong shape or with non-finite weights.
    """
    n = _size(n)
    if isinstance(spec, str):
        if spec == "ring":
            if sparse:
                rows, cols, weights = graph_edges(spec, n)
                return sp.csr_matrix((weights, (rows, cols)), shape=(n, n))
            return ring_adjacency(n)
        if spec == "all":
            dense = complete_adjacency(n)
        else:
            raise ValueError(f"graph must be 'ring', 'all', ('random', p, seed) or an {n}x{n} matrix, got {spec!r}")
    elif is_random_graph(spec):
        dense = random_adjacency(n, *random_graph_params(spec))
    elif sp.issparse(spec):
        matrix = sp.csr_matrix(spec, dtype=float)
        if matrix.shape != (n, n) or not np.isfinite(matrix.data).all():
            raise ValueError(f"the adjacency matrix must be {n}x{n} and finite, got shape {matrix.shape}")
        return matrix if sparse else matrix.toarray()
    else:
        dense = np.asarray(spec, dtype=float)
        if dense.shape != (n, n) or not np.isfinite(dense).all():
            raise ValueError(f"the adjacency matrix must be {n}x{n} and finite, got shape {dense.shape}")
    return sp.csr_matrix(dense) if sparse else dense
