"""Driving a :class:`LearningController` from a source of measurements: live, simulated or recorded.

:func:`run_learning` is the closed loop in its plainest form, for scripted experiments, benchmarks and
tests: apply the correction, measure, update, until converged, diverged or out of iterations, with
an optional re-identification when progress stalls (a plant that changed beyond the loop's margin).
:func:`replay_recording` runs the estimator and the controller over a recording's segments (one
measurement window per segment, with the commands that were applied, when recorded) and returns
what the loop would have decided at each step.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ppod_ros.control.learning import CONVERGED, STALLED, ControlStep, LearningController
from ppod_ros.control.plant import PlantModel
from ppod_ros.errors import ConfigError
from ppod_ros.estimation import AccelEstimator, AccelRecording, PlateEstimate

log = logging.getLogger(__name__)

#: ``measure(correction_a (Kc, 6) complex) -> PlateEstimate or phasors (Km, 6)``: apply the
#: correction (on top of the feed-forward), wait for the plate to settle, estimate.
Measure = Callable[[np.ndarray], "PlateEstimate | np.ndarray"]


@dataclass
class LoopResult:
    """Every step of a run, and when the plant was re-identified (iteration numbers)."""

    steps: list[ControlStep] = field(default_factory=list)
    reidentified_at: list[int] = field(default_factory=list)

    @property
    def final(self) -> ControlStep:
        return self.steps[-1]

    def errors(self) -> np.ndarray:
        return np.array([s.error_relative for s in self.steps])


def run_learning(
    controller: LearningController,
    measure: Measure,
    *,
    max_iterations: int = 10,
    stop_when_converged: bool = True,
    identify: Callable[[], PlantModel] | None = None,
    on_step: Callable[[ControlStep], None] | None = None,
) -> LoopResult:
    """Run the loop: measure with the current correction, update, repeat.

    Parameters
    ----------
    max_iterations : int
        Updates at most (each needs one measurement).
    stop_when_converged : bool
        Stop at the first converged step (else keep learning for all iterations).
    identify : callable, optional
        Called when the controller reports a stall; its plant replaces the controller's.
    on_step : callable, optional
        Called with every step (publishing, logging).
    """
    if not (isinstance(max_iterations, int) and max_iterations >= 1):
        raise ConfigError(f"max_iterations: expected an integer >= 1, got {max_iterations!r}")
    result = LoopResult()
    for _ in range(max_iterations):
        step = controller.update(measure(controller.correction_a.copy()))
        result.steps.append(step)
        if on_step is not None:
            on_step(step)
        if step.ramp_down:
            log.warning("learning control stopped at iteration %d: %s", step.iteration, step.message)
            break
        if step.state == CONVERGED and stop_when_converged:
            break
        if step.state == STALLED and identify is not None:
            log.info(
                "learning control stalled at iteration %d (error %.3g): re-identifying the plant",
                step.iteration,
                step.error_relative,
            )
            controller.replace_plant(identify())
            result.reidentified_at.append(step.iteration)
    return result


def replay_recording(
    recording: AccelRecording, estimator: AccelEstimator, controller: LearningController
) -> list[tuple[PlateEstimate, ControlStep]]:
    """Estimate each segment of ``recording`` and update ``controller`` with it, in segment order.

    When the recording carries the commands applied in each segment, the controller's correction is
    set to (command - feed-forward) before each update, so every step answers "given what was
    applied and measured, what would the loop send next?".
    """
    if recording.goal is not None and recording.goal != controller.goal:
        raise ConfigError("recording: its goal differs from the controller's goal")
    out = []
    for s in recording.segments():
        est = estimator.from_recording(recording, s)
        applied = recording.command(s)
        if applied is not None:
            ks, cmd = applied
            table = np.zeros((controller.k.size, 6), complex)
            for row, k in enumerate(ks):
                if k in controller.k:
                    table[int(k) - 1] = cmd[row]
            controller.sync_correction(table - controller.feedforward_a)
        out.append((est, controller.update(est)))
    return out


__all__ = ["LoopResult", "Measure", "replay_recording", "run_learning"]
