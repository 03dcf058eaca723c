"""The simulated device running in a background thread of the test process (real-time pace).

Nodes under test reach it over python-can's in-process virtual bus, exactly as they reach the
separate sim process over the localhost bridge.
"""

from __future__ import annotations

import itertools
import threading

from ppod_ros.device import default_device_config
from ppod_sim.process import SimProcess

_ids = itertools.count()


class SimThread:
    def __init__(self, config=None, seed: int = 1, rate: float = 1.0):
        base = config or default_device_config()
        self.channel = f"test-sim-{next(_ids)}"
        self.config = base.with_can(interface="virtual", channel=self.channel)
        self.sim = SimProcess(self.config, port=0, rate=rate, seed=seed, channel=self.channel)
        self.device = self.sim.device
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self.sim.run, kwargs={"stop": self._stop}, daemon=True,
                                        name="sim-device")

    def __enter__(self) -> SimThread:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.sim.close()
