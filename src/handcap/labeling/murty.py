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

    The problem is first split into its independent parts (connected
    components of the rows and columns joined by finite costs): a part with
    one row is just its sorted options, a larger part goes to Murty's
    algorithm, and the k best totals of the parts together come from a heap
    over their ranked lists. Labels far apart in space rarely compete, so
    most parts are single rows and few assignment problems are solved.

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
    if k == 1:  # the best alone: one assignment problem
        best = _solve(cost)
        return [] if best is None else [best]
    finite = np.isfinite(cost)
    if not finite.any(axis=1).all():
        return []
    # Rows joined when they share a column, closed transitively (R is small: a few boolean products).
    f = finite.astype(np.float64)
    reach = (f @ f.T) > 0
    while True:
        wider = (reach.astype(np.float64) @ reach) > 0
        if (wider == reach).all():
            break
        reach = wider
    component = np.argmax(reach, axis=1)  # the first row of each row's part names it
    size = np.bincount(component, minlength=n_rows)[component]
    single = np.flatnonzero(size == 1)  # rows that compete with no other: their options, best first
    order = np.argsort(cost[single], axis=1, kind="stable")[:, :k]
    ranked_costs = np.take_along_axis(cost[single], order, axis=1)
    lists = [row[np.isfinite(row)] for row in ranked_costs]
    groups = []
    for label in np.unique(component[size > 1]):
        rows = np.flatnonzero(component == label)
        cols = np.flatnonzero(finite[rows].any(axis=0))
        if len(cols) < len(rows):
            return []
        ranked = [(cols[a], t) for a, t in _murty(cost[np.ix_(rows, cols)], k)]
        if not ranked:
            return []
        groups.append((rows, ranked))
        lists.append(np.array([t for _, t in ranked]))
    out = []
    n_single = len(single)
    for pick, total in _k_best_sums([lst.tolist() for lst in lists], k):
        columns = np.empty(n_rows, dtype=np.intp)
        columns[single] = order[np.arange(n_single), pick[:n_single]]
        for (rows, ranked), i in zip(groups, pick[n_single:]):
            columns[rows] = ranked[i][0]
        out.append((columns, float(total)))
    return out


def _k_best_sums(lists, k):
    """The k smallest totals choosing one entry from each ranked list (ascending arrays): (indices, total)."""
    start = (0,) * len(lists)
    heap = [(sum(lst[0] for lst in lists), start)]
    seen = {start}
    out = []
    while heap and len(out) < k:
        total, pick = heapq.heappop(heap)
        out.append((pick, total))
        for j, lst in enumerate(lists):
            if pick[j] + 1 < len(lst):
                nxt = pick[:j] + (pick[j] + 1,) + pick[j + 1:]
                if nxt not in seen:
                    seen.add(nxt)
                    heapq.heappush(heap, (total - lst[pick[j]] + lst[pick[j] + 1], nxt))
    return out


def _murty(cost, k: int) -> list[tuple[np.ndarray, float]]:
    """Murty's ranking of the k best assignments of one connected part (R <= C)."""
    n_rows, n_cols = cost.shape
    first = _solve(cost)
    if first is None:
        return []
    out = []
    # A subproblem: rows < `fixed` forced to their columns in `columns` (its best solution), and the
    # (row, column) pairs in `excluded` forbidden. Heap entries: (total, tie-breaker, columns, fixed, excluded).
    finite = np.isfinite(cost)
    counter = 0
    heap = [(first[1], counter, first[0], 0, ())]
    while heap and len(out) < k:
        total, _, columns, fixed, excluded = heapq.heappop(heap)
        out.append((columns, total))
        if len(out) == k:
            break
        # Partition the rest of this subproblem (Murty): for each row r >= fixed, the solutions that
        # agree with `columns` on rows < r and give row r another column.
        base, allowed = cost, finite
        if excluded:
            base, allowed = cost.copy(), finite.copy()
            for r, c in excluded:
                base[r, c] = np.inf
                allowed[r, c] = False
        forced_cost = float(cost[np.arange(fixed), columns[:fixed]].sum())
        free = np.ones(n_cols, bool)
        free[columns[:fixed]] = False
        for r in range(fixed, n_rows):
            own = columns[r]
            others = allowed[r] & free
            others[own] = False
            if others.any():  # otherwise no solution differs from this one first at row r
                free_cols = np.flatnonzero(free)
                sub = base[r:][:, free_cols]
                sub[0, np.searchsorted(free_cols, own)] = np.inf
                solved = _solve(sub)
                if solved is not None:
                    cols_sub, sub_total = solved
                    new = columns.copy()
                    new[r:] = free_cols[cols_sub]
                    counter += 1
                    child_excluded = tuple(e for e in excluded if e[0] >= r) + ((r, int(own)),)
                    heapq.heappush(heap, (forced_cost + sub_total, counter, new, r, child_excluded))
            # The children after this one keep row r at its column.
            forced_cost += cost[r, own]
            free[own] = False
    return out
