"""The live view's connections (:mod:`.foxglove_server`): what the node does around the foxglove SDK's server.

The SDK has no limit on its connections, no timeout, no call that
closes one, and its accept loop ends at the first failed ``accept()`` (``server.rs``,
``accept_connections``: at the descriptor limit, EMFILE), after which the port refuses every client
for good.  So the node raises its soft descriptor limit to the hard one (at most 2^20) at start and
refuses a ``max_clients`` that would not leave room for its own descriptors (exit 2), and a thread
looks at the process's own sockets five times a second (``/proc/self/fd``, ``getsockname``, the
kernel's ``TCP_INFO``): a connection over the cap or idle is shut down (``shutdown(2)`` on the
SDK's socket: the SDK sees the connection end and drops it, and the relay in front of it,
:mod:`.foxglove_relay`, closes the client's); and when the SDK's listening socket is gone (a burst of
connections faster than that thread), the server is started again on a port of its own (the relay
passes new clients to it; the old one serves its remaining clients until they leave).  The SDK's
ends are judged (on the SDK's port); the log names the client's own address (the relay's
``origin``).  Each refusal, closure and
restart is logged as a warning (at most one line per reason and second, with the counts) and
counted in ``/diagnostics``.  Which connection belongs to a subscribed client is read from the
SDK's own debug record ("Client ADDR subscribed to channel ...", logged just before the
``on_subscribe`` callback on the same thread); the SDK's warnings and errors go to the node's log
(rate-limited) instead of stderr.

:class:`ConnectionWatch` is that thread, :class:`SdkLog` the SDK's log records, :class:`Subscriptions` the SDK's
server listener (which client subscribed which channel, from which address), :func:`check_room` the descriptor
limit at start.
"""
from __future__ import annotations

import errno
import ipaddress
import logging
import os
import re
import resource
import socket
import struct
import threading
import time
from typing import Dict, List, Optional, Set, Tuple

from foxglove.websocket import ServerListener

from mwip_ros.params import ParamError

__all__ = ["ConnectionWatch", "SdkLog", "Subscriptions", "check_room", "raise_descriptor_limit", "WATCH_PERIOD_S",
           "OWN_DESCRIPTORS", "MAX_NOFILE", "LOG_PERIOD_S"]

WATCH_PERIOD_S = 0.2          # the connection watch's period (at most; a quarter of idle_timeout_s if shorter)
OWN_DESCRIPTORS = 32          # descriptors kept free for the node itself (DDS, files) beside max_clients
MAX_NOFILE = 1 << 20          # the soft descriptor limit is raised to the hard one, at most this
LOG_PERIOD_S = 1.0            # at most one warning per reason and second (with the counts since the last)


def _peer_key(host: str, port: int) -> str:
    """``ip:port`` of a peer, the same text for the SDK's ``SocketAddr`` and for ``getpeername()``
    (an IPv4-mapped IPv6 address as the IPv4 one)."""
    try:
        ip = ipaddress.ip_address(host.strip("[]").split("%", 1)[0])
        if ip.version == 6 and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        return f"{ip}:{port}"
    except ValueError:
        return f"{host}:{port}"


def _sdk_addr_key(text: str) -> str:
    host, _, port = text.rpartition(":")
    return _peer_key(host, int(port)) if port.isdigit() else text


