"""The live view admits foxglove.websocket.v1 clients (older Foxglove Studio, Lichtblick) as well as
foxglove.sdk.v1 ones, on the same port."""

from __future__ import annotations

import json

import pytest
from websockets.sync.client import connect

from simcore.live import LiveServer
from simcore.live_front import rewrite_request, rewrite_response


def test_rewrites_only_the_old_name_offered_alone() -> None:
    head = b"GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n"
    request, translated = rewrite_request(head)
    assert translated and b"Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n" in request
    both = head.replace(b"foxglove.websocket.v1", b"foxglove.websocket.v1, foxglove.sdk.v1")
    assert rewrite_request(both) == (both, False)
    assert rewrite_request(b"GET / HTTP/1.1\r\n\r\n") == (b"GET / HTTP/1.1\r\n\r\n", False)
    answer = b"HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n"
    assert rewrite_response(answer).endswith(b"sec-websocket-protocol: foxglove.websocket.v1\r\n\r\n")


@pytest.mark.parametrize("subprotocol", ["foxglove.websocket.v1", "foxglove.sdk.v1"])
def test_live_view_accepts_both_subprotocol_names(subprotocol: str) -> None:
    server = LiveServer(port=0).start()
    try:
        with connect(server.url, subprotocols=[subprotocol], open_timeout=10) as ws:  # type: ignore[list-item]
            assert ws.subprotocol == subprotocol
            hello = json.loads(ws.recv(timeout=10))
            assert hello["op"] == "serverInfo" and hello["name"] == "carlos"
    finally:
        server.stop()
