"""The field planner (docs/planner.md): requested fields, motion design, closed-loop manipulation.

- :class:`FieldSpec`: a requested linear field (PlanField's field_type and params).
- :func:`design_field` -> :class:`DesignResult`: the plate motion whose asymptotic field matches it,
  within the device's limits.
- :class:`Task`: bring a tracked part to a goal pose from camera feedback, step by step.
- :func:`plan_sensorless` -> :class:`SensorlessPlan`, played by :class:`SensorlessTask`: the same
  without a camera, from the stable fixed points of the fields.
- :class:`MultiTask` (:class:`PartGoal`, :class:`MpcSettings`): several parts, each to its own goal
  pose at once, by model-predictive choice of the plate motion itself (planning/mpc.py).

Nothing here imports rclpy or message types.
"""

from ppod_ros.planning.design import DEFAULT_FREQUENCY_HZ, DesignResult, design_field, evaluate
from ppod_ros.planning.mpc import MpcSettings, MultiStep, MultiTask, PartGoal
from ppod_ros.planning.sensorless import SensorlessPlan, SensorlessTask, plan_sensorless
from ppod_ros.planning.specs import FieldSpec
from ppod_ros.planning.task import Task, TaskStep, orient_motion

__all__ = ["DEFAULT_FREQUENCY_HZ", "DesignResult", "FieldSpec", "MpcSettings", "MultiStep", "MultiTask", "PartGoal",
           "SensorlessPlan", "SensorlessTask", "Task", "TaskStep", "design_field", "evaluate", "orient_motion",
           "plan_sensorless"]
