"""The live view's port (:mod:`.foxglove_server`): both Foxglove WebSocket subprotocols, ``foxglove.sdk.v1`` and
the classic ``foxglove.websocket.v1``, in front of the foxglove SDK's server.

The SDK (0.30.3, ``websocket/handshake.rs``) answers a handshake that does not offer ``foxglove.sdk.v1`` with HTTP
400, and has no setting for it; but after the handshake the two subprotocols are the same protocol (the SDK's is
the classic one renamed: the same JSON and binary frames).  So the node listens on ``host:port`` itself and
:class:`Relay` passes every connection on to the SDK's server, listening on 127.0.0.1 on a port of its own: a
request that offers the classic subprotocol and not the SDK's is handed on offering the SDK's, and the answer's
``Sec-WebSocket-Protocol`` names the classic one again; every other byte passes as it is, both ways.  One thread
moves the bytes (``selectors``); a side that cannot take more stops the reading from the other (the SDK's
per-client backlog then drops a slow client's oldest messages, as it does without the relay).

Each client is three descriptors: the client's, the relay's to the SDK and the SDK's own end, which the connection
watch (:mod:`.foxglove_connections`) judges as before (max_clients, idle_timeout_s): when it shuts the SDK's end it
tells the relay (:meth:`Relay.drop`), which closes the client's at once (the relay no longer reads the SDK's side of a
client that reads nothing, so it would never see that end).  A client that reads nothing for ``stall_s`` while data
waits for it (it subscribed and never reads) is closed too, counted as ``stalled_connections``: it held a slot of
``max_clients`` and the SDK's queue for it.  When the client ends, the relay ends its side to the SDK and closes both
once the SDK has closed.
"""
from __future__ import annotations

import errno
import selectors
import socket
import struct
import threading
import time
from typing import Callable, Dict, Optional, Tuple

__all__ = ["Relay", "SDK_SUBPROTOCOL", "CLASSIC_SUBPROTOCOL", "offer_for_sdk", "answer_for_client",
           "DESCRIPTORS_PER_CLIENT"]

SDK_SUBPROTOCOL = "foxglove.sdk.v1"
CLASSIC_SUBPROTOCOL = "foxglove.websocket.v1"
DESCRIPTORS_PER_CLIENT = 3    # the client's, the relay's to the SDK, the SDK's end of it
HEADER_MAX = 16384            # a handshake longer than this is passed on as it is (the SDK refuses it)
FLUSH_S = 1.0                 # a client whose connection the SDK ended has this long to take what was sent to it
CHUNK = 1 << 16
_PROTOCOL = b"sec-websocket-protocol"
_END = b"\r\n\r\n"


def _offered(head: bytes) -> list:
    """The subprotocols a handshake request offers (every ``Sec-WebSocket-Protocol`` header, comma-separated)."""
    out = []
    for line in head.split(b"\r\n")[1:]:
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == _PROTOCOL:
            out += [v.strip().decode("latin-1") for v in value.split(b",") if v.strip()]
    return out


def offer_for_sdk(head: bytes) -> Tuple[bytes, bool]:
    """The handshake request ``head`` (up to its blank line) as the SDK takes it: one that offers the classic
    subprotocol and not the SDK's offers the SDK's instead (True); any other as it is (False)."""
    offered = _offered(head)
    if SDK_SUBPROTOCOL in offered or CLASSIC_SUBPROTOCOL not in offered:
        return head, False
    lines = [line for line in head[:-len(_END)].split(b"\r\n")
             if line.partition(b":")[0].strip().lower() != _PROTOCOL]
    return b"\r\n".join(lines + [b"Sec-WebSocket-Protocol: " + SDK_SUBPROTOCOL.encode()]) + _END, True


def answer_for_client(head: bytes) -> bytes:
    """The SDK's answer ``head`` (up to its blank line) to a classic client: its subprotocol named the classic way."""
    lines = head[:-len(_END)].split(b"\r\n")
    for i, line in enumerate(lines):
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == _PROTOCOL and value.strip() == SDK_SUBPROTOCOL.encode():
            lines[i] = name + b": " + CLASSIC_SUBPROTOCOL.encode()
    return b"\r\n".join(lines) + _END


