"""Bare Zenoh programs for the floors: a queryable, a relay, a recording process, record batching.

The floor of a bus crossing is a bare query between two processes (``queryable`` answers
``pong``). The floor of a *recorded* one adds what recording costs at its barest: both ends
queue a record of the exchange, a thread of each sends what gathered every
``TRACE_BATCH_S`` as one message (``Batcher``, as rob6's services batch their records), and a
third process appends every batch to a file (``recorder``). The floor of a client's command
that crosses the bus once, as an Alter target does, is ``relay``: a TCP server that answers
each line after a bare query to the queryable, received on the thread that read the line.
Plain Zenoh and the standard library only: none of rob6's layers.

    python -m bench.bare_zenoh queryable SETTINGS_JSON [KEY]
    python -m bench.bare_zenoh relay SETTINGS_JSON PORT
    python -m bench.bare_zenoh recorder SETTINGS_JSON FILE

Each prints ``ready`` once declared and runs until its standard input closes.
"""

from __future__ import annotations

import json
import socket
import sys
import threading
import time
from queue import Empty, SimpleQueue

import zenoh

from rob6.bus.trace import TRACE_BATCH_S

QUERY_KEY = "bench/bare"
#: Zenoh's batching off on the sending side (rob6 keeps it on: docs/PERFORMANCE.md)
BATCHING_OFF = {"transport/link/tx/queue/batching/enabled": False}
RECORDS_KEY = "bench/records"
#: the payload of a query whose exchange is recorded
RECORD = b"record"


def open_peer(settings: dict[str, object]) -> zenoh.Session:
    """A Zenoh session with ``settings`` (key -> value) inserted into the default config."""
    config = zenoh.Config()
    for key, value in settings.items():
        config.insert_json5(key, json.dumps(value))
    return zenoh.open(config)


class Batcher:
    """Records (JSON bytes) queued by ``add`` leave as one JSON array on
    ``RECORDS_KEY/<name>`` ``TRACE_BATCH_S`` after the first of them, from a thread of
    their own, never dropped (blocking congestion control)."""

    def __init__(self, session: zenoh.Session, name: str):
        self._queue: SimpleQueue[bytes | None] = SimpleQueue()
        self._publisher = session.declare_publisher(f"{RECORDS_KEY}/{name}",
                                                    congestion_control=zenoh.CongestionControl.BLOCK)
        self._sender = threading.Thread(target=self._send, name=f"{name}-records", daemon=True)
        self._sender.start()

    def add(self, record: bytes) -> None:
        self._queue.put(record)

    def close(self) -> None:
        """What was added still leaves; then the thread ends."""
        self._queue.put(None)
        self._sender.join(5.0)

    def _send(self) -> None:
        while (first := self._queue.get()) is not None:
            time.sleep(TRACE_BATCH_S)
            batch, closing = [first], False
            while not closing:
                try:
                    record = self._queue.get_nowait()
                except Empty:
                    break
                if record is None:
                    closing = True
                else:
                    batch.append(record)
            self._publisher.put(b"[" + b",".join(batch) + b"]")
            if closing:
                return


def queryable(session: zenoh.Session, key: str = QUERY_KEY) -> list[object]:
    """``key`` answers ``pong``; a query with the payload ``RECORD`` is then recorded
    (what it asked and what it got, timed, as a service records what it served)."""
    batcher = Batcher(session, "queryable")

    def on_query(query: zenoh.Query) -> None:
        started = time.time()
        asked = query.payload.to_bytes() if query.payload is not None else b""
        query.reply(query.key_expr, b"pong")
        query.drop()
        if asked == RECORD:
            batcher.add(b'{"t":%.6f,"dt":%.6f,"request":"%s","reply":"pong"}' % (started, time.time() - started, asked))

    return [batcher, session.declare_queryable(key, on_query)]


def relay(session: zenoh.Session, port: int) -> socket.socket:
    """A TCP server on loopback ``port``: each line a client sends is answered with
    ``pong`` once ``QUERY_KEY`` has answered a query for it (one client at a time, blocking
    reads and a blocking receive on one thread, as the gateway serves a session)."""
    listener = socket.create_server(("127.0.0.1", port))

    def serve() -> None:
        while True:
            try:
                sock, _ = listener.accept()
            except OSError:  # closed: the program ends
                return
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with sock:
                sock.sendall(b"welcome\n")
                pending = b""
                while data := sock.recv(65536):
                    pending += data
                    while b"\n" in pending:
                        _, pending = pending.split(b"\n", 1)
                        replies = list(session.get(QUERY_KEY, consolidation=zenoh.ConsolidationMode.NONE))
                        sock.sendall(b"pong\n" if len(replies) == 1 and replies[0].ok is not None else b"ERROR\n")

    threading.Thread(target=serve, name="relay", daemon=True).start()
    return listener


def recorder(session: zenoh.Session, path: str) -> list[object]:
    """Every batch on ``RECORDS_KEY/*`` appended to the file ``path`` as it came."""
    out = open(path, "ab", buffering=0)  # noqa: SIM115  (open while the process runs; each batch written as it comes)
    return [out, session.declare_subscriber(f"{RECORDS_KEY}/*", lambda sample: out.write(sample.payload.to_bytes()))]


def main(argv: list[str]) -> None:
    role, settings = argv[0], json.loads(argv[1])
    session = open_peer(settings)
    if role == "queryable":
        held = queryable(session, *argv[2:])
    elif role == "relay":
        held = [relay(session, int(argv[2]))]
    else:
        held = recorder(session, argv[2])
    print("ready", flush=True)
    sys.stdin.read()
    for item in held:
        if isinstance(item, (Batcher, socket.socket)):
            item.close()
    session.close()


if __name__ == "__main__":
    main(sys.argv[1:])
