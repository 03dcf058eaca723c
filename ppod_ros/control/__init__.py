"""Closed-loop learning control of the plate's acceleration harmonics.

Public API (docs/feedback.md):

- :class:`PlantModel`: G_k (6 x 6 complex, A -> m/s^2 and rad/s^2) per harmonic, from a
  frequency-response callable (the nominal model), a table, or identification.
- :class:`IdentificationPlan`, :func:`identify`, :func:`run_identification`: one actuator at a
  time, one harmonic at a time.
- :class:`PlantStore`, :class:`CorrectionStore`: identified plants per device and excitation
  frequency, learned corrections per goal, under a cache directory.
- :class:`DeviceLimits`: peak current and step per iteration, clipped and reported.
- :class:`LearningController` (with :class:`LearningSettings`, :class:`ControlStep`): the update
  c_k <- c_k + gain G_k^-1 e_k, error measure, convergence, divergence (ramp down), stall.
- :func:`run_learning`, :func:`replay_recording`: drive a controller live or from recorded data.
"""

from ppod_ros.control.identification import (
    IdentificationPlan,
    IdentificationStep,
    identify,
    run_identification,
)
from ppod_ros.control.learning import (
    CONVERGED,
    DIVERGED,
    RUNNING,
    STALLED,
    ControlStep,
    LearningController,
    LearningSettings,
    controlled_harmonics,
    feedforward,
)
from ppod_ros.control.limits import DeviceLimits, LimitEvent, LimitReport, peak_a
from ppod_ros.control.loop import LoopResult, replay_recording, run_learning
from ppod_ros.control.plant import PlantModel, as_plant
from ppod_ros.control.store import CorrectionStore, PlantStore

__all__ = [
    "CONVERGED",
    "DIVERGED",
    "RUNNING",
    "STALLED",
    "ControlStep",
    "CorrectionStore",
    "DeviceLimits",
    "IdentificationPlan",
    "IdentificationStep",
    "LearningController",
    "LearningSettings",
    "LimitEvent",
    "LimitReport",
    "LoopResult",
    "PlantModel",
    "PlantStore",
    "as_plant",
    "controlled_harmonics",
    "feedforward",
    "identify",
    "peak_a",
    "replay_recording",
    "run_identification",
    "run_learning",
]
