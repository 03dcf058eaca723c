"""CAN codec: every frame round-trips; bad frames are rejected and counted, never a crash."""

import dataclasses
import math

import can
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ppod_ros.can import codec
from ppod_ros.can.codec import (
    CoilRms,
    CoilTemps,
    Control,
    DeviceLimit,
    Estop,
    FaultEvent,
    FrameCounters,
    Heartbeat,
    RawData,
    RawHeader,
    RawRequest,
    Status,
    StatusExt,
    SummaryData,
    SummaryHeader,
    TableAck,
    TableCommit,
    TableCrc,
    TableEntry,
    TableHeader,
    Version,
    VersionRequest,
    decode,
    encode_summary,
    encode_table,
    table_checksum,
    table_crc,
)
from ppod_ros.can.protocol import (
    CURRENT_LSB_A,
    DEVICE_TO_HOST,
    HOST_TO_DEVICE,
    RAW_LSB_MPS2,
    SUMMARY_LSB_MPS2,
    AckResult,
    Command,
    DeviceState,
    Fn,
    bus_load,
    can_id,
    frame_bits,
    quantise_currents,
)
from ppod_ros.errors import ProtocolError

NODE = 1
u8 = st.integers(0, 255)
finite = {"allow_nan": False, "allow_infinity": False}


def complex24(lsb):
    lim = (2**23 - 1) * lsb
    return st.builds(
        lambda re, im: complex(round(re / lsb) * lsb, round(im / lsb) * lsb),
        st.floats(-lim, lim, **finite),
        st.floats(-lim, lim, **finite),
    )


def ms(hi):
    return st.integers(0, hi).map(lambda v: v * 1e-3)


RECORDS = st.one_of(
    st.builds(Estop, u8),
    st.builds(Control, st.sampled_from([c for c in Command if c != Command.SUMMARY_HARMONICS]), ms(0xFFFF)),
    st.builds(Control, st.just(Command.SUMMARY_HARMONICS), harmonics=st.integers(1, 10)),
    st.builds(Heartbeat, u8, st.integers(0, 15)),
    st.builds(
        TableHeader, u8, st.integers(0, 60), st.integers(1, 2**32 - 1).map(lambda v: v * 1e-6), ms(0xFFFF)
    ),
    st.builds(TableEntry, u8, st.integers(0, 5), st.integers(1, 10), complex24(CURRENT_LSB_A)),
    st.builds(TableCommit, u8, st.integers(0, 60), st.integers(0, 0xFFFF)),
    st.builds(TableCrc, u8, st.integers(0, 60), st.integers(0, 0xFFFF)),
    st.builds(
        DeviceLimit,
        st.integers(0, 9),
        st.just(10),
        st.integers(0, 2**32 - 1).map(lambda v: v * 1e-6),
    ),
    st.builds(VersionRequest, u8, u8, st.integers(0, 15)),
    st.builds(RawRequest, st.integers(0, 15), st.integers(1, 0xFFFF), st.integers(1, 16)),
    st.builds(FaultEvent, st.integers(0, 0xFFFF), st.sampled_from(list(DeviceState)), ms(2**32 - 1)),
    st.builds(TableAck, u8, st.sampled_from(list(AckResult)), st.integers(0, 2**24 - 1)),
    st.builds(Status, st.sampled_from(list(DeviceState)), st.integers(0, 0xFFFF), u8, ms(2**32 - 1)),
    st.builds(
        StatusExt,
        st.integers(0, 2**32 - 1),
        st.integers(0, 255).map(lambda v: v / 255),
        st.integers(0, 254).map(lambda v: v * 2e-3),
        st.integers(0, 0xFFFF),
    ),
    st.builds(CoilTemps, st.tuples(*[st.integers(0, 255).map(float)] * 6)),
    st.builds(CoilRms, st.tuples(*[st.integers(0, 255).map(lambda v: v * 0.05)] * 6)),
    st.builds(
        Version,
        u8,
        u8,
        st.integers(1, 6),
        st.integers(1, 16),
        st.integers(1, 10),
        st.integers(1, 15),
        st.booleans(),
    ),
    st.builds(
        SummaryHeader,
        u8,
        st.integers(1, 16),
        st.integers(1, 10),
        st.integers(0, 2**24 - 1),
        st.integers(32, 0xFFFF),
        u8,
    ),
    st.builds(SummaryData, u8, st.integers(0, 15), st.integers(1, 10), complex24(SUMMARY_LSB_MPS2)),
    st.builds(
        RawHeader,
        st.integers(0, 15),
        st.integers(1, 16),
        st.integers(1, 0xFFFF),
        st.integers(0, 2**24 - 1),
        st.integers(8, 256),
    ),
    st.builds(
        RawData,
        st.integers(0, 15),
        st.integers(0, 4095),
        st.tuples(*[st.integers(-32768, 32767).map(lambda v: v * RAW_LSB_MPS2)] * 3),
    ),
)


