"""The coupling sum of a Kuramoto group, ``Σ_j a_ij sin(θ_j − θ_i)``, dense or over the edges only."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from cogblocks.data.graphs import adjacency_matrix, graph_edges, is_random_graph
from cogblocks.sim.memory import check_memory
from cogblocks.sim.params import finite_array

__all__ = ["DENSE_MAX_N", "SPARSE_MAX_DENSITY", "Coupling", "checked_graph", "use_sparse"]

#: Groups up to this size always use the dense N × N product (it is faster there, and the bundled
#: groups keep their exact arithmetic).
DENSE_MAX_N = 64
#: Above DENSE_MAX_N, graphs with at most this share of the N² entries use the edge list.
SPARSE_MAX_DENSITY = 0.25


def use_sparse(n: int, n_edges: int) -> bool:
    """Whether a group of ``n`` participants with ``n_edges`` edges is cheaper on its edge list."""
    return n > DENSE_MAX_N and n_edges <= SPARSE_MAX_DENSITY * n * n


def _coupling_bytes(graph: Any, n: int) -> float:
    """Peak bytes of building a coupling: the N x N matrices drawn on the way, the edge list, the dense form."""
    if isinstance(graph, str):
        edges, drawn = (2 * n, 0) if graph == "ring" else (n * (n - 1), 8 * n * n)
    elif is_random_graph(graph):
        edges, drawn = float(graph[1]) * n * n, 9 * n * n  # drawn as dense floats and booleans
    else:
        edges, drawn = (graph.nnz if sp.issparse(graph) else np.count_nonzero(graph)), 0
    dense_form = 0 if use_sparse(n, int(edges)) else 16 * n * n  # the matrix and the per-tick differences
    return drawn + 36 * edges + dense_form  # rows, columns, weights and the CSR copy per edge


def checked_graph(owner: object, graph: Any, n: int) -> Any:
    """``graph`` as a valid spec for ``n`` participants (a dense matrix as a finite float array), or ``ValueError``
    naming ``owner`` and its ``adjacency`` parameter, also when the coupling would not fit in memory
    (:mod:`cogblocks.sim.memory`)."""
    if isinstance(graph, str):
        if graph not in ("ring", "all"):
            raise ValueError(
                f"{type(owner).__name__}: adjacency must be 'ring', 'all', ('random', p, seed) or an {n}x{n} matrix, "
                f"got {graph!r}"
            )
    elif not (is_random_graph(graph) or sp.issparse(graph)):
        graph = finite_array(owner, "adjacency", graph, shape=(n, n))
    check_memory(
        _coupling_bytes(graph, n),
        f"{type(owner).__name__}: the coupling of N = {n} participants on adjacency "
        f"{graph if isinstance(graph, (str, tuple)) else type(graph).__name__!r}",
        "use a sparse graph ('ring', or a scipy.sparse matrix of the links) or fewer participants",
    )
    if is_random_graph(graph) or sp.issparse(graph):
        try:
            adjacency_matrix(graph, n, sparse=True)
        except ValueError as exc:
            raise ValueError(f"{type(owner).__name__}: adjacency: {exc}") from None
    return graph


class Coupling:
    """``Σ_j a_ij sin(θ_j − θ_i)`` for one graph, computed in O(N²) or O(edges), chosen from the density.

    Parameters
    ----------
    graph : graph spec
        ``"ring"``, ``"all"``, ``("random", p, seed)`` or a matrix (see :mod:`cogblocks.data.graphs`).
    n : int
        Number of participants.
    sparse : bool, optional
        Force the edge list (True) or the dense product (False); chosen by :func:`use_sparse` by default.

    Attributes
    ----------
    sparse : bool
        Which form is used.
    matrix : ndarray or scipy.sparse.csr_matrix
        The adjacency matrix, in that form.
    """

    def __init__(self, graph: Any, n: int, *, sparse: bool | None = None) -> None:
        self.n = n
        self.rows, self.cols, self.weights = graph_edges(graph, n)
        self.sparse = use_sparse(n, len(self.weights)) if sparse is None else bool(sparse)
        if self.sparse:
            self.matrix = sp.csr_matrix((self.weights, (self.rows, self.cols)), shape=(n, n))
        else:
            self.matrix = adjacency_matrix(graph, n)
            self._diff = np.zeros((n, n))

    def size_for(self, lead: tuple[int, ...]) -> None:
        """Size the work buffer for phases with the leading axes ``lead`` (``(B,)`` for a batch of B runs)."""
        if not self.sparse:
            self._diff = np.zeros(lead + (self.n, self.n))

    def pull(self, seen: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Write ``Σ_j a_ij sin(seen_j − seen_i)`` for every i into ``out`` (shape (N,), or (B, N) for a batch
        sized by :meth:`size_for`) and return it; each row of a batch is computed as that row alone would be."""
        if self.sparse:
            for row_seen, row_out in zip(seen.reshape(-1, self.n), out.reshape(-1, self.n), strict=True):
                terms = np.sin(row_seen[self.cols] - row_seen[self.rows])
                terms *= self.weights
                row_out[...] = np.bincount(self.rows, weights=terms, minlength=self.n)
            return out
        d = self._diff
        np.subtract(seen[..., None, :], seen[..., :, None], out=d)
        np.sin(d, out=d)
        d *= self.matrix
        return np.add.reduce(d, axis=-1, out=out)

    def row(self, i: int) -> np.ndarray:
        """Row ``i`` of the adjacency matrix, dense, shape (N,)."""
        return np.asarray(self.matrix[i].toarray()).ravel() if self.sparse else self.matrix[i].copy()
