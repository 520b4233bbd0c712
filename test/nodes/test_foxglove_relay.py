"""The live view's port takes both Foxglove subprotocols (mwip_ros/nodes/tools/foxglove_relay.py): the handshake as the
SDK is handed it and as the client gets the answer.  The whole path, a client offering only the classic one
decoding the graph's messages, is test_foxglove_server.py's."""
import pytest

from mwip_ros.nodes.tools.foxglove_relay import CLASSIC_SUBPROTOCOL, SDK_SUBPROTOCOL, answer_for_client, offer_for_sdk

pytestmark = pytest.mark.unit


def request(*protocol_lines: str) -> bytes:
    lines = ["GET / HTTP/1.1", "Host: 127.0.0.1:8765", "Upgrade: websocket", "Connection: Upgrade",
             "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==", *protocol_lines, "Sec-WebSocket-Version: 13"]
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def headers(head: bytes) -> list:
    return head.decode().split("\r\n")


def test_a_classic_only_offer_is_handed_on_as_the_sdks_and_nothing_else_changes():
    head, classic = offer_for_sdk(request(f"Sec-WebSocket-Protocol: {CLASSIC_SUBPROTOCOL}"))
    assert classic and head.endswith(b"\r\n\r\n")
    assert [h for h in headers(head) if h.lower().startswith("sec-websocket-protocol")] == \
        [f"Sec-WebSocket-Protocol: {SDK_SUBPROTOCOL}"]
    others = [h for h in headers(request()) if h]
    assert [h for h in headers(head) if h and not h.lower().startswith("sec-websocket-protocol")] == others


@pytest.mark.parametrize("lines", [
    (f"Sec-WebSocket-Protocol: {CLASSIC_SUBPROTOCOL}, {SDK_SUBPROTOCOL}",),    # both: the SDK picks its own
    (f"sec-websocket-protocol: {CLASSIC_SUBPROTOCOL}", f"Sec-WebSocket-Protocol:{SDK_SUBPROTOCOL}"),
    ("Sec-WebSocket-Protocol: foxglove.other.v1",),                             # neither: the SDK refuses it
    (),                                                                         # none at all: refused too
    (f"X-Comment: {CLASSIC_SUBPROTOCOL}",),                                     # not an offer
])
def test_any_other_offer_is_handed_on_unchanged(lines):
    head = request(*lines)
    assert offer_for_sdk(head) == (head, False)


def test_a_classic_offer_in_any_spelling_of_the_header_is_seen():
    head, classic = offer_for_sdk(request(f"SEC-WEBSOCKET-PROTOCOL:   {CLASSIC_SUBPROTOCOL} ,other"))
    assert classic and f"Sec-WebSocket-Protocol: {SDK_SUBPROTOCOL}" in headers(head)


def test_the_answer_to_a_classic_client_names_the_classic_subprotocol():
    answer = ("HTTP/1.1 101 Switching Protocols\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n"
              f"sec-websocket-protocol: {SDK_SUBPROTOCOL}\r\n"
              "Sec-WebSocket-Accept: s3pPLMBiTxaQ9kYGzzhZRbK+xOo=\r\n\r\n")
    out = answer_for_client(answer.encode()).decode()
    assert out == answer.replace(f"sec-websocket-protocol: {SDK_SUBPROTOCOL}",
                                 f"sec-websocket-protocol: {CLASSIC_SUBPROTOCOL}")
    refusal = b"HTTP/1.1 400 Bad Request\r\ncontent-length: 46\r\n\r\n"
    assert answer_for_client(refusal) == refusal
