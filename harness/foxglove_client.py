"""A small Foxglove WebSocket client of the live view, for the tests and the live-view benchmark.

It speaks subprotocol ``foxglove.sdk.v1`` (the successor of ``foxglove.websocket.v1``). Collects the server info, the advertised channels and, per subscribed topic, the
decoded JSON messages with their timestamps; can fetch an asset. Runs a reader thread.
"""

from __future__ import annotations

import json
import struct
import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterable
from typing import Any

from websockets.sync.client import connect
from websockets.typing import Subprotocol

SUBPROTOCOLS = [Subprotocol("foxglove.sdk.v1"), Subprotocol("foxglove.websocket.v1")]  # the SDK serves the first


class FoxgloveClient:
    def __init__(self, url: str, timeout: float = 10.0) -> None:
        self._connection = connect(url, subprotocols=SUBPROTOCOLS, open_timeout=timeout, max_size=None)
        self.ws = self._connection.__enter__()  # websockets wants it used as a context manager
        self.server_info: dict[str, Any] = {}
        self.channels: dict[int, dict[str, Any]] = {}  # channel id -> advertised channel
        self.messages: dict[str, list[tuple[int, Any]]] = defaultdict(list)  # topic -> [(t, data)]
        self.times: list[int] = []
        self.playback_states: list[tuple[int, int, float, bool]] = []  # (status, time, speed, did_seek)
        self.assets: dict[int, tuple[int, bytes]] = {}
        self._subs: dict[int, str] = {}  # subscription id -> topic
        self._next = 1
        self._lock = threading.RLock()  # predicates of wait() read under it
        self._changed = threading.Condition(self._lock)
        self.closed = False
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            while True:
                frame = self.ws.recv()
                with self._changed:
                    if isinstance(frame, str):
                        self._text(json.loads(frame))
                    else:
                        self._binary(frame)
                    self._changed.notify_all()
        except Exception:
            pass
        finally:
            with self._changed:
                self.closed = True
                self._changed.notify_all()

    def _text(self, msg: dict[str, Any]) -> None:
        op = msg.get("op")
        if op == "serverInfo":
            self.server_info = msg
        elif op == "advertise":
            for ch in msg["channels"]:
                self.channels[ch["id"]] = ch
        elif op == "unadvertise":
            for cid in msg["channelIds"]:
                self.channels.pop(cid, None)

    def _binary(self, frame: bytes) -> None:
        opcode = frame[0]
        if opcode == 1:  # message data
            sub, t = struct.unpack_from("<IQ", frame, 1)
            topic = self._subs.get(sub)
            if topic is not None:
                self.messages[topic].append((t, json.loads(frame[13:])))
        elif opcode == 2:  # time
            self.times.append(struct.unpack_from("<Q", frame, 1)[0])
        elif opcode == 4:  # fetch asset response
            request, status, n = struct.unpack_from("<IBI", frame, 1)
            self.assets[request] = (status, frame[10 + n:] if status == 0 else frame[10:10 + n])
        elif opcode == 5:  # playback state: status u8, time u64, speed f32, did_seek u8, id
            status, t, speed, seek = struct.unpack_from("<BQfB", frame, 1)
            self.playback_states.append((status, t, speed, bool(seek)))

    def wait(self, predicate: Callable[[], object], timeout: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout
        with self._changed:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0 or self.closed:
                    return bool(predicate())
                self._changed.wait(min(left, 0.1))
            return True

    def topics(self) -> dict[str, dict[str, Any]]:
        with self._lock:
            return {ch["topic"]: ch for ch in self.channels.values()}

    def wait_topics(self, topics: Iterable[str], timeout: float = 10.0) -> dict[str, dict[str, Any]]:
        self.wait(lambda: set(topics) <= {ch["topic"] for ch in self.channels.values()}, timeout)
        return self.topics()

    def subscribe(self, *topics: str, timeout: float = 10.0) -> None:
        chans = self.wait_topics(topics, timeout)
        missing = set(topics) - set(chans)
        assert not missing, f"not advertised: {missing}; have {sorted(chans)}"
        subs = []
        with self._lock:
            for topic in topics:
                sid = self._next
                self._next += 1
                self._subs[sid] = topic
                subs.append({"id": sid, "channelId": chans[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def received(self, topic: str) -> list[tuple[int, Any]]:
        with self._lock:
            return list(self.messages.get(topic, ()))

    def wait_messages(self, topic: str, count: int = 1, timeout: float = 10.0) -> list[tuple[int, Any]]:
        self.wait(lambda: len(self.messages.get(topic, ())) >= count, timeout)
        return self.received(topic)

    def fetch_asset(self, uri: str, timeout: float = 5.0) -> tuple[int, bytes] | None:
        with self._lock:
            request = self._next
            self._next += 1
        self.ws.send(json.dumps({"op": "fetchAsset", "uri": uri, "requestId": request}))
        self.wait(lambda: request in self.assets, timeout)
        return self.assets.get(request)

    def playback_control(self, command: int, speed: float = 1.0, seek_ns: int | None = None,
                         request_id: str = "r") -> None:
        """A PlaybackControlRequest (binary opcode 3): command 0 play, 1 pause."""
        rid = request_id.encode()
        frame = struct.pack("<BBfB", 3, command, speed, 1 if seek_ns is not None else 0)
        frame += struct.pack("<Q", seek_ns or 0) + struct.pack("<I", len(rid)) + rid
        self.ws.send(frame)

    def close(self) -> None:
        self._connection.__exit__(None, None, None)
        self._thread.join(2)

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
