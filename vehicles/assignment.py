"""Optimal one-to-one assignment of tracks to detections (the Hungarian method).

The tracker's matrices are a few rows by a few columns; this O(n^2 m) shortest-augmenting-path
solver gives the same optimum as `scipy.optimize.linear_sum_assignment` (tested against it)
without importing scipy.optimize, which alone costs a tenth of a second at start-up.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def linear_sum_assignment(
    cost: NDArray[np.float64],
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Rows and columns of a minimum-cost matching of min(n, m) pairs, rows ascending."""
    cost = np.asarray(cost, dtype=np.float64)
    if cost.ndim != 2:
        raise ValueError("cost must be a 2-D matrix")
    if not np.isfinite(cost).all():
        raise ValueError("cost must be finite")
    transposed = cost.shape[0] > cost.shape[1]
    c = cost.T if transposed else cost
    n, m = c.shape
    if n == 0:
        empty = np.zeros(0, np.intp)
        return empty, empty
    # Potentials u (rows), v (columns); column j is matched to row match[j] (1-based, 0: none).
    u = np.zeros(n + 1)
    v = np.zeros(m + 1)
    match = np.zeros(m + 1, np.intp)
    way = np.zeros(m + 1, np.intp)
    for row in range(1, n + 1):
        match[0] = row
        j0 = 0
        shortest = np.full(m + 1, np.inf)
        used = np.zeros(m + 1, bool)
        while True:
            used[j0] = True
            i0 = match[j0]
            free = ~used[1:]
            reduced = c[i0 - 1] - u[i0] - v[1:]
            better = free & (reduced < shortest[1:])
            shortest[1:][better] = reduced[better]
            way[1:][better] = j0
            candidates = np.where(free, shortest[1:], np.inf)
            j1 = int(np.argmin(candidates)) + 1
            delta = candidates[j1 - 1]
            u[match[used]] += delta
            v[used] -= delta
            shortest[1:][free] -= delta
            j0 = j1
            if match[j0] == 0:
                break
        while j0:  # augment along the path
            j1 = way[j0]
            match[j0] = match[j1]
            j0 = j1
    cols = np.flatnonzero(match[1:]) + 1
    rows = match[cols] - 1
    cols = cols - 1
    if transposed:
        rows, cols = cols, rows
    order = np.argsort(rows)
    return rows[order].astype(np.intp), cols[order].astype(np.intp)
