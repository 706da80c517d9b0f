"""Fuzzing the gateway of a real running system (``rob6 run --dummy``) through TCP.

Every fuzzed line is followed by a ``CM_PING`` sentinel and the reply read up to ``PONG``, so
each non-empty command line is checked to get exactly one well-formed reply (one line; or
``ERROR: …`` + ``false``; ForwardCalc's two lines; nothing for an empty line or a successful
SetAllowedStatus). Read timeouts are generous and only detect hangs. Checked along the way and
at the end (tests run in file order on one system): the gateway process is the same and alive,
the session survives, memory stays bounded, the robot never leaves the widest turn limits
that were ever configured.
"""
import os
from collections.abc import Iterator
from typing import TypedDict

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from harness.fuzz import COMMAND_NAMES, EXTREMES_TCP, TcpFuzzer, command_line_strategy, vm_rss_kib
from harness.system import running


class _Settings(TypedDict):
    """The hypothesis settings the TCP tests share."""

    deadline: None
    database: None
    suppress_health_check: list[HealthCheck]


TCP = _Settings(deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.fixture(scope="module")
def fuzzer() -> Iterator[TcpFuzzer]:
    with running("kr16", dummy=True, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system:
        fuzzer = TcpFuzzer(system)
        fuzzer.start()
        fuzzer.rss0 = vm_rss_kib(fuzzer.gateway_pid)
        yield fuzzer
        fuzzer.client.close()


def _clean(fuzzer: TcpFuzzer) -> None:
    assert fuzzer.problems == []
    assert fuzzer.hangs == 0
    assert fuzzer.alive()


@settings(max_examples=500, **TCP)
@given(text=command_line_strategy())
def test_random_command_lines(fuzzer: TcpFuzzer, text: str) -> None:
    fuzzer.line(text)
    _clean(fuzzer)


@pytest.mark.parametrize("terminated", [True, False])
def test_one_mib_lines(fuzzer: TcpFuzzer, terminated: bool) -> None:
    fuzzer.oversized(1 << 20, terminated)
    fuzzer.oversized(65537, terminated)
    _clean(fuzzer)


def test_pipelined_flood_of_2000_commands_in_one_write(fuzzer: TcpFuzzer) -> None:
    fuzzer.flood(2000)
    _clean(fuzzer)


def test_pipelined_flood_of_mixed_commands(fuzzer: TcpFuzzer) -> None:
    # 500 x (unknown, parse error, ForwardCalc, empty line): 500 * (1 + 2 + 2 + 0) lines then PONG
    block = b"nope\nMovePTPJoints 1 2\nForwardCalc 1 2 3 4 5 6\n\n"
    fuzzer.client.sock.sendall(block * 500 + b"CM_PING\n")
    lines = fuzzer.client.until_pong()
    assert len(lines) == 2500
    assert lines[:5] == [b"ERROR: nope", b"ERROR: incorrect joints", b"false", lines[3], b"noflip up lefty"]


@settings(max_examples=150, **TCP)
@given(text=command_line_strategy(), cuts=st.lists(st.integers(0, 200), min_size=1, max_size=6))
def test_commands_split_across_tcp_segments(fuzzer: TcpFuzzer, text: str, cuts: list[int]) -> None:
    fuzzer.split(text, cuts)
    _clean(fuzzer)


@pytest.mark.parametrize("value", EXTREMES_TCP)
def test_every_command_with_extreme_values_and_wrong_arity(fuzzer: TcpFuzzer, value: str) -> None:
    for name in COMMAND_NAMES:
        for arity in (0, 1, 6, 7, 12, 13):
            fuzzer.line(" ".join([name] + [value] * arity))
    _clean(fuzzer)


def test_non_ascii_nul_and_raw_bytes(fuzzer: TcpFuzzer) -> None:
    for text in ["GetVersion\x00garbage", "\x00", "é", "GetVersion\xff", "\x80\x81\x82",
                 "ForwardCalc 1\x002 3", "\r", "\r\r", " ", "\t\x0b\x0c", "Hello Robot"]:
        fuzzer.line(text)
    _clean(fuzzer)


def test_moves_never_leave_narrowed_turn_limits(fuzzer: TcpFuzzer) -> None:
    assert fuzzer.narrowed_limit_moves(150) > 10
    _clean(fuzzer)


def test_invariants_after_the_fuzz(fuzzer: TcpFuzzer) -> None:
    assert fuzzer.inputs > 1000
    fuzzer.check_position()
    assert fuzzer.limit_violations == 0
    assert not any("limit monitor" in line for line in fuzzer.system.output)
    # the same gateway process, session still usable, memory bounded
    assert fuzzer.alive()
    os.kill(fuzzer.gateway_pid, 0)
    fuzzer.flood(10)
    _clean(fuzzer)
    grown_mib = (vm_rss_kib(fuzzer.gateway_pid) - fuzzer.rss0) / 1024
    assert grown_mib < 64, f"gateway VmRSS grew by {grown_mib:.1f} MiB"