def direction_of(rec):
    return "to_device" if rec.FN in HOST_TO_DEVICE else "to_host"


def same(a, b):
    for name in (f.name for f in dataclasses.fields(a)):
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, float) and math.isinf(x):
            assert math.isinf(y)
        elif isinstance(x, (float, complex, tuple)):
            assert np.allclose(
                np.asarray(x, dtype=complex), np.asarray(y, dtype=complex), rtol=1e-12, atol=1e-9
            ), name
        else:
            assert x == y, name


@settings(max_examples=400, deadline=None)
@given(RECORDS)
def test_every_frame_round_trips_through_encode_and_decode(rec):
    msg = rec.encode(NODE)
    assert msg.arbitration_id == can_id(rec.FN, NODE) and not msg.is_extended_id
    assert len(msg.data) == rec.LENGTH <= 8
    back = decode(msg, node_id=NODE, direction=direction_of(rec))
    assert type(back) is type(rec)
    same(rec, back)


def test_emergency_stop_has_the_highest_priority_of_all_frames():
    ids = [can_id(fn, NODE) for fn in Fn]
    assert can_id(Fn.ESTOP, NODE) == min(ids)
    assert Estop().encode(0).arbitration_id == 0x000  # broadcast e-stop beats everything on the bus
    # Any payload stops: the identifier is the command.
    for data in (b"", b"\x01", bytes(8)):
        assert isinstance(
            decode(
                can.Message(arbitration_id=0x001, data=data, is_extended_id=False),
                node_id=NODE,
                direction="to_device",
            ),
            Estop,
        )
    assert isinstance(
        decode(
            can.Message(arbitration_id=0x000, data=b"", is_extended_id=False),
            node_id=NODE,
            direction="to_device",
        ),
        Estop,
    )


def test_every_function_code_has_one_direction_and_one_record():
    assert set(Fn) == HOST_TO_DEVICE | DEVICE_TO_HOST and not HOST_TO_DEVICE & DEVICE_TO_HOST
    assert set(codec.RECORDS) == set(Fn)


def frame(arb, data, **kw):
    return can.Message(arbitration_id=arb, data=bytes(data), is_extended_id=kw.pop("ext", False), **kw)


@pytest.mark.parametrize(
    ("msg", "reason"),
    [
        (frame(can_id(Fn.STATUS, NODE), b"\x00" * 7), "wrong length"),
        (frame(can_id(Fn.TABLE_ENTRY, NODE), b"\x00" * 5), "wrong length"),
        (frame(0x7F1, b"\x00" * 8), "unknown id"),
        (frame(can_id(Fn.STATUS, NODE), b"\x09" + b"\x00" * 7), "out of range"),  # state 9
        (frame(can_id(Fn.TABLE_ENTRY, NODE), b"\x01\x71" + b"\x00" * 6), "out of range"),  # actuator 7
        (frame(can_id(Fn.TABLE_ENTRY, NODE), b"\x01\x00" + b"\x00" * 6), "out of range"),  # harmonic 0
        (frame(can_id(Fn.CONTROL, NODE), b"\x09\x00\x00"), "out of range"),  # unknown command
        (frame(can_id(Fn.TABLE_HEADER, NODE), b"\x01\x02" + b"\x00" * 6), "out of range"),  # 0 Hz
        (frame(can_id(Fn.STATUS, NODE), b"\x00" * 8, ext=True), "not a data frame"),
        (
            can.Message(arbitration_id=can_id(Fn.STATUS, NODE), is_remote_frame=True, is_extended_id=False),
            "not a data frame",
        ),
    ],
)
def test_malformed_frames_are_rejected_with_a_reason(msg, reason):
    direction = "to_device" if msg.arbitration_id >> 4 in HOST_TO_DEVICE else "to_host"
    with pytest.raises(ProtocolError) as info:
        decode(msg, node_id=NODE, direction=direction)
    assert info.value.reason == reason


