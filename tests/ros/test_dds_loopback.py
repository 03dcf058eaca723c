"""DDS traffic of a running stack stays on loopback (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).

tcpdump listens on every non-loopback interface while two nodes discover each other and exchange
messages; no UDP packet may appear there (DNS excluded). A positive control checks that the same
capture on loopback does see the DDS traffic. Skipped where tcpdump is missing or not permitted.
"""

import shutil
import subprocess
import time
from pathlib import Path

import pytest

from tests.ros.helpers import LISTENER_ELEVENTH, ROOT, ppod

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def _interfaces() -> list[str]:
    """Non-loopback interfaces that are up (IFF_UP in their flags)."""
    return sorted(p.name for p in Path("/sys/class/net").iterdir()
                  if p.name != "lo" and int((p / "flags").read_text(), 16) & 0x1)


def _capture(iface: str, path: Path) -> subprocess.Popen:
    return subprocess.Popen(["tcpdump", "-i", iface, "-n", "-U", "-w", str(path), "udp and not port 53"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _count(path: Path) -> int:
    out = subprocess.run(["tcpdump", "-n", "-r", str(path)], capture_output=True, text=True)
    return len([ln for ln in out.stdout.splitlines() if ln.strip()])


@pytest.mark.skipif(shutil.which("tcpdump") is None, reason="tcpdump not installed")
def test_no_dds_packet_leaves_loopback_while_nodes_talk(tmp_path):
    caps = {iface: (_capture(iface, tmp_path / f"{iface}.pcap"), tmp_path / f"{iface}.pcap")
            for iface in [*_interfaces(), "lo"]}
    time.sleep(1.0)
    if any(p.poll() is not None for p, _ in caps.values()):
        errors = " ".join(p.stderr.read().decode() for p, _ in caps.values() if p.poll() is not None)
        for p, _ in caps.values():
            p.kill()
            p.wait(timeout=10)
        pytest.skip(f"tcpdump cannot capture here: {errors.strip()[:200]}")
    proc = ppod("up", "--config", str(ROOT / "tests" / "support" / "two_nodes.yaml"), "--duration", "6")
    try:
        proc.wait_for(LISTENER_ELEVENTH, 60)
        assert proc.wait(60) == 0
    finally:
        proc.kill()
        time.sleep(0.5)
        for p, _ in caps.values():
            p.terminate()
            p.wait(timeout=10)
    counts = {iface: _count(path) for iface, (_, path) in caps.items()}
    assert counts.pop("lo") > 50, "positive control: DDS traffic should be visible on loopback"
    assert counts == {iface: 0 for iface in counts}
