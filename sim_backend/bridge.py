"""The localhost CAN bridge: other processes reach the simulated device's virtual bus through it.

There is no SocketCAN/vcan here and python-can's ``virtual`` bus only connects buses inside one
process. The simulator process therefore serves its virtual channel with python-can-remote's
``RemoteServer`` (a WebSocket server; every client gets its own virtual bus on the channel), bound
to 127.0.0.1 only (the server's own default, 0.0.0.0, would listen on every interface). Clients open
``can.Bus(interface="remote", channel="ws://127.0.0.1:PORT/")`` (:func:`ppod_ros.can.bus.open_bus`
with ``interface: remote``).
"""

from __future__ import annotations

import errno
import logging
import select
import sys
import threading

import can_remote.server
from can_remote import RemoteServer

from ppod_ros.errors import DeviceError

log = logging.getLogger(__name__)

LOOPBACK = "127.0.0.1"

#: A client that went away while its connection was being written or closed (a node stopping
#: before the simulator): its end of the session, not an error of the server.
_PEER_GONE = (BrokenPipeError, ConnectionResetError, ConnectionAbortedError)


def _peer_gone(exc: BaseException | None) -> bool:
    return isinstance(exc, _PEER_GONE) or (isinstance(exc, OSError) and exc.errno == errno.ENOTCONN)


_library_send_to_client = can_remote.server.RemoteServerProtocol._send_to_client


def _send_to_client(self) -> None:
    """A client's session forwards the bus to it in a thread of its own; at a stack's shutdown that
    thread of a node that had just stopped raised ``BrokenPipeError`` writing a frame, and Python
    printed the uncaught traceback to the stack's log (one CI run of tests/system/test_sim_stack.py).
    A client gone ends the thread quietly, as ``_Server.handle_error`` does for the request threads."""
    try:
        _library_send_to_client(self)
    except OSError as exc:
        if not _peer_gone(exc):
            raise
        log.debug("CAN bridge: client left while frames were sent to it (%s)", exc)
        self.running = False
        self.bus.shutdown()


# The sessions are built inside can_remote's request handler, which has no hook for another class
# (and calls super() by its class's module name, so a subclass put in its place breaks __init__):
# the sending loop is wrapped on the library's class, for the simulator's process.
can_remote.server.RemoteServerProtocol._send_to_client = _send_to_client


class _Server(RemoteServer):
    """``RemoteServer`` that logs a client gone at close at debug level. socketserver prints the
    traceback of any exception in a request thread to stderr; at a stack's shutdown the handler of a
    node that had already stopped raised ``BrokenPipeError`` sending the WebSocket close and
    ``OSError(ENOTCONN)`` shutting the socket down, and that traceback reached the stack's log."""

    def handle_error(self, request, client_address) -> None:
        exc = sys.exc_info()[1]
        if _peer_gone(exc):
            log.debug("CAN bridge: client %s left before its connection was closed (%s)", client_address, exc)
            return
        super().handle_error(request, client_address)


class Bridge:
    """A python-can-remote server for one virtual channel, on 127.0.0.1.

    Parameters
    ----------
    channel : str
        The python-can virtual channel the device is on.
    port : int
        TCP port; 0 picks a free one (see :attr:`port` / :attr:`url`).
    """

    def __init__(self, channel: str, port: int = 0):
        try:
            self.server = _Server(host=LOOPBACK, port=int(port), channel=channel, interface="virtual")
        except OSError as exc:
            raise DeviceError(
                f"cannot serve the CAN bridge on {LOOPBACK}:{port}: {exc.strerror or exc}"
            ) from exc
        self.channel = channel
        self.port = int(self.server.server_address[1])
        self._thread = threading.Thread(
            target=self.server.serve_forever,
            kwargs={"poll_interval": 0.1},
            name="ppod-sim-bridge",
            daemon=True,
        )
        self._thread.start()
        log.info("CAN bridge for virtual channel %r on %s", channel, self.url)

    @property
    def url(self) -> str:
        return f"ws://{LOOPBACK}:{self.port}/"

    @property
    def clients(self) -> int:
        return len(self.server.clients)

    def pending(self) -> bool:
        """Whether a client's frames wait in its socket, not yet read onto the virtual bus (the
        reading thread needs the GIL: on a busy machine it can wait its turn for 100 ms)."""
        socks = []
        for client in list(self.server.clients):
            ws = getattr(client, "_ws", None)
            sock = getattr(ws, "socket", None)
            if sock is not None and not getattr(ws, "closed", False):
                socks.append(sock)
        if not socks:
            return False
        try:
            return bool(select.select(socks, [], [], 0)[0])
        except (OSError, ValueError):  # a socket closed meanwhile
            return False

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        self._thread.join(timeout=2.0)


__all__ = ["Bridge", "LOOPBACK"]
