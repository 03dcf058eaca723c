"""Safety campaign: random goals, corrections, stops, e-stops and bus faults against the simulated device.

Everything the host sends goes through the waveform generator's core (``WaveformGenerator``) over a
``FaultInjectingBus`` (frames lost and corrupted in both directions, bus-off episodes) to the
simulated device (``SimDevice``). A passive listener on the bus sees every frame as the device sees
it; it decodes them with its *own* decoder (written from docs/can_protocol.md, not the codec), keeps
the table each sequence number assembled to, and when the device acknowledges a commit ACCEPTED
checks that table with its *own* model of the nominal plant (written from docs/device.md: M, C, K from
the geometry, the coil circuit and the PI current loop; 1024 samples per period of the highest row)
against every limit of the device description. It also compares each accepted table with what the
host meant to send. A second part flips every single bit (identifier and data) of every frame of a
few tables and counts the accepted tables that differ from what was sent.

Printed: goals, accepted goals, corrections (applied, scaled, rows blocked), tables accepted by the
device, over-limit tables by limit, tables with current at a forbidden frequency, accepted altered
tables, exceptions that escaped the generator, retries and rejections, device faults.

examples:
  ppod bench safety --quick
  ppod bench safety --goals 5000 --seed 1
"""

from __future__ import annotations

import argparse
import math
import time
import traceback
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

HELP = "safety campaign: fuzzed goals, corrections and bus faults; independent decoder and limit checker"

GRAVITY = 9.81  # m/s^2, as docs/device.md's contact margin
#: Relative tolerance of the independent check: the two models agree to ~1e-9, the protocol quantises
#: currents to 2^-19 A (1e-6 of a typical entry).
CHECK_RTOL = 1e-5
#: The limits that belong to the plate's own motion (docs/device.md, "Planning and limits").
PLATE_SIDE = ("limits.plate_accel_mps2", "limits.plate_angular_accel_radps2", "limits.contact_margin_mps2")
#: Samples per period of the highest row in the independent check (the issue asks for >= 1024).
CHECK_SAMPLES = 1024


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--goals", type=int, default=5000, help="random goals (default %(default)s)")
    parser.add_argument("--seed", type=int, default=1, help="random seed (default %(default)s)")
    parser.add_argument("--drop", type=float, default=0.05, help="frame loss probability (default %(default)s)")
    parser.add_argument("--corrupt", type=float, default=0.05,
                        help="frame corruption probability (default %(default)s)")
    parser.add_argument("--bitflip-tables", type=int, default=12,
                        help="tables whose every single bit is flipped in turn (default %(default)s)")
    parser.add_argument("--quick", action="store_true", help="200 goals, 2 bit-flip tables")


# ----------------------------------------------------------------------------------------------
# An independent decoder (docs/can_protocol.md)
# ----------------------------------------------------------------------------------------------
FN_HEADER, FN_ENTRY, FN_COMMIT, FN_ACK, FN_CRC = 5, 6, 7, 4, 19
ACK_NAMES = {0: "ACCEPTED", 1: "ACTIVE", 2: "INCOMPLETE", 3: "CHECKSUM", 4: "OVER_LIMIT", 5: "BAD_STATE",
             6: "SUPERSEDED"}


def _i24(b: bytes) -> int:
    v = b[0] | b[1] << 8 | b[2] << 16
    return v - (1 << 24) if v & 0x800000 else v


@dataclass
class DecodedTable:
    seq: int
    frequency_hz: float
    ramp_s: float
    n_entries: int
    entries: dict = field(default_factory=dict)  # (k, actuator) -> complex A

    def dense(self) -> np.ndarray:
        K = max((k for k, _ in self.entries), default=1)
        out = np.zeros((K, 6), complex)
        for (k, a), v in self.entries.items():
            out[k - 1, a] = v
        return out


