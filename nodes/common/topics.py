"""Topic and service names of the PPOD stack (relative names resolve in the nodes' namespace).

Keep every name here so nodes, the CLI, the recorder and the tests agree.
"""

# waveform generator
GOAL = "ppod/plate_motion_goal"                  # ppod_msgs/PlateMotion      in
ACTIVE_MOTION = "ppod/plate_motion_active"       # ppod_msgs/PlateMotion      out, latched
MOTION_STATUS = "ppod/plate_motion_status"       # ppod_msgs/PlateMotionStatus out, latched
DEVICE_STATUS = "ppod/device_status"             # ppod_msgs/DeviceStatus     out
SET_MOTION = "ppod/set_plate_motion"             # ppod_msgs/SetPlateMotion   service
STOP = "ppod/stop"                               # std_srvs/Trigger: ramp down
ESTOP = "ppod/emergency_stop"                    # std_srvs/Trigger: emergency stop frame
# accelerometer feedback
ACCELERATION = "ppod/plate_acceleration"         # ppod_msgs/PlateAcceleration out
CORRECTION = "ppod/harmonic_correction"          # ppod_msgs/HarmonicCorrection out -> generator
ACCEL_SUMMARIES = "ppod/accel_summaries"         # ppod_msgs/AccelSummary     out (recorded by default)
# camera and tracker
IMAGE = "ppod/camera/image_raw"                  # sensor_msgs/Image
CAMERA_INFO = "ppod/camera/camera_info"          # sensor_msgs/CameraInfo
PART_POSES = "ppod/part_poses"                   # ppod_msgs/PartPoseArray
# planner
PLAN_FIELD = "ppod/plan_field"                   # ppod_msgs/PlanField service
MOVE_PART = "ppod/move_part"                     # ppod_msgs/MovePart action
MOVE_PARTS = "ppod/move_parts"                   # ppod_msgs/MoveParts action
# simulation only
SIM_TRUE_POSES = "ppod/sim/ground_truth/part_poses"        # ppod_msgs/PartPoseArray
SIM_TRUE_ACCELERATION = "ppod/sim/ground_truth/plate_acceleration"  # ppod_msgs/PlateAcceleration
DIAGNOSTICS = "/diagnostics"                     # diagnostic_msgs/DiagnosticArray
# drawable and plottable (nodes/viz.py; docs/ros.md, "Drawable topics")
VIZ_MARKERS = "ppod/viz/markers"                 # visualization_msgs/MarkerArray: plate, parts, goals, field
TF = "/tf"                                       # ppod_msgs/TFMessage (recorded as tf2_msgs/msg/TFMessage)
ACCEL_GOAL_PLOT = "ppod/viz/accel_goal"          # geometry_msgs/AccelStamped: goal amplitude, harmonic 1
ACCEL_MEASURED_PLOT = "ppod/viz/accel_measured"  # geometry_msgs/AccelStamped: measured amplitude, harmonic 1
PLANNER_PROGRESS = "ppod/planner/progress"       # ppod_msgs/PlannerProgress: the action feedback, recordable
MOVE_PART_TARGET = "ppod/move_part/target"       # ppod_msgs/PartPoseArray, latched: targets of MovePart goals
ROSOUT = "/rosout"                               # rcl_interfaces/Log: every node's log (recorded)
# names that lived elsewhere before (kept importable there)
RESET_ESTOP = "ppod/reset_emergency_stop"        # std_srvs/Trigger: leave the latched emergency stop
SIM_SCENARIO = "ppod/sim/scenario"               # std_msgs/String, latched: the simulated device's scenario
CLOCK = "/clock"                                 # rosgraph_msgs/Clock: device time (simulated device)
CAPTURE_RAW = "ppod/capture_raw"                 # std_srvs/Trigger: a raw accelerometer capture, to a file
# Foxglove live-view channels (ppod view; not ROS topics)
VIEW_SCENE = "/ppod/scene"                       # foxglove.SceneUpdate
VIEW_TF = "/ppod/tf"                             # foxglove.FrameTransform