class SdkLog(logging.Handler):
    """The SDK's log records (its Rust ``tracing`` events, as Python ``logging`` records through pyo3-log).

    Keeps, per SDK thread, the client address of the last "Client ADDR subscribed to channel ID" record (the
    SDK logs it just before it calls ``on_subscribe`` on the same thread), and collects the SDK's warnings and
    errors for the node's log (they went to stderr, unformatted, one line each: a flood when clients misbehave)."""

    SUBSCRIBED = re.compile(r"^Client (\S+) subscribed to channel (\d+)\b")
    LOGGERS = {"foxglove": logging.WARNING, "foxglove.websocket.connected_client": logging.DEBUG,
               # its submodules' debug records are per message (a slow client's drops) or nothing we need
               "foxglove.websocket.connected_client.poller": logging.WARNING,
               "foxglove.websocket.connected_client.send_lossy": logging.WARNING}

    def __init__(self):
        super().__init__(logging.DEBUG)
        # SDK thread (its pthread: the SDK's threads are not Python's, a threading.local is not kept between
        # two of their calls into Python) -> (address, channel id) of its last subscription record
        self.subscribing: Dict[int, Tuple[str, int]] = {}
        self.problems_lock = threading.Lock()
        self.problems: List[str] = []     # the first few since the node last logged them
        self.problem_count = 0            # since the node last logged them
        self.problems_total = 0

    def install(self) -> None:
        for name, level in self.LOGGERS.items():
            logging.getLogger(name).setLevel(level)   # before the first record: pyo3-log caches the levels
        root = logging.getLogger("foxglove")
        root.addHandler(self)
        root.propagate = False

    def uninstall(self) -> None:
        logging.getLogger("foxglove").removeHandler(self)

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage()
        except Exception:   # noqa: BLE001 - a record that cannot be formatted is not worth a thread's life
            return
        if record.levelno >= logging.WARNING:
            with self.problems_lock:
                self.problem_count += 1
                self.problems_total += 1
                if len(self.problems) < 3:
                    self.problems.append(text)
            return
        m = self.SUBSCRIBED.match(text)
        if m:
            self.subscribing[threading.get_ident()] = (_sdk_addr_key(m.group(1)), int(m.group(2)))

    def take_problems(self) -> Tuple[int, List[str]]:
        with self.problems_lock:
            n, texts = self.problem_count, self.problems
            self.problem_count, self.problems = 0, []
        return n, texts

    def take_subscribing(self) -> Optional[Tuple[str, int]]:
        return self.subscribing.pop(threading.get_ident(), None)   # (dict operations: atomic under the GIL)


class Subscriptions(ServerListener):
    """Which client subscribed which channel, and from which address; called from the SDK's threads."""

    def __init__(self, log, sdk_log: SdkLog):
        self.log = log
        self.sdk_log = sdk_log
        self.lock = threading.Lock()
        self.pairs: Set[Tuple[int, int]] = set()
        self.clients: Set[int] = set()
        self.address: Dict[int, str] = {}   # subscribed client id -> its peer address (_peer_key)
        self.new_topics: List[str] = []      # the topics subscribed since take_subscribed (latched resends)

    def on_subscribe(self, client, channel) -> None:
        pending = self.sdk_log.take_subscribing()
        with self.lock:
            self.pairs.add((client.id, channel.id))
            if len(self.new_topics) < 1000:
                self.new_topics.append(channel.topic)
            new = client.id not in self.clients
            self.clients.add(client.id)
            if pending is not None and pending[1] == channel.id:
                self.address[client.id] = pending[0]
        if new:
            self.log.info(f"client {client.id} subscribed its first channel ({channel.topic})")

    def on_unsubscribe(self, client, channel) -> None:
        with self.lock:
            self.pairs.discard((client.id, channel.id))
            if not any(c == client.id for c, _ in self.pairs):
                self.clients.discard(client.id)
                self.address.pop(client.id, None)

    def counts(self) -> Tuple[int, int]:
        with self.lock:
            return len(self.clients), len(self.pairs)

    def take_subscribed(self) -> List[str]:
        """The topics subscribed since the last call (each once)."""
        with self.lock:
            out, self.new_topics = list(dict.fromkeys(self.new_topics)), []
        return out

    def subscribed_peers(self) -> Tuple[Set[str], int]:
        """The addresses of the subscribed clients, and how many subscribed clients have no known address."""
        with self.lock:
            return set(self.address.values()), len(self.clients - set(self.address))


class _Conn:
    __slots__ = ("inode", "fd", "family", "peer", "first_seen", "state", "quiet_recv_s", "quiet_sent_s", "closed")

    def __init__(self, inode: int, fd: int, family: int, peer: str, now: float):
        self.inode, self.fd, self.family, self.peer, self.first_seen = inode, fd, family, peer, now
        self.state, self.quiet_recv_s, self.quiet_sent_s, self.closed = 0, 0.0, 0.0, False


_OTHER, _LISTEN = "other", "listen"
TCP_ESTABLISHED = 1
_TCP_INFO_LEN = 104          # struct tcp_info up to tcpi_rcv_space and beyond: every kernel since 2.6 fills 104
_TCP_INFO_TIMES = 44         # offset of tcpi_last_data_sent, tcpi_last_ack_sent, tcpi_last_data_recv (u32 ms)