class Listener:
    """Decodes the table traffic of one device node from raw frames (docs/can_protocol.md)."""

    def __init__(self, node: int):
        self.node = node
        self.current: DecodedTable | None = None
        self.closed: dict[int, DecodedTable] = {}  # seq -> table as of its commit
        self.acks: list[tuple[int, str]] = []

    def feed(self, msg) -> None:
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            return
        fn, node = msg.arbitration_id >> 4, msg.arbitration_id & 0xF
        d = bytes(msg.data)
        if node != self.node:
            return
        if fn == FN_HEADER and len(d) == 8:
            f_uhz = int.from_bytes(d[2:6], "little")
            self.current = DecodedTable(d[0], f_uhz * 1e-6, int.from_bytes(d[6:8], "little") * 1e-3, d[1])
        elif fn == FN_ENTRY and len(d) == 8 and self.current is not None and d[0] == self.current.seq:
            a, k = d[1] >> 4, d[1] & 0xF
            self.current.entries[(k, a)] = complex(_i24(d[2:5]), _i24(d[5:8])) * 2.0**-19
        elif fn == FN_COMMIT and len(d) == 4 and self.current is not None and d[0] == self.current.seq:
            self.closed[d[0]] = self.current
        elif fn == FN_ACK and len(d) == 5:
            self.acks.append((d[0], ACK_NAMES.get(d[1], f"?{d[1]}")))


# ----------------------------------------------------------------------------------------------
# An independent nominal plant and limit check (docs/device.md)
# ----------------------------------------------------------------------------------------------
def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


class Checker:
    """The device description's limits on a current table, from the equations of docs/device.md."""

    def __init__(self, config):
        self.cfg = config
        g, pl, a, fl = config.geometry, config.plate, config.actuators, config.flexures
        P = np.array([0.0, 0.0, g.home_height_m])
        legs = P + g.plate_points_m - g.base_points_m
        n = legs / np.linalg.norm(legs, axis=1)[:, None]
        self.J = np.hstack([n, np.cross(g.plate_points_m, n)])  # dL/d[p, phi] at home
        m, c = pl.mass_kg, np.asarray(pl.com_m)
        Ic = np.asarray(pl.inertia_kgm2)
        Ic = np.diag(Ic) if Ic.ndim == 1 else Ic
        Mp = np.block([[m * np.eye(3), -m * _skew(c)], [m * _skew(c), Ic - m * _skew(c) @ _skew(c)]])
        JtJ = self.J.T @ self.J
        self.M = Mp + a.moving_mass_kg * JtJ
        self.C = fl.leg_damping_n_s_per_m * JtJ
        self.K = fl.leg_stiffness_n_per_m * JtJ
        wc = 2 * math.pi * a.current_loop_bandwidth_hz
        self.kp, self.ki = a.inductance_h * wc, a.resistance_ohm * wc
        self.a = a

    def response(self, f_hz: float):
        """(accel, legs, current, voltage) per unit current reference, each (6, 6), at f_hz."""
        s = 2j * math.pi * f_hz
        a = self.a
        Z = self.M * s**2 + self.C * s + self.K
        G = np.linalg.solve(Z, self.J.T * a.force_constant_n_per_a)  # q per coil current
        Pi = self.kp + self.ki / s
        A = (a.inductance_h * s + a.resistance_ohm + Pi) * np.eye(6) + a.back_emf_v_s_per_m * s * self.J @ G
        I = np.linalg.solve(A, Pi * np.eye(6))  # coil current per reference
        q = G @ I
        return s**2 * q, self.J @ q, I, Pi * (np.eye(6) - I)

    def check(self, f_hz: float, table: np.ndarray) -> tuple[dict[str, float], list[int]]:
        """{limit: use / limit} and the rows carrying current at a forbidden frequency."""
        lim = self.cfg.limits
        K = table.shape[0]
        rows = [k for k in range(1, K + 1) if np.any(table[k - 1] != 0)]
        forbidden = []
        for k in rows:
            fk = k * f_hz
            if not lim.frequency_range_hz[0] <= fk <= lim.frequency_range_hz[1] or any(
                    lo <= fk <= hi for lo, hi in lim.excluded_bands_hz):
                forbidden.append(k)
        outs = {name: np.zeros((K, 6), complex) for name in ("accel", "leg", "current", "voltage")}
        for k in rows:
            acc, leg, cur, volt = self.response(k * f_hz)
            for name, H in zip(("accel", "leg", "current", "voltage"), (acc, leg, cur, volt), strict=True):
                outs[name][k - 1] = H @ table[k - 1]
        N = CHECK_SAMPLES * max(rows, default=1)
        theta = 2 * math.pi * np.arange(N) / N
        basis = np.exp(1j * np.outer(theta, np.arange(1, K + 1)))

        def wave(X):
            return (basis @ X).imag

        u = wave(outs["accel"])
        r = lim.working_radius_m
        margin = GRAVITY + np.min(u[:, 2] - r * np.hypot(u[:, 3], u[:, 4]))
        i_ref = wave(table)
        i_rms = np.sqrt(np.sum(np.abs(table) ** 2, axis=0) / 2)
        temp = self.a.ambient_temperature_c + self.a.thermal_resistance_k_per_w * self.a.resistance_ohm * i_rms**2
        ratios = {
            "limits.plate_accel_mps2": np.max(np.linalg.norm(u[:, :3], axis=1)) / lim.plate_accel_mps2,
            "limits.plate_angular_accel_radps2": np.max(np.linalg.norm(u[:, 3:], axis=1))
            / lim.plate_angular_accel_radps2,
            "limits.contact_margin_mps2": (GRAVITY - margin) / (GRAVITY - lim.contact_margin_mps2),
            "limits.leg_stroke_m": np.max(np.abs(wave(outs["leg"]))) / lim.leg_stroke_m,
            "limits.coil_current_a": np.max(np.abs(i_ref)) / lim.coil_current_a,
            # sqrt of the temperature rise over the allowed one: I_rms over its limit (linear in amplitude)
            "limits.coil_temperature_c": math.sqrt((np.max(temp) - self.a.ambient_temperature_c)
                                                   / (lim.coil_temperature_c - self.a.ambient_temperature_c)),
            "limits.amplifier_voltage_v": np.max(np.abs(wave(outs["voltage"]))) / lim.amplifier_voltage_v,
        }
        return {k: float(v) for k, v in ratios.items()}, forbidden


