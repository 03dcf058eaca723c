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
