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
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import zenoh

from harness.client import Client
from harness.ports import free_port
from rob6.bus.trace import TRACE_BATCH_S

from .bare_zenoh import QUERY_KEY, RECORD, Batcher, open_peer

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


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


def timed_query(session: zenoh.Session, key: str = QUERY_KEY, payload: bytes = b"") -> float:
    """One bare query received blocking: its round trip in seconds; RuntimeError unless
    exactly one answer came."""
    start = time.perf_counter()
    replies = list(session.get(key, payload=payload, consolidation=zenoh.ConsolidationMode.NONE))
    elapsed = time.perf_counter() - start
    if len(replies) != 1 or replies[0].ok is None:
        raise RuntimeError("the bare queryable did not answer once")
    return elapsed


def peer_config(**settings: object) -> dict[str, object]:
    """Zenoh settings (key -> value) of a bare peer: no scouting, and ``settings``."""
    return {"mode": "peer", "scouting/multicast/enabled": False, **settings}


def bare_process(role: str, settings: dict[str, object], *args: str) -> subprocess.Popen[str]:
    """A ``bench.bare_zenoh`` program (``queryable``, ``relay``, ``recorder``), ready when returned;
    it ends when its standard input closes (``end``)."""
    process = subprocess.Popen([sys.executable, "-m", "bench.bare_zenoh", role, json.dumps(settings), *args],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
    assert process.stdout is not None and process.stdout.readline().strip() == "ready"
    return process


def bare_queryable(settings: dict[str, object]) -> subprocess.Popen[str]:
    """A process with one queryable, ``bench/bare``, answering ``pong`` (``bench.bare_zenoh``)."""
    return bare_process("queryable", settings)


@contextmanager
def bare_relay() -> Iterator[tuple[int, subprocess.Popen[str]]]:
    """A ``bench.bare_zenoh`` relay linked directly to a bare queryable: yields the relay's
    TCP port and the queryable's process; both must end cleanly afterwards (``end``)."""
    port, relay_port = free_port(), free_port()
    server = bare_queryable(peer_config(**{"listen/endpoints": [f"tcp/127.0.0.1:{port}"]}))
    relay = bare_process("relay", peer_config(**{"connect/endpoints": [f"tcp/127.0.0.1:{port}"]}), str(relay_port))
    try:
        yield relay_port, server
        end(relay)
        end(server)
    finally:
        for process in (relay, server):
            process.kill()
            process.wait()


def end(process: subprocess.Popen[str]) -> None:
    """Close a ``bare_process``'s standard input and wait for its clean end."""
    assert process.stdin is not None
    process.stdin.close()
    if process.wait(10) != 0:
        raise RuntimeError(f"{process.args!r} ended with {process.returncode}")


#: how long a fresh peer may take to reach the bare queryable before the benchmark fails
REACH_S = 10.0


def wait_answered(session: zenoh.Session, key: str = QUERY_KEY) -> None:
    """Return once ``key`` answers ``session`` (peers find each other through the router or
    their direct link a moment after they open); RuntimeError after ``REACH_S``."""
    deadline = time.monotonic() + REACH_S
    while time.monotonic() < deadline:
        replies = list(session.get(key, consolidation=zenoh.ConsolidationMode.NONE, timeout=1.0))
        if any(reply.ok is not None for reply in replies):
            return
        time.sleep(0.05)  # not reachable yet: ask again
    raise RuntimeError(f"{key} did not answer within {REACH_S:.0f} s")


def zenoh_baselines(router_port: int, count: int, warmup: int = 200, block: int = 250) -> dict[str, list[float]]:
    """The bare Zenoh query round trip between two Python processes (peers beside the same
    router as rob6's services, linked directly to each other as they are), three ways:

    - ``blocking``: the reply taken on the asking thread (``for reply in session.get(...)``),
      the floor of a request that crosses the bus;
    - ``asyncio``: awaited on an event loop through ``call_soon_threadsafe`` (what the
      gateway did before it served on threads), interleaved with ``blocking``;
    - ``recorded``: ``blocking``, with both ends batching a record of each exchange to a
      bare recording process (``bench.bare_zenoh``), the floor of a recorded request. Its
      batches outlive the exchange by ``TRACE_BATCH_S``, so it runs in blocks of ``block``
      queries in turn with the other two, each block after the last batch has gone.

    All three use Zenoh's default settings, as rob6 does: the floor issue 25 names.
    """
    block = min(block, count)
    # peers beside the router, with a direct link between them, as rob6's processes have
    settings = peer_config(**{"connect/endpoints": [f"tcp/127.0.0.1:{router_port}"],
                              "listen/endpoints": ["tcp/127.0.0.1:0"]})
    folder = tempfile.TemporaryDirectory()
    records = os.path.join(folder.name, "records")
    server = bare_queryable(settings)
    recording = bare_process("recorder", settings, records)
    session = open_peer(settings)
    batcher = Batcher(session, "asker")
    samples: dict[str, list[float]] = {"blocking": [], "asyncio": [], "recorded": []}
    try:
        def recorded_once() -> float:
            t_in = time.time()
            elapsed = timed_query(session, payload=RECORD)
            batcher.add(b'{"t_in":%.6f,"t_out":%.6f,"line":"%s","reply":"pong"}' % (t_in, time.time(), RECORD))
            return elapsed

        async def bridged_once() -> float:
            loop = asyncio.get_running_loop()
            future = loop.create_future()

            def on_reply(reply: zenoh.Reply) -> None:
                loop.call_soon_threadsafe(future.set_result, reply.ok is not None)

            start = time.perf_counter()
            session.get(QUERY_KEY, zenoh.handlers.Callback(on_reply), consolidation=zenoh.ConsolidationMode.NONE)
            if not await asyncio.wait_for(future, 5):
                raise RuntimeError("the bare queryable answered with an error")
            return time.perf_counter() - start

        async def run() -> None:
            for i in range(warmup + count):
                one, other = timed_query(session), await bridged_once()
                if i >= warmup:
                    samples["blocking"].append(one)
                    samples["asyncio"].append(other)
                if i >= warmup and (i - warmup) % block == block - 1:
                    samples["recorded"] += [recorded_once() for _ in range(block)]
                    time.sleep(3 * TRACE_BATCH_S)  # the last batch goes before the next block

        wait_answered(session)
        asyncio.run(run())
        expected, deadline = 2 * len(samples["recorded"]), time.monotonic() + REACH_S
        while (recorded := _count(records, b'"reply":"pong"')) < expected and time.monotonic() < deadline:
            time.sleep(0.05)  # the last batches on their way
        if recorded != expected:
            raise RuntimeError(f"the bare recording has {recorded} records of {expected}")
        end(server)
        end(recording)
        return samples
    finally:
        batcher.close()
        session.close()
        for process in (server, recording):
            process.kill()
            process.wait()
        folder.cleanup()


def _count(path: str, record: bytes) -> int:
    with open(path, "rb") as f:
        return f.read().count(record)


def cpu_seconds(pid: int) -> float:
    """The CPU time process ``pid`` has used so far, all its threads, in seconds (10 ms steps)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime, in clock ticks


def usage(pids: list[int], seconds: float) -> tuple[float, float, float]:
    """CPU (share of one core), resident memory summed (MB) and proportional set size summed
    (MB) of ``pids`` together, over ``seconds``. The RSS sum counts every shared page (the
    Python interpreter, Zenoh's library, numpy) once per process; PSS divides each shared page
    among the processes that map it, so its sum is the memory the system occupies."""
    def cpu_total() -> float:
        return sum(cpu_seconds(pid) for pid in pids)

    def kilobytes(path: str, field: str) -> int:
        with open(path) as f:
            return next(int(line.split()[1]) for line in f if line.startswith(field))

    before, start = cpu_total(), time.monotonic()
    time.sleep(seconds)
    cpu = (cpu_total() - before) / (time.monotonic() - start)
    rss = sum(kilobytes(f"/proc/{pid}/status", "VmRSS:") for pid in pids)
    pss = sum(kilobytes(f"/proc/{pid}/smaps_rollup", "Pss:") for pid in pids)
    return cpu, rss / 1024, pss / 1024
