"""The scene (ppod_ros.view) as ROS drawables (MarkerArray, TF) and as Foxglove's live-server schemas."""
