"""The plant learned online from what the feedback loop measures, so that new goals start close.

Every learning iteration applies a known current table ``I_k`` (feed-forward plus correction) and
measures the plate's acceleration harmonics ``U_k``. For a linear plant ``U_k = G_k I_k``, so each
iteration is one sample of ``G`` at the excitation frequency ``k f``. :class:`PlantLearner` keeps,
per excitation frequency, the exponentially weighted sums

    S_uu = sum_n w_n I_n I_n^H        S_au = sum_n w_n U_n I_n^H

and estimates ``G`` by ridge regression towards the prior (the nominal model)

    G = (S_au + lam G_prior) (S_uu + lam 1)^-1
      = G_prior + (S_au - G_prior S_uu) (S_uu + lam 1)^-1 ,

which is the nominal model in every current direction never excited and the measured plant in the
directions the goals have used. That is what matters: the planner's goals at one frequency differ
little (sinks with shifted centres, rotations), so a few learned goals predict the next one. The
feedback loop then starts a new goal from the predicted correction ``G^-1 goal - feedforward``
instead of zero, and uses ``G`` in its updates.

Only harmonics the goal contains are learned: at the others the measurement is the plant's own
distortion (not proportional to the current there), which learning control cancels per goal.
Forgetting (``forgetting`` per sample) lets a plant that drifts (coil heating, a changed load)
be followed; unexcited directions then relax back to the prior. A learned matrix that is
ill-conditioned, or that implies currents differing from the prior's by more than
``max_relative_change`` of those applied (a measurement taken during a transient, a plant that changed
beyond reason), is not used: the prior is, and the fact is reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ppod_ros.config.fields import Fields
from ppod_ros.control.plant import PlantModel
from ppod_ros.errors import ConfigError


@dataclass(frozen=True)
class PlantLearningSettings:
    """How the plant is learned online (``plant_learning`` in the feedback parameters).

    Parameters
    ----------
    enabled : bool
        Learn and use the plant (default True); False keeps the nominal model.
    prior_weight_a2 : float
        Ridge weight ``lam`` (A^2): a direction must be excited by about ``sqrt(lam)`` amperes of
        current before the measurement outweighs the prior there.
    forgetting : float
        Weight multiplier per new sample, in (0, 1]; 0.95 halves a sample's weight after 14 more.
    min_relative_amplitude : float
        Harmonics of the goal smaller than this fraction of its largest are not learned from.
    max_relative_change : float
        A learned G_k that needs currents differing from the prior's by more than this fraction of
        the currents applied so far (``G0^-1 (G - G0)`` weighted by them) is not used: an actuator
        mismatch beyond it means a broken device or configuration, not one to learn.
    coupling_weight_a2 : float
        Ridge weight (A^2) of the off-diagonal entries of the actuator-side error
        ``E = G0^-1 G - 1`` (``prior_weight_a2`` weighs its diagonal). A real actuator's error is
        mostly its own gain and phase (coil constant, amplifier), little cross-coupling: with a
        heavier weight off the diagonal one goal's samples already say how each actuator differs,
        so the next goal, in other current directions, is predicted too (equal weights: the plain
        ridge regression towards G0, exact only in the directions already excited).
    """

    enabled: bool = True
    prior_weight_a2: float = 0.01
    coupling_weight_a2: float = 0.1
    forgetting: float = 0.95
    min_relative_amplitude: float = 0.05
    max_relative_change: float = 0.6

    @classmethod
    def from_dict(cls, data: Any, where: str = "plant_learning") -> PlantLearningSettings:
        f = Fields(data, where)
        out = cls(
            enabled=f.boolean("enabled", cls.enabled),
            prior_weight_a2=f.number("prior_weight_a2", cls.prior_weight_a2, min_value=1e-9, unit="A^2"),
            forgetting=f.number("forgetting", cls.forgetting, min_value=1e-3, max_value=1.0),
            min_relative_amplitude=f.number("min_relative_amplitude", cls.min_relative_amplitude, min_value=0.0,
                                            max_value=1.0),
            max_relative_change=f.number("max_relative_change", cls.max_relative_change, min_value=0.0),
            coupling_weight_a2=f.number("coupling_weight_a2", cls.coupling_weight_a2, min_value=1e-9, unit="A^2"),
        )
        f.finish()
        return out


@dataclass
class _Stats:
    S_uu: np.ndarray = field(default_factory=lambda: np.zeros((6, 6), complex))
    S_au: np.ndarray = field(default_factory=lambda: np.zeros((6, 6), complex))
    samples: int = 0


def _key(excitation_hz: float) -> int:
    # To the nearest mHz, as PlantStore keys identified plants: harmonic 2 of a 15 Hz goal shares
    # the plant learned at 30 Hz.
    return int(round(excitation_hz * 1000.0))


class PlantLearner:
    """See the module docstring.

    Parameters
    ----------
    settings : PlantLearningSettings, optional
    """

    def __init__(self, settings: PlantLearningSettings | None = None):
        self.settings = settings or PlantLearningSettings()
        self._stats: dict[int, _Stats] = {}
        #: Why the last :meth:`model` call fell back to the prior at some harmonic ("" if it did not).
        self.last_fallback = ""

    def samples(self, excitation_hz: float) -> int:
        """How many samples have been taken at ``excitation_hz``."""
        st = self._stats.get(_key(excitation_hz))
        return 0 if st is None else st.samples

    def observe(self, frequency_hz: float, goal_table: np.ndarray, k: np.ndarray, command_a: np.ndarray,
                measured: np.ndarray) -> int:
        """Take one sample: current table ``command_a`` (K, 6) on harmonics ``k`` gave ``measured``.

        ``goal_table`` (Km, 6) and ``measured`` (Km, 6) are phasor tables on harmonics 1..Km. Returns
        the number of harmonics learned from.
        """
        if not self.settings.enabled:
            return 0
        k = np.asarray(k, dtype=int)
        command = np.asarray(command_a, complex)
        M = np.asarray(measured, complex)
        goal = np.asarray(goal_table, complex)
        if command.shape != (k.size, 6) or M.ndim != 2 or M.shape[1] != 6:
            raise ConfigError(f"plant learning: command {command.shape} on harmonics {k.tolist()} and "
                              f"measured {M.shape} do not fit")
        if not (np.all(np.isfinite(command)) and np.all(np.isfinite(M))):
            return 0  # a non-finite estimate teaches nothing (the loop reports it elsewhere)
        size = np.linalg.norm(goal, axis=1) if goal.size else np.zeros(0)
        if not size.size or size.max() <= 0:
            return 0
        learned = 0
        gamma = self.settings.forgetting
        for row, kk in enumerate(k):
            if kk > M.shape[0] or kk > goal.shape[0]:
                continue
            if size[kk - 1] < self.settings.min_relative_amplitude * size.max():
                continue
            u, a = command[row], M[kk - 1]
            st = self._stats.setdefault(_key(kk * frequency_hz), _Stats())
            st.S_uu = gamma * st.S_uu + np.outer(u, u.conj())
            st.S_au = gamma * st.S_au + np.outer(a, u.conj())
            st.samples += 1
            learned += 1
        return learned

    @staticmethod
    def _actuator_error(G0: np.ndarray, st: _Stats, lam_d: float, lam_o: float) -> np.ndarray:
        """Ridge estimate of ``E`` in ``G = G0 (1 + E)``: row r minimises
        ``sum_n w_n |V_n[r] - E[r] I_n|^2 + lam_d |E[r, r]|^2 + lam_o sum_(j != r) |E[r, j]|^2``,
        ``V_n = G0^-1 U_n - I_n`` (what the currents did beyond the prior, in amperes), so
        ``E[r] = S_vu[r] (S_uu + P_r)^-1`` with ``S_vu = G0^-1 S_au - S_uu``."""
        S_vu = np.linalg.solve(G0, st.S_au) - st.S_uu
        E = np.empty((6, 6), complex)
        for r in range(6):
            P = np.full(6, lam_o)
            P[r] = lam_d
            # Row r: e (S_uu + P) = S_vu[r]  <=>  (S_uu + P)^T e^T = S_vu[r]^T.
            E[r] = np.linalg.solve((st.S_uu + np.diag(P)).T, S_vu[r])
        return E

    def model(self, prior: PlantModel) -> PlantModel:
        """The learned plant on the prior's harmonics and frequency (the prior where nothing is known)."""
        self.last_fallback = ""
        if not self.settings.enabled:
            return prior
        lam_d, lam_o = self.settings.prior_weight_a2, self.settings.coupling_weight_a2
        G = prior.G.copy()
        changed = False
        notes = []
        for i, kk in enumerate(prior.k):
            st = self._stats.get(_key(kk * prior.frequency_hz))
            if st is None or st.samples == 0:
                continue
            G0 = prior.G[i]
            Gi = G0 @ (np.eye(6) + self._actuator_error(G0, st, lam_d, lam_o))
            # The implied actuator-side error E = G0^-1 (G - G0): how different, relative to the
            # currents applied, are the currents this plant needs from what the prior says. Measured
            # in current space it is the actuators' own mismatch (0.15-0.19 for the simulated plant);
            # in acceleration space a goal that is a small residual of large motions (a sink, a
            # rotation) would magnify it several times.
            E = np.linalg.solve(G0, Gi - G0)
            change = math.sqrt(abs(np.trace(E @ st.S_uu @ E.conj().T)) / abs(np.trace(st.S_uu)))
            if not math.isfinite(change) or change > self.settings.max_relative_change:
                notes.append(f"harmonic {kk}: the learned plant needs currents {change:.2g} off the prior's (> "
                             f"{self.settings.max_relative_change:g}), not used")
                continue
            G[i] = Gi
            changed = True
        if not changed:
            self.last_fallback = "; ".join(notes)
            return prior
        try:
            model = PlantModel(prior.frequency_hz, prior.k, G, source="learned", max_condition=prior.max_condition,
                               length_scale_m=prior.length_scale_m)
        except ConfigError as exc:
            notes.append(f"learned plant rejected: {exc}")
            model = prior
        self.last_fallback = "; ".join(notes)
        return model


__all__ = ["PlantLearner", "PlantLearningSettings"]
