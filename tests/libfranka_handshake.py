"""A stand-in for a Franka controller of another libfranka version: it answers a
connection as the arm's controller does when the client speaks another version of
libfranka's protocol, and nothing more.

libfranka's first message on the command port (TCP 1337) is ``Connect``: a header
(command 0, command id, size: three little-endian uint32) and the client's protocol
version and UDP port (two uint16). A controller of another version answers with the header
and ``<BH``: status 1 (``kIncompatibleLibraryVersion``) and its own version, and the client
raises libfranka's ``IncompatibleVersionException`` (server version, library version).
That layout is what franky-control 2.0's libfranka 0.21.2 and panda-python's libfranka
0.9.2 both read (each was run against this stub: 0.21.2 reported "server version: 5",
0.9.2 "10"). A client offering the stub's own version would be accepted by a real
controller, which the stub cannot go on from: it closes that connection unanswered.
"""

from __future__ import annotations

import itertools
import os
import socket
import struct
import threading
from collections.abc import Iterator
from types import TracebackType

from qpavoid.drive import franka_sim

#: libfranka's command port.
PORT = 1337
HEADER = struct.Struct("<III")  # command, command id, size (header included)
CONNECT = struct.Struct("<HH")  # the client's version, its UDP port
REFUSAL = struct.Struct("<BH")  # status, the server's version
INCOMPATIBLE = 1


def loopback_addresses(first: int) -> Iterator[str]:
    """Loopback addresses of this process's own, 127.<pid>.k from k = ``first`` (Linux
    routes all of 127/8 to the loopback), so that parallel workers, and parallel runs,
    never share one."""
    pid = os.getpid()
    return (f"127.{(pid >> 8) % 256}.{pid % 256}.{k}" for k in itertools.count(first))


def free_address(addresses: Iterator[str]) -> str:
    """The next of ``addresses`` on whose command port nothing serves yet (another run may
    use some)."""
    return next(h for h in addresses if not franka_sim._accepts(h, franka_sim.FCI_PORT))


def _exactly(conn: socket.socket, size: int) -> bytes:
    data = b""
    while len(data) < size:
        chunk = conn.recv(size - len(data))
        if not chunk:
            raise ConnectionError("the client closed the connection")
        data += chunk
    return data


class RefusingController:
    """A controller of version ``server_version`` on ``host``:1337 that refuses every client
    of another version, for the length of a ``with`` block.

    Attributes
    ----------
    offered
        The version each client offered, in order.
    """

    def __init__(self, host: str, server_version: int):
        self.host, self.server_version = host, int(server_version)
        self.offered: list[int] = []
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._server.settimeout(0.05)  # the accept loop looks at _done this often
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)

    def __enter__(self) -> RefusingController:
        self._server.bind((self.host, PORT))
        self._server.listen()
        self._thread.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._done.set()  # (closing a socket does not wake a thread blocked in accept)
        self._thread.join()
        self._server.close()

    def _serve(self) -> None:
        while not self._done.is_set():
            try:
                conn, _ = self._server.accept()
            except TimeoutError:
                continue
            conn.settimeout(5.0)
            with conn:
                try:
                    command, command_id, size = HEADER.unpack(_exactly(conn, HEADER.size))
                    version, _udp_port = CONNECT.unpack(
                        _exactly(conn, size - HEADER.size)[: CONNECT.size]
                    )
                except (ConnectionError, OSError, struct.error):
                    continue
                self.offered.append(version)
                if command == 0 and version != self.server_version:
                    conn.sendall(
                        HEADER.pack(command, command_id, HEADER.size + REFUSAL.size)
                        + REFUSAL.pack(INCOMPATIBLE, self.server_version)
                    )