class ConnectionWatch:
    """Bounds the SDK's connections and keeps its listening socket (see the module's Notes)."""

    def __init__(self, node, max_clients: int, idle_timeout_s: float):
        self.node = node
        self.log = node.get_logger()
        self.max_clients = max_clients
        self.idle_timeout_s = idle_timeout_s
        self.period = min(WATCH_PERIOD_S, idle_timeout_s / 4.0)
        self.kinds: Dict[int, object] = {}        # socket inode -> _OTHER, _LISTEN or its _Conn
        self.conns: Dict[int, _Conn] = {}
        self.lock = threading.Lock()              # the counters below, read by the diagnostics
        self.refused = 0                          # over max_clients
        self.closed_idle = 0
        self.restarts = 0                         # the listening socket was gone: the server started again
        self.open_connections = 0
        self.descriptors = 0
        self.limit = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
        self.unmapped_warned = False
        self.last_look = time.monotonic()          # of the last complete look at the connections
        self.retired: List[Tuple[object, Set[int]]] = []   # old servers and the connections they still serve
        self._pending: Dict[str, List] = {}       # reason -> [count since the last line, examples, last line time]
        self._spare: Optional[int] = None         # a descriptor to give back when the process is out of them
        self._take_spare()
        self.stop_event = threading.Event()
        self.thread = threading.Thread(target=self._run, name="foxglove-connection-watch", daemon=True)

    # --- thread ------------------------------------------------------------------------------------

    def start(self) -> None:
        self.thread.start()

    def stop(self) -> None:
        self.stop_event.set()
        if self.thread.is_alive():
            self.thread.join(5.0)
        self._flush_logs(final=True)
        if self._spare is not None:
            os.close(self._spare)
            self._spare = None

    def _run(self) -> None:
        failures = 0
        while not self.stop_event.wait(self.period):
            try:
                self.scan(time.monotonic())
                failures = 0
            except Exception as exc:  # noqa: BLE001 - the watch must outlive whatever it meets
                failures += 1
                if failures in (1, 10) or failures % 100 == 0:
                    self.log.error(f"connection watch: {type(exc).__name__}: {exc} ({failures} in a row); "
                                   "trying again")

    def _take_spare(self) -> None:
        if self._spare is None:
            try:
                self._spare = os.open(os.devnull, os.O_RDONLY | os.O_CLOEXEC)
            except OSError:
                pass

    def _fd_names(self) -> List[str]:
        try:
            return os.listdir("/proc/self/fd")
        except OSError as exc:
            if exc.errno not in (errno.EMFILE, errno.ENFILE) or self._spare is None:
                raise
            os.close(self._spare)   # out of descriptors: the spare one lets the watch look, and act
            self._spare = None
            return os.listdir("/proc/self/fd")

    # --- one look ----------------------------------------------------------------------------------

    def scan(self, now: float) -> None:
        names = self._fd_names()
        seen: Dict[int, int] = {}
        for name in names:
            try:
                link = os.readlink(f"/proc/self/fd/{name}")
            except OSError:
                continue
            if link.startswith("socket:["):
                seen[int(link[8:-1])] = int(name)
        listening = False
        for inode, fd in seen.items():
            kind = self.kinds.get(inode)
            if kind is None:
                kind = self._classify(inode, fd, now)
                if kind is None:   # closed meanwhile, its number reused: look again next time
                    continue
                self.kinds[inode] = kind
                if isinstance(kind, _Conn):
                    self.conns[inode] = kind
            if kind is _LISTEN:
                listening = True
            elif isinstance(kind, _Conn):
                kind.fd = fd
                self._measure(kind)
        for inode in [i for i in self.kinds if i not in seen]:
            del self.kinds[inode]
            self.conns.pop(inode, None)
        self._enforce(now)
        with self.lock:
            self.descriptors = len(names)
            self.open_connections = sum(1 for c in self.conns.values() if c.state == TCP_ESTABLISHED and not c.closed)
        if not listening and not self.stop_event.is_set():
            self._listen_again(now, len(names))
        self._retire(set(self.conns))
        self._take_spare()
        self._flush_logs()
        self.last_look = time.monotonic()

    def _classify(self, inode: int, fd: int, now: float):
        """_OTHER, _LISTEN (the server's listening socket) or a _Conn (one of its connections); None: not now."""
        try:
            s = socket.socket(fileno=fd)
        except OSError:
            return None
        try:
            if os.fstat(fd).st_ino != inode:
                return None
            if s.type != socket.SOCK_STREAM or s.family not in (socket.AF_INET, socket.AF_INET6):
                return _OTHER
            if s.getsockname()[1] != self.node.server.port:   # the SDK's own port (behind the relay)
                return _OTHER
            if s.getsockopt(socket.SOL_SOCKET, socket.SO_ACCEPTCONN):
                return _LISTEN
            try:
                host, port = s.getpeername()[:2]
                peer = _peer_key(host, port)
            except OSError:   # reset meanwhile: it goes away
                peer = "?"
            return _Conn(inode, fd, s.family, peer, now)
        except OSError:
            return None
        finally:
            s.detach()   # the descriptor is the SDK's: never closed here

    def _measure(self, c: _Conn) -> None:
        try:
            s = socket.socket(c.family, socket.SOCK_STREAM, 0, fileno=c.fd)
        except OSError:
            c.state = 0
            return
        try:
            if os.fstat(c.fd).st_ino != c.inode:
                c.state = 0
                return
            info = s.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, _TCP_INFO_LEN)
            last_sent, _, last_recv = struct.unpack_from("=3I", info, _TCP_INFO_TIMES)
            c.state, c.quiet_sent_s, c.quiet_recv_s = info[0], last_sent / 1000.0, last_recv / 1000.0
        except OSError:
            c.state = 0
        finally:
            s.detach()

    def _enforce(self, now: float) -> None:
        peers, unmapped = self.node.listener.subscribed_peers()
        if unmapped and not self.unmapped_warned:
            self.unmapped_warned = True
            self.log.warning("the SDK did not tell the address of a subscribed client (its debug record "
                             "'Client ADDR subscribed to channel ID' changed?): a connection that was sent data in "
                             f"the last {self.idle_timeout_s:g} s is not idle either")
        live = [c for c in self.conns.values() if c.state == TCP_ESTABLISHED and not c.closed]
        # subscribed clients first, then the oldest: the newest beyond the cap are refused
        live.sort(key=lambda c: (c.peer not in peers, c.first_seen, c.inode))
        for c in live[self.max_clients:]:
            if self._shut(c):
                with self.lock:
                    self.refused += 1
                self._note("refused", self.node.relay.origin.get(c.peer, c.peer))
        for c in live[:self.max_clients]:
            if c.peer in peers:
                continue
            # a subscribed client whose address the SDK did not tell: what it was sent counts as use too
            quiet = min(c.quiet_recv_s, c.quiet_sent_s) if unmapped else c.quiet_recv_s
            if quiet >= self.idle_timeout_s and self._shut(c):
                with self.lock:
                    self.closed_idle += 1
                self._note("idle", self.node.relay.origin.get(c.peer, c.peer))

    def _shut(self, c: _Conn) -> bool:
        """End connection ``c`` under the SDK: ``shutdown(2)`` its socket (the SDK reads the end, closes it)."""
        try:
            s = socket.socket(c.family, socket.SOCK_STREAM, 0, fileno=c.fd)
        except OSError:
            return False
        try:
            if os.fstat(c.fd).st_ino != c.inode:
                return False
            s.shutdown(socket.SHUT_RDWR)
        except OSError:
            return False
        finally:
            s.detach()
        c.closed = True
        relay = getattr(self.node, "relay", None)
        if relay is not None:   # its client's end too, at once: the relay may not be reading the SDK's (a stalled one)
            relay.drop(c.peer)
        return True

    def _listen_again(self, now: float, descriptors: int) -> None:
        node = self.node
        try:
            server = node.start_server()
        except Exception as exc:  # noqa: BLE001 - out of descriptors, the port taken meanwhile: next look
            self._note("listen_failed", str(exc).replace("FoxgloveError: ", ""))
            return
        old, node.server = node.server, server
        self.retired.append((old, set(self.conns)))
        with self.lock:
            self.restarts += 1
        self._note("restarted", f"{descriptors} descriptors open of {self.limit}")

    def _retire(self, alive: Set[int]) -> None:
        """Stop an old server once no connection it served is left (on a thread of its own: see stop_servers)."""
        keep = []
        for server, inodes in self.retired:
            inodes &= alive
            if inodes:
                keep.append((server, inodes))
            else:
                threading.Thread(target=server.stop, name="foxglove-stop", daemon=True).start()
        self.retired = keep

    def shut_all(self) -> int:
        """Shut down every connection on the port now; returns how many."""
        n = 0
        for name in self._fd_names():
            try:
                link = os.readlink(f"/proc/self/fd/{name}")
            except OSError:
                continue
            if not link.startswith("socket:["):
                continue
            inode, fd = int(link[8:-1]), int(name)
            kind = self.kinds.get(inode) or self._classify(inode, fd, time.monotonic())
            if isinstance(kind, _Conn):
                kind.fd, kind.closed = fd, False
                n += self._shut(kind)
        return n

    def stop_servers(self, servers, timeout_s: float = 5.0) -> bool:
        """``server.stop()`` of each of ``servers``: the SDK's stop waits for every connection's task, also for a
        handshake that never comes (one idle TCP connection kept the node from ever ending on SIGINT); so the
        connections are shut down while it waits.  False: not stopped within ``timeout_s`` (left to the exit)."""
        done = threading.Event()

        def stop_all() -> None:
            try:
                for server in servers:
                    server.stop()
            finally:
                done.set()
        threading.Thread(target=stop_all, name="foxglove-stop", daemon=True).start()
        end = time.monotonic() + timeout_s
        while not done.wait(0.05):
            self.shut_all()
            if time.monotonic() > end:
                self.log.warning(f"the WebSocket server did not stop within {timeout_s:g} s; exiting anyway")
                return False
        return True

    # --- warnings, at most one line per reason and second --------------------------------------------

    def _note(self, reason: str, example: str) -> None:
        entry = self._pending.setdefault(reason, [0, [], 0.0])
        entry[0] += 1
        if len(entry[1]) < 3:
            entry[1].append(example)

    def _flush_logs(self, final: bool = False) -> None:
        now = time.monotonic()
        problems, texts = self.node.sdk_log.take_problems()
        if problems:
            entry = self._pending.setdefault("sdk", [0, [], 0.0])
            entry[0] += problems
            entry[1] = (entry[1] + texts)[:3]
        for reason, entry in self._pending.items():
            count, examples, last = entry
            if not count or (now - last < LOG_PERIOD_S and not final):
                continue
            entry[0], entry[1], entry[2] = 0, [], now
            self.log.warning(self._line(reason, count, examples))

    def _line(self, reason: str, count: int, examples: List[str]) -> str:
        url = f"ws://{self.node.host}:{self.node.port}"
        e = ", ".join(examples) + (", ..." if count > len(examples) else "")
        with self.lock:
            refused, idle, restarts = self.refused, self.closed_idle, self.restarts
        if reason == "refused":
            return (f"refused {count} connection(s) ({e}): max_clients {self.max_clients} connections open; "
                    f"{refused} refused since the start")
        if reason == "idle":
            return (f"closed {count} idle connection(s) ({e}): no subscription and nothing received for "
                    f"{self.idle_timeout_s:g} s; {idle} closed idle since the start")
        if reason == "restarted":
            return (f"the listening socket of {url} was gone (the SDK stops accepting at a failed accept(), "
                    f"e.g. out of descriptors: {e}): listening again; {restarts} restart(s) since the start")
        if reason == "listen_failed":
            return f"the listening socket of {url} is gone and cannot be opened yet ({e}); trying again"
        return f"foxglove-sdk: {count} warning(s)/error(s): {e}"

    def counts(self) -> Dict[str, int]:
        with self.lock:
            return {"connections": self.open_connections, "refused_connections": self.refused,
                    "closed_idle_connections": self.closed_idle, "listener_restarts": self.restarts,
                    "descriptors_open": self.descriptors}

    def stalled_s(self) -> float:
        """How long the watch has not completed a look, beyond a few periods (0: it is looking)."""
        age = time.monotonic() - self.last_look
        return age if age > 10 * self.period + 1.0 else 0.0


