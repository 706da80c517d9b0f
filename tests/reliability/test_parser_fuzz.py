"""In-process fuzzing of the gateway's framer, argument parser and command dispatch (fast).

Properties (see ``bench/reliability.py``): the framer's lines do not depend on how TCP
chunks the stream and equal a reference split; ``Args`` never raises anything but
``ParseError`` nor returns nan/inf; every command line gets one well-formed reply even when
every service is unreachable.
"""


import pytest
from hypothesis import HealthCheck, given, settings, strategies as st
from pytest import FixtureRequest

from harness.fuzz import (
    COMMAND_NAMES,
    DeadGateway,
    check_args,
    check_execute,
    check_framer,
    command_line_strategy,
    make_dead_gateway,
    reference_lines,
)
from rob6_gateway.commands import _split_command
from rob6_gateway.framing import MAX_LINE, Framer

FAST = settings(max_examples=1000, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@FAST
@given(st.binary(max_size=300), st.lists(st.integers(0, 300), max_size=8), st.integers(1, 40))
def test_framer_is_chunking_independent(stream: bytes, cuts: list[int], max_line: int) -> None:
    check_framer(stream, cuts, max_line)


@FAST
@given(st.lists(st.sampled_from([b"\n", b"\r", b"\r\n", b"\0", b"a", b"x" * 7, b"\xff", b" "]), max_size=60),
       st.lists(st.integers(0, 200), max_size=10), st.integers(1, 12))
def test_framer_terminators_and_nul(parts: list[bytes], cuts: list[int], max_line: int) -> None:
    check_framer(b"".join(parts), cuts, max_line)


@pytest.mark.parametrize("chunk", [1 << 20, 65536, 4096, 1000])
def test_framer_one_mib_line_is_dropped_with_bounded_buffer(chunk: int) -> None:
    stream = b"GetVersion\n" + b"y" * (1 << 20) + b"\nGetVersion\n" + b"z" * (1 << 20)
    check_framer(stream, list(range(0, len(stream), chunk)), MAX_LINE)
    assert [t for t in reference_lines(stream, MAX_LINE)] == [
        ("GetVersion", 0), ("", (1 << 20) + 1), ("GetVersion", 0), ("", 1 << 20)]


def test_framer_buffer_stays_bounded_on_endless_line() -> None:
    framer = Framer()
    for _ in range(64):  # 64 MiB without a newline
        assert framer.feed(b"q" * (1 << 20)) == []
        assert len(framer._buffer) <= MAX_LINE
    assert [(line.text, line.too_long) for line in framer.feed(b"\n")] == [("", 64 * (1 << 20) + 1)]


@FAST
@given(command_line_strategy())
def test_args_never_crash(text: str) -> None:
    check_args(_split_command(text)[2])


@FAST
@given(st.text(max_size=200))
def test_args_never_crash_on_any_unicode(text: str) -> None:
    check_args(text)


@pytest.fixture(scope="module", params=["kr16", "ad850"])
def dead_gateway(request: FixtureRequest) -> DeadGateway:
    return make_dead_gateway(request.param)


@settings(max_examples=800, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(text=command_line_strategy())
def test_every_command_line_gets_one_well_formed_reply(dead_gateway: DeadGateway, text: str) -> None:
    gateway, session = dead_gateway
    check_execute(gateway, session, text)


EXTREMES = ["nan", "inf", "-inf", "1e308", "-1e308", "1e309", "-0", "4.9e-324", "10abc", ""]


@pytest.mark.parametrize("name", COMMAND_NAMES)
def test_every_command_with_extreme_values_and_wrong_arity(dead_gateway: DeadGateway, name: str) -> None:
    gateway, session = dead_gateway
    for value in EXTREMES:
        for arity in (0, 1, 5, 6, 7, 11, 12, 13, 20):
            check_execute(gateway, session, " ".join([name] + [value] * arity))
            check_execute(gateway, session, " ".join([name] + ["1"] * arity + [value, "up"]))
