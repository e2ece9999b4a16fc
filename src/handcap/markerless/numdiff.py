"""Sparse forward-difference Jacobians with every difference taken in one batched call of the residuals.

scipy's ``least_squares`` with ``jac_sparsity`` groups the columns that share no
row and calls the residual function once per group: each call is a whole pass
over the frames in Python. Where the residuals of many parameter vectors can be
computed at once (the hand model and the projections are vectorised), all the
groups' steps go in one call instead. The steps and the differences are
scipy's two-point ones (a relative step of the square root of the machine
epsilon), so the Jacobian is the one scipy would take.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix


def column_groups(sparsity) -> np.ndarray:
    """Greedy groups of columns that share no row: a group index (n,) per column.

    Parameters
    ----------
    sparsity : array_like or scipy sparse (m, n)
        Nonzero where a residual depends on a parameter.

    Returns
    -------
    ndarray (n,) int
    """
    pattern = csr_matrix(sparsity, dtype=bool).tocsc()
    m, n = pattern.shape
    taken = []  # per group: the rows its columns touch
    group = np.zeros(n, int)
    for col in range(n):
        rows = pattern.indices[pattern.indptr[col]:pattern.indptr[col + 1]]
        g = next((k for k, used in enumerate(taken) if not used[rows].any()), len(taken))
        if g == len(taken):
            taken.append(np.zeros(m, bool))
        taken[g][rows] = True
        group[col] = g
    return group


def sparse_differences(batched, sparsity):
    """The Jacobian function of residuals that can be evaluated for many parameter vectors at once.

    Parameters
    ----------
    batched : callable
        ``batched(P)`` for parameter vectors ``P`` (B, n) gives their residuals (B, m).
    sparsity : array_like or scipy sparse (m, n)
        Nonzero where a residual depends on a parameter (a dependence left out gives a wrong Jacobian,
        as with scipy's ``jac_sparsity``).

    Returns
    -------
    callable
        ``jac(x)`` for a parameter vector (n,): the Jacobian (m, n) as a CSR matrix.
    """
    coo = csr_matrix(sparsity, dtype=bool).tocoo()
    rows, cols = coo.row, coo.col
    group = column_groups(sparsity)
    member = np.zeros((group.max() + 1 if len(group) else 0, len(group)))
    member[group, np.arange(len(group))] = 1.0
    shape = coo.shape

    def jac(x):
        x = np.asarray(x, dtype=np.float64)
        step = np.sqrt(np.finfo(np.float64).eps) * np.where(x >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
        step = (x + step) - x  # the step the sum can hold exactly
        found = batched(np.vstack([x, x + member * step]))
        values = (found[1 + group[cols], rows] - found[0, rows]) / step[cols]
        return csr_matrix((values, (rows, cols)), shape=shape)

    return jac