def raise_descriptor_limit(log) -> int:
    """The soft RLIMIT_NOFILE raised to the hard one (at most MAX_NOFILE); returns the soft limit."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = MAX_NOFILE if hard == resource.RLIM_INFINITY else min(hard, MAX_NOFILE)
    if soft != resource.RLIM_INFINITY and soft < want:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
            log.info(f"descriptor limit raised from {soft} to {want}")
            return want
        except (OSError, ValueError) as exc:
            log.warning(f"cannot raise the descriptor limit from {soft} to {want} ({exc})")
    return soft


def check_room(log, max_clients: int, per_client: int = 1) -> None:
    """The soft descriptor limit raised (:func:`raise_descriptor_limit`); ParamError naming ``max_clients`` when
    that many connections, ``per_client`` descriptors each, would not leave :data:`OWN_DESCRIPTORS` for the node
    itself."""
    limit = raise_descriptor_limit(log)
    in_use = len(os.listdir("/proc/self/fd"))
    room = (limit - in_use - OWN_DESCRIPTORS) // per_client
    if max_clients > room:
        raise ParamError("max_clients", f"must be at most {max(room, 0)} here: the descriptor limit is {limit}, "
                         f"{in_use} are in use, {OWN_DESCRIPTORS} are kept for the node itself and each connection "
                         f"takes {per_client} (got {max_clients})")
