"""ppod_nodes: the ROS 2 side of the PPOD stack (installed from the repository's nodes/ folder).

Thin rclpy nodes (waveform generator, accelerometer feedback, part tracker, field planner), the
shared ROS plumbing they use, the process launcher (``ppod up``) and the ``ppod`` command line.

Importing this package confines DDS discovery to loopback unless the environment already chose
otherwise: ROS_AUTOMATIC_DISCOVERY_RANGE must be set before rclpy.init(), and the default Fast DDS
discovery would multicast on every interface. A lab deployment sets PPOD_DISCOVERY_RANGE=SUBNET.
It also pins OpenBLAS and numpy to their AVX2 kernels before numpy is imported, so that results do
not depend on the machine's CPU (``ppod_nodes.numeric_env``; ``PPOD_NATIVE_NUMERICS=1``: off).
"""

from ppod_nodes.numeric_env import configure_numeric_environment
from ppod_nodes.ros_env import configure_ros_environment

configure_numeric_environment()
configure_ros_environment()
