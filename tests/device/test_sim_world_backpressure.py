"""The simulated device waits for its parts physics instead of running ahead of it."""

import time

from ppod_ros.device import default_device_config
from ppod_sim.ros_node import default_scene_path
from ppod_sim.scene import load_scene
from ppod_sim.world import SimWorld


def test_the_device_never_runs_more_than_a_few_cycles_ahead_of_slow_parts_physics():
    config = default_device_config().with_can(interface="virtual", channel="test-backpressure")
    world = SimWorld(config, load_scene(default_scene_path()), None, rate=20.0)
    backlog = []
    original = world.advance_parts

    def slow(truth):  # parts physics at 20 ms a cycle against a device 20x faster than real time
        backlog.append(world._cycles.unfinished_tasks)
        time.sleep(0.02)
        original(truth)

    world.advance_parts = slow
    try:
        world.run(duration_s=1.0)
        world.drain()
    finally:
        world.close()
    assert len(backlog) >= 25  # every cycle of the second reached the parts
    assert max(backlog) <= world.max_backlog_cycles + 2, max(backlog)
    assert world.backpressure_s > 0.2
    assert abs(world.parts_truth().time_s - world.device.time_s) < 0.1
