"""Real-time cycle runner: calls ``step()`` every ``period_s`` on its own thread.

Deadlines are absolute on the monotonic clock (``start + k * period``), so sleeping
errors do not accumulate. If a cycle overruns so far that one or more deadlines have
already passed, those ticks are skipped (not caught up in a burst) and counted as
missed; the simulated clock then simply runs slower than wall time.

``publish(state)`` is called after every step with the step's result; exceptions in
``step`` or ``publish`` are logged and counted, they never stop the loop.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

log = logging.getLogger(__name__)

S = TypeVar("S")


@dataclass
class CycleStats:
    cycles: int = 0  # steps executed
    missed: int = 0  # deadlines skipped because a cycle overran
    late: int = 0  # cycles that started after their deadline (but within the period)
    errors: int = 0  # exceptions in step/publish
    max_lateness_s: float = 0.0  # worst start delay after a deadline
    max_work_s: float = 0.0  # worst step + publish time


class CycleRunner(Generic[S]):
    """Runs ``step`` at a fixed period on a daemon thread."""

    def __init__(self, step: Callable[[], S], period_s: float,
                 publish: Callable[[S], None] | None = None, *,
                 clock: Callable[[], float] = time.monotonic,
                 name: str = "rob6-cycle", late_tolerance_s: float | None = None) -> None:
        if period_s <= 0:
            raise ValueError("period must be > 0")
        self.step = step
        self.period_s = float(period_s)
        self.publish = publish
        self.clock = clock
        self.name = name
        self.late_tolerance_s = period_s * 0.25 if late_tolerance_s is None else late_tolerance_s
        self.stats = CycleStats()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # ------------------------------------------------------------------ control
    def start(self) -> None:
        if self._thread is not None and self._thread.is_alive():
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()

    def stop(self, timeout: float | None = 1.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def __enter__(self) -> CycleRunner[S]:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ the loop
    def _run(self) -> None:
        period = self.period_s
        stats = self.stats
        deadline = self.clock()
        while not self._stop.is_set():
            begin = self.clock()
            lateness = begin - deadline
            stats.max_lateness_s = max(stats.max_lateness_s, lateness)
            if lateness > self.late_tolerance_s:
                stats.late += 1
            try:
                state = self.step()
                if self.publish is not None:
                    self.publish(state)
            except Exception:
                stats.errors += 1
                log.exception("cycle %d failed", stats.cycles)
            stats.cycles += 1
            now = self.clock()
            work = now - begin
            stats.max_work_s = max(stats.max_work_s, work)
            deadline += period
            if now > deadline + period:
                # overran past the next deadline: skip the ticks we cannot keep
                skipped = int((now - deadline) // period)
                stats.missed += skipped
                deadline += skipped * period
            delay = deadline - self.clock()
            if delay > 0:
                self._stop.wait(delay)
