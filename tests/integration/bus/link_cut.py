"""A TCP relay between two Zenoh sessions on loopback that a test can cut: the link dropping
under a live pair (a lease expiring on a loaded machine, a router or a NAT losing the flow, an
adversary on the wire resetting it), with both sessions open. Real sockets, no Zenoh inside."""
from __future__ import annotations

import socket
import threading

from sim.net import free_port


class LinkCut:
    """Accepts on ``127.0.0.1:port`` and relays each connection to ``127.0.0.1:target``;
    :meth:`cut` closes every relayed connection at once (the sessions reconnect through it);
    :meth:`down` cuts and refuses new connections until :meth:`up`; :attr:`accepted` counts the
    connections relayed. A context manager: leaving it closes everything and
    joins its threads."""

    def __init__(self, target: int) -> None:
        self.target = target
        self.port = free_port()
        self.accepted = 0
        self._refusing = False
        self._lock = threading.Lock()
        self._sockets: list[socket.socket] = []
        self._threads: list[threading.Thread] = []
        self._server = socket.create_server(("127.0.0.1", self.port))
        self._spawn(self._accept)

    @property
    def endpoint(self) -> str:
        return f"tcp/127.0.0.1:{self.port}"

    def _spawn(self, target: object, *args: object) -> None:
        t = threading.Thread(target=target, args=args, daemon=True, name="link-cut")  # type: ignore[arg-type]
        with self._lock:
            self._threads.append(t)
        t.start()

    def _accept(self) -> None:
        while True:
            try:
                near, _ = self._server.accept()
            except OSError:
                return
            with self._lock:
                refusing = self._refusing
            if refusing:
                near.close()
                continue
            try:
                far = socket.create_connection(("127.0.0.1", self.target))
            except OSError:
                near.close()
                continue
            with self._lock:
                self._sockets += [near, far]
                self.accepted += 1
            self._spawn(self._pump, near, far)
            self._spawn(self._pump, far, near)

    @staticmethod
    def _pump(src: socket.socket, dst: socket.socket) -> None:
        try:
            while data := src.recv(65536):
                dst.sendall(data)
        except OSError:
            pass
        for s in (src, dst):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def cut(self) -> None:
        """Close every relayed connection now (new ones are relayed again)."""
        with self._lock:
            sockets, self._sockets = self._sockets, []
        for s in sockets:
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()

    def down(self) -> None:
        """Cut, and refuse connections until :meth:`up`."""
        with self._lock:
            self._refusing = True
        self.cut()

    def up(self) -> None:
        """Relay connections again."""
        with self._lock:
            self._refusing = False

    def close(self) -> None:
        try:
            self._server.shutdown(socket.SHUT_RDWR)  # wakes the accepting thread
        except OSError:
            pass
        self._server.close()
        self.cut()
        with self._lock:
            threads = list(self._threads)
        for t in threads:
            t.join(timeout=5.0)

    def __enter__(self) -> "LinkCut":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
