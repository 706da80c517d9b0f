"""Benchmark of Zenoh's transport options side by side (TCP, unix socket, lowlatency, batching off).

Zenoh's transport options side by side: a bare query between two processes over loopback
TCP and a unix socket, with the default transport and with ``lowlatency``, and over TCP
with Zenoh's batching off (rob6 keeps Zenoh's defaults: docs/PERFORMANCE.md)."""

from __future__ import annotations

import tempfile
from collections.abc import Callable

from harness.ports import free_port

from .bare_zenoh import BATCHING_OFF, open_peer
from .latency import bare_queryable, peer_config, percentiles, timed_query, wait_answered

#: what ``lowlatency`` needs on both ends (QoS off)
_LOWLATENCY = {"transport/unicast/lowlatency": True, "transport/unicast/qos/enabled": False}
_SETTINGS = {"default": {}, "lowlatency": _LOWLATENCY, "batching off": BATCHING_OFF}


def transport_table(count: int, table: Callable[..., None], warmup: int = 200) -> None:
    with tempfile.TemporaryDirectory() as folder:
        # one queryable process per variant, each on its own port or socket
        variants = [("loopback TCP, default", f"tcp/127.0.0.1:{free_port()}", "default"),
                    ("loopback TCP, lowlatency", f"tcp/127.0.0.1:{free_port()}", "lowlatency"),
                    ("loopback TCP, batching off", f"tcp/127.0.0.1:{free_port()}", "batching off"),
                    ("unix socket, default", f"unixsock-stream/{folder}/a.sock", "default"),
                    ("unix socket, lowlatency", f"unixsock-stream/{folder}/b.sock", "lowlatency")]
        servers, sessions = [], []
        try:
            for _, endpoint, transport in variants:
                extra = _SETTINGS[transport]
                servers.append(bare_queryable(peer_config(**{"listen/endpoints": [endpoint]}, **extra)))
                sessions.append(open_peer(peer_config(**{"connect/endpoints": [endpoint]}, **extra)))
            for session in sessions:
                wait_answered(session)
            samples: list[list[float]] = [[] for _ in variants]
            for i in range(warmup + count):  # interleaved: every variant sees the same moments
                for k, session in enumerate(sessions):
                    elapsed = timed_query(session)
                    if i >= warmup:
                        samples[k].append(elapsed)
        finally:
            for session in sessions:
                session.close()
            for server in servers:
                server.kill()
                server.wait()
    rows = [(name, *("%.3f" % v for v in percentiles(x))) for (name, _, _), x in zip(variants, samples, strict=True)]
    table(f"Zenoh transports: a bare query between two processes, blocking receive, ms ({count} each, interleaved)",
          ("link, transport", "p50", "p99"), rows)
