"""STYLE.md rule 1: ppod_ros never imports rclpy or message types."""

import subprocess
import sys
import textwrap
from pathlib import Path

import ppod_ros


def test_ppod_ros_imports_with_rclpy_unavailable():
    code = textwrap.dedent(
        """
        import importlib, pkgutil, sys

        class Block:
            BLOCKED = ("rclpy", "ppod_msgs", "std_msgs", "sensor_msgs", "geometry_msgs",
                       "diagnostic_msgs", "builtin_interfaces", "rosidl_runtime_py")
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in self.BLOCKED:
                    raise ImportError(f"blocked for this test: {name}")
                return None

        sys.meta_path.insert(0, Block())
        import ppod_ros
        names = [m.name for m in pkgutil.walk_packages(ppod_ros.__path__, "ppod_ros.")]
        for name in names:
            importlib.import_module(name)
        loaded = [m for m in sys.modules if m.split(".")[0] in Block.BLOCKED]
        assert not loaded, loaded
        print(len(names))
        """
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert int(proc.stdout.strip()) >= 3


def test_no_core_module_mentions_rclpy_in_an_import():
    root = Path(ppod_ros.__file__).parent
    offenders = []
    for path in root.rglob("*.py"):
        for line in path.read_text().splitlines():
            s = line.strip()
            if s.startswith(("import ", "from ")) and ("rclpy" in s or "ppod_msgs" in s):
                offenders.append(f"{path}: {s}")
    assert not offenders
