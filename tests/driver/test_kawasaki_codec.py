"""The kawasaki link's side of rob6-kas 2: what it writes (points, cancels) and how it reads the
controller's lines, every bad line refused with a reason; the link's settings checked in one line."""

from __future__ import annotations

import numpy as np
import pytest

from rob6_driver.links.kawasaki import KawasakiSettings
from rob6_driver.links.kawasaki_codec import Ack, Hello, KasError, State, cancel, parse, point

STATE = b"S 12 0.000 90.000 -30.500 0.000 0.000 0.000 1 0 1 3 17 0 2 1"


def test_points_and_cancel() -> None:
    assert point(1, [10, -20, 30, 0, 45, -90], 0.048, False) == (
        b"P 1 10.000 70.000 -30.000 0.000 -45.000 90.000 48 0\n")
    assert point(2, np.zeros(6), 0.0001, True).endswith(b" 1 1\n")  # at least 1 ms
    assert point(3, np.zeros(6), 1000.0, True).endswith(b" 99999 1\n")  # at most 99999 ms
    assert cancel(5) == b"C 5\n"


def test_the_controllers_lines() -> None:
    assert parse(b"H rob6-kas 3 64") == Hello(64)
    assert parse(b"A 17 0 3\r") == Ack(17, 0, 3)
    st = parse(STATE)
    assert isinstance(st, State)
    assert st.joints == (0.0, 90.0, -30.5, 0.0, 0.0, 0.0)
    assert (st.motor, st.teach, st.moving, st.queued, st.done, st.error, st.underruns, st.running) == (
        True, False, True, 3, 17, 0, 2, True)
    stopped = parse(STATE[:-1] + b"0")  # rob6_motion not running (TASK(1) not 1)
    assert isinstance(stopped, State) and not stopped.running
    assert parse(b"S     12 " + STATE[5:]) == st  # AS pads its numbers: runs of spaces


@pytest.mark.parametrize("line, error", [
    (b"", "an empty line"),
    (b"X 1", "an unknown message type 'X'"),
    (b"H rob6-kas 1 64", "protocol version 1 (rob6 speaks 3): update the AS program"),
    (b"H other 1 64", "a hello that is not rob6-kas: 'H other 1 64'"),
    (b"A 1 0", "an answer with 2 fields (3 expected): 'A 1 0'"),
    (b"A x 0 1", "sequence 'x' is not an integer"),
    (STATE.replace(b" 1 0 1 3 ", b" 1 2 1 3 "), "flag '2' is not 0 or 1"),
    (STATE.replace(b"-30.500", b"nan"), "joint 'nan' is not finite"),
    (STATE.replace(b"-30.500", b"abc"), "joint 'abc' is not a number"),
    (STATE[:-2], "a state with 14 fields (15 expected): 'S 12 0.000 90.000 -30.500 0.000 0.000 0.000 1 0 1 3 17 0 2'"),
    (b"A " + b"1" * 200, "a line of 203 characters (at most 120)"),
    (b"A \xff 0 1", "a line that is not ASCII"),
])
def test_bad_lines_are_refused_with_a_reason(line: bytes, error: str) -> None:
    with pytest.raises(KasError) as exc:
        parse(line)
    assert str(exc.value) == error


@pytest.mark.parametrize("settings, error", [
    (KawasakiSettings(host=" "), "ROB6_KAS_HOST is empty: give the controller's address"),
    (KawasakiSettings(port=70000), "ROB6_KAS_PORT=70000: expected a TCP port 1..65535"),
    (KawasakiSettings(period_s=0), "ROB6_KAS_PERIOD=0: expected seconds, more than 0 and at most 1"),
    (KawasakiSettings(period_s=float("nan")), "ROB6_KAS_PERIOD=nan: expected seconds, more than 0 and at most 1"),
])
def test_settings_that_cannot_work(settings: KawasakiSettings, error: str) -> None:
    with pytest.raises(ValueError) as exc:
        settings.check()
    assert str(exc.value) == error