def _reset(sock: socket.socket) -> None:
    """Make ``sock``'s close a reset (SO_LINGER 0): the kernel drops what it holds for the peer."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    except OSError:
        pass


def _unsent(sock: socket.socket) -> int:
    """Bytes the kernel still holds to send on ``sock`` (SIOCOUTQ); 0 when it cannot say."""
    import fcntl
    import termios
    try:
        return struct.unpack("i", fcntl.ioctl(sock.fileno(), termios.TIOCOUTQ, b"\0\0\0\0"))[0]
    except OSError:
        return 0


class _Side:
    """One socket of a pair: what waits to be sent to it (since when no byte of it went: ``waiting_since``), and
    whether it has ended its sending."""

    __slots__ = ("sock", "pending", "ended", "head", "waiting_since")

    def __init__(self, sock: socket.socket):
        self.sock, self.pending, self.ended = sock, bytearray(), False
        self.waiting_since: Optional[float] = None
        self.head: Optional[bytearray] = None   # the handshake being read from this side, before it is passed on


class _Pair:
    __slots__ = ("client", "sdk", "classic", "own")

    def __init__(self, client: socket.socket, sdk: socket.socket):
        self.client, self.sdk, self.classic, self.own = _Side(client), _Side(sdk), False, ""
        self.client.head = bytearray()   # the client's request is read whole before it goes on


class Relay:
    """Listens on ``(host, port)`` and passes each connection to ``target()``, the SDK server's address now (it
    changes when the connection watch starts the server again).  ``counts()``: the clients that offered only the
    classic subprotocol."""

    def __init__(self, host: str, port: int, target: Callable[[], Tuple[str, int]], log, stall_s: float = 60.0):
        family, kind, proto, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                                           flags=socket.AI_PASSIVE)[0]
        self.listener = socket.socket(family, kind, proto)
        try:
            self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.listener.bind(addr)
            self.listener.listen(1024)
        except OSError:
            self.listener.close()
            raise
        self.listener.setblocking(False)
        self.port = self.listener.getsockname()[1]
        self.target, self.log = target, log
        self.selector = selectors.DefaultSelector()
        self.selector.register(self.listener, selectors.EVENT_READ, None)
        self.sides: Dict[int, Tuple[_Pair, _Side, _Side]] = {}   # fd -> (pair, this side, the other side)
        self.lock = threading.Lock()
        self.classic = 0                                           # handshakes offering only the classic one
        self.stalled = 0                                           # clients closed for reading nothing (stall_s)
        self.stall_s = stall_s
        self.origin: Dict[str, str] = {}   # "ip:port" of the relay's end to the SDK -> the client's "ip:port"
        self.pairs: Dict[str, _Pair] = {}  # the same key -> its pair
        self._drops: set = set()           # keys of pairs the connection watch shut (Relay.drop), for the thread
        self.closing: list = []            # (client socket, when to close it): its end sent, its bytes in flight
        self._looked = 0.0
        self.stop_event = threading.Event()
        self.paused_until = 0.0                                    # out of descriptors: accept again later
        self.thread = threading.Thread(target=self._run, name="foxglove-relay", daemon=True)

    def start(self) -> None:
        self.thread.start()

    def close(self) -> None:
        """Stop: the listening socket and every connection closed (the SDK sees its connections end)."""
        self.stop_event.set()
        if self.thread.is_alive():
            self.thread.join(5.0)
        for pair, _, _ in list(self.sides.values()):
            self._close(pair)
        self._closing(time.monotonic(), final=True)
        self.selector.close()
        self.listener.close()

    def counts(self) -> Dict[str, int]:
        with self.lock:
            return {"classic_subprotocol_clients": self.classic, "stalled_connections": self.stalled}

    def drop(self, own: str) -> None:
        """Close the client whose pair's end to the SDK is ``own`` ("ip:port"): the connection watch shut the SDK's
        end of it (any thread; the relay's thread closes it within a turn of its loop)."""
        with self.lock:
            self._drops.add(own)

    def _housekeeping(self, now: float) -> None:
        """The pairs the watch shut, and the clients that read nothing for ``stall_s`` while data waits for them."""
        with self.lock:
            drops, self._drops = self._drops, set()
        for own in drops:
            pair = self.pairs.get(own)
            if pair is not None:
                self._close(pair, abort=True)
        if now - self._looked < 0.1:
            return
        self._looked = now
        self._closing(now)
        for pair in list(self.pairs.values()):
            c = pair.client
            if c.pending and c.waiting_since is not None and now - c.waiting_since > self.stall_s:
                with self.lock:
                    self.stalled += 1
                self.log.warning(f"closed a client that read nothing for {self.stall_s:g} s while data waited for it "
                                 f"({self.origin.get(pair.own, '?')}); {self.stalled} since the start",
                                 throttle_duration_sec=1.0)
                self._close(pair, abort=True)

    # --- the thread ----------------------------------------------------------------------------------

    def _run(self) -> None:
        while not self.stop_event.is_set():
            if self.paused_until and time.monotonic() >= self.paused_until:
                self.paused_until = 0.0
                self._events(self.listener, selectors.EVENT_READ)
            self._housekeeping(time.monotonic())
            try:
                events = self.selector.select(0.1)
            except OSError:   # pragma: no cover - a socket closed under the selector
                continue
            for key, mask in events:
                try:
                    if key.fileobj is self.listener:
                        self._accept(time.monotonic())
                    elif key.fd in self.sides:
                        self._serve(key.fd, mask)
                except Exception as exc:  # noqa: BLE001 - the relay must outlive whatever one connection does
                    entry = self.sides.get(key.fd)
                    if entry is not None:
                        self._close(entry[0])
                    self.log.warning(f"relay: {type(exc).__name__}: {exc}", throttle_duration_sec=1.0)

    def _accept(self, now: float) -> None:
        for _ in range(64):
            try:
                client, addr = self.listener.accept()
            except BlockingIOError:
                return
            except OSError as exc:
                if exc.errno in (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM):
                    self.paused_until = now + 0.05   # the watch frees descriptors; the kernel keeps the queue
                    self._events(self.listener, 0)
                    return
                continue
            try:
                sdk = socket.create_connection(self.target(), timeout=2.0)
            except OSError:
                client.close()   # the SDK cannot take it now (out of descriptors): the client sees it closed
                continue
            for s in (client, sdk):
                s.setblocking(False)
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            pair = _Pair(client, sdk)
            pair.own = "%s:%d" % sdk.getsockname()[:2]
            self.origin[pair.own] = "%s:%d" % addr[:2]
            self.pairs[pair.own] = pair
            self.sides[client.fileno()] = (pair, pair.client, pair.sdk)
            self.sides[sdk.fileno()] = (pair, pair.sdk, pair.client)
            self.selector.register(client, selectors.EVENT_READ, None)
            self.selector.register(sdk, selectors.EVENT_READ, None)

    def _serve(self, fd: int, mask: int) -> None:
        pair, side, other = self.sides[fd]
        if mask & selectors.EVENT_WRITE and side.pending:
            self._send(side)
        if mask & selectors.EVENT_READ and not other.pending and not side.ended:
            try:
                data = side.sock.recv(CHUNK)
            except (BlockingIOError, InterruptedError):
                data = None
            except OSError:
                self._close(pair)
                return
            if data == b"":
                side.ended = True
                if side is pair.sdk:   # the SDK ended it (or the watch shut it): what is read goes, then the end
                    self._flush_and_close(pair)
                    return
                if side.head is not None and side.head:
                    other.pending += side.head
                    side.head = None
                if not other.pending:
                    self._end_sending(other)
            elif data is not None:
                self._take(pair, side, other, data)
        if pair.client.sock.fileno() != -1:
            self._watch(pair)

    def _take(self, pair: _Pair, side: _Side, other: _Side, data: bytes) -> None:
        if side.head is None:
            other.pending += data
        else:
            side.head += data
            end = side.head.find(_END)
            if end < 0 and len(side.head) <= HEADER_MAX:
                return
            head, rest = (bytes(side.head[:end + len(_END)]), side.head[end + len(_END):]) if end >= 0 else \
                (bytes(side.head), b"")
            side.head = None
            if side is pair.client:
                head, pair.classic = offer_for_sdk(head) if end >= 0 else (head, False)
                if pair.classic:
                    with self.lock:
                        self.classic += 1
                    pair.sdk.head = bytearray()   # the SDK's answer is read whole too, to rename its subprotocol
            else:
                head = answer_for_client(head) if end >= 0 else head
            other.pending += head + rest
        if other.pending:
            if other.waiting_since is None:
                other.waiting_since = time.monotonic()
            self._send(other)

    def _send(self, side: _Side) -> None:
        try:
            n = side.sock.send(side.pending)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            entry = self.sides.get(side.sock.fileno())
            if entry is not None:
                self._close(entry[0])
            return
        del side.pending[:n]
        side.waiting_since = (time.monotonic() if side.pending else None) if n else side.waiting_since
        entry = self.sides.get(side.sock.fileno())
        if not side.pending and entry is not None and entry[2].ended:
            self._end_sending(side)

    def _end_sending(self, side: _Side) -> None:
        try:
            side.sock.shutdown(socket.SHUT_WR)
        except OSError:
            pass

    def _flush_and_close(self, pair: _Pair) -> None:
        """The SDK ended the connection: what was read of it goes to the client, then its end (FIN).  A client that
        reads nothing would never get that FIN (it waits behind the closed window), so its socket is kept for
        :data:`FLUSH_S` at most: closed then, reset if the kernel still holds bytes for it."""
        client = pair.client
        if client.pending:
            try:
                del client.pending[:client.sock.send(client.pending)]
            except OSError:
                pass
        if client.pending or client.sock.fileno() == -1:
            self._close(pair, abort=True)   # it could not even take what was read: it goes with a reset
            return
        try:
            client.sock.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        self._close(pair, keep_client=True)
        self.closing.append((client.sock, time.monotonic() + FLUSH_S))

    def _watch(self, pair: _Pair) -> None:
        """Read a side only while nothing waits to go to the other; write a side while something waits for it."""
        for side, other in ((pair.client, pair.sdk), (pair.sdk, pair.client)):
            self._events(side.sock, (0 if other.pending or side.ended else selectors.EVENT_READ)
                         | (selectors.EVENT_WRITE if side.pending else 0))

    def _events(self, sock: socket.socket, events: int) -> None:
        """Select ``sock`` for ``events`` (0: not at all)."""
        try:
            key = self.selector.get_key(sock)
        except (KeyError, ValueError):
            key = None
        if not events:
            if key is not None:
                self.selector.unregister(sock)
        elif key is None:
            self.selector.register(sock, events, None)
        elif key.events != events:
            self.selector.modify(sock, events, None)

    def _close(self, pair: _Pair, abort: bool = False, keep_client: bool = False) -> None:
        """Close both sockets of ``pair``; ``abort``: the client is reset at once (SO_LINGER 0: what waits for a client
        that reads nothing is dropped, not kept by the kernel behind its closed window); ``keep_client``: its socket
        is only forgotten (:meth:`_flush_and_close` closes it later)."""
        self.origin.pop(pair.own, None)
        self.pairs.pop(pair.own, None)
        for side in (pair.client, pair.sdk):
            fd = side.sock.fileno()
            if fd == -1:
                continue
            self.sides.pop(fd, None)
            try:
                self.selector.unregister(side.sock)
            except (KeyError, ValueError):
                pass
            if side is pair.client and keep_client:
                continue
            if abort and side is pair.client:
                _reset(side.sock)
            side.sock.close()

    def _closing(self, now: float, final: bool = False) -> None:
        """Close the clients whose end was sent (:meth:`_flush_and_close`) once :data:`FLUSH_S` passed: reset those
        for which the kernel still holds bytes (they read nothing)."""
        keep = []
        for sock, deadline in self.closing:
            if now < deadline and not final:
                keep.append((sock, deadline))
                continue
            if _unsent(sock):
                _reset(sock)
            sock.close()
        self.closing = keep
