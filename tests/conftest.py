"""Session-wide test settings.

DDS stays on loopback and each test session gets its own ROS_DOMAIN_ID, before anything can call
rclpy.init() (see docs/ros.md). Matplotlib renders headless.
"""

import os
import random

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_LOCALHOST_ONLY", None)
os.environ.setdefault("MPLBACKEND", "Agg")
if "PPOD_TEST_DOMAIN_ID" not in os.environ:
    # Domain ids 1..101 leave room for the ports of several concurrent sessions on one machine.
    os.environ["PPOD_TEST_DOMAIN_ID"] = str(random.SystemRandom().randint(1, 101))
os.environ["ROS_DOMAIN_ID"] = os.environ["PPOD_TEST_DOMAIN_ID"]


def pytest_sessionfinish(session, exitstatus):
    """Remove shared-memory segments that processes killed by tests (SIGKILL) left behind."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    fastdds = Path(sys.executable).parent / "fastdds"
    if fastdds.exists() or shutil.which("fastdds"):
        subprocess.run([str(fastdds) if fastdds.exists() else "fastdds", "shm", "clean"],
                       capture_output=True, timeout=30)


import pytest  # noqa: E402


@pytest.fixture
def ros():
    """An in-process ROS harness: private context, executor thread, teardown in the safe order."""
    from tests.support.ros_harness import RosHarness

    harness = RosHarness()
    try:
        yield harness
    finally:
        harness.close()