def test_frames_in_the_wrong_direction_are_rejected_by_the_device_and_ignored_by_a_host():
    status = Status(DeviceState.ENABLED, 0, 1, 1.0).encode(NODE)
    with pytest.raises(ProtocolError, match="wrong direction"):
        decode(status, node_id=NODE, direction="to_device")
    host = FrameCounters(NODE, "to_host")
    assert host.decode(Heartbeat(1).encode(NODE)) is None  # another host's heartbeat: normal traffic
    assert host.foreign == 1 and host.rejected_total == 0


def test_frames_for_other_nodes_are_counted_as_foreign_not_as_errors():
    counters = FrameCounters(NODE, "to_device")
    assert counters.decode(Heartbeat(1).encode(5)) is None
    assert counters.foreign == 1 and counters.rejected_total == 0


@settings(max_examples=1500, deadline=None)
@given(st.integers(0, 0x7FF), st.binary(max_size=8), st.booleans(), st.booleans())
def test_random_frames_never_crash_a_receiver_and_are_all_accounted_for(arb, data, ext, remote):
    for direction in ("to_device", "to_host"):
        counters = FrameCounters(NODE, direction)
        msg = can.Message(
            arbitration_id=arb, data=data, is_extended_id=ext, is_remote_frame=remote, dlc=len(data)
        )
        rec = counters.decode(msg)
        assert counters.accepted + counters.rejected_total + counters.foreign == 1
        if rec is not None:
            # Whatever was accepted re-encodes to a frame that decodes to the same record.
            again = decode(
                rec.encode(arb & 0xF), node_id=NODE if arb & 0xF == NODE else arb & 0xF, direction=direction
            )
            same(rec, again)


@settings(max_examples=300, deadline=None)
@given(RECORDS, st.integers(0, 7))
def test_truncated_frames_are_rejected(rec, cut):
    msg = rec.encode(NODE)
    if rec.FN == Fn.ESTOP or cut >= len(msg.data):
        return
    short = can.Message(arbitration_id=msg.arbitration_id, data=bytes(msg.data[:cut]), is_extended_id=False)
    counters = FrameCounters(NODE, direction_of(rec))
    assert counters.decode(short) is None
    assert counters.rejected["wrong length"] == 1


@pytest.mark.parametrize(
    "make",
    [
        lambda: TableEntry(1, 6, 1, 0j),
        lambda: TableEntry(1, 0, 11, 0j),
        lambda: TableEntry(1, 0, 1, complex(17.0, 0)),
        lambda: TableEntry(1, 0, 1, complex(math.nan, 0)),
        lambda: TableHeader(1, 2, -30.0, 0.5),
        lambda: TableHeader(1, 2, 30.0, 70.0),
        lambda: SummaryData(1, 16, 1, 0j),
        lambda: Heartbeat(1, 16),
        lambda: Control(Command.DISABLE, -1.0),
        lambda: Control(Command.SUMMARY_HARMONICS, harmonics=11),
        lambda: RawData(0, 4096, (0.0, 0.0, 0.0)),
    ],
)
def test_encoding_rejects_values_that_do_not_fit_instead_of_clipping(make):
    with pytest.raises(ProtocolError, match="out of range"):
        make().encode(NODE)


