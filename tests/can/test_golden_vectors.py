"""Golden byte vectors: one frame of every kind, written by hand from docs/can_protocol.md's tables.

The codec must produce exactly these bytes and decode them back to the same record, so a change of
the wire format shows up here even when encode and decode change together.
"""

import math

import can
import pytest

from ppod_ros.can.codec import RECORDS, decode
from ppod_ros.can.protocol import DEVICE_TO_HOST
from tests.can.golden_frames import GOLDEN


def _close(a, b) -> bool:
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    if isinstance(a, (float, complex)) or isinstance(b, (float, complex)):
        return abs(complex(a) - complex(b)) <= 1e-9 * max(1.0, abs(complex(a)))
    return a == b


def test_there_is_a_golden_vector_for_every_frame_kind_of_the_codec():
    assert sorted(type(r).FN for r, _, _ in GOLDEN) == sorted(RECORDS)


@pytest.mark.parametrize("record, frame_id, payload", GOLDEN, ids=[type(r).__name__ for r, _, _ in GOLDEN])
def test_the_codec_writes_and_reads_the_documented_bytes(record, frame_id, payload):
    msg = record.encode(1)
    assert msg.arbitration_id == frame_id
    assert bytes(msg.data).hex() == payload
    direction = "to_host" if type(record).FN in DEVICE_TO_HOST else "to_device"
    back = decode(can.Message(arbitration_id=frame_id, data=bytes.fromhex(payload), is_extended_id=False),
                  node_id=1, direction=direction)
    assert type(back) is type(record)
    for name in record.__dataclass_fields__:
        a, b = getattr(back, name), getattr(record, name)
        assert _close(a, b), f"{type(record).__name__}.{name}: decoded {a!r}, expected {b!r}"
    assert not any(isinstance(v, float) and math.isnan(v) for v in vars(back).values())
