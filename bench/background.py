"""Benchmark of the floor beside background work: a bare query while a busy loop runs.

A recorded system does work beside each request (the recorder decodes and writes, the
services send their records). This table shows what work of that size costs a bare Zenoh
query on this machine when it is nobody's work at all: a separate process that spins for
a share of every period and sleeps for the rest, at the lowest priority Linux has
(``SCHED_IDLE``: it runs only on a CPU nothing else wants). Blocks of queries run in turn
alone and beside each load.

    python -m bench.background spin SHARE PERIOD_S
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable

from harness.ports import free_port

from .bare_zenoh import BATCHING_OFF, open_peer
from .latency import ROOT, bare_queryable, peer_config, percentiles, timed_query, wait_answered

#: (share of one core, period in s) of each load, beside none
LOADS = ((0.05, 0.005), (0.15, 0.005), (0.30, 0.005), (0.15, 0.001))


def spin(share: float, period: float) -> None:
    """Busy for ``share`` of every ``period``, asleep for the rest, at idle priority, until killed."""
    os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    while True:
        start = time.perf_counter()
        while time.perf_counter() - start < share * period:
            pass
        time.sleep(period * (1.0 - share))


def background_table(count: int, table: Callable[..., None], block: int = 250, warmup: int = 200) -> None:
    # two peers linked directly, as in the transport table, with Zenoh's batching off: with
    # its default batching its own 1 ms backoff hides what the background costs
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    server = bare_queryable(peer_config(**{"listen/endpoints": [endpoint]}, **BATCHING_OFF))
    session = open_peer(peer_config(**{"connect/endpoints": [endpoint]}, **BATCHING_OFF))
    loads = [subprocess.Popen([sys.executable, "-m", "bench.background", "spin", str(share), str(period)], cwd=ROOT)
             for share, period in LOADS]
    samples: list[list[float]] = [[] for _ in range(len(LOADS) + 1)]
    try:
        for load in loads:
            os.kill(load.pid, signal.SIGSTOP)
        wait_answered(session)
        for _ in range(warmup):
            timed_query(session)
        for _ in range(max(1, count // block)):
            for k in range(len(samples)):  # alone (0), then beside each load in turn
                for n, load in enumerate(loads, start=1):
                    os.kill(load.pid, signal.SIGCONT if n == k else signal.SIGSTOP)
                time.sleep(0.02)
                samples[k] += [timed_query(session) for _ in range(block)]
    finally:
        for load in loads:
            load.kill()
            load.wait()
        session.close()
        server.kill()
        server.wait()
    alone50, alone99 = percentiles(samples[0])
    rows = [("alone", f"{alone50:.3f}", f"{alone99:.3f}", "", "")]
    for (share, period), x in zip(LOADS, samples[1:], strict=True):
        p50, p99 = percentiles(x)
        rows.append((f"beside a busy loop: {share:.0%} of a core, {share * period * 1e3:.2f} ms of every "
                     f"{period * 1e3:.0f} ms", f"{p50:.3f}", f"{p99:.3f}", f"{p50 / alone50:.2f}x", f"{p99 / alone99:.2f}x"))
    table(f"The bare Zenoh query (rob6's Zenoh settings) beside background work at idle priority (ms, "
          f"{len(samples[0])} each, in turn)",
          ("background", "p50", "p99", "p50 / alone", "p99 / alone"), rows)


if __name__ == "__main__":
    if sys.argv[1:2] != ["spin"]:
        raise SystemExit("usage: python -m bench.background spin SHARE PERIOD_S")
    spin(float(sys.argv[2]), float(sys.argv[3]))
