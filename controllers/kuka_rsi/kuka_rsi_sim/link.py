"""The network between the controller and the PC, with the faults a lab network has."""

from __future__ import annotations

import math
import socket
import time
from collections import deque
from collections.abc import Callable
from typing import Any


class FaultError(ValueError):
    pass


class Link:
    """Puts the controller's packets on the wire, or loses, drops, delays, duplicates and
    reorders them. Periodic faults count the packets the controller offers."""

    def __init__(self, sock: socket.socket, on_sent: Callable[[int, float], None], log: Callable[[str], None]) -> None:
        self._sock = sock
        self._on_sent = on_sent
        self._log = log
        self.dest: tuple[str, int] | None = None
        self.offered = 0
        self.packets_sent = 0
        self.send_errors = 0
        self.stats = dict(lost_out=0, lost_in=0, dropped=0, delayed=0, duplicated=0, reordered=0)
        self._queue: deque[tuple[float, bytes, int]] = deque()  # delayed packets: (due, packet, ipoc)
        self._held: tuple[bytes, int] | None = None  # the first packet of a pair being swapped
        self.clear()

    # ------------------------------------------------------------------ configuration
    def clear(self) -> None:
        self.lose_until = 0.0
        self.drop_every = 0
        self.delay_ms = 0.0
        self.delay_until: float | None = None  # None: until cleared
        self.duplicate_every = 0
        self.reorder_every = 0

    def reset(self) -> None:
        """Controller switched off: nothing it queued leaves any more."""
        self._queue.clear()
        self._held = None

    def set_faults(self, req: dict[str, Any], now: float) -> None:
        """Apply a fault request ({"lose_s": 0.3} ...); validated completely before any change."""
        known = {"lose_s", "drop_every", "delay_ms", "for_s", "duplicate_every", "reorder_every"}
        unknown = sorted(set(req) - known)
        if unknown:
            raise FaultError(f"unknown fault field(s) {unknown}; expected {sorted(known)}")
        if not req:
            raise FaultError(f"no fault given; expected one of {sorted(known)}")
        if "for_s" in req and "delay_ms" not in req:
            raise FaultError("for_s goes with delay_ms")
        lose_s = _number(req, "lose_s", minimum=0.0)
        delay_ms = _number(req, "delay_ms", minimum=0.0)
        for_s = _number(req, "for_s", minimum=0.0, exclusive=True)
        counts = {k: _count(req, k) for k in ("drop_every", "duplicate_every", "reorder_every")}
        if lose_s is not None:
            self.lose_until = now + lose_s
        if delay_ms is not None:
            self.delay_ms = delay_ms
            self.delay_until = None if for_s is None else now + for_s
        for k, v in counts.items():
            if v is not None:
                setattr(self, k, v)

    def describe(self, now: float) -> dict[str, Any]:
        return {
            "lose_s": round(max(0.0, self.lose_until - now), 3),
            "drop_every": self.drop_every,
            "delay_ms": self.delay_ms if self._delaying(now) else 0.0,
            "delay_for_s": None if self.delay_until is None else round(max(0.0, self.delay_until - now), 3),
            "duplicate_every": self.duplicate_every,
            "reorder_every": self.reorder_every,
        }

    # ------------------------------------------------------------------ traffic
    def losing(self, now: float) -> bool:
        return now < self.lose_until

    def _delaying(self, now: float) -> bool:
        return self.delay_ms > 0.0 and (self.delay_until is None or now < self.delay_until)

    def transmit(self, packet: bytes, ipoc: int, now: float) -> None:
        self.offered += 1
        n = self.offered
        if now < self.lose_until:
            self.stats["lost_out"] += 1
            return
        if self.drop_every and n % self.drop_every == 0:
            self.stats["dropped"] += 1
            return
        if self.reorder_every and n % self.reorder_every == 0 and self._held is None:
            self._held = (packet, ipoc)  # goes out right after the next one
            return
        self._out(packet, ipoc, now)
        if self.duplicate_every and n % self.duplicate_every == 0:
            self.stats["duplicated"] += 1
            self._out(packet, ipoc, now)
        if self._held is not None:
            held, self._held = self._held, None
            self.stats["reordered"] += 1
            self._out(held[0], held[1], now)

    def _out(self, packet: bytes, ipoc: int, now: float) -> None:
        if self._delaying(now):
            self.stats["delayed"] += 1
            self._queue.append((now + self.delay_ms / 1000.0, packet, ipoc))
        else:
            self._send(packet, ipoc)

    def next_due(self) -> float | None:
        return self._queue[0][0] if self._queue else None

    def flush_due(self, now: float) -> None:
        q = self._queue
        while q and q[0][0] <= now:
            _, packet, ipoc = q.popleft()
            self._send(packet, ipoc)

    def _send(self, packet: bytes, ipoc: int) -> None:
        if self.dest is None:
            return
        try:
            self._sock.sendto(packet, self.dest)
        except OSError as e:
            self.send_errors += 1
            if self.send_errors == 1 or self.send_errors % 1000 == 0:
                self._log(f"send to {self.dest[0]}:{self.dest[1]} failed ({self.send_errors}x): {e}")
            return
        self.packets_sent += 1
        self._on_sent(ipoc, time.monotonic())


def _number(req: dict[str, Any], key: str, minimum: float, exclusive: bool = False) -> float | None:
    if key not in req:
        return None
    v = req[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise FaultError(f"{key} must be a number, got {v!r}")
    if v < minimum or (exclusive and v == minimum):
        raise FaultError(f"{key} must be {'>' if exclusive else '>='} {minimum:g}, got {v!r}")
    return float(v)


def _count(req: dict[str, Any], key: str) -> int | None:
    if key not in req:
        return None
    v = req[key]
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise FaultError(f"{key} must be an integer >= 0 (0: off), got {v!r}")
    return v