# ----------------------------------------------------------------------------------------------
# The campaign
# ----------------------------------------------------------------------------------------------
def _random_goal(rng, lim):
    from ppod_ros.motion import PlateMotion

    n = int(rng.integers(1, 6))
    ks = np.sort(rng.choice(np.arange(1, 6), size=n, replace=False))
    scale = rng.uniform(0.0, 3.0) if rng.random() < 0.3 else rng.uniform(0.0, 1.2)  # up to 3x the limits
    amp = np.abs(rng.normal(size=(n, 6))) * np.array([lim.plate_accel_mps2] * 3 + [lim.plate_angular_accel_radps2] * 3)
    amp *= scale / max(1.0, np.sqrt(n * 6)) * rng.uniform(0.1, 1.0, size=(n, 1))
    amp[:, 2] *= rng.uniform(0, 0.3)  # vertical motion: mostly small, as fields use it
    phase = rng.uniform(0, 2 * math.pi, size=(n, 6))
    f = float(rng.choice([rng.uniform(5, 30), rng.uniform(18, 80), rng.uniform(80, 200)]))
    ramp = float(rng.choice([rng.uniform(0.05, 0.6), 70.0])) if rng.random() < 0.05 else float(rng.uniform(0.05, 0.6))
    return PlateMotion(f, ks, amp, phase, name=f"fuzz-{rng.integers(1e9)}", ramp_time_s=ramp)


def _spin_goal(rng, planner, lim):
    """A 30 Hz turn about z with some translation, scaled to 60-95 % of the legs' stroke on the worst
    plant the checker allows for (``limits.plant_uncertainty``; on the nominal plant about 0.69 of
    that) (None if the envelope refuses it anyway)."""
    from ppod_ros.errors import ConfigError, LimitError
    from ppod_ros.motion import PlateMotion

    amp = np.concatenate([rng.uniform(0, 10, 2), rng.uniform(0, 1, 1), rng.uniform(0, 40, 2), [300.0]])
    goal = PlateMotion.single(30, amp, rng.uniform(0, 2 * math.pi, 6), name="spin", ramp_time_s=0.5)
    try:
        small = planner.plan(goal.scaled(0.1))
        report = planner.envelope.check_table(small.frequency_hz, small.currents_a, planner.allowance)
        use = report.ratios["limits.leg_stroke_m"] * 10
        goal = goal.scaled(rng.uniform(0.6, 0.95) / use)
        planner.plan(goal)
    except (ConfigError, LimitError):
        return None
    return goal


