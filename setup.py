"""Package layout: the repository's top-level folders are installed under project-specific names.

    ppod_ros/     -> ppod_ros     (ROS-free core)
    nodes/        -> ppod_nodes   (rclpy nodes, launcher, CLI; a bare ``nodes`` would collide)
    sim_backend/  -> ppod_sim     (the simulated device)
    benchmarks/   -> ppod_bench   (benchmark programs behind ``ppod bench``)
"""

from setuptools import find_packages, setup

MAPPED = {"ppod_nodes": "nodes", "ppod_sim": "sim_backend", "ppod_bench": "benchmarks"}


def _mapped_packages(name: str, where: str) -> list[str]:
    return [name] + [f"{name}.{sub}" for sub in find_packages(where)]


packages = find_packages(include=["ppod_ros", "ppod_ros.*"])
for _name, _where in MAPPED.items():
    packages += _mapped_packages(_name, _where)

setup(
    packages=packages,
    package_dir={**MAPPED, "ppod_ros": "ppod_ros"},
    package_data={"ppod_ros": ["data/*.yaml", "data/motions/*.yaml"], "ppod_nodes": ["data/*.yaml", "data/*.py"],
                  "ppod_sim": ["data/*.yaml"]},
    # colcon/ament_python: the package marker and manifest that `ros2 run ppod_control ...` looks up.
    data_files=[("share/ament_index/resource_index/packages", ["resource/ppod_control"]),
                ("share/ppod_control", ["package.xml"])],
)
