"""The N best assignments of a cost matrix (Murty's algorithm).

Murty K.G. (1968) An algorithm for ranking all the assignments in order of
increasing cost, Operations Research 16(3):682-687, doi:10.1287/opre.16.3.682,
with the usual refinements (Miller, Stone & Cox 1997, doi:10.1109/7.570713):
a subproblem inherits its parent's fixed rows, and each solved subproblem is
pushed with its cost so the best open one is taken next. Every linear
assignment inside is scipy's ``linear_sum_assignment`` (Crouse 2016,
doi:10.1109/TAES.2016.140952).

Costs may be ``inf`` to forbid a pairing. Rows are assigned to distinct
columns; a matrix with more columns than rows leaves columns unused.
"""

from __future__ import annotations

import heapq

import numpy as np
from scipy.optimize import linear_sum_assignment


def _solve(cost):
    """Best assignment of every row (array of columns) and its cost; None when none is feasible."""
    try:
        rows, cols = linear_sum_assignment(cost)
    except ValueError:  # infeasible: some row has only forbidden columns left
        return None
    total = cost[rows, cols].sum()
    if not np.isfinite(total):
        return None
    out = np.empty(cost.shape[0], dtype=np.intp)
    out[rows] = cols
    return out, float(total)


def k_best_assignments(cost, k: int) -> list[tuple[np.ndarray, float]]:
    """The ``k`` cheapest assignments of rows to distinct columns, cheapest first.

    Parameters
    ----------
    cost : ndarray (R, C), R <= C
        Cost of giving row r column c; ``inf`` forbids it.
    k : int
        How many assignments to return (fewer when fewer exist).

    Returns
    -------
    list of (columns, total)
        ``columns`` (R,) int: the column of every row; ``total`` its cost.
    """
    cost = np.asarray(cost, dtype=np.float64)
    n_rows, n_cols = cost.shape
    if n_rows > n_cols:
        raise ValueError(f"more rows ({n_rows}) than columns ({n_cols})")
    if n_rows == 0:
        return [(np.zeros(0, dtype=np.intp), 0.0)]
    first = _solve(cost)
    if first is None:
        return []
    out = []
    # A subproblem: rows < `fixed` forced to their columns in `columns` (its best solution), and the
    # (row, column) pairs in `excluded` forbidden. Heap entries: (total, tie-breaker, columns, fixed, excluded).
    counter = 0
    heap = [(first[1], counter, first[0], 0, ())]
    all_cols = np.arange(n_cols)
    while heap and len(out) < k:
        total, _, columns, fixed, excluded = heapq.heappop(heap)
        out.append((columns, total))
        if len(out) == k:
            break
        # Partition the rest of this subproblem (Murty): for each row r >= fixed, the solutions that
        # agree with `columns` on rows < r and give row r another column.
        base = cost.copy()
        for r, c in excluded:
            base[r, c] = np.inf
        forced_cost = float(cost[np.arange(fixed), columns[:fixed]].sum())
        free_cols = np.setdiff1d(all_cols, columns[:fixed])
        for r in range(fixed, n_rows):
            sub = base[r:][:, free_cols]
            sub[0, np.searchsorted(free_cols, columns[r])] = np.inf
            solved = _solve(sub)
            if solved is not None:
                cols_sub, sub_total = solved
                new = columns.copy()
                new[r:] = free_cols[cols_sub]
                counter += 1
                child_excluded = tuple((rr, cc) for rr, cc in excluded if rr > r) + ((r, int(columns[r])),) \
                    + tuple((rr, cc) for rr, cc in excluded if rr == r)
                heapq.heappush(heap, (forced_cost + sub_total, counter, new, r, child_excluded))
            # The children after this one keep row r at its column.
            forced_cost += cost[r, columns[r]]
            free_cols = free_cols[free_cols != columns[r]]
    return out
