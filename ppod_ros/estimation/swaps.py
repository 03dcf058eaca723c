"""Two channels swapped in wiring: how much of the misfit exchanging them back explains.

A swapped pair reads ``y_b`` on channel a and ``y_a`` on channel b. Where the swap mimics a rigid
motion the array's residual test sees only part of it: on the PPOD2 lab's device, the vertical
channels u3 and u9 are mirror images across the x axis, so their swap reads like reversing alpha_x on
that pair, and on motions with little roll it misfits by 27-34 % of their readings, no more than
this device's healthy weak channels (up to 36 %). Exchanging the two back is the direct test: it
leaves a healthy array's least-squares residual at most 23 % smaller (any other exchange makes it
larger), a swapped array's 64-94 % smaller (every swap of two live channels carrying different
signals in the lab's 9 driven records, `ppod bench feedback --sections real`).

Per harmonic with ``M = I - H H^+`` (the residual projector of the used channels) and residual
``r = M y``, exchanging a and b changes the readings by ``d (e_a - e_b)`` with ``d = y_b - y_a``, so

    |r'|^2 = |r|^2 + 2 Re(d (conj(r_a) - conj(r_b))) + |d|^2 (M_aa + M_bb - 2 M_ab),

every pair at once, no refit.
"""

from __future__ import annotations

import numpy as np


def exchange_ratios(H: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Residual norm after exchanging each pair of channels, over the residual norm as read.

    Parameters
    ----------
    H : ndarray (K, C, 6)
        Per-harmonic measurement matrices of the used channels.
    Y : complex ndarray (K, C)
        Their readings (second-order terms removed).

    Returns
    -------
    ndarray (C, C)
        Symmetric; the diagonal and every entry are inf when the readings fit exactly.
    """
    K, C, _ = H.shape
    before = 0.0
    after = np.zeros((C, C))
    for k in range(K):
        M = np.eye(C) - H[k] @ np.linalg.pinv(H[k])
        r = M @ Y[k]
        before += float(np.sum(np.abs(r) ** 2))
        d = Y[k][None, :] - Y[k][:, None]  # d[a, b] = y_b - y_a
        rc = np.conj(r)
        diag = np.diag(M)
        after += (np.sum(np.abs(r) ** 2) + 2 * np.real(d * (rc[:, None] - rc[None, :]))
                  + np.abs(d) ** 2 * (diag[:, None] + diag[None, :] - 2 * M))
    if before <= 0.0:
        return np.full((C, C), np.inf)
    ratio = np.sqrt(np.maximum(after, 0.0) / before)
    np.fill_diagonal(ratio, np.inf)
    return ratio


__all__ = ["exchange_ratios"]
