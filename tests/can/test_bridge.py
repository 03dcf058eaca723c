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
