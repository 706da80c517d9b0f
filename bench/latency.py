"""Round-trip latency through the gateway, next to a bare asyncio TCP echo measured in the
same run (the echo is the floor any asyncio TCP server on this machine can reach)."""

from __future__ import annotations

import asyncio
import socket
import statistics
import threading
import time

from rob6.testing import Client, free_port


def percentiles(samples: list[float]) -> tuple[float, float]:
    ordered = sorted(samples)
    return (statistics.median(ordered) * 1e3, ordered[min(len(ordered) - 1, int(len(ordered) * 0.99))] * 1e3)


def measure(client: Client, command: str, lines: int, count: int, warmup: int = 200) -> list[float]:
    data = (command + "\n").encode("latin-1")
    for _ in range(warmup):
        client.send(data)
        client.read_lines(lines)
    samples = []
    for _ in range(count):
        start = time.perf_counter()
        client.send(data)
        reply = client.read_lines(lines)
        samples.append(time.perf_counter() - start)
        if reply.count("\n") != lines:
            raise RuntimeError(f"{command}: short reply {reply!r}")
    return samples


def echo_baseline(count: int) -> list[float]:
    """A bare asyncio line echo server in a thread of its own event loop."""
    port = free_port()
    ready = threading.Event()

    async def handle(reader, writer):
        sock = writer.get_extra_info("socket")
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        writer.write(b"welcome\n")
        while line := await reader.readline():
            writer.write(line)

    def serve():
        loop = asyncio.new_event_loop()
        server = loop.run_until_complete(asyncio.start_server(handle, "127.0.0.1", port))
        ready.set()
        loop.run_until_complete(server.serve_forever())

    threading.Thread(target=serve, daemon=True).start()
    ready.wait()
    client = Client(port, handshake=False)
    try:
        return measure(client, "CM_PING", 1, count)
    finally:
        client.close()
