"""The 6-DoF least-squares solve behind :class:`~ppod_ros.estimation.AccelEstimator`.

Per harmonic the channels read ``Y_k = H_k U_k + S_k(U)``: ``H_k`` is the layout's first-order
matrix with the tilted-gravity term of that harmonic, ``S_k`` the second-order terms
(:mod:`~ppod_ros.estimation.second_order`), which depend on the motion itself. They are removed by
iterating solve -> evaluate S at the estimate -> subtract -> solve again (a contraction: S is about
1 % of the signal, so each pass gains about two digits).

Around that solve sits the channel logic: suspects (flat, stuck, not periodic) are set aside and
dropped only when the other channels predict a reading they do not show; then a channel whose
residual is inconsistent with the rest is dropped (the one whose removal explains the residuals
best, by leaving each out in turn) while the remaining channels still determine all six
components. Otherwise :class:`EstimationError` says which channels failed and which combination
became unobservable.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ppod_ros.errors import ConfigError, DeviceError
from ppod_ros.estimation.harmonic_fit import HealthSettings
from ppod_ros.estimation.layout import AccelerometerLayout
from ppod_ros.estimation.second_order import second_order_phasors
from ppod_ros.estimation.swaps import exchange_ratios
from ppod_ros.motion import MAX_HARMONIC, PlateMotion

OK = "ok"
#: Most channels removed at once to make the rest consistent (two: a pair of swapped wires;
#: C(12, 2) = 66 refits per estimate at most), and the most one estimate blames on residuals: a
#: record that needs more is an EstimationError, not a guess (suspects such as flat channels do not
#: count; they are dropped on their own evidence).
MAX_SUBSET_DROP = 2

#: Alternative channel sets named in an ambiguity error (the rest are counted).
AMBIGUOUS_SHOWN = 4


class EstimationError(DeviceError):
    """The healthy channels no longer determine the plate's acceleration.

    Attributes
    ----------
    channel_status : dict of str to str
        Every channel's status ("ok" or why it was dropped).
    """

    def __init__(self, message: str, channel_status: dict[str, str]):
        super().__init__(message)
        self.channel_status = dict(channel_status)


@dataclass(frozen=True)
class PlateEstimate:
    """Estimated plate-acceleration harmonics and how they were obtained.

    Attributes
    ----------
    frequency_hz : float
    k : ndarray of int, shape (K,)
        Harmonic numbers of the rows of ``phasors``.
    phasors : complex ndarray, shape (K, 6)
        U_k = [p''x, p''y, p''z, alpha_x, alpha_y, alpha_z] (m/s^2, rad/s^2), PHYSICS.md convention.
    std : ndarray, shape (K, 6)
        Standard deviation of each phasor from the channels' noise (0 where no noise is known).
    channels : tuple of str, length C
    status : tuple of str, length C
        "ok" or why the channel was dropped.
    residual_rms_mps2 : float
        RMS over used channels and harmonics of the least-squares residual phasors (m/s^2).
    residual_mps2 : ndarray, shape (K,)
        Residual norm over the used channels per harmonic (m/s^2).
    second_order_mps2 : ndarray, shape (K,)
        RMS over used channels of the second-order reading removed, per harmonic (m/s^2).
    iterations : int
        Solve passes of the second-order correction (of the final channel set).
    last_change : float
        Relative change of the estimate in the last pass (what the iteration leaves unconverged).
    cycles : float
        Periods of data behind the estimate (fractional for a partial cycle; the number of
        cycles averaged for summaries).
    channel_misfit : ndarray, shape (C,), optional
        Each used channel's in-sample residual (leverage-corrected) as a fraction of its own
        reading; NaN for channels not used. What :class:`~ppod_ros.estimation.misfit.MisfitHistory`
        learns the device's allowance from.
    """

    frequency_hz: float
    k: np.ndarray
    phasors: np.ndarray
    std: np.ndarray
    channels: tuple[str, ...]
    status: tuple[str, ...]
    residual_rms_mps2: float
    residual_mps2: np.ndarray
    second_order_mps2: np.ndarray
    iterations: int
    last_change: float
    cycles: float
    channel_misfit: np.ndarray | None = None

    @property
    def used(self) -> np.ndarray:
        """Boolean mask (C,) of channels that entered the final solve."""
        return np.array([s == OK for s in self.status])

    @property
    def dropped(self) -> dict[str, str]:
        return {n: s for n, s in zip(self.channels, self.status) if s != OK}

    def table(self, kmax: int) -> np.ndarray:
        """Phasors on a dense harmonic axis 1..kmax (row k-1 = harmonic k), shape (kmax, 6)."""
        out = np.zeros((kmax, 6), dtype=complex)
        for row, k in enumerate(self.k):
            if k <= kmax:
                out[k - 1] = self.phasors[row]
        return out

    def motion(self, name: str = "measured") -> PlateMotion:
        """The estimate as a :class:`PlateMotion` (harmonics up to MAX_HARMONIC)."""
        keep = self.k <= MAX_HARMONIC
        return PlateMotion.from_phasors(self.frequency_hz, self.k[keep], self.phasors[keep], name=name)


class _AmbiguousError(Exception):
    """Several channel sets of the same size explain the misfit equally (internal to the solver)."""

    def __init__(self, candidates: list[tuple[int, ...]]):
        super().__init__(candidates)
        self.candidates = candidates


class SixDofSolver:
    """Least squares over channels with second-order removal and channel rejection (see module doc)."""

    def __init__(
        self,
        layout: AccelerometerLayout,
        terms: Sequence[str],
        gravity_mps2: float,
        health: HealthSettings,
        max_iterations: int,
        tolerance: float,
        misfit_allowance: np.ndarray | None = None,
        bending: np.ndarray | None = None,
    ):
        self.layout = layout
        # Each channel's reading per unit p''z of the plate's bending (C,) (a calibration's), else none.
        self.bending = None if bending is None or not np.any(bending) else np.asarray(bending, float)
        # Relative misfit each layout channel may show against the others' prediction (C,): the
        # device's own, from its calibration, else the settings' default for every channel.
        allow = np.full(layout.num_channels, health.misfit_allowance)
        if misfit_allowance is not None:
            allow = np.asarray(misfit_allowance, dtype=float)
            if allow.shape != (layout.num_channels,) or np.any(~(allow >= 0)):
                raise ConfigError(
                    f"misfit_allowance: expected {layout.num_channels} values >= 0, got {allow.tolist()}"
                )
        self.allowance = allow
        self.terms = tuple(terms)
        self.gravity_mps2 = gravity_mps2
        self.health = health
        self.max_iterations = max_iterations
        self.tolerance = tolerance

    def solve(
        self,
        idx: np.ndarray,
        ks: np.ndarray,
        Y: np.ndarray,
        var: np.ndarray,
        freq_hz: float,
        fatal: list[str | None],
        suspect: list[str | None],
        cycles: float,
    ) -> PlateEstimate:
        if not (math.isfinite(freq_hz) and freq_hz > 0):
            raise ConfigError(f"frequency_hz: must be a finite number > 0 Hz, got {freq_hz}")
        ks = np.asarray(ks, dtype=int)
        names = tuple(self.layout.names[i] for i in idx)
        omega = 2 * math.pi * freq_hz
        H = np.stack(
            [self.layout.measurement_matrix(omega * k, self.gravity_mps2)[idx] for k in ks]
        )  # (K, C, 6)
        if self.bending is not None:
            H[..., 2] += self.bending[idx][None]
        pos, ax = self.layout.position_m[idx], self.layout.axis[idx]
        thr = self.health.residual_threshold
        allow = self.allowance[idx]
        # Each channel's own reading (K-norm): a misfit is judged against it as well as against the
        # noise, so that a live channel with a device-sized misfit (gain, axis, bending) is kept.
        own = np.sqrt(np.sum(np.abs(np.nan_to_num(Y)) ** 2, axis=0))
        status: list[str] = [OK if f is None else f for f in fatal]
        usable = np.array([s == OK for s in status])
        pending = {c: suspect[c] for c in np.flatnonzero(usable) if suspect[c] is not None}
        use = usable.copy()
        use[list(pending)] = False
        verify = bool(pending) and self._determined(idx, use)
        unverified: dict[int, str] = {}
        if not verify:
            # The channels above suspicion cannot determine the motion: suspects must take part,
            # and are accepted only if every channel then fits consistently.
            use, unverified, pending = usable.copy(), dict(pending), {}
        self._require(idx, use, names, status, "before any residual test")
        U = np.zeros((ks.size, 6), dtype=complex)
        while True:
            U, S, iters, change, P = self._second_order_solve(U, ks, Y, H, use, freq_hz, pos, ax)
            Yc = Y - S
            R = Yc - np.einsum("kcj,kj->kc", H, U)
            scale2 = self._scale2(Y, var, use)
            # Suspects, out of sample: dropped if the others predict a reading they do not show.
            admitted = False
            for c, why in list(pending.items()):
                z = math.sqrt(np.sum(np.abs(R[:, c]) ** 2) / np.sum(scale2[:, c]))
                del pending[c]
                if z > thr:
                    status[c] = f"{why}; inconsistent with the other channels (residual {z:.1f} sigma)"
                else:
                    use[c] = admitted = True
            if admitted:
                continue
            z_in, rel_in = self._studentized(H, P, R, scale2, use, own)
            bad_in = (z_in > thr) & (rel_in > allow)
            if unverified and bad_in.any():
                bad = ", ".join(f"{names[c]} ({why})" for c, why in unverified.items())
                raise EstimationError(
                    f"accelerometer channels {bad} look dead, and the other channels cannot determine the "
                    f"plate acceleration to check them; the readings are inconsistent "
                    f"(residual {z_in.max():.1f} sigma at {names[int(np.argmax(z_in))]})",
                    dict(zip(names, status)),
                )
            # Find the fewest channels whose removal leaves a consistent set (two swapped wires
            # are two bad channels at once, and removing one at a time can blame a good one; a
            # bad channel next to its near-collinear twin pulls the fit and hides in-sample), else
            # remove the one that best explains the misfit.
            try:
                found = self._consistent_subset(idx, H, Yc, scale2, use, own, thr, allow)
            except _AmbiguousError as amb:
                suspects = sorted({c for drop in amb.candidates for c in drop})
                for c in suspects:
                    status[c] = "ambiguous: inconsistent, or a consistent channel's twin"
                shown = amb.candidates[:AMBIGUOUS_SHOWN]
                alternatives = " or ".join("{" + ", ".join(names[c] for c in d) + "}" for d in shown)
                if len(amb.candidates) > len(shown):
                    alternatives += f" ({len(amb.candidates)} alternatives in all)"
                raise EstimationError(
                    f"accelerometer channels are inconsistent and the array cannot tell which are broken: "
                    f"removing {alternatives} each leaves a consistent set; check their wiring and gains",
                    dict(zip(names, status)),
                ) from None
            if not found:
                worst, z_out, rel_out = self._leave_one_out(idx, H, Yc, scale2, use, own, thr, allow)
                found = [] if worst is None else [(worst, z_out, rel_out)]
            blamed = sum(s.startswith("inconsistent residual") for s in status) + len(found)
            if blamed > MAX_SUBSET_DROP:
                # More channels misfit than a record can attribute (the most a single fault
                # breaks is two, a swapped pair): blaming them one by one would keep going until
                # a set agrees, which need not be the healthy one.
                for c, z_out, rel_out in found:
                    status[c] = f"inconsistent residual ({z_out:.1f} sigma, {rel_out:.0%} of its reading)"
                raise EstimationError(
                    f"accelerometer channels are inconsistent beyond attribution: {blamed} channels misfit "
                    f"(more than {MAX_SUBSET_DROP}), so which are broken cannot be told; check the wiring and "
                    f"the sensors' gains",
                    dict(zip(names, status)),
                )
            for c, z_out, rel_out in found:
                use[c] = False
                status[c] = (
                    f"inconsistent residual ({z_out:.1f} sigma, {rel_out:.0%} of its reading; "
                    f"allowed {allow[c]:.0%})"
                )
            if found:
                continue
            # Leave-one-out found nobody to blame; an inconsistency left is in a channel the layout
            # cannot spare (it could not be left out), so the estimate cannot be trusted.
            for c in np.flatnonzero(bad_in):
                rest = use.copy()
                rest[c] = False
                if not self._determined(idx, rest):
                    status[c] = f"inconsistent residual ({z_in[c]:.1f} sigma, {rel_in[c]:.0%} of its reading)"
                    self._require(
                        idx,
                        rest,
                        names,
                        status,
                        "after a channel the layout cannot spare became inconsistent",
                    )
            break
        self._check_swaps(H, Yc, use, z_in, thr, names, status)
        std = np.sqrt(np.einsum("kjc,kc->kj", np.abs(P) ** 2, np.where(use, np.nan_to_num(var), 0.0)))
        Ru = R[:, use]
        return PlateEstimate(
            frequency_hz=freq_hz,
            k=ks.copy(),
            phasors=U,
            std=std,
            channels=names,
            status=tuple(status),
            residual_rms_mps2=float(np.sqrt(np.mean(np.abs(Ru) ** 2))),
            residual_mps2=np.linalg.norm(Ru, axis=1),
            second_order_mps2=np.sqrt(np.mean(np.abs(S[:, use]) ** 2, axis=1)),
            iterations=iters,
            last_change=change,
            cycles=cycles,
            channel_misfit=np.where(use, rel_in, np.nan),
        )

    def _check_swaps(self, H: np.ndarray, Yc: np.ndarray, use: np.ndarray, z_in: np.ndarray, thr: float,
                     names: tuple[str, ...], status: list[str]) -> None:
        """EstimationError when exchanging two used channels explains most of the misfit (:mod:`swaps`)."""
        cols = np.flatnonzero(use)
        if cols.size <= 6:
            return
        ratio = exchange_ratios(H[:, cols], np.nan_to_num(Yc[:, cols]))
        significant = z_in[cols] > thr
        hit = (ratio <= self.health.swap_ratio) & (significant[:, None] | significant[None, :])
        pairs = sorted(((ratio[a, b], a, b) for a, b in zip(*np.nonzero(np.triu(hit)))), key=lambda p: p[0])
        if not pairs:
            return
        shown = []
        for r, a, b in pairs[:AMBIGUOUS_SHOWN]:
            ca, cb = int(cols[a]), int(cols[b])
            status[ca] = f"swapped with {names[cb]}? (exchanging them leaves {r:.0%} of the misfit)"
            status[cb] = f"swapped with {names[ca]}? (exchanging them leaves {r:.0%} of the misfit)"
            shown.append(f"exchanging {names[ca]} and {names[cb]} leaves {r:.0%} of the misfit")
        raise EstimationError(
            "accelerometer channels look swapped in wiring: " + "; or ".join(shown) + "; check their wiring",
            dict(zip(names, status)),
        )

    @staticmethod
    def _studentized(
        H: np.ndarray, P: np.ndarray, R: np.ndarray, scale2: np.ndarray, use: np.ndarray, own: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """In-sample residual of each used channel, corrected for its leverage (0 if untestable).

        Returns it in sigmas of noise plus model floor, and as a fraction of the channel's reading.
        """
        lev = np.einsum("kcj,kjc->c", H, P) / H.shape[0]
        z = np.zeros(use.size)
        rel = np.zeros(use.size)
        ok = use & (lev < 1 - 1e-6)
        r2 = np.sum(np.abs(R[:, ok]) ** 2, axis=0) / (1 - lev[ok])
        z[ok] = np.sqrt(r2 / np.sum(scale2[:, ok], axis=0))
        with np.errstate(divide="ignore"):
            rel[ok] = np.sqrt(r2) / own[ok]
        return z, rel

    def _consistent_subset(
        self,
        idx: np.ndarray,
        H: np.ndarray,
        Yc: np.ndarray,
        scale2: np.ndarray,
        use: np.ndarray,
        own: np.ndarray,
        thr: float,
        allow: np.ndarray,
    ) -> list[tuple[int, float, float]]:
        """The fewest used channels (at most ``MAX_SUBSET_DROP``) whose removal leaves a consistent set.

        The rest must determine the motion and every one of its channels pass the in-sample test;
        every removed channel must fail the others' prediction. Among candidate sets of one size,
        the one with the smallest normalised residual power. Returns (channel, sigmas, fraction)
        per removed channel, or [] when no such set exists. Raises :class:`_AmbiguousError` when such
        a set exists but another removal of the same size also leaves a consistent rest: which
        channels are broken is then not identifiable from the record.
        """
        used = np.flatnonzero(use)
        K = H.shape[0]
        for m in range(1, MAX_SUBSET_DROP + 1):
            best, best_chi2, candidates, blamed = [], math.inf, [], []
            for drop in itertools.combinations(used.tolist(), m):
                rest = use.copy()
                rest[list(drop)] = False
                if not self._determined(idx, rest):
                    continue
                P = np.stack([np.linalg.pinv(H[i][rest]) for i in range(K)])
                U = np.einsum("kjc,kc->kj", P, Yc[:, rest])
                R = Yc - np.einsum("kcj,kj->kc", H, U)
                Pfull = np.zeros((K, 6, use.size))
                Pfull[:, :, rest] = P
                z_in, rel_in = self._studentized(H, Pfull, R, scale2, rest, own)
                if np.any((z_in > thr) & (rel_in > allow)):
                    continue
                candidates.append(drop)
                out = []
                for c in drop:
                    r_c = math.sqrt(np.sum(np.abs(R[:, c]) ** 2))
                    # The rest's misfit reaches the prediction amplified by the prediction's gain
                    # h (a channel the rest sees poorly, a twin of a removed one, is predicted poorly).
                    h = float(np.mean(np.sum(np.abs(np.einsum("kj,kjc->kc", H[:, c], P)) ** 2, axis=1)))
                    z = r_c / math.sqrt(np.sum(scale2[:, c]) * (1 + h))
                    rel = r_c / own[c] / math.sqrt(1 + h) if own[c] > 0 else math.inf
                    out.append((c, z, rel))
                if not all(z > thr and rel > allow[c] for c, z, rel in out):
                    continue
                blamed.append(drop)
                chi2 = float(np.sum(np.abs(R[:, rest]) ** 2 / scale2[:, rest]))
                if chi2 < best_chi2:
                    best, best_chi2 = out, chi2
            if len(blamed) > 1 or (blamed and len(candidates) > 1):
                # A removal explains the misfit, but another of the same size also leaves a
                # consistent set (a channel and its near-collinear twin, a swapped pair and a pair
                # the swap mimics): the data cannot say which channels are broken, and dropping the
                # wrong ones would feed a broken channel to the estimate.
                raise _AmbiguousError(candidates)
            if best:
                return best
        return []

    def _leave_one_out(
        self,
        idx: np.ndarray,
        H: np.ndarray,
        Yc: np.ndarray,
        scale2: np.ndarray,
        use: np.ndarray,
        own: np.ndarray,
        thr: float,
        allow: np.ndarray,
    ) -> tuple[int | None, float, float]:
        """The inconsistent channel whose removal best explains the residuals (None if none is).

        A channel is inconsistent when the others' prediction of it misses by more than ``thr``
        sigmas of noise and model floor and by more than its misfit allowance (a fraction of its own
        reading). One bad channel pulls a least-squares fit towards itself and can make a good
        neighbour's residual the largest; refitting without each candidate in turn does not suffer
        from that. Returns (channel, prediction residual in sigmas, as a fraction of its reading).
        """
        best, best_chi2, best_z, best_rel = None, math.inf, 0.0, 0.0
        for c in np.flatnonzero(use):
            rest = use.copy()
            rest[c] = False
            if not self._determined(idx, rest):
                continue
            U = np.stack([np.linalg.pinv(H[i][rest]) @ Yc[i, rest] for i in range(H.shape[0])])
            R = Yc - np.einsum("kcj,kj->kc", H, U)
            r_c = math.sqrt(np.sum(np.abs(R[:, c]) ** 2))
            z = r_c / math.sqrt(np.sum(scale2[:, c]))
            rel = r_c / own[c] if own[c] > 0 else math.inf
            if not (z > thr and rel > allow[c]):
                continue
            chi2 = float(np.sum(np.abs(R[:, rest]) ** 2 / scale2[:, rest]))
            if chi2 < best_chi2:
                best, best_chi2, best_z, best_rel = int(c), chi2, z, rel
        return best, best_z, best_rel

    def _second_order_solve(self, U0, ks, Y, H, use, freq_hz, pos, ax):
        """Fixed-point iteration U = H^+ (Y - S(U)) on the channels in ``use``."""
        P = np.stack([np.linalg.pinv(H[i][use]) for i in range(ks.size)])  # (K, 6, Cu)
        kmax = int(ks.max())
        U, change, iters = U0, math.inf, 0
        scale = np.array(
            [1, 1, 1, self.layout.length_scale_m, self.layout.length_scale_m, self.layout.length_scale_m]
        )

        def second_order(U: np.ndarray) -> np.ndarray:
            # The terms need the motion on a dense harmonic axis; harmonics not estimated count as 0.
            if not self.terms:
                return np.zeros_like(Y)
            dense = np.zeros((kmax, 6), dtype=complex)
            dense[ks - 1] = U
            return second_order_phasors(dense, freq_hz, pos, ax, self.terms, self.gravity_mps2)[ks - 1]

        for it in range(1, self.max_iterations + 1):
            iters = it
            S = second_order(U)
            Yc = (Y - S)[:, use]
            U_new = np.einsum("kjc,kc->kj", P, Yc)
            norm = np.linalg.norm(U_new * scale)
            change = float(np.linalg.norm((U_new - U) * scale) / norm) if norm > 0 else 0.0
            U = U_new
            if not self.terms or change < self.tolerance:
                break
        S = second_order(U)  # at the final estimate, so residuals and reports match U
        Pfull = np.zeros((ks.size, 6, use.size))
        Pfull[:, :, use] = P
        return U, S, iters, change, Pfull

    def _scale2(self, Y: np.ndarray, var: np.ndarray, use: np.ndarray) -> np.ndarray:
        """Expected residual power per harmonic and channel: noise plus the model floor.

        The noise is the median over the used channels, not each channel's own: a failing channel's
        own scatter is large and would excuse its residual.
        """
        h = self.health
        signal = np.sqrt(np.mean(np.abs(Y[:, use]) ** 2, axis=1))  # (K,) RMS channel signal per harmonic
        floor2 = (h.model_floor * signal) ** 2 + h.flat_mps2**2
        noise = np.median(np.nan_to_num(var[:, use], nan=0.0), axis=1)
        return np.broadcast_to((noise + floor2)[:, None], Y.shape)

    def _determined(self, idx: np.ndarray, use: np.ndarray) -> bool:
        return use.sum() >= 6 and self.layout.observability(self._full_mask(idx, use)).ok(
            self.layout.max_condition
        )

    def _full_mask(self, idx: np.ndarray, use: np.ndarray) -> np.ndarray:
        # ``use`` indexes the data's columns; observability needs a mask over the whole layout.
        mask = np.zeros(self.layout.num_channels, bool)
        mask[idx[use]] = True
        return mask

    def _require(
        self, idx: np.ndarray, use: np.ndarray, names: tuple[str, ...], status: list[str], when: str
    ) -> None:
        if self._determined(idx, use):
            return
        obs = self.layout.observability(self._full_mask(idx, use))
        by_reason: dict[str, list[str]] = {}
        for n, s in zip(names, status):
            if s != OK:
                by_reason.setdefault(s, []).append(n)
        raise EstimationError(
            f"accelerometer channels no longer determine the plate acceleration {when}: "
            f"{int(use.sum())} usable channels, condition {obs.condition:.3g} > "
            f"{self.layout.max_condition:g}, "
            f"unobservable: {obs.describe_weakest()}; dropped: "
            + "; ".join(f"{', '.join(ns)}: {s}" for s, ns in by_reason.items()),
            dict(zip(names, status)),
        )


__all__ = ["OK", "EstimationError", "PlateEstimate", "SixDofSolver"]
