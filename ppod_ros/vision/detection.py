"""Blob detection and sub-pixel blob moments in the plate frame.

One frame, in order:

1. Crop to the image rectangle around the work area; pixels outside the work area are ignored.
2. Background: the plate's brightness under the current lighting, from a block-averaged copy of
   the image with the parts removed by a morphological opening (closing for dark parts) and
   smoothed. Lighting gradients and slow lighting changes are absorbed here, frame by frame.
3. Foreground: pixels brighter than ``threshold_ratio`` times the background (darker, for dark
   parts); connected components (8-connected) are the blobs.
4. For each blob, a weight per pixel w = (I / B - 1) / (kappa - 1), the fraction of the pixel the
   part covers (kappa is the part-to-plate brightness ratio measured on the blob's interior), over
   the blob dilated by two pixels so that anti-aliased and blurred edges count in full. Moments of
   w are summed with each pixel's plate coordinates and plate area from the calibration's pixel
   map: the area, centroid and complex moments sum(w dA (z - c)^n) come out in the plate frame,
   free of distortion and perspective. Complex moments of order n >= 1 are unchanged by an
   isotropic blur, which is why they are used for orientation.

Blobs that touch the work area's boundary are flagged ``at_edge`` (the part is only partly in
view). Nothing here knows the parts; :mod:`ppod_ros.vision.shapes` matches blobs to part types.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.vision.camera import PlateLayout
from ppod_ros.vision.frames import BadFrameError
from ppod_ros.vision.geometry import PlateCalibration

_K3 = np.ones((3, 3), np.uint8)
_K5 = np.ones((5, 5), np.uint8)
#: Reach of the ring of plate pixels that gives each blob its local plate brightness (4 px: the
#: ring is the two pixels just outside a blob's support).
_RING_REACH = 4
_K_RING = np.ones((2 * _RING_REACH + 1, 2 * _RING_REACH + 1), np.uint8)


@dataclass(frozen=True)
class DetectorSettings:
    """Parameters of blob detection (see the module docstring).

    polarity : "bright" (parts brighter than the plate) or "dark".
    threshold_ratio : brightness ratio to the local plate level above which (below 1/ratio for
        dark parts) a pixel is foreground.
    min_area_px : components smaller than this are noise.
    background_cell_px : block size of the background estimate (pixels).
    max_part_size_m : the largest part's diameter (m): sets the opening that removes parts from
        the background estimate.
    max_order : highest complex moment computed.
    dark_level_dn, bright_level_dn : a plate background below / above these (DN) means the frame
        is unusable (lamp off or lens covered; overexposed).
    """

    polarity: str = "bright"
    threshold_ratio: float = 1.8
    min_area_px: int = 12
    background_cell_px: int = 8
    max_part_size_m: float = 0.04
    max_order: int = 6
    dark_level_dn: float = 4.0
    bright_level_dn: float = 245.0


@dataclass(frozen=True, eq=False)
class Blob:
    """One connected foreground region, measured in the plate frame on the plane z = 0.

    Attributes
    ----------
    area_m2 : float
        Weighted area (m^2).
    centroid_m : ndarray, shape (2,)
        Weighted centroid (m).
    moments : ndarray, shape (max_order + 1,), complex
        sum(w dA (z - c)^n) for n = 0..max_order (m^(n+2)); moments[1] is 0 by construction.
    radial2 : float
        sum(w dA |z - c|^2) (m^4).
    extent_m : float
        Largest distance from the centroid to a pixel of the blob (m).
    area_px : int
        Foreground pixels.
    bbox_px : (u0, v0, u1, v1)
        Image window of the blob (exclusive end).
    at_edge : bool
        The blob touches the work area's boundary (only partly in view).
    crowded : bool
        Another blob is within the two-pixel edge band: both lose edge pixels, so neither is a
        clean measurement of one part.
    contrast : float
        Measured part-to-plate brightness ratio kappa on the blob's interior.
    """

    area_m2: float
    centroid_m: np.ndarray
    moments: np.ndarray
    radial2: float
    extent_m: float
    area_px: int
    bbox_px: tuple[int, int, int, int]
    at_edge: bool
    crowded: bool
    contrast: float


class BlobDetector:
    """Detect blobs in the work area of frames from one calibrated camera.

    Parameters
    ----------
    calibration : PlateCalibration
    plate : PlateLayout
        Gives the work area.
    settings : DetectorSettings
    """

    def __init__(
        self, calibration: PlateCalibration, plate: PlateLayout, settings: DetectorSettings | None = None
    ):
        self.settings = settings or DetectorSettings()
        self.calibration = calibration
        x0, x1, y0, y1 = plate.work_area_m
        pm = calibration.pixel_map(calibration.window_of_region((x0, x1), (y0, y1)))
        with np.errstate(invalid="ignore"):
            inside = (pm.x_m >= x0) & (pm.x_m <= x1) & (pm.y_m >= y0) & (pm.y_m <= y1)
        rows, cols = np.nonzero(inside)
        if rows.size == 0:
            raise ConfigError("plate.work_area_m: the work area is not in the camera's view")
        # The crop is the smallest window holding the work area, in image and map coordinates.
        r0, r1, c0, c1 = int(rows.min()), int(rows.max()) + 1, int(cols.min()), int(cols.max()) + 1
        wu, wv = pm.window[:2]
        self._crop = (wu + c0, wv + r0, wu + c1, wv + r1)
        # Contiguous copies: the per-frame gathers index their flattened views.
        self._x = np.ascontiguousarray(pm.x_m[r0:r1, c0:c1])
        self._y = np.ascontiguousarray(pm.y_m[r0:r1, c0:c1])
        self._dA = np.ascontiguousarray(pm.area_m2[r0:r1, c0:c1])
        work = inside[r0:r1, c0:c1].astype(np.uint8)
        self._work = work  # 0/1, so that masks combined with it stay 0/1 (viewable as bool)
        band = work.astype(bool) & ~cv2.erode(
            work, _K3, borderType=cv2.BORDER_CONSTANT, borderValue=0
        ).astype(bool)
        self._band_rc = np.nonzero(band)  # rows, cols of the work area's boundary pixels
        # The background is estimated on a copy reduced by 2^levels per axis (Gaussian pyramid).
        self._pyr_levels = max(0, int(round(np.log2(max(1, self.settings.background_cell_px)))))
        cell = 2**self._pyr_levels
        small_work = work
        for _ in range(self._pyr_levels):
            small_work = cv2.pyrDown(small_work * 255)
            small_work = (small_work > 254).astype(np.uint8)
        self._small_work = small_work.astype(bool)
        px = calibration.pixel_size_m(tuple(np.mean(np.array(plate.work_area_m).reshape(2, 2), axis=1)))
        k = int(np.ceil(self.settings.max_part_size_m / (px * cell))) + 2
        self._open_kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * (k // 2) + 1, 2 * (k // 2) + 1))
        self.pixel_size_m = px
        #: Complex-moment orders computed (besides 0); a tracker narrows them to what its parts need.
        self.orders: tuple[int, ...] = tuple(range(2, self.settings.max_order + 1))

    @property
    def crop_px(self) -> tuple[int, int, int, int]:
        """Image window (u0, v0, u1, v1) that holds the work area."""
        return self._crop

    def detect(self, gray: np.ndarray) -> list[Blob]:
        """Blobs in a grey (H, W) uint8 frame of the calibrated size."""
        s = self.settings
        u0, v0, u1, v1 = self._crop
        crop = np.ascontiguousarray(gray[v0:v1, u0:u1])
        small = self._background(crop)
        bright = s.polarity == "bright"
        # The threshold is formed on the reduced background and enlarged as 8-bit: cheaper than
        # enlarging the background itself, and the blobs' own plate level comes from their rings.
        thr_small = cv2.convertScaleAbs(small, alpha=s.threshold_ratio if bright else 1.0 / s.threshold_ratio)
        thr = cv2.resize(thr_small, (crop.shape[1], crop.shape[0]), interpolation=cv2.INTER_LINEAR)
        fg = cv2.bitwise_and(cv2.compare(crop, thr, cv2.CMP_GT if bright else cv2.CMP_LT), self._work)
        # Everything after the threshold runs on the window around the foreground, with room for
        # the rings: few parts cost little.
        bx, by, bw, bh = cv2.boundingRect(fg)
        if bw == 0:
            return []
        m = _RING_REACH + 1
        r0, c0 = max(by - m, 0), max(bx - m, 0)
        r1, c1 = min(by + bh + m, crop.shape[0]), min(bx + bw + m, crop.shape[1])
        win = (slice(r0, r1), slice(c0, c1))
        fg_w = np.ascontiguousarray(fg[win])
        # 16-bit labels: OpenCV's morphology below works on them directly. Component statistics
        # come from the sorted pixel lists: cheaper than OpenCV's.
        n, labels = cv2.connectedComponents(fg_w, connectivity=8, ltype=cv2.CV_16U)
        if n > 65000:
            raise BadFrameError(
                f"frame has {n} foreground regions: noise, not parts (threshold too low?)", "noise"
            )
        if n <= 1:
            return []
        return self._measure_all(np.ascontiguousarray(crop[win]), small, fg_w, labels, n, (r0, c0))

    def _background(self, crop: np.ndarray) -> np.ndarray:
        """The plate's brightness on the reduced grid (1 / 2^levels), parts removed."""
        s = self.settings
        small = crop
        for _ in range(self._pyr_levels):
            small = cv2.pyrDown(small)
        small = small.astype(np.float32)
        level = float(np.median(small[self._small_work]))
        if level < s.dark_level_dn:
            raise BadFrameError(
                f"frame is dark: plate level {level:.1f} DN (< {s.dark_level_dn} DN); lamp off or lens "
                "covered?",
                "exposure",
            )
        if level > s.bright_level_dn:
            raise BadFrameError(
                f"frame is overexposed: plate level {level:.1f} DN (> {s.bright_level_dn} DN)", "exposure"
            )
        small[~self._small_work] = level
        op = cv2.MORPH_OPEN if s.polarity == "bright" else cv2.MORPH_CLOSE
        small = cv2.morphologyEx(small, op, self._open_kernel, borderType=cv2.BORDER_REPLICATE)
        return cv2.GaussianBlur(small, (0, 0), 1.0, borderType=cv2.BORDER_REPLICATE)

    def _sample_background(self, small: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Bilinear samples of the reduced background at crop pixels (rows, cols)."""
        cell = float(2**self._pyr_levels)
        fy = np.clip(rows / cell, 0, small.shape[0] - 1.001)
        fx = np.clip(cols / cell, 0, small.shape[1] - 1.001)
        iy, ix = fy.astype(np.int64), fx.astype(np.int64)
        wy, wx = fy - iy, fx - ix
        top = small[iy, ix] * (1 - wx) + small[iy, ix + 1] * wx
        bottom = small[iy + 1, ix] * (1 - wx) + small[iy + 1, ix + 1] * wx
        return (top * (1 - wy) + bottom * wy).astype(np.float32)

    def _local_background(
        self,
        crop: np.ndarray,
        fg: np.ndarray,
        support: np.ndarray,
        work: np.ndarray,
        labels: np.ndarray,
        ids: np.ndarray,
        n: int,
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Per blob, a plane I = a + b u + c v (window pixel coordinates) fitted to the plate
        pixels 3 to 4 pixels around it.

        The global background is an opening, which is biased near parts on a lighting gradient
        (a part hides the plate's darkest pixels from it); the ring around each blob sees the
        plate's brightness right there. Returns (coefficients (len(ids), 3), usable (len(ids),)),
        or None when no blob has a ring.
        """
        # Masks are 0/1: the saturating subtraction removes the support from the reach.
        ring = cv2.subtract(cv2.bitwise_and(cv2.dilate(fg, _K_RING), work), support)
        ridx = np.flatnonzero(ring.view(bool))
        if ridx.size == 0:
            return None
        # Ring pixels belong to the blob with the largest label within reach: any plate pixel
        # near a blob serves its fit, so sharing needs no tie-break.
        rlab = cv2.dilate(labels, _K_RING).ravel()[ridx]
        width = crop.shape[1]
        u = (ridx % width).astype(np.float64)
        v = (ridx // width).astype(np.float64)
        val = crop.ravel()[ridx].astype(np.float64)
        cols = [np.ones_like(u), u, v, u * u, u * v, v * v, val, u * val, v * val]
        sums = np.stack([np.bincount(rlab, w, minlength=n + 1) for w in cols], axis=1)[ids]
        A = sums[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(-1, 3, 3)
        rhs = sums[:, 6:9]
        # A ring surrounds its blob, so its normal equations are well conditioned; a ring cut
        # short by the work area's edge may not be: those blobs keep the global background.
        a, b, c = A[:, 0], A[:, 1], A[:, 2]
        det = (
            a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1])
            - a[:, 1] * (b[:, 0] * c[:, 2] - b[:, 2] * c[:, 0])
            + a[:, 2] * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0])
        )
        ok = (sums[:, 0] >= 12) & (np.abs(det) > 1e-9 * np.abs(a[:, 0] * b[:, 1] * c[:, 2]) + 1e-300)
        A[~ok] = np.eye(3)
        coef = np.linalg.solve(A, rhs[..., None])[..., 0]
        return coef.astype(np.float32), ok

    def _measure_all(
        self,
        crop: np.ndarray,
        small: np.ndarray,
        fg: np.ndarray,
        labels: np.ndarray,
        n: int,
        origin: tuple[int, int],
    ) -> list[Blob]:
        """Measure every blob of a window of the crop whose top-left crop pixel is ``origin``."""
        s = self.settings
        r0, c0 = origin
        height, width = crop.shape
        win = (slice(r0, r0 + height), slice(c0, c0 + width))
        work = np.ascontiguousarray(self._work[win])
        # Support: foreground plus two pixels around it, where anti-aliased and blurred edges
        # fall. A pixel within two pixels of two blobs would mix both parts: it belongs to neither.
        near_max = cv2.dilate(labels, _K5)
        inv = np.zeros_like(labels)
        cv2.subtract((float(n + 1), 0.0, 0.0, 0.0), labels, dst=inv, mask=fg)
        near_inv = cv2.dilate(inv, _K5)  # n + 1 - (smallest label nearby), 0 if none
        support = cv2.bitwise_and(cv2.dilate(fg, _K5), work)
        idx = np.flatnonzero(support.view(bool))
        lab = labels.ravel()[idx].astype(np.int32)
        own = lab > 0
        mx = near_max.ravel()[idx].astype(np.int32)
        mn = (n + 1) - near_inv.ravel()[idx].astype(np.int32)
        unique = own | (mx == mn)
        # Blobs closer than the support's reach lose edge pixels to each other: flag them, since
        # their moments are no longer those of one whole part.
        crowded = np.zeros(n + 2, bool)
        crowded[mx[~unique]] = True
        crowded[mn[~unique]] = True
        lab = np.where(own, lab, mx)
        idx, lab, own = idx[unique], lab[unique], own[unique]
        # Group the pixels by blob: every per-blob sum is then one contiguous reduction.
        order = np.argsort(lab, kind="stable")
        idx, lab, own = idx[order], lab[order], own[order]
        starts = np.flatnonzero(np.r_[True, lab[1:] != lab[:-1]])
        ids = lab[starts]
        area_px = np.add.reduceat(own.astype(np.int64), starts)
        counts = np.diff(np.r_[starts, idx.size])
        rows, cols = idx // width, idx % width
        # Each blob's own plane of plate brightness where its ring allowed one, else the global one.
        plate_level = None
        local = self._local_background(crop, fg, support, work, labels, ids, n)
        if local is not None:
            coef, ok = local
            c = np.repeat(coef, counts, axis=0)
            plate_level = c[:, 0] + c[:, 1] * cols.astype(np.float32) + c[:, 2] * rows.astype(np.float32)
            if not ok.all():
                fallback = self._sample_background(small, rows + r0, cols + c0)
                plate_level = np.where(np.repeat(ok, counts), plate_level, fallback)
        if plate_level is None:
            plate_level = self._sample_background(small, rows + r0, cols + c0)
        ratio = crop.ravel()[idx].astype(np.float32) / plate_level
        # kappa, the part-to-plate brightness ratio, on each blob's interior (2 px inside its
        # edge); thin blobs without an interior use their most extreme pixel.
        interior = cv2.erode(fg, _K5, borderType=cv2.BORDER_CONSTANT, borderValue=0).ravel()[idx].astype(bool)
        n_in = np.add.reduceat(interior.astype(np.int64), starts)
        kappa = np.add.reduceat(np.where(interior, ratio, 0.0), starts) / np.maximum(n_in, 1)
        thin = n_in == 0
        if thin.any():
            extreme = (np.maximum if s.polarity == "bright" else np.minimum).reduceat(ratio, starts)
            kappa = np.where(thin, extreme, kappa)
        denom = np.where(np.abs(kappa - 1.0) > 0.05, kappa - 1.0, np.inf)
        # Plate coordinates and areas come from the calibration's maps of the whole crop.
        cidx = (rows + r0) * self._x.shape[1] + (cols + c0)
        mass = ((ratio - 1.0) * self._dA.ravel()[cidx] / np.repeat(denom, counts)).astype(np.float64)
        x = self._x.ravel()[cidx].astype(np.float64)
        y = self._y.ravel()[cidx].astype(np.float64)
        m0 = np.add.reduceat(mass, starts)
        safe = np.where(m0 > 0, m0, 1.0)
        cx = np.add.reduceat(mass * x, starts) / safe
        cy = np.add.reduceat(mass * y, starts) / safe
        z = (x - np.repeat(cx, counts)) + 1j * (y - np.repeat(cy, counts))
        moments = np.zeros((ids.size, s.max_order + 1), dtype=complex)
        moments[:, 0] = m0
        zn, power = np.ones_like(z), 0
        for n_order in self.orders:
            while power < n_order:
                zn *= z
                power += 1
            moments[:, n_order] = np.add.reduceat(mass * zn, starts)
        r2 = z.real**2 + z.imag**2
        radial2 = np.add.reduceat(mass * r2, starts)
        extent = np.sqrt(np.maximum.reduceat(np.where(own, r2, 0.0), starts))
        edge = np.zeros(n, bool)
        br, bc = self._band_rc[0] - r0, self._band_rc[1] - c0
        inside = (br >= 0) & (br < height) & (bc >= 0) & (bc < width)
        edge[labels[br[inside], bc[inside]]] = True
        u_lo, u_hi = np.minimum.reduceat(cols, starts), np.maximum.reduceat(cols, starts)
        v_lo, v_hi = np.minimum.reduceat(rows, starts), np.maximum.reduceat(rows, starts)
        # Window pixels to image pixels.
        du, dv = self._crop[0] + c0, self._crop[1] + r0
        blobs = []
        for j in np.flatnonzero((area_px >= s.min_area_px) & (m0 > 0) & np.isfinite(denom)):
            blobs.append(
                Blob(
                    float(m0[j]),
                    np.array([cx[j], cy[j]]),
                    moments[j],
                    float(radial2[j]),
                    float(extent[j]),
                    int(area_px[j]),
                    (int(u_lo[j]) + du, int(v_lo[j]) + dv, int(u_hi[j]) + du + 1, int(v_hi[j]) + dv + 1),
                    bool(edge[ids[j]]),
                    bool(crowded[ids[j]]),
                    float(kappa[j]),
                )
            )
        return blobs


__all__ = ["Blob", "BlobDetector", "DetectorSettings"]
