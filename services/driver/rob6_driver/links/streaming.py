"""Socket helpers of the TCP links: sending within a deadline, endpoint names, latency quantiles.

Used by the simple_message and kawasaki links and their base (``streamed_points``)."""

from __future__ import annotations

import math
import select
import socket
import time


def send_all(sock: socket.socket, data: bytes, timeout: float) -> None:
    """sendall on a non-blocking socket, within ``timeout``."""
    deadline = time.monotonic() + timeout
    view = memoryview(data)
    while view:
        try:
            sent = sock.send(view)
            view = view[sent:]
        except BlockingIOError:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise OSError("the controller does not take data (send timed out)") from None
            select.select([], [sock], [], remaining)


def endpoint_name(addr: tuple[str, int]) -> str:
    host, port = addr
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def quantile(values: list[float], q: float) -> float:
    return values[min(len(values) - 1, max(0, math.ceil(q * len(values)) - 1))]
