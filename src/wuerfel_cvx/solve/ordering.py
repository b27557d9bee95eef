"""A fill-reducing order of a large pile's unknowns, for the polish's ``L D L'``.

The polish (:mod:`wuerfel_cvx.solve.kkt`) factors the reduced KKT matrix with its rows
eliminated first; what remains to factor is the unknowns' block ``P + delta I + A' A /
delta``, whose graph is the contact graph of the bodies (a body's unknowns joined to those
of the bodies it touches).  In scene order a pile is numbered row by row, and that block is
banded with a band as wide as a row of bodies: factoring it costs ``n b^2`` (field-pyramid-100:
15,150 unknowns, a band of about 300, 0.4 s).  Nested dissection (George 1973) orders a
planar graph's unknowns so that the factor costs about ``n^1.5``: split the graph by a
separator, number each part (recursively) before the separator.  The separators here are
level sets of a breadth-first search from a pseudo-peripheral node (George and Liu 1979's
automatic nested dissection), which on a pile's graph are lines of bodies across it.

Below :data:`DISSECTION_MIN_UNKNOWNS` unknowns the scene order is kept: there the band is
narrow and ordering would cost more than it saves.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, shortest_path

__all__ = ["DISSECTION_MIN_UNKNOWNS", "fill_reducing_order"]

DISSECTION_MIN_UNKNOWNS = 1000
"""Unknowns from which :func:`fill_reducing_order` dissects (fewer: the identity)."""

LEAF_NODES = 64
"""A part of at most this many unknowns is numbered as it comes (its factor is dense)."""


def fill_reducing_order(graph: sp.csr_array) -> np.ndarray:
    """An order (old index of each new position) of the symmetric ``graph``'s nodes.

    The identity below :data:`DISSECTION_MIN_UNKNOWNS` nodes, nested dissection above.
    ``graph``'s pattern is what counts (its values are ignored); its diagonal may be stored.
    """
    size = graph.shape[0]
    if size < DISSECTION_MIN_UNKNOWNS:
        return np.arange(size)
    pattern = sp.csr_array((np.ones(graph.nnz), graph.indices, graph.indptr), shape=graph.shape)
    parts: list[np.ndarray] = []
    _dissect(pattern, np.arange(size), parts)
    order = np.concatenate(parts)
    assert np.array_equal(np.sort(order), np.arange(size))
    return order


def _dissect(graph: sp.csr_array, nodes: np.ndarray, parts: list[np.ndarray]) -> None:
    """Append the order of ``nodes`` (a subgraph of ``graph``) to ``parts``: parts, separator."""
    pending = [(nodes, False)]  # (nodes, whether they are a separator to append as they are)
    while pending:
        current, final = pending.pop()
        if final or len(current) <= LEAF_NODES:
            parts.append(current)
            continue
        sub = graph[current][:, current]
        n_components, labels = connected_components(sub, directed=False)
        if n_components > 1:
            pending.extend((current[labels == label], False)
                           for label in range(n_components - 1, -1, -1))
            continue
        levels = _levels(sub)
        middle = int(levels.max()) // 2
        if middle == 0:  # a clique-like part: no separator to gain
            parts.append(current)
            continue
        # popped last-in first-out: the part before the separator, the part after, then it
        pending.append((current[levels == middle], True))
        pending.append((current[levels > middle], False))
        pending.append((current[levels < middle], False))


def _levels(graph: sp.csr_array) -> np.ndarray:
    """Breadth-first levels of a connected ``graph`` from a pseudo-peripheral node."""
    start = 0
    for _ in range(2):  # the farthest node from the last start, twice (George and Liu)
        levels = _distances(graph, start)
        start = int(np.argmax(levels))
    return _distances(graph, start)


def _distances(graph: sp.csr_array, start: int) -> np.ndarray:
    """Distances (edges) of every node of a connected ``graph`` from ``start``."""
    distances = shortest_path(graph, method="D", directed=False, unweighted=True,
                              indices=start)
    return np.asarray(distances, dtype=np.int64)