def test_table_frames_are_header_nonzero_entries_and_commit_with_an_order_free_checksum():
    table = np.zeros((3, 6), complex)
    table[0] = np.arange(6) * 0.1 + 0.05j
    table[1, 2] = -0.3
    frames = encode_table(7, 30.0, 0.5, table, NODE)
    fns = [f.arbitration_id >> 4 for f in (frames[0], frames[-2], frames[-1])]
    assert fns == [Fn.TABLE_HEADER, Fn.TABLE_CRC, Fn.TABLE_COMMIT]
    entries = [decode(f, node_id=NODE, direction="to_device") for f in frames[1:-2]]
    assert len(entries) == 7  # six of harmonic 1, one of harmonic 2; zeros are not sent
    header = decode(frames[0], node_id=NODE, direction="to_device")
    crc = decode(frames[-2], node_id=NODE, direction="to_device")
    assert crc.seq == 7 and crc.n_entries == 7 and crc.crc == table_crc(header, entries[::-1])
    commit = decode(frames[-1], node_id=NODE, direction="to_device")
    assert commit.n_entries == 7 and commit.checksum == table_checksum(entries[::-1])
    assert table_checksum(entries[:-1]) != commit.checksum
    got = np.zeros_like(table)
    for e in entries:
        got[e.k - 1, e.actuator] = e.current_a
    assert np.array_equal(got, quantise_currents(table))


def test_an_all_zero_table_is_a_header_and_a_commit():
    frames = encode_table(1, 30.0, 0.5, np.zeros((3, 6)), NODE)
    assert [f.arbitration_id >> 4 for f in frames] == [Fn.TABLE_HEADER, Fn.TABLE_CRC, Fn.TABLE_COMMIT]


def test_the_table_crc_changes_with_every_single_bit_of_the_header_and_the_entries():
    table = np.zeros((2, 6), complex)
    table[0] = 0.3 + 0.1j
    frames = encode_table(9, 30.0, 0.5, table, NODE)
    header = decode(frames[0], node_id=NODE, direction="to_device")
    entries = [decode(f, node_id=NODE, direction="to_device") for f in frames[1:-2]]
    reference = table_crc(header, entries)
    payload = bytes(frames[0].data)
    for bit in range(64):
        flipped = bytearray(payload)
        flipped[bit // 8] ^= 1 << (bit % 8)
        try:
            other = TableHeader._parse(bytes(flipped))
        except ProtocolError:
            continue  # a flip that makes the header invalid is rejected on its own
        assert table_crc(other, entries) != reference, bit


def test_new_frames_declare_their_payload_layout_for_generators():
    for cls in (TableCrc, DeviceLimit):
        fields = cls.FIELDS
        assert fields and sum(f.size for f in fields) == cls.LENGTH
        assert [f.offset for f in fields] == sorted(f.offset for f in fields)


def test_frame_bits_follow_the_worst_case_stuffing_formula():
    assert frame_bits(0) == 47 + 8
    assert frame_bits(8) == 135
    assert frame_bits(2) == 75
    assert bus_load([8] * 1000, 1.0, 1_000_000) == pytest.approx(0.135)
    with pytest.raises(ProtocolError):
        frame_bits(9)


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 10), st.integers(1, 16), st.integers(0, 2**31))
def test_bulk_summary_encoding_equals_frame_by_frame_encoding(H, C, seed):
    rng = np.random.default_rng(seed)
    X = (rng.normal(size=(H, C)) + 1j * rng.normal(size=(H, C))) * 10 ** rng.uniform(-3, 2.5)
    X *= min(1.0, 500.0 / np.max(np.abs(X)))
    header = SummaryHeader(9, 2, H, 1234, 70, 3)
    bulk = encode_summary(header, X, NODE)
    single = [header.encode(NODE)] + [
        SummaryData(9, c, k, complex(X[k - 1, c])).encode(NODE) for c in range(C) for k in range(1, H + 1)
    ]
    assert [(m.arbitration_id, bytes(m.data)) for m in bulk] == [
        (m.arbitration_id, bytes(m.data)) for m in single
    ]
    with pytest.raises(ProtocolError, match="out of range"):
        encode_summary(header, X * 0 + 600.0, NODE)
