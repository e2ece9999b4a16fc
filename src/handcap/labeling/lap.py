"""The k best assignments of a small cost matrix in compiled loops (numba, extra 'stream').

:func:`handcap.labeling.murty.k_best_assignments` splits a frame's problem into its independent parts and
solves each part's assignment problems with scipy; on one frame of a 19-marker hand its many small Python
and numpy steps are most of its time (about 0.6 ms of a 1.1 ms labelled frame on the 2-core VM), and the
live stream labels one frame at a time. Here the same ranking runs compiled on the whole matrix:

- each assignment problem is solved by shortest augmenting paths with dual potentials (the Hungarian
  method in the form of Jonker & Volgenant 1987, doi:10.1007/BF02278710, rows added one at a time), which
  handles ``inf`` (forbidden) costs and stops when a row can reach no free column;
- the ranking is Murty's (1968) partition with Miller, Stone & Cox's (1997) inherited fixed rows: a solved
  subproblem is kept with its cost and the cheapest open one is taken next (ties: the one made first).

The k best totals are those of :func:`~handcap.labeling.murty.k_best_assignments`; only among equal totals
may the two pick different assignments (a test compares them on random matrices and on brute force).
"""

from __future__ import annotations

import numpy as np

from handcap.core.compiled import AVAILABLE  # noqa: F401 (whether the ranking runs compiled; else scipy's code)
from handcap.core.compiled import njit as _njit


@_njit
def _assign(cost, n_rows, n_cols, out):
    """Cheapest assignment of the first ``n_rows`` rows of ``cost`` to distinct columns among the first
    ``n_cols`` (``n_rows <= n_cols``); the column of each row goes to ``out``. Returns its total, ``inf``
    when no assignment avoids the forbidden (``inf``) costs."""
    inf = np.inf
    u = np.zeros(n_rows + 1)
    v = np.zeros(n_cols + 1)
    p = np.zeros(n_cols + 1, np.int64)  # p[j]: the row (1-based) holding column j (1-based), 0 if free
    way = np.zeros(n_cols + 1, np.int64)
    minv = np.empty(n_cols + 1)
    used = np.empty(n_cols + 1, np.bool_)
    for i in range(1, n_rows + 1):
        p[0] = i
        j0 = 0
        minv[:] = inf
        used[:] = False
        while True:  # grow the shortest-path tree from row i until it reaches a free column
            used[j0] = True
            i0 = p[j0]
            delta = inf
            j1 = -1
            for j in range(1, n_cols + 1):
                if not used[j]:
                    cur = cost[i0 - 1, j - 1] - u[i0] - v[j]
                    if cur < minv[j]:
                        minv[j] = cur
                        way[j] = j0
                    if minv[j] < delta:
                        delta = minv[j]
                        j1 = j
            if j1 < 0 or delta == inf:
                return inf
            for j in range(n_cols + 1):
                if used[j]:
                    u[p[j]] += delta
                    v[j] -= delta
                else:
                    minv[j] -= delta
            j0 = j1
            if p[j0] == 0:
                break
        while j0 != 0:  # augment along the path back to the root
            j1 = way[j0]
            p[j0] = p[j1]
            j0 = j1
    total = 0.0
    for j in range(1, n_cols + 1):
        if p[j] != 0:
            out[p[j] - 1] = j - 1
            total += cost[p[j] - 1, j - 1]
    return total


@_njit
def _k_best(cost, k, out_cols, out_total):
    """Murty's ranking of the ``k`` cheapest assignments of ``cost`` (R, C), R <= C, into ``out_cols`` (k, R)
    and ``out_total`` (k,); returns how many were found."""
    n_rows, n_cols = cost.shape
    most = 1 + k * n_rows  # each of the k subproblems taken makes at most one child per row
    cols = np.empty((most, n_rows), np.int64)
    fixed = np.zeros(most, np.int64)
    total = np.empty(most)
    excluded = np.zeros((most, n_rows, n_cols), np.bool_)
    is_open = np.zeros(most, np.bool_)
    sub = np.empty((n_rows, n_cols))
    sub_cols = np.empty(n_rows, np.int64)
    free_cols = np.empty(n_cols, np.int64)
    free = np.empty(n_cols, np.bool_)
    first = _assign(cost, n_rows, n_cols, sub_cols)
    if first == np.inf:
        return 0
    cols[0] = sub_cols[:n_rows]
    total[0] = first
    is_open[0] = True
    made, found = 1, 0
    while found < k:
        node, best = -1, np.inf
        for q in range(made):  # the cheapest open subproblem, the first made among equals
            if is_open[q] and (node < 0 or total[q] < best):
                node, best = q, total[q]
        if node < 0:
            break
        is_open[node] = False
        out_cols[found] = cols[node]
        out_total[found] = best
        found += 1
        if found == k:
            break
        free[:] = True
        forced = 0.0  # the cost of rows < r, kept at the node's columns
        for r in range(fixed[node]):
            free[cols[node, r]] = False
            forced += cost[r, cols[node, r]]
        for r in range(fixed[node], n_rows):  # the solutions agreeing on rows < r, row r elsewhere
            own = cols[node, r]
            n_free = 0
            other = False
            for c in range(n_cols):
                if free[c]:
                    free_cols[n_free] = c
                    n_free += 1
                    if c != own and not excluded[node, r, c] and cost[r, c] < np.inf:
                        other = True
            if other:
                for i in range(r, n_rows):
                    for f in range(n_free):
                        c = free_cols[f]
                        forbid = excluded[node, i, c] or (i == r and c == own)
                        sub[i - r, f] = np.inf if forbid else cost[i, c]
                sub_total = _assign(sub, n_rows - r, n_free, sub_cols)
                if sub_total < np.inf:
                    child = made
                    made += 1
                    cols[child, :r] = cols[node, :r]
                    for i in range(r, n_rows):
                        cols[child, i] = free_cols[sub_cols[i - r]]
                    total[child] = forced + sub_total
                    fixed[child] = r
                    excluded[child] = excluded[node]
                    excluded[child, r, own] = True
                    is_open[child] = True
            free[own] = False
            forced += cost[r, own]
    return found


def k_best_compiled(cost, k: int) -> list[tuple[np.ndarray, float]]:
    """The ``k`` cheapest assignments of rows to distinct columns, cheapest first, compiled.

    Parameters
    ----------
    cost : ndarray (R, C), R <= C, float64
        Cost of giving row r column c; ``inf`` forbids it.
    k : int
        How many assignments to return (fewer when fewer exist), >= 1.

    Returns
    -------
    list of (columns, total)
        ``columns`` (R,) int: the column of every row; ``total`` its cost.
    """
    cost = np.ascontiguousarray(cost, dtype=np.float64)
    if k < 1 or cost.shape[0] == 0:
        return [] if k < 1 else [(np.zeros(0, dtype=np.intp), 0.0)]
    out_cols = np.empty((k, cost.shape[0]), np.intp)
    out_total = np.empty(k)
    found = _k_best(cost, k, out_cols, out_total)
    return [(out_cols[i], float(out_total[i])) for i in range(found)]


def prepare() -> None:
    """Compile the ranking now (or load it from numba's cache): a live stream calls this before its first frame,
    which would otherwise wait for the compiler (about 6 s once per machine)."""
    if AVAILABLE:
        k_best_compiled(np.array([[0.0, 1.0], [1.0, 0.0]]), 2)
