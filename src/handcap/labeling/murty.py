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

Where numba is installed (extra 'stream') the same ranking runs compiled on the
whole matrix (:mod:`handcap.labeling.lap`): the same k best totals, 0.6 ms less
per labelled frame of a 19-marker hand; this code is the fallback.
"""

from __future__ import annotations

import heapq

import numpy as np
from scipy.optimize import linear_sum_assignment

from handcap.labeling import lap


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


def k_best_assignments(cost, k: int, compiled: bool = True) -> list[tuple[np.ndarray, float]]:
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
    compiled : bool
        Rank them compiled (:func:`handcap.labeling.lap.k_best_compiled`)
        where numba is installed; equal totals may then come as other,
        equally cheap assignments.

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
    if compiled and lap.AVAILABLE:
        return lap.k_best_compiled(cost, k)
    if k == 1:  # the best alone: one assignment problem
        best = _solve(cost)
        return [] if best is None else [best]
    # Rows joined when they share a column (union-find over the finite entries). Labels are few, so
    # plain Python over the finite entries costs less than array operations here.
    rows_f, cols_f = np.nonzero(np.isfinite(cost))
    options = [[] for _ in range(n_rows)]
    parent = list(range(n_rows))
    owner = {}

    def root(r):
        while parent[r] != r:
            parent[r] = parent[parent[r]]
            r = parent[r]
        return r

    for r, c, v in zip(rows_f.tolist(), cols_f.tolist(), cost[rows_f, cols_f].tolist()):
        options[r].append((v, c))
        if c in owner:
            a, b = root(r), root(owner[c])
            if a != b:
                parent[max(a, b)] = min(a, b)
        else:
            owner[c] = r
    if not all(options):
        return []
    parts = {}
    for r in range(n_rows):
        parts.setdefault(root(r), []).append(r)
    single, lists, choices, groups = [], [], [], []
    for rows in parts.values():
        if len(rows) == 1:  # a row that competes with no other: its options, best first
            ranked = sorted(options[rows[0]])[:k]
            single.append(rows[0])
            lists.append([v for v, _ in ranked])
            choices.append([c for _, c in ranked])
    for rows in parts.values():
        if len(rows) > 1:
            cols = sorted({c for r in rows for _, c in options[r]})
            if len(cols) < len(rows):
                return []
            ranked = _murty(cost[np.ix_(rows, cols)], k)
            if not ranked:
                return []
            cols = np.array(cols)
            groups.append(rows)
            lists.append([t for _, t in ranked])
            choices.append([cols[a] for a, _ in ranked])
    out = []
    for pick, total in _k_best_sums(lists, k):
        columns = np.empty(n_rows, dtype=np.intp)
        columns[single] = [choices[j][i] for j, i in enumerate(pick[:len(single)])]
        for g, rows in enumerate(groups):
            j = len(single) + g
            columns[rows] = choices[j][pick[j]]
        out.append((columns, float(total)))
    return out


def _k_best_sums(lists, k):
    """The k smallest totals choosing one entry from each ranked list (ascending): (indices, total).

    Any k - 1 entries that are not first in their list give k - 1 distinct choices besides the all-first
    one, so the k-th best total exceeds the all-first one by at most the (k - 1)-th smallest such step;
    entries further than that from their list's first are never chosen, and a list left with one entry
    is a constant. The lists left are merged one at a time, keeping the k best partial choices.
    """
    base = sum(lst[0] for lst in lists)
    steps = sorted(v - lst[0] for lst in lists for v in lst[1:])
    if not steps or k == 1:
        return [((0,) * len(lists), base)]
    bound = steps[k - 2] if k <= len(steps) + 1 else np.inf
    best = [(0.0, ())]  # (extra over base, choice in each live list so far)
    live = []
    for j, lst in enumerate(lists):
        first = lst[0]
        extra = [v - first for v in lst if v - first <= bound]
        if len(extra) < 2:
            continue
        live.append(j)
        best = sorted((t + e, pick + (i,)) for t, pick in best for i, e in enumerate(extra) if t + e <= bound)[:k]
    out = []
    for t, pick in best:
        full = [0] * len(lists)
        for j, i in zip(live, pick):
            full[j] = i
        out.append((tuple(full), base + t))
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
