"""Benchmark of the gateway's round trips, beside the floors (bare TCP echo, bare Zenoh query).

Round-trip latency through the gateway, next to its floors measured in the same run: a
bare TCP echo and a bare Zenoh query between two processes."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import statistics
import subprocess
import sys
import threading
import time

import zenoh

from harness.client import Client


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


def measure_beside(client: Client, command: str, lines: int, count: int,
                   beside: str = "CM_PING") -> tuple[list[float], list[float]]:
    """``command``'s round trips, each right after one of ``beside`` (one reply line), and
    those of ``beside``: their ratio holds even when the machine changes pace within a run
    (this 2-core VM has two, the bare TCP echo at 0.05 or 0.1 ms p50)."""
    measure(client, command, lines, 0)  # the warm-up
    samples: list[float] = []
    baseline: list[float] = []
    for _ in range(count):
        baseline += measure(client, beside, 1, 1, warmup=0)
        samples += measure(client, command, lines, 1, warmup=0)
    return samples, baseline


def echo_baseline(count: int) -> list[float]:
    """A bare line echo over TCP: a blocking server thread per client, as the gateway serves
    (the floor of any Python TCP request/reply on this machine)."""
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]

    def serve() -> None:
        sock, _ = listener.accept()
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.sendall(b"welcome\n")
        while data := sock.recv(65536):
            sock.sendall(data)
        sock.close()

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    client = Client(port, handshake=False)
    try:
        return measure(client, "CM_PING", 1, count)
    finally:
        client.close()
        server.join(5)
        listener.close()


_BARE_QUERYABLE = """
import json, sys, zenoh
config = zenoh.Config()
for key, value in json.loads(sys.argv[1]).items():
    config.insert_json5(key, json.dumps(value))
session = zenoh.open(config)
queryable = session.declare_queryable("bench/bare", lambda query: query.reply(query.key_expr, b"pong"))
print("ready", flush=True)
sys.stdin.read()
"""


def peer_config(**settings: object) -> dict[str, object]:
    """Zenoh settings (key -> value) of a bare peer: no scouting, and ``settings``."""
    return {"mode": "peer", "scouting/multicast/enabled": False, **settings}


def open_peer(settings: dict[str, object]) -> zenoh.Session:
    config = zenoh.Config()
    for key, value in settings.items():
        config.insert_json5(key, json.dumps(value))
    return zenoh.open(config)


def bare_queryable(settings: dict[str, object]) -> subprocess.Popen[str]:
    """A process with one queryable, ``bench/bare``, answering ``pong``; ready when returned.
    Kill it when done."""
    server = subprocess.Popen([sys.executable, "-c", _BARE_QUERYABLE, json.dumps(settings)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert server.stdout is not None and server.stdout.readline().strip() == "ready"
    return server


#: how long a fresh peer may take to reach the bare queryable before the benchmark fails
REACH_S = 10.0


def wait_answered(session: zenoh.Session, key: str = "bench/bare") -> None:
    """Return once ``key`` answers ``session`` (peers find each other through the router or
    their direct link a moment after they open); RuntimeError after ``REACH_S``."""
    deadline = time.monotonic() + REACH_S
    while time.monotonic() < deadline:
        replies = list(session.get(key, consolidation=zenoh.ConsolidationMode.NONE, timeout=1.0))
        if any(reply.ok is not None for reply in replies):
            return
        time.sleep(0.05)  # not reachable yet: ask again
    raise RuntimeError(f"{key} did not answer within {REACH_S:.0f} s")


def zenoh_baselines(router_port: int, count: int, warmup: int = 200) -> dict[str, list[float]]:
    """The bare Zenoh query round trip between two Python processes (peers beside the same
    router as rob6's services, linked directly to each other as they are), received two
    ways, interleaved so both see the same moment of the machine: ``blocking``, the reply
    taken on the asking thread (``for reply in session.get(...)``), the floor of a request
    that crosses the bus; ``asyncio``, awaited on an event loop through
    ``call_soon_threadsafe`` (what the gateway did before it served on threads)."""
    # peers beside the router, with a direct link between them, as rob6's processes have
    settings = peer_config(**{"connect/endpoints": [f"tcp/127.0.0.1:{router_port}"],
                              "listen/endpoints": ["tcp/127.0.0.1:0"]})
    server = bare_queryable(settings)
    session = open_peer(settings)
    blocking: list[float] = []
    bridged: list[float] = []
    try:
        def blocking_once() -> float:
            start = time.perf_counter()
            replies = list(session.get("bench/bare", consolidation=zenoh.ConsolidationMode.NONE))
            elapsed = time.perf_counter() - start
            if len(replies) != 1 or replies[0].ok is None:
                raise RuntimeError("the bare queryable did not answer once")
            return elapsed

        async def bridged_once() -> float:
            loop = asyncio.get_running_loop()
            future = loop.create_future()

            def on_reply(reply: zenoh.Reply) -> None:
                loop.call_soon_threadsafe(future.set_result, reply.ok is not None)

            start = time.perf_counter()
            session.get("bench/bare", zenoh.handlers.Callback(on_reply), consolidation=zenoh.ConsolidationMode.NONE)
            if not await asyncio.wait_for(future, 5):
                raise RuntimeError("the bare queryable answered with an error")
            return time.perf_counter() - start

        async def run() -> None:
            for i in range(warmup + count):
                one, other = blocking_once(), await bridged_once()
                if i >= warmup:
                    blocking.append(one)
                    bridged.append(other)

        wait_answered(session)
        asyncio.run(run())
        return {"blocking": blocking, "asyncio": bridged}
    finally:
        session.close()
        server.kill()
        server.wait()


def usage(pids: list[int], seconds: float) -> tuple[float, float, float]:
    """CPU (share of one core), resident memory summed (MB) and proportional set size summed
    (MB) of ``pids`` together, over ``seconds``. The RSS sum counts every shared page (the
    Python interpreter, Zenoh's library, numpy) once per process; PSS divides each shared page
    among the processes that map it, so its sum is the memory the system occupies."""
    def cpu_seconds() -> float:
        total = 0
        for pid in pids:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += int(fields[11]) + int(fields[12])  # utime + stime, in clock ticks
        return total / os.sysconf("SC_CLK_TCK")

    def kilobytes(path: str, field: str) -> int:
        with open(path) as f:
            return next(int(line.split()[1]) for line in f if line.startswith(field))

    before, start = cpu_seconds(), time.monotonic()
    time.sleep(seconds)
    cpu = (cpu_seconds() - before) / (time.monotonic() - start)
    rss = sum(kilobytes(f"/proc/{pid}/status", "VmRSS:") for pid in pids)
    pss = sum(kilobytes(f"/proc/{pid}/smaps_rollup", "Pss:") for pid in pids)
    return cpu, rss / 1024, pss / 1024
