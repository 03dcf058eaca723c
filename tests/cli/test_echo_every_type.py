"""`ppod echo` prints one message of every ppod_msgs type and exits; a failing callback exits 1."""

import inspect
import subprocess
import sys

import pytest
import yaml

pytestmark = pytest.mark.ros


def _message_types():
    import ppod_msgs.msg

    return sorted((name, cls) for name, cls in inspect.getmembers(ppod_msgs.msg, inspect.isclass)
                  if hasattr(cls, "get_fields_and_field_types") and not name.startswith("_"))


def _ppod(*args: str) -> list[str]:
    return [sys.executable, "-c", "import sys; from ppod_nodes.cli.main import main; sys.exit(main())", *args]


def test_echo_prints_one_message_of_every_ppod_msgs_type(ros):
    from rclpy.qos import DurabilityPolicy, QoSProfile

    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    types = _message_types()
    assert len(types) >= 8
    topics = {}
    for name, cls in types:
        topic = f"/ppod_test/echo/{name.lower()}"
        ros.helper.create_publisher(cls, topic, latched).publish(cls())
        topics[name] = topic
    procs = {name: subprocess.Popen(_ppod("echo", topic, "--once", "--timeout", "60", "--discovery-wait", "60"),
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for name, topic in topics.items()}
    try:
        for name, proc in procs.items():
            out, err = proc.communicate(timeout=120)
            assert proc.returncode == 0, f"{name}: {err}"
            document = yaml.safe_load(out.split("---\n")[0])
            cls = dict(types)[name]
            assert set(document) == set(cls.get_fields_and_field_types()), name
    finally:   # no echo process outlives the test (a ROS process can hang in its DDS teardown)
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()


def test_echo_exits_non_zero_when_printing_a_message_fails(ros):
    from ppod_msgs.msg import DeviceStatus
    from rclpy.qos import DurabilityPolicy, QoSProfile

    topic = "/ppod_test/echo/failing"
    ros.helper.create_publisher(DeviceStatus, topic, QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
                                ).publish(DeviceStatus())
    done = subprocess.run(_ppod("echo", topic, "--once", "--field", "no_such_field", "--discovery-wait", "60"),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "no_such_field" in done.stderr and "Traceback" not in done.stderr
