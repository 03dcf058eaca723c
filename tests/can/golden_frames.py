"""One frame of every kind, its record and its bytes written by hand from docs/can_protocol.md.

Each entry: (record, arbitration id for node 1, payload hex). Shared by the golden-vector test (the
codec against the docs) and the DBC test (cantools against the codec).
"""

from ppod_ros.can.codec import (
    CoilRms,
    CoilTemps,
    Control,
    DeviceLimit,
    Estop,
    FaultEvent,
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
)
from ppod_ros.can.protocol import AckResult, Command, DeviceState

GOLDEN = [
    # [0] u8 reason
    (Estop(7), 0x001, "07"),
    # [0:2] u16 faults 0x0005 (ESTOP | THERMAL), [2] u8 state 5 FAULT, [3:7] u32 1234 ms
    (FaultEvent(0x0005, DeviceState.FAULT, 1.234), 0x011, "050005d2040000"),
    # [0] u8 command 2 DISABLE, [1:3] u16 ramp 500 ms
    (Control(Command.DISABLE, ramp_s=0.5), 0x021, "02f401"),
    # [0] u8 counter 42, [1] u8 host node 0
    (Heartbeat(42, 0), 0x031, "2a00"),
    # [0] u8 seq 3, [1] u8 result 1 ACTIVE, [2:5] u24 cycle index 0x012345
    (TableAck(3, AckResult.ACTIVE, 0x012345), 0x041, "0301452301"),
    # [0] u8 seq 1, [1] u8 entries 12, [2:6] u32 30 Hz = 30 000 000 uHz, [6:8] u16 ramp 200 ms
    (TableHeader(1, 12, 30.0, 0.2), 0x051, "010c80c3c901c800"),
    # [0] u8 seq 1, [1] actuator 2 << 4 | k 3, [2:5] i24 Re 1 A = 2^19, [5:8] i24 Im -0.5 A = -2^18
    (TableEntry(1, 2, 3, complex(1.0, -0.5)), 0x061, "01230000080000fc"),
    # [0] u8 seq 1, [1] u8 entries 12, [2:4] u16 checksum 0xBEEF
    (TableCommit(1, 12, 0xBEEF), 0x071, "010cefbe"),
    # [0] u8 state 1 ENABLED, [1:3] u16 faults 0, [3] u8 active seq 1, [4:8] u32 65536 ms
    (Status(DeviceState.ENABLED, 0, 1, 65.536), 0x081, "0100000100000100"),
    # [0:4] u32 cycles 1000, [4] u8 ramp 255/255, [5] u8 heartbeat age 25 x 2 ms, [6:8] u16 rejected 2
    (StatusExt(1000, 1.0, 0.05, 2), 0x091, "e8030000ff190200"),
    # [0:6] u8 deg C per coil
    (CoilTemps((25.0, 26.0, 27.0, 28.0, 29.0, 30.0)), 0x0A1, "191a1b1c1d1e"),
    # [0:6] u8 RMS per coil, 0.05 A steps
    (CoilRms((0.5, 1.0, 0.0, 0.05, 2.0, 12.75)), 0x0B1, "0a14000128ff"),
    # [0] u8 major 1, [1] u8 minor 0, [2] u8 host node 0
    (VersionRequest(1, 0, 0), 0x0C1, "010000"),
    # major 1, minor 0, 6 actuators, 12 channels, max harmonic 10, node 1, simulated
    (Version(1, 0, 6, 12, 10, 1, True), 0x0D1, "0100060c0a0101"),
    # [0] u8 seq 7, [1] (cycles 2 - 1) << 4 | H 3, [2:5] u24 first cycle 256, [5:7] u16 64 samples, [7] table seq 1
    (SummaryHeader(7, 2, 3, 256, 64, 1), 0x0E1, "0713000100400001"),
    # [0] u8 seq 7, [1] channel 11 << 4 | k 2, [2:5] i24 Re 1 m/s^2 = 2^14, [5:8] i24 Im -2^-14 m/s^2 = -1
    (SummaryData(7, 11, 2, complex(1.0, -(2.0**-14))), 0x0F1, "07b2004000ffffff"),
    # [0] u8 capture id 3, [1:3] u16 mask 0x0FFF, [3] u8 cycles 2
    (RawRequest(3, 0x0FFF, 2), 0x101, "03ff0f02"),
    # [0] id 3 << 4 | (cycles 2 - 1), [1:3] u16 mask 0x0FFF, [3:6] u24 start cycle 16, [6:8] u16 64 samples
    (RawHeader(3, 2, 0x0FFF, 16, 64), 0x111, "31ff0f1000004000"),
    # [0:2] channel 5 << 12 | index 9, [2:8] 3 x i16: 1 m/s^2 = 512, -1 m/s^2, 0 (2^-9 m/s^2 steps)
    (RawData(5, 9, (1.0, -1.0, 0.0)), 0x121, "09500002 00fe0000".replace(" ", "")),
    # [0] u8 seq 1, [1] u8 entries 12, [2:4] u16 crc 0x1D0F
    (TableCrc(1, 12, 0x1D0F), 0x131, "010c0f1d"),
    # [0] u8 item 1 (coil current), [1] u8 items 10, [2:6] u32 value 3 A = 3 000 000 micro-units
    (DeviceLimit(1, 10, 3.0), 0x141, "010ac0c62d00"),
]
