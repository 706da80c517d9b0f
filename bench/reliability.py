"""Reliability campaign: fuzzing the gateway (in process and through a real system).

    .venv/bin/python -m bench.reliability [--parser-examples 100000] [--tcp-examples 3000]

prints the figures table of RELIABILITY.md (run from the project root: it imports the
development harness, ``harness/``).

The building blocks and the invariants every fuzzed input is checked against are those the
test suite uses too (``harness/fuzz.py``): this campaign runs them with larger budgets, adds
the recording check and the fault injection (``harness/faults.py``).
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings, strategies as st

from harness.fuzz import (
    FuzzClient,
    TcpFuzzer,
    _blocking_ping,
    _random_line,
    check_args,
    check_execute,
    check_framer,
    command_line_strategy,
    make_dead_gateway,
    vm_rss_kib,
)
from harness.system import System
from rob6.robots import DEFAULT_ROBOT
from rob6_gateway.commands import _split_command
from rob6_gateway.framing import _clean


def records_session(system: System, examples: int, seed: int = 2) -> int:
    """Session 1 of a fresh system: a known number of non-empty lines (counted for the
    recorder check: every one must be in the session's MCAP file). Returns the count."""
    rng = random.Random(seed)
    client = FuzzClient(system.port)
    sent = 1  # the handshake line
    client.sock.sendall(b"GetVersion\n" * 2000 + b"CM_PING\n")
    assert len(client.until_pong()) == 2000
    sent += 2001
    while examples > 0:
        text = _random_line(rng)
        name = _split_command(_clean(text.encode("latin-1")))[0]
        if not _clean(text.encode("latin-1")) or name in ("Quit", "CM_PING") or _blocking_ping(text):
            continue
        client.sock.sendall(text.encode("latin-1") + b"\nCM_PING\n")
        client.until_pong()
        sent += 2
        examples -= 1
    client.close()
    return sent


def recorded_lines(log_dir: str, session: int = 1) -> int:
    from rob6_recorder.inspect import summarize
    total = 0
    for path in Path(log_dir).glob(f"*_session{session}.mcap"):
        for s in summarize(path).sessions.values():
            total += s.lines
    return total


def run_tcp_campaign(system: System, examples: int, seed: int = 1) -> dict[str, Any]:
    rng = random.Random(seed)
    fuzzer = TcpFuzzer(system)
    fuzzer.start()
    rss0 = vm_rss_kib(fuzzer.gateway_pid)
    for _ in range(3):
        fuzzer.oversized()
    fuzzer.oversized(terminated=False)
    fuzzer.flood()
    for i in range(examples):
        text = _random_line(rng)
        if rng.random() < 0.1:
            fuzzer.split(text, [rng.randrange(len(text) + 2) for _ in range(3)])
        else:
            fuzzer.line(text)
        if i % 500 == 0 and not fuzzer.alive():
            break
    fuzzer.flood()
    fuzzer.narrowed_limit_moves(500)
    fuzzer.check_position()
    rss1 = vm_rss_kib(fuzzer.gateway_pid)
    alive = fuzzer.alive()
    fuzzer.client.close()
    return {"inputs": fuzzer.inputs, "hangs": fuzzer.hangs, "problems": fuzzer.problems,
            "alive": alive, "rss0": rss0, "rss1": rss1, "reconnects": fuzzer.reconnects,
            "limit_violations": fuzzer.limit_violations, "moves_ok": fuzzer.moves_ok}


# ============================================================== the campaign
def run_parser_campaign(examples: int) -> dict[str, int]:
    """Hypothesis-driven in-process fuzz; returns counts. Failures raise (crash = 1)."""
    counts: dict[str, int] = {}
    budget = settings(max_examples=examples, deadline=None, database=None,
                      suppress_health_check=list(HealthCheck))

    n = [0]

    @budget
    @given(st.binary(max_size=300), st.lists(st.integers(0, 300), max_size=8), st.integers(1, 40))
    def framer(stream: bytes, cuts: list[int], max_line: int) -> None:
        n[0] += 1
        check_framer(stream, cuts, max_line)
    framer()
    counts["framer"] = n[0]

    n2 = [0]

    @budget
    @given(command_line_strategy())
    def args(text: str) -> None:
        n2[0] += 1
        check_args(_split_command(text)[2])
    args()
    counts["args"] = n2[0]

    gateway, session = make_dead_gateway()
    n3 = [0]

    @budget
    @given(command_line_strategy())
    def execute(text: str) -> None:
        n3[0] += 1
        check_execute(gateway, session, text)
    execute()
    counts["execute"] = n3[0]
    return counts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parser-examples", type=int, default=35000,
                        help="hypothesis examples per in-process target (framer, args, execute)")
    parser.add_argument("--tcp-examples", type=int, default=5000)
    parser.add_argument("--robot", default=DEFAULT_ROBOT)
    parser.add_argument("--skip-faults", action="store_true")
    opts = parser.parse_args(argv)
    from harness.system import running

    t0 = time.monotonic()
    crashes = 0
    parser_counts: dict[str, int | str]
    try:
        parser_counts = dict(run_parser_campaign(opts.parser_examples))
    except Exception as exc:  # a falsified property
        crashes += 1
        parser_counts = {"error": repr(exc)[:300]}
    t1 = time.monotonic()
    log_dir = tempfile.mkdtemp(prefix="rob6-reliability-")
    with running(opts.robot, dummy=True, log_dir=log_dir, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system:
        records_sent = records_session(system, 1000)
        tcp = run_tcp_campaign(system, opts.tcp_examples)
        violations = sum("limit monitor" in line for line in system.output)
    records_lost = records_sent - recorded_lines(log_dir)
    t2 = time.monotonic()
    faults = None
    if not opts.skip_faults:
        from harness.faults import run_fault_campaign
        faults = run_fault_campaign()
    t3 = time.monotonic()

    in_process = sum(v for v in parser_counts.values() if isinstance(v, int))
    rows = [
        ("in-process inputs (Framer / Args / Gateway.execute)",
         f"{in_process} ({' / '.join(str(parser_counts.get(k, '-')) for k in ('framer', 'args', 'execute'))})"),
        ("TCP inputs through a real gateway", str(tcp["inputs"])),
        ("total fuzzed inputs", str(in_process + tcp["inputs"])),
        ("crashes (in-process property failures + gateway deaths)", str(crashes + (0 if tcp["alive"] else 1))),
        ("hangs (no reply within 15 s)", str(tcp["hangs"])),
        ("malformed / missing replies", str(sum(1 for p in tcp["problems"] if p[1] != "hang" and p[0] != "limit"))),
        ("reconnects needed (Quit + lost connections)", str(tcp["reconnects"])),
        ("gateway VmRSS before / after (MiB)", f"{tcp['rss0'] / 1024:.1f} / {tcp['rss1'] / 1024:.1f}"),
        ("limit violations (outside widest turn limits)", str(tcp["limit_violations"])),
        ("successful moves checked against the limits", str(tcp["moves_ok"])),
        ("driver limit-monitor events in the logs", str(violations)),
        ("client lines recorded / lost (session 1, no fault on the recorder)",
         f"{records_sent - records_lost} / {records_lost}"),
    ]
    if faults is not None:
        rows += [
            ("faults injected", str(faults["injected"])),
            ("faults survived (error/timeout reply, same session recovered)", str(faults["recovered"])),
            ("gateway restarts needed", str(faults["gateway_restarts"])),
        ]
    rows.append(("wall time (s): parser / TCP / faults", f"{t1 - t0:.0f} / {t2 - t1:.0f} / {t3 - t2:.0f}"))
    width = max(len(r[0]) for r in rows)
    print(f"| {'figure'.ljust(width)} | value |")
    print(f"|{'-' * (width + 2)}|-------|")
    for name, value in rows:
        print(f"| {name.ljust(width)} | {value} |")
    for p in tcp["problems"][:20]:
        print("problem:", repr(p)[:300])
    if faults:
        for p in faults["problems"][:20]:
            print("fault problem:", repr(p)[:300])
    if "error" in parser_counts:
        print("in-process failure:", parser_counts["error"])
    bad = crashes or not tcp["alive"] or tcp["hangs"] or tcp["problems"] or (faults and faults["problems"])
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
