"""Anti-aliased rasterisation of projected polygons.

Polygons are given in the plate (or board) frame, projected through the real lens model (their
edges densified first, because distortion bends straight edges), and filled on a supersampled
canvas that is then box-filtered down: each output pixel holds the fraction of its area the polygon
covers, to within 1/ss^2. That is what a real sensor integrates, and it is what makes sub-pixel
accuracy of a tracker meaningful.

Pixel convention (OpenCV's): the centre of pixel (u, v) is at (u, v); it spans [u - 0.5, u + 0.5).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

#: Fractional bits of cv2.fillPoly's fixed-point vertex coordinates.
_SHIFT = 4


def densify(polygon: np.ndarray, step: float) -> np.ndarray:
    """Closed polygon (M, 2) with extra vertices so that no edge is longer than ``step``."""
    p = np.asarray(polygon, dtype=float)
    d = np.roll(p, -1, axis=0) - p
    n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / step).astype(int))
    edge = np.repeat(np.arange(len(p)), n)
    # Position of each new vertex along its edge: 0, 1/n, ..., (n-1)/n.
    t = np.arange(edge.size) - np.repeat(np.cumsum(n) - n, n)
    return p[edge] + (t / n[edge])[:, None] * d[edge]


def coverage(
    polygons_px: Sequence[np.ndarray], origin: tuple[int, int], size: tuple[int, int], ss: int
) -> np.ndarray:
    """Fraction of each pixel of a window covered by the union of polygons.

    Parameters
    ----------
    polygons_px : sequence of ndarray, shape (M, 2)
        Polygons in image pixel coordinates (u, v).
    origin : (u0, v0)
        Pixel of the window's top-left corner.
    size : (width, height)
        Window size (pixels).
    ss : int
        Supersampling factor per axis.

    Returns
    -------
    ndarray, shape (height, width), float32 in [0, 1]
    """
    w, h = size
    canvas = np.zeros((h * ss, w * ss), dtype=np.uint8)
    fill_polygons(canvas, polygons_px, origin, ss, 255)
    return downsample(canvas, ss)


def fill_polygons(
    canvas: np.ndarray, polygons_px: Sequence[np.ndarray], origin: tuple[int, int], ss: int, value: int
) -> None:
    """Fill polygons (image pixel coordinates) into a supersampled uint8 canvas whose pixel
    (0, 0) is the first sub-pixel of image pixel ``origin``."""
    pts = [_to_fixed(p, origin, ss) for p in polygons_px if len(p) >= 3]
    if pts:
        cv2.fillPoly(canvas, pts, int(value), lineType=cv2.LINE_8, shift=_SHIFT)


def downsample(canvas: np.ndarray, ss: int) -> np.ndarray:
    """Box-filter a supersampled uint8 canvas by ``ss`` into float32 values in [0, 1]."""
    h, w = canvas.shape[0] // ss, canvas.shape[1] // ss
    # Summing in integers keeps the exact 1/ss^2 steps that cv2.INTER_AREA on uint8 would round.
    total = canvas.reshape(h, ss, w, ss).sum(axis=(1, 3), dtype=np.uint32)
    return total.astype(np.float32) * np.float32(1.0 / (255 * ss * ss))


def _to_fixed(poly_px: np.ndarray, origin: tuple[int, int], ss: int) -> np.ndarray:
    # Sub-pixel k of the canvas has its centre at image coordinate origin - 0.5 + (k + 0.5) / ss.
    p = (np.asarray(poly_px, dtype=float) - np.array(origin, dtype=float) + 0.5) * ss - 0.5
    # cv2.fillPoly also fills sub-pixels whose centres round onto the outline: a shape grows by
    # 0.4-0.55 sub-pixel per edge, depending on the edge's direction. Moving the outline 0.4
    # sub-pixel inwards leaves areas within 0.2 % (measured on rotated rectangles and disks).
    p = _offset_inwards(p, 0.4)
    return np.round(p * (1 << _SHIFT)).astype(np.int32).reshape(-1, 1, 2)


def _offset_inwards(p: np.ndarray, d: float) -> np.ndarray:
    """Polygon (M, 2) with every edge moved ``d`` inwards (mitred corners)."""
    keep = np.any(np.abs(p - np.roll(p, 1, axis=0)) > 1e-9, axis=1)
    p = p[keep]
    if len(p) < 3:
        return p
    e = np.roll(p, -1, axis=0) - p
    e /= np.hypot(e[:, 0], e[:, 1])[:, None]
    signed = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    # Inward normal of each edge: left of the direction of travel for a positive (counter-
    # clockwise in these axes) polygon, right otherwise.
    n = np.stack([-e[:, 1], e[:, 0]], axis=1) * (1.0 if signed > 0 else -1.0)
    n_prev = np.roll(n, 1, axis=0)
    denom = np.maximum(1.0 + np.sum(n * n_prev, axis=1), 1e-6)
    return p + d * (n + n_prev) / denom[:, None]


def window_of(
    points_px: np.ndarray, width: int, height: int, margin: int
) -> tuple[int, int, int, int] | None:
    """Integer window (u0, v0, u1, v1) (exclusive end) around points, clipped to the image;
    None if it lies wholly outside."""
    lo = np.floor(points_px.min(axis=0)).astype(int) - margin
    hi = np.ceil(points_px.max(axis=0)).astype(int) + margin + 1
    u0, v0 = max(lo[0], 0), max(lo[1], 0)
    u1, v1 = min(hi[0], width), min(hi[1], height)
    if u0 >= u1 or v0 >= v1:
        return None
    return u0, v0, u1, v1


__all__ = ["coverage", "densify", "downsample", "fill_polygons", "window_of"]
