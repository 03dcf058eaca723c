"""The localhost CAN bridge (ppod_sim.bridge): a client gone at close is no error."""

from __future__ import annotations

import errno

import pytest

from ppod_sim.bridge import LOOPBACK, Bridge


@pytest.fixture
def bridge():
    b = Bridge("ppod-test-bridge", port=0)
    yield b
    b.close()


@pytest.mark.parametrize("exc", [BrokenPipeError(errno.EPIPE, "Broken pipe"),
                                 OSError(errno.ENOTCONN, "Transport endpoint is not connected"),
                                 ConnectionResetError(errno.ECONNRESET, "Connection reset by peer")])
def test_a_client_gone_before_its_connection_closed_prints_no_traceback(bridge, capsys, exc):
    # Regression (tests/system/test_sim_stack.py, one CI run): at the stack's shutdown the handler
    # of a node that had already stopped raised BrokenPipeError sending the WebSocket close, then
    # OSError(ENOTCONN) shutting the socket down; socketserver printed the traceback to the log.
    try:
        raise exc
    except OSError:
        bridge.server.handle_error(None, (LOOPBACK, 40896))
    assert capsys.readouterr().err == ""


def test_any_other_error_in_a_client_thread_is_still_reported(bridge, capsys):
    try:
        raise ValueError("a bug in a handler")
    except ValueError:
        bridge.server.handle_error(None, (LOOPBACK, 40896))
    err = capsys.readouterr().err
    assert "Traceback" in err and "a bug in a handler" in err


class _GoneClient:
    """A session whose client has gone: writing a frame raises ``exc``."""

    def __init__(self, exc):
        self.exc = exc

    def __call__(self, msg):
        raise self.exc


@pytest.mark.parametrize("exc, quiet", [(BrokenPipeError(errno.EPIPE, "Broken pipe"), True),
                                        (OSError(errno.ENOTCONN, "Transport endpoint is not connected"), True),
                                        (ConnectionResetError(errno.ECONNRESET, "Connection reset"), True),
                                        (OSError(errno.EIO, "Input/output error"), False)])
def test_a_session_whose_client_left_while_frames_were_sent_ends_quietly(exc, quiet):
    # Regression (tests/system/test_sim_stack.py, one CI run): at the stack's shutdown the sending
    # thread of a node that had just stopped raised BrokenPipeError writing a frame, and its uncaught
    # traceback reached the stack's log. The bridge wraps the library's sending loop.
    import can
    import can_remote.server

    from ppod_sim import bridge as bridge_module

    assert can_remote.server.RemoteServerProtocol._send_to_client is bridge_module._send_to_client
    session = object.__new__(can_remote.server.RemoteServerProtocol)   # its __init__ needs a client's handshake
    session.running = True
    session.bus = can.Bus(interface="virtual", channel="ppod-test-session")
    device = can.Bus(interface="virtual", channel="ppod-test-session")
    try:
        device.send(can.Message(arbitration_id=0x10, data=[1, 2]))
        session.send_msg = _GoneClient(exc)
        if quiet:
            session._send_to_client()
            assert not session.running and session.bus._is_shutdown
        else:
            with pytest.raises(OSError, match="Input/output error"):
                session._send_to_client()
    finally:
        session.bus.shutdown()
        device.shutdown()
