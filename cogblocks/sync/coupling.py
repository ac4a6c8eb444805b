"""The coupling sum of a Kuramoto group, ``Σ_j a_ij sin(θ_j − θ_i)``, dense or over the edges only."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from cogblocks.data.graphs import adjacency_matrix, graph_edges, is_random_graph
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


def checked_graph(owner: object, graph: Any, n: int) -> Any:
    """``graph`` as a valid spec for ``n`` participants (a dense matrix as a finite float array), or ``ValueError``
    naming ``owner`` and its ``adjacency`` parameter."""
    if isinstance(graph, str):
        if graph not in ("ring", "all"):
            raise ValueError(
                f"{type(owner).__name__}: adjacency must be 'ring', 'all', ('random', p, seed) or an {n}x{n} matrix, "
                f"got {graph!r}"
            )
        return graph
    if is_random_graph(graph) or sp.issparse(graph):
        try:
            adjacency_matrix(graph, n, sparse=True)
        except ValueError as exc:
            raise ValueError(f"{type(owner).__name__}: adjacency: {exc}") from None
        return graph
    return finite_array(owner, "adjacency", graph, shape=(n, n))


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

    def pull(self, seen: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Write ``Σ_j a_ij sin(seen_j − seen_i)`` for every i into ``out`` (shape (N,)) and return it."""
        if self.sparse:
            terms = np.sin(seen[self.cols] - seen[self.rows])
            terms *= self.weights
            out[...] = np.bincount(self.rows, weights=terms, minlength=self.n)
            return out
        d = self._diff
        np.subtract(seen[None, :], seen[:, None], out=d)
        np.sin(d, out=d)
        d *= self.matrix
        return np.add.reduce(d, axis=1, out=out)

    def row(self, i: int) -> np.ndarray:
        """Row ``i`` of the adjacency matrix, dense, shape (N,)."""
        return np.asarray(self.matrix[i].toarray()).ravel() if self.sparse else self.matrix[i].copy()
