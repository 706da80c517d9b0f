"""Round-trip latency through the gateway, next to a bare asyncio TCP echo measured in the
same run (the echo is the floor any asyncio TCP server on this machine can reach)."""

from __future__ import annotations

import asyncio
import os
import socket
import statistics
import subprocess
import sys
import threading
import time

import zenoh

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


_BARE_QUERYABLE = """
import sys, time, zenoh
config = zenoh.Config()
config.insert_json5("mode", '"peer"')
config.insert_json5("connect/endpoints", '["tcp/127.0.0.1:%s"]' % sys.argv[1])
config.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
config.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(config)
queryable = session.declare_queryable("bench/bare", lambda query: query.reply(query.key_expr, b"pong"))
print("ready", flush=True)
sys.stdin.read()
"""


def zenoh_baseline(router_port: int, count: int, warmup: int = 200) -> list[float]:
    """The bare Zenoh query round trip between two Python processes (peers beside the same
    router as rob6's services, linked directly to each other as they are), awaited on an
    asyncio loop the way the gateway awaits."""
    server = subprocess.Popen([sys.executable, "-c", _BARE_QUERYABLE, str(router_port)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", f'["tcp/127.0.0.1:{router_port}"]')
    config.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')  # a direct link, as rob6's peers have
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    try:
        assert server.stdout is not None and server.stdout.readline().strip() == "ready"

        async def run() -> list[float]:
            loop = asyncio.get_running_loop()
            samples = []
            for i in range(warmup + count):
                future = loop.create_future()

                def on_reply(reply, future=future):
                    loop.call_soon_threadsafe(future.set_result, reply.ok is not None)

                start = time.perf_counter()
                session.get("bench/bare", zenoh.handlers.Callback(on_reply),
                            consolidation=zenoh.ConsolidationMode.NONE)  # as rob6.bus asks
                if not await asyncio.wait_for(future, 5):
                    raise RuntimeError("the bare queryable answered with an error")
                if i >= warmup:
                    samples.append(time.perf_counter() - start)
            return samples

        time.sleep(0.5)  # the peers find each other through the router
        return asyncio.run(run())
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
