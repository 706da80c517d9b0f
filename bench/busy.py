"""Benchmark of a busy robot PC: the mixed client on the real-time kr16rt, quiet and with CPU hogs.

A busy robot PC: the mixed client (bench/workload.py) on the real-time kr16rt, once on a quiet
machine and once with CPU hogs spinning at normal priority, errors and round trips per
command side by side."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable

from harness.system import running

from .latency import percentiles
from .workload import MixResult, cpu_hogs, mixed_session

START = [0.0, -80.0, 100.0, 0.0, 30.0, 0.0]
ORDER = ("GetPositionJoints", "GetStatus", "ForwardCalc", "BackwardCalc", "IsPossible", "MovePTPJoints",
         "EnableAlter", "MoveRTJoints", "DisableAlter")


def mixed_run(seconds: float, hogs: int) -> MixResult:
    """One system, one client, the mix for ``seconds`` with ``hogs`` busy processes."""
    with tempfile.TemporaryDirectory() as logs, running("kr16rt", dummy=False, log_dir=logs) as system, \
            system.client(timeout=60) as client, cpu_hogs(hogs):
        return mixed_session(client, START, seconds)


def busy_table(seconds: float, table: Callable[..., None], hogs: int = 4) -> None:
    quiet = mixed_run(seconds, 0)
    busy = mixed_run(seconds, hogs)
    rows = []
    for word in ORDER:
        cells: list[str] = []
        for result in (quiet, busy):
            samples = result.samples.get(word, [])
            p50, p99 = percentiles(samples) if samples else (float("nan"), float("nan"))
            cells += [str(len(samples)), str(result.errors_of(word)), f"{p50:.2f}", f"{p99:.2f}"]
        rows.append((word, *cells))
    rows.append(("moves true / sent", f"{quiet.moves_true}/{quiet.moves}", "", "", "",
                 f"{busy.moves_true}/{busy.moves}", "", "", ""))
    table(f"A busy robot PC: the mixed client on kr16rt (real time, sim link), {seconds:.0f} s quiet, then "
          f"{seconds:.0f} s with {hogs} CPU hogs on {os.cpu_count()} cores; round trips in ms "
          "(a move's includes its motion); goal: no error the quiet run does not have, every move true",
          ("command", "quiet n", "errors", "p50", "p99", "busy n", "errors", "p50", "p99"), rows)
    for line, reply in busy.errors[:10]:
        print(f"  under load: {line[:60]!r} -> {reply!r}")
