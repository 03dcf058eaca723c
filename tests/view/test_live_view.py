"""`ppod view`: a websocket client on 127.0.0.1 receives the scene (Foxglove WebSocket, foxglove.sdk.v1)."""

import asyncio
import json
import struct
import time

import pytest

pytestmark = pytest.mark.ros


async def _first_scene(port: int, timeout_s: float) -> tuple[dict, bytes]:
    import websockets

    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"],
                                  open_timeout=timeout_s) as ws:
        channel = None
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            frame = await asyncio.wait_for(ws.recv(), timeout=max(0.1, deadline - time.monotonic()))
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get("op") == "advertise":
                    channel = next((c for c in msg["channels"] if c["topic"] == "/ppod/scene"), channel)
                    if channel is not None:
                        await ws.send(json.dumps({"op": "subscribe",
                                                  "subscriptions": [{"id": 1, "channelId": channel["id"]}]}))
                continue
            if frame[0] == 0x01 and struct.unpack_from("<I", frame, 1)[0] == 1:
                return channel, bytes(frame[13:])  # opcode, subscription id, log time, payload
        raise AssertionError("no scene message within the timeout")


def test_a_websocket_client_receives_the_scene_with_the_tracked_part(ros):
    from ppod_msgs.msg import PartPose, PartPoseArray

    from ppod_nodes.common import qos, topics
    from ppod_nodes.view.live import LiveView

    pub = ros.helper.create_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)
    with LiveView(ros.helper, 0.175, ((0.0, 0.0, 0.7), (1.0, 0.0, 0.0, 0.0)), port=0, rate_hz=10.0,
                  field_grid=0) as view:
        assert view.port > 0
        msg = PartPoseArray()
        msg.parts = [PartPose(id=7, label="washer")]
        msg.parts[0].pose.x = 0.05
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and view.state.scene().parts == ():
            pub.publish(msg)
            time.sleep(0.05)
        assert view.state.scene().parts[0].id == 7
        channel, payload = asyncio.run(_first_scene(view.port, 20.0))
    assert channel["schemaName"] == "foxglove.SceneUpdate"
    assert b"part/7" in payload and b"washer" in payload and b"plate" in payload
