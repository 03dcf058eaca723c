"""The DBC (docs/ppod.dbc) is generated from the codec, and cantools decodes every frame as the codec does."""

import subprocess
import sys
from pathlib import Path

import pytest

from ppod_ros.can.codec import RECORDS
from ppod_ros.can.dbc import LAYOUTS, generate_dbc
from tests.can.golden_frames import GOLDEN

DBC_PATH = Path(__file__).parents[2] / "docs" / "ppod.dbc"


def test_the_committed_dbc_is_what_the_generator_writes_now():
    # Regenerate with: python -m ppod_ros.can.dbc > docs/ppod.dbc
    assert DBC_PATH.read_text() == generate_dbc(node=1)


def test_the_generator_runs_as_one_command():
    done = subprocess.run([sys.executable, "-m", "ppod_ros.can.dbc", "--node", "3"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "BO_ 51 PPOD_HEARTBEAT: 2 PPOD_HOST" in done.stdout  # 3 << 4 | 3


def test_every_frame_kind_of_the_codec_has_a_signal_layout():
    assert sorted(RECORDS) == sorted(LAYOUTS), "add the new frame's layout to ppod_ros.can.dbc.LAYOUTS"


def test_signals_fit_their_frame_and_do_not_overlap():
    for fn, layout in LAYOUTS.items():
        bits = [b for sig in layout for b in range(sig.start, sig.start + sig.length)]
        assert len(bits) == len(set(bits)), fn.name
        assert max(bits) < 8 * RECORDS[fn].LENGTH, fn.name


def _field(record, path: str):
    value = record
    for part in path.replace("]", "").replace("[", ".").split("."):
        value = value[int(part)] if part.isdigit() else getattr(value, part)
    return value


@pytest.mark.parametrize("record, frame_id, payload", GOLDEN, ids=[type(r).__name__ for r, _, _ in GOLDEN])
def test_cantools_decodes_a_frame_of_every_kind_as_the_codec_does(record, frame_id, payload):
    cantools = pytest.importorskip("cantools")
    db = cantools.database.load_string(DBC_PATH.read_text(), database_format="dbc")
    message = db.get_message_by_frame_id(frame_id)
    assert message.name == "PPOD_" + type(record).FN.name
    msg = record.encode(1)
    signals = db.decode_message(frame_id, bytes(msg.data), decode_choices=False)
    compared = 0
    for sig in LAYOUTS[type(record).FN]:
        if sig.field is None:
            continue
        expected = _field(record, sig.field)
        got = signals[sig.name]
        assert got == pytest.approx(float(expected), abs=1e-9), f"{message.name}.{sig.name}"
        compared += 1
    assert compared >= 1
    # And back: cantools encodes the codec's bytes from the decoded values.
    assert bytes(db.encode_message(frame_id, signals, scaling=True, strict=False)) == bytes(msg.data)
