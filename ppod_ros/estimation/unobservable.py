"""What an accelerometer array cannot see: the calibration's unobservable directions, named.

Per harmonic a channel reads ``h_c . u`` with ``u = [p'', alpha]`` (6) and ``h_c = [w_c, l_c x w_c]``
(``w_c`` its sensitivity vector, gain times axis; ``l_c`` its lever). Any real 6 x 6 map ``N`` that
keeps every ``h_c`` a reading vector of its own channel (``h_c + eps N^T h_c = [w', l_c x w']`` for
some ``w'``), applied with ``u -> u - eps N u`` to every motion, leaves every reading unchanged: no
recording of any motion shows it. The calibration fixes such directions by a convention (least
change from the nominal axes, mean gain 1); what a direction does to the motion is then a bias of
every estimate made with the calibration, which no learning removes.

For a coplanar ring (every channel at one radius ``R`` in one plane, the levers measured from the
ring's centre; its height only shifts each harmonic's motion) the table :data:`DIRECTIONS` names ten
such maps, with the motion each trades with. On the default 12-channel layout (tangential and
vertical channels) all ten are unobservable; a layout off the ring keeps only those that do not
need its symmetry (the calibration's Jacobian decides, :func:`null_space`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

#: Singular values of the calibration's column-scaled Jacobian below this fraction of the largest count
#: as unobserved: a change along such a direction moves the readings by less than 1e-4 of the best
#: observed one, far below any device's misfit. On the default layout the ring's ten directions sit
#: at 1e-16 (7) and 4e-8 to 8e-7 (3: its positions are rounded to 0.1 mm, radii equal to 1e-4), the
#: first observed one at 7e-2.
NULL_TOLERANCE = 1e-4
#: Singular value (of unit columns) below which a direction repeats others in the unobserved basis.
DISTINCT = 0.1
#: A named direction lies in the unobserved subspace when its part outside it is below this fraction.
NAMED_TOLERANCE = 0.05


def _map(entries: Sequence[tuple[int, int, str]]) -> Callable[[float], np.ndarray]:
    """N^T (6 x 6) from (row, column, factor) with factor '1', '-1', 'R', '-R', '1/R', '-1/R'."""
    factors = {"1": lambda r: 1.0, "-1": lambda r: -1.0, "R": lambda r: r, "-R": lambda r: -r,
               "1/R": lambda r: 1.0 / r, "-1/R": lambda r: -1.0 / r}

    def make(radius_m: float) -> np.ndarray:
        m = np.zeros((6, 6))
        for i, j, f in entries:
            m[i, j] = factors[f](radius_m)
        return m

    return make


# Motion components: 0 p''x, 1 p''y, 2 p''z, 3 alpha_x, 4 alpha_y, 5 alpha_z (at the ring's centre).
# Each entry: name (what changes in the sensitivities, and the motion it trades with), N^T.
#: The ten unobservable directions of a coplanar ring of radius R (module docstring).
DIRECTIONS: dict[str, Callable[[float], np.ndarray]] = {
    "common gain of all channels (trades with the scale of every motion)":
        _map([(i, i, "1") for i in range(6)]),
    "gain of the in-plane parts of the sensitivities relative to the vertical parts "
    "(trades with the scale of p''x, p''y, alpha_z)":
        _map([(0, 0, "1"), (1, 1, "1"), (5, 5, "1")]),
    "common in-plane rotation of the in-plane parts (trades with a yaw of p''x, p''y)":
        _map([(0, 1, "1"), (1, 0, "-1")]),
    "common tilt of the in-plane axes out of the plate (trades alpha_z with p''z, "
    "alpha_x with p''x, alpha_y with p''y)":
        _map([(2, 5, "1/R"), (3, 0, "-R"), (4, 1, "-R")]),
    "common offset of the in-plane axes along x (trades p''x with alpha_z)":
        _map([(0, 5, "-1/R"), (5, 0, "-R")]),
    "common offset of the in-plane axes along y (trades p''y with alpha_z)":
        _map([(1, 5, "1/R"), (5, 1, "R")]),
    "common tilt of the vertical axes towards x (trades p''x with p''z, alpha_z with alpha_x)":
        _map([(0, 2, "1"), (5, 3, "-1")]),
    "common tilt of the vertical axes towards y (trades p''y with p''z, alpha_z with alpha_y)":
        _map([(1, 2, "1"), (5, 4, "-1")]),
    "common radial tilt of the vertical axes (trades p''x, p''y with alpha_y, alpha_x)":
        _map([(0, 4, "-1/R"), (1, 3, "1/R")]),
    "common tangential tilt of the vertical axes (trades alpha_z with p''z, p''x, p''y with "
    "alpha_x, alpha_y)":
        _map([(0, 3, "-1/R"), (1, 4, "-1/R"), (5, 2, "R")]),
}


def _reading_matrix(rho: np.ndarray) -> np.ndarray:
    """S (3 x 6) with S u = p'' + alpha x rho: a channel with sensitivity w has h = S^T w."""
    x, y, z = rho
    return np.array([[1, 0, 0, 0, z, -y], [0, 1, 0, -z, 0, x], [0, 0, 1, y, -x, 0]], float)


def direction_fields(position_m: np.ndarray, w: np.ndarray) -> dict[str, np.ndarray]:
    """Each named direction's sensitivity change (C, 3) at sensitivities ``w`` (C, 3).

    Levers from the centroid of the channel positions; the change is the least-squares ``dw_c`` with
    ``S_c^T dw_c = N^T h_c`` (exact where the direction is unobservable).
    """
    centre = position_m.mean(axis=0)
    rho = position_m - centre
    radius = float(np.mean(np.linalg.norm(rho[:, :2], axis=1)))
    out = {}
    for name, make in DIRECTIONS.items():
        nt = make(radius)
        dw = np.empty_like(w)
        for c in range(w.shape[0]):
            s = _reading_matrix(rho[c])
            dw[c] = np.linalg.lstsq(s.T, nt @ (s.T @ w[c]), rcond=None)[0]
        out[name] = dw
    return out


def name_directions(position_m: np.ndarray, w: np.ndarray, basis: np.ndarray) -> tuple[list[str], int]:
    """The named directions that lie in ``basis`` (3C, n orthonormal), and how many dimensions remain.

    Returns (names, others): ``others`` is ``n`` minus the rank of the named directions found in it.
    """
    found, vecs = [], []
    if basis.shape[1] == 0:
        return found, 0
    for name, dw in direction_fields(position_m, w).items():
        v = dw.reshape(-1)
        norm = float(np.linalg.norm(v))
        if norm == 0.0:
            continue
        outside = v - basis @ (basis.T @ v)
        if np.linalg.norm(outside) <= NAMED_TOLERANCE * norm:
            found.append(name)
            vecs.append(v / norm)
    rank = int(np.linalg.matrix_rank(np.array(vecs).T, 1e-6)) if vecs else 0
    return found, basis.shape[1] - rank


def unseen_directions(position_m: np.ndarray, w: np.ndarray, jacobian: np.ndarray) -> list[str]:
    """Names of the ring's directions the readings do not see at sensitivities ``w`` (C, 3).

    ``jacobian`` (rows, 3C): the readings' Jacobian with respect to the sensitivities, the motions
    projected out (a direction is unseen when it moves the readings by less than
    :data:`NULL_TOLERANCE` of the best seen direction).
    """
    top = float(right_singular(jacobian)[0][0])
    out = []
    for name, dw in direction_fields(position_m, w).items():
        v = dw.reshape(-1)
        norm = float(np.linalg.norm(v))
        if norm > 0 and np.linalg.norm(jacobian @ v) <= NULL_TOLERANCE * top * norm:
            out.append(name)
    return out


def unobserved_basis(position_m: np.ndarray, w: np.ndarray, jacobian: np.ndarray, names: Sequence[str]
                     ) -> np.ndarray:
    """Orthonormal basis (3C, n): the named directions at ``w`` and whatever else ``jacobian`` does not see.

    The named directions are taken at the current sensitivities even where the array's deviation from
    the ring lets the readings see them faintly (a few per cent of the best seen direction for errors
    of 3 degrees and 3 %): too faint to fit from operating data, they stay the convention's.
    """
    fields = direction_fields(position_m, w)
    cols = [fields[n].reshape(-1) for n in names] + list(null_space(jacobian, jacobian.shape[1]).T)
    if not cols:
        return np.zeros((jacobian.shape[1], 0))
    cols = np.array(cols).T
    u, s, _ = np.linalg.svd(cols / np.linalg.norm(cols, axis=0), full_matrices=False)
    return u[:, s > DISTINCT]  # a named direction and the numerical null's copy of it count once


def right_singular(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Singular values (descending) and right singular vectors (rows) of a tall ``matrix`` (rows, P).

    From the P x P Gram matrix: a tall SVD in threaded LAPACK takes 50x longer on a loaded machine,
    and the squared condition still resolves singular values to 1e-8 of the largest, far below
    :data:`NULL_TOLERANCE`.
    """
    lam, vec = np.linalg.eigh(matrix.T @ matrix)
    order = np.argsort(lam)[::-1]
    return np.sqrt(np.maximum(lam[order], 0.0)), vec[:, order].T


def null_space(jacobian: np.ndarray, num_sensitivities: int) -> np.ndarray:
    """Orthonormal basis (num_sensitivities, n) of the sensitivity parts of ``jacobian``'s null space.

    Parameters
    ----------
    jacobian : ndarray (rows, P)
        Real Jacobian of every reading; its first ``num_sensitivities`` columns are the sensitivities.
        Columns are scaled to unit norm first (so units do not decide what is observed).
    """
    norms = np.maximum(np.linalg.norm(jacobian, axis=0), 1e-300)
    s, vt = right_singular(jacobian / norms)
    null = vt[s < s[0] * NULL_TOLERANCE] / norms  # back to unscaled parameters
    if null.size == 0:
        return np.zeros((num_sensitivities, 0))
    q, r = np.linalg.qr(null[:, :num_sensitivities].T)
    return q[:, np.abs(np.diag(r)) > 1e-12 * np.abs(r).max()]


__all__ = ["DIRECTIONS", "NULL_TOLERANCE", "direction_fields", "name_directions", "null_space", "right_singular",
           "unobserved_basis", "unseen_directions"]
