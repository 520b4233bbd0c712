"""The live view against clients that subscribe and never read (issue 46 item 6): with ``max_clients`` 4, twelve such
clients on a busy topic are closed (the ones over the cap at once, the rest once they read nothing for
``idle_timeout_s`` while data waits), and a well-behaved newcomer is then served.  Before, the relay stopped reading
the SDK's side of a client that read nothing, so it never saw the connection watch shut it: 20 of 40 such clients
were still connected after 20 s, the server grew from 104 to 365 MB and a newcomer was dropped."""
import base64
import json
import os
import socket
import struct
import time
from concurrent.futures import ThreadPoolExecutor

import pytest
from std_msgs.msg import String
from websockets.sync.client import connect

from graphproc import Graph
from injector import Injector
from test_foxglove_server import SUBPROTOCOL, FoxgloveClient, free_port

pytestmark = pytest.mark.graph

STALLED = 12
MAX_CLIENTS = 4
IDLE_S = 1.0


def _frame(sock: socket.socket, buf: bytearray):
    """One unmasked frame from the server: (opcode, payload); ``buf`` holds what was read past it."""
    def need(n):
        while len(buf) < n:
            data = sock.recv(1 << 16)
            if not data:
                raise ConnectionError("closed")
            buf.extend(data)
    need(2)
    op, n, at = buf[0] & 0x0F, buf[1] & 0x7F, 2
    if n == 126:
        need(4)
        n, at = struct.unpack(">H", bytes(buf[2:4]))[0], 4
    elif n == 127:
        need(10)
        n, at = struct.unpack(">Q", bytes(buf[2:10]))[0], 10
    need(at + n)
    payload = bytes(buf[at:at + n])
    del buf[:at + n]
    return op, payload


def _stalled_client(port: int, topic: str) -> socket.socket:
    """A client that completes the WebSocket handshake, subscribes ``topic`` and then never reads again (a raw socket:
    no library reads for it behind its back)."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=30)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                  f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: {SUBPROTOCOL}"
                  "\r\n\r\n").encode())
    buf = bytearray()
    while b"\r\n\r\n" not in buf:
        data = sock.recv(4096)
        if not data:
            raise ConnectionError("closed during the handshake")
        buf.extend(data)
    head, rest = bytes(buf).split(b"\r\n\r\n", 1)
    assert b" 101 " in head.split(b"\r\n")[0], head
    buf = bytearray(rest)
    while True:
        op, payload = _frame(sock, buf)
        if op != 1:
            continue
        m = json.loads(payload)
        chans = [c for c in m.get("channels", ()) if c["topic"] == topic] if m.get("op") == "advertise" else []
        if chans:
            text = json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": chans[0]["id"]}]}).encode()
            mask = os.urandom(4)
            sock.sendall(bytes([0x81, 0x80 | 126]) + struct.pack(">H", len(text)) + mask
                         + bytes(b ^ mask[i % 4] for i, b in enumerate(text)))
            return sock


def _closed_by_server(sock: socket.socket) -> bool:
    """Whether the server closed the client's TCP connection, asked of the kernel (TCP_INFO's state) without reading
    a byte (reading would make the client one that reads)."""
    try:
        state = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 8)[0]
    except OSError:
        return True
    return state != 1   # not ESTABLISHED: CLOSE_WAIT (its FIN came), CLOSE (a reset)


def test_clients_that_never_read_are_closed_and_a_newcomer_is_served(tmp_path):
    port = free_port()
    url = f"ws://127.0.0.1:{port}"
    big = String(data="x" * 200_000)   # 200 kB a message: the stalled clients' windows fill in a moment
    with Graph(tmp_path) as g, Injector(g.domain_id) as inj:
        fox = g.start("foxglove_server", "-p", f"port:={port}", "-p", f"max_clients:={MAX_CLIENTS}",
                      "-p", f"idle_timeout_s:={IDLE_S}", "-p", "topics:=['robot_description']")
        assert fox.wait_for_output(f"on ws://127.0.0.1:{port}", 60), fox.output()
        pub = inj.node.create_publisher(String, "robot_description", 10)

        def publishing_for(seconds: float, cond=lambda: False) -> bool:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                if cond():
                    return True
                pub.publish(big)
                inj.spin(0.05)
            return cond()
        assert publishing_for(60, lambda: "advertised /robot_description" in fox.output()), fox.output()[-3000:]
        # all at once (as a hostile user's script does): most are in before the connection watch's next look
        with ThreadPoolExecutor(STALLED) as pool:
            futures = [pool.submit(_stalled_client, port, "/robot_description") for _ in range(STALLED)]
            publishing_for(3.0, lambda: all(f.done() for f in futures))
        stalled = [f.result() for f in futures if f.exception() is None]
        assert len(stalled) > MAX_CLIENTS, len(stalled)   # some over the cap got in: what the watch must close
        closed = publishing_for(20, lambda: all(_closed_by_server(ws) for ws in stalled))
        n_closed = sum(_closed_by_server(ws) for ws in stalled)
        states = [ws.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 8)[0] for ws in stalled]
        with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=30, ping_interval=None) as ws:
            newcomer = FoxgloveClient(ws, topics=("/robot_description",))
            served = publishing_for(20, lambda: len(newcomer.got("/robot_description")) >= 3)
            newcomer.close()
        for sock in stalled:
            sock.close()
        out = fox.output()
        assert fox.stop() == 0, out[-3000:]
    print(f"\n{n_closed} of {STALLED} clients that never read closed; newcomer served: {served}; TCP states {states}")
    assert closed, (n_closed, out[-3000:])
    assert served and not newcomer.errors, (newcomer.errors, out[-3000:])
    assert "read nothing for" in out or "refused" in out