def campaign(n_goals: int, seed: int, drop: float, corrupt: float, progress=None, reversals: float = 0.05) -> dict:
    """Run the fuzzing campaign; returns the counts (see the module docstring). ``reversals``: the
    fraction of goals that are a spin near the legs' stroke, played and then reversed."""
    import itertools

    from ppod_ros.actuation.generator import WaveformGenerator
    from ppod_ros.actuation.planning import GoalPlanner
    from ppod_ros.can import DeviceLink, FaultInjectingBus, open_bus
    from ppod_ros.can.protocol import quantise_currents, quantise_frequency
    from ppod_ros.device import default_device_config
    from ppod_ros.errors import DeviceError
    from ppod_ros.motion import PlateMotion
    from ppod_sim.device import SimDevice

    rng = np.random.default_rng(seed)
    config = default_device_config().with_can(interface="virtual", channel=f"bench-safety-{seed}-{time.time_ns()}")
    dev_bus, inner, spy = open_bus(config.can), open_bus(config.can), open_bus(config.can)
    host_bus = FaultInjectingBus(inner, drop=drop, corrupt=corrupt, seed=seed)
    device = SimDevice(config, dev_bus, seed=seed)
    link = DeviceLink(host_bus, config, clock=lambda: device.time_s)
    gen = WaveformGenerator(link, GoalPlanner(config))
    listener, checker = Listener(config.can.device_node_id), Checker(config)
    intended: dict[int, tuple] = {}
    send_table = link.send_table

    def recording_send(currents, frequency_hz, ramp_s):
        seq = send_table(currents, frequency_hz, ramp_s)
        intended[seq] = (quantise_currents(np.asarray(currents, complex)), quantise_frequency(frequency_hz),
                         round(ramp_s * 1000) / 1000)
        return seq

    link.send_table = recording_send
    counts: Counter = Counter()
    over: Counter = Counter()
    worst: dict[str, float] = {}
    # Tables made from a correction judged on a (random, often wrong) measured plate: their plate-side
    # limits may exceed the nominal plant's by limits.plant_model_allowance at most (docs/device.md).
    measured_tables: set[bytes] = set()
    worst_measured: dict[str, float] = {}
    allowance = config.limits.plant_model_allowance
    playing: list[int | None] = [None]
    exceptions: list[str] = []
    seen_acks = 0

    def pump(seconds: float) -> None:
        nonlocal seen_acks
        end = device.time_s + seconds
        while device.time_s < end - 1e-9:
            try:
                link.heartbeat()
            except DeviceError:
                counts["heartbeats refused (bus-off)"] += 1
            device.advance(0.02)
            link.poll()
            gen.state()
            while (msg := spy.recv(0.0)) is not None:
                listener.feed(msg)
            for seq, result in listener.acks[seen_acks:]:
                if result == "ACCEPTED":
                    judge(seq)
            seen_acks = len(listener.acks)

    def judge(seq: int) -> None:
        table = listener.closed.get(seq)
        if table is None:
            counts["accepted without a decoded table"] += 1
            return
        counts["tables accepted by the device"] += 1
        dense = table.dense()
        ratios, forbidden = checker.check(table.frequency_hz, dense)
        if forbidden:
            counts["accepted with current at a forbidden frequency"] += 1
        want = intended.get(seq)
        measured = want is not None and want[0].tobytes() in measured_tables
        bound = {name: 1.0 + (allowance if measured and name in PLATE_SIDE else 0.0) for name in ratios}
        uses = worst_measured if measured else worst
        for name, r in ratios.items():
            uses[name] = max(uses.get(name, 0.0), r)
            if r > bound[name] + CHECK_RTOL:
                over[name] += 1
        if any(r > bound[name] + CHECK_RTOL for name, r in ratios.items()):
            counts["over-limit tables"] += 1
        if want is not None:
            K = max(want[0].shape[0], dense.shape[0])
            a, b = np.zeros((K, 6), complex), np.zeros((K, 6), complex)
            a[: want[0].shape[0]], b[: dense.shape[0]] = want[0], dense
            if not (np.array_equal(a, b) and abs(want[1] - table.frequency_hz) < 1e-9
                    and abs(max(want[2], 0) - table.ramp_s) < 1e-9):
                counts["accepted tables that differ from what was sent"] += 1

    def guarded(what: str, fn, *args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except DeviceError:
            counts[f"{what}: DeviceError (bus-off; the node answers failure)"] += 1
        except Exception as exc:  # noqa: BLE001 - the campaign counts what would kill a node
            counts["exceptions"] += 1
            if len(exceptions) < 5:
                exceptions.append(f"{what}: {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=4)}")
        return None

    pump(0.1)
    lim = config.limits
    for i in itertools.count():
        if i >= n_goals:
            break
        if progress and i % max(1, n_goals // 20) == 0:
            progress(i, n_goals)
        roll = rng.random()
        if roll < 0.03:
            host_bus.go_bus_off(rng.uniform(0.05, 0.4))
            counts["bus-off episodes"] += 1
        elif roll < 0.06:
            guarded("estop", gen.estop)
            pump(0.05)
            guarded("reset", gen.reset_estop)
            counts["e-stops"] += 1
        elif roll < 0.12:
            guarded("stop", gen.stop)
            counts["stops"] += 1
        goal = _random_goal(rng, lim)
        reversal = rng.random() < reversals
        if reversal:
            # A spin at 60-95 % of the stroke the checker allows (on its worst plant) played, then
            # reversed (the planner turning a part the other way), with a correction 0-60 ms into the
            # reversal's ramp: corrections must not shorten the goal's ramp (crossfaded in 50 ms, the
            # legs overshoot the stroke and the device faults).
            spin = _spin_goal(rng, gen.planner, lim)
            if spin is not None:
                guarded("submit", gen.submit, spin)
                pump(1.0)
                goal = PlateMotion(spin.frequency_hz, spin.k, spin.amplitude, spin.phase + math.pi,
                                   name=spin.name, ramp_time_s=0.5)
                counts["reversals (a spin near the stroke limit reversed, corrected in its ramp)"] += 1
            else:
                reversal = False
        counts["goals"] += 1
        out = guarded("submit", gen.submit, goal, dry_run=bool(rng.random() < 0.05))
        if out is not None:
            counts["goals accepted" if out.accepted else "goals rejected"] += 1
            if out.accepted and out.seq is not None:
                playing[0] = out.seq
        if reversal and out is not None and out.accepted:
            pump(float(rng.uniform(0.0, 0.06)))
            guarded("correction", gen.apply_correction, None, np.array([1]),
                    np.full((1, 6), 0.01 + 0j), absolute=True)
        pump(float(rng.uniform(0.03, 0.1)))
        plan = gen.active_plan
        for _ in range(int(rng.integers(0, 4))):
            if plan is None:
                break
            K = plan.currents_a.shape[0]
            ks = np.sort(rng.choice(np.arange(1, K + 1), size=int(rng.integers(1, K + 1)), replace=False))
            corr = (rng.normal(size=(ks.size, 6)) + 1j * rng.normal(size=(ks.size, 6))) * rng.uniform(0.01, 1.5)
            claim, claim_seq = None, None
            applied = gen.applied_correction_a
            if rng.random() < 0.5 and playing[0] is not None and applied is not None:
                # A measured plate, mostly wrong: the nominal prediction of the table playing scaled
                # by 0.2-1.5 plus noise, sometimes of another table (stale).
                claim = gen.planner.plant.predict(plan.frequency_hz, plan.currents_a + applied, "accel")
                claim = claim * rng.uniform(0.2, 1.5) + rng.normal(size=claim.shape) * rng.uniform(0.0, 2.0)
                claim_seq = playing[0] if rng.random() < 0.8 else playing[0] % 255 + 1
            res = guarded("correction", gen.apply_correction, None, ks, corr, absolute=bool(rng.random() < 0.7),
                          start=bool(rng.random() < 0.2), measured_accel=claim, measured_seq=claim_seq)
            counts["corrections"] += 1
            if res is not None and res.applied:
                playing[0] = res.seq
                if res.result.measured_ratios is not None:
                    counts["corrections judged on a measured plate"] += 1
                    if res.seq in intended:
                        measured_tables.add(intended[res.seq][0].tobytes())
                counts["corrections applied"] += 1
                if res.result.limited_by:
                    counts["corrections scaled back by the envelope"] += 1
                if res.result.blocked_rows:
                    counts["corrections with rows blocked (forbidden frequency)"] += 1
            pump(float(rng.uniform(0.02, 0.08)))
    pump(1.0)
    for name, n in gen.ack_counters.items():
        counts[f"generator: {name}"] += n
    # Counted on the device, as each is raised: the host's FAULT frames can be lost, and a latched
    # fault's bits ride along in every later event.
    counts["device faults (stroke, voltage, current, thermal)"] = device.stopping_fault_count
    for b in (host_bus, dev_bus, spy):
        b.shutdown()
    return {"counts": counts, "over": over, "worst": worst, "worst_measured": worst_measured,
            "allowance": allowance, "exceptions": exceptions, "device_faults": device.stopping_faults[:10],
            "device_time_s": device.time_s, "frames_mangled": dict(host_bus.stats)}


def bitflips(n_tables: int, seed: int) -> dict:
    """Flip every single bit (11 identifier bits and every data bit) of every frame of ``n_tables``."""
    import can

    from ppod_ros.can import DeviceLink, open_bus
    from ppod_ros.can.codec import encode_table
    from ppod_ros.can.protocol import quantise_currents, quantise_frequency
    from ppod_ros.device import default_device_config
    from ppod_sim.device import SimDevice

    rng = np.random.default_rng(seed + 1)
    config = default_device_config().with_can(interface="virtual", channel=f"bench-flip-{seed}-{time.time_ns()}")
    dev_bus, host_bus = open_bus(config.can), open_bus(config.can)
    device = SimDevice(config, dev_bus, seed=seed)
    link = DeviceLink(host_bus, config, clock=lambda: device.time_s)
    accepted: list = []
    commit = device.tables.commit

    def recording_commit(rec):
        table, ack = commit(rec)
        if table is not None:
            accepted.append(table)
        return table, ack

    device.tables.commit = recording_commit
    link.enable()
    node = config.can.device_node_id
    counts: Counter = Counter()
    seq = 0
    for _ in range(n_tables):
        K = int(rng.integers(1, 4))
        currents = quantise_currents((rng.normal(size=(K, 6)) + 1j * rng.normal(size=(K, 6))) * 0.02)
        freq = quantise_frequency(float(rng.uniform(20, 60)))
        seq = seq % 250 + 1
        before = len(accepted)
        link.heartbeat()
        for msg in encode_table(seq, freq, 0.2, currents, node):  # the unaltered table: must be accepted
            host_bus.send(msg)
        device.step()
        counts["unaltered tables accepted (control)"] += len(accepted) - before
        n_frames = len(encode_table(1, freq, 0.2, currents, node))
        for fi in range(n_frames):
            n_bits = 11 + 8 * len(encode_table(1, freq, 0.2, currents, node)[fi].data)
            for bit in range(n_bits):
                seq = seq % 250 + 1
                frames = encode_table(seq, freq, 0.2, currents, node)
                frame = frames[fi]
                if bit < 11:
                    bad = can.Message(arbitration_id=frame.arbitration_id ^ (1 << bit), data=frame.data,
                                      is_extended_id=False)
                else:
                    data = bytearray(frame.data)
                    data[(bit - 11) // 8] ^= 1 << ((bit - 11) % 8)
                    bad = can.Message(arbitration_id=frame.arbitration_id, data=bytes(data), is_extended_id=False)
                before = len(accepted)
                link.heartbeat()
                for msg in frames[:fi] + [bad] + frames[fi + 1:]:
                    host_bus.send(msg)
                device.step()
                counts["single-bit variants sent"] += 1
                for table in accepted[before:]:
                    counts["single-bit variants accepted"] += 1
                    same = (table.seq == seq and abs(table.frequency_hz - freq) < 1e-9
                            and np.array_equal(_pad(table.currents, K), _pad(currents, table.currents.shape[0])))
                    if not same:
                        counts["accepted tables that differ from what was sent"] += 1
                if device.state.name in ("ESTOP", "FAULT", "DISABLED", "WATCHDOG"):
                    # A flipped identifier can become an ESTOP or a CONTROL frame: reset and carry on.
                    counts[f"device left ENABLED ({device.state.name})"] += 1
                    link.reset_estop()
                    link.clear_faults()
                    device.step()
                    link.enable()
                    device.step()
                link.poll()
    counts.setdefault("accepted tables that differ from what was sent", 0)
    dev_bus.shutdown()
    host_bus.shutdown()
    return counts


def _pad(table: np.ndarray, K: int) -> np.ndarray:
    out = np.zeros((max(K, table.shape[0]), 6), complex)
    out[: table.shape[0]] = table
    return out


def run(args: argparse.Namespace) -> int:
    import os

    n = 200 if args.quick else args.goals
    n_flip = 2 if args.quick else args.bitflip_tables
    print(f"ppod bench safety: {n} goals, seed {args.seed}, frame loss {args.drop:.0%}, corruption "
          f"{args.corrupt:.0%}; load average {os.getloadavg()[0]:.2f}", flush=True)
    t0 = time.perf_counter()

    def progress(i, total):
        print(f"  {i}/{total} goals, {time.perf_counter() - t0:.0f} s", flush=True)

    res = campaign(n, args.seed, args.drop, args.corrupt, progress)
    c = res["counts"]
    print(f"\ncampaign: {res['device_time_s']:.0f} s of device time in {time.perf_counter() - t0:.0f} s")
    print(f"{'count':58s} {'value':>8s}")
    for name in sorted(c):
        print(f"{name:58s} {c[name]:8d}")
    print(f"{'over-limit tables (independent check, rtol 1e-5)':58s} {c.get('over-limit tables', 0):8d}")
    for name, ratio in sorted(res["worst"].items()):
        print(f"  {name:56s} worst use {ratio:6.4f}  over: {res['over'].get(name, 0)}")
    if res["worst_measured"]:
        print(f"tables corrected on a measured plate (plate-side limits bounded by 1 + plant_model_allowance "
              f"= {1 + res['allowance']:g} on the nominal plant, the others by 1):")
        for name, ratio in sorted(res["worst_measured"].items()):
            print(f"  {name:56s} worst use {ratio:6.4f}")
    print(f"frames mangled by the fault injection: {res['frames_mangled']}")
    for text in res["exceptions"]:
        print("EXCEPTION", text)
    for at_s, flag, state in res["device_faults"]:
        print(f"DEVICE FAULT {flag.name} at {at_s:.3f} s of device time, in state {state.name}")
    t1 = time.perf_counter()
    flips = bitflips(n_flip, args.seed)
    print(f"\nsingle-bit flips of every frame of {n_flip} tables ({time.perf_counter() - t1:.0f} s)")
    for name in sorted(flips):
        print(f"{name:58s} {flips[name]:8d}")
    bad = (c.get("over-limit tables", 0) + c.get("accepted with current at a forbidden frequency", 0)
           + c.get("device faults (stroke, voltage, current, thermal)", 0)
           + c.get("accepted tables that differ from what was sent", 0) + c.get("exceptions", 0)
           + flips.get("accepted tables that differ from what was sent", 0))
    verdict = "PASS (0 over-limit, 0 forbidden, 0 altered, 0 exceptions, 0 device faults)"
    print("\nsafety campaign: " + (verdict if bad == 0 else f"FAIL ({bad} findings)"))
    return 0 if bad == 0 else 1
