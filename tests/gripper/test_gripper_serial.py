"""SchunkGripper (pyserial, SMP) against the fake module on a pseudo-terminal."""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Iterator

import pytest

from rob6_gripper import smp
from rob6_gripper.backend import ERROR, GRIPPING, IDLE
from rob6_gripper.fake_device import FakeSmpDevice
from rob6_gripper.schunk import SchunkGripper
from tests.gripper.stopping import stopped_mid_move

RT = 0.2  # response timeout used in these tests, s
SCALE = 5.0  # the fake's simulated time runs 5x faster than the wall clock


@pytest.fixture
def dev() -> Iterator[FakeSmpDevice]:
    d = FakeSmpDevice(module_id=12, object_width=0.030, time_scale=SCALE).start()
    yield d
    d.close()


@pytest.fixture
def grip(dev: FakeSmpDevice) -> Iterator[SchunkGripper]:
    g = SchunkGripper(dev.port, 9600, 12, response_timeout=RT, retries=1, poll_interval=0.01)
    yield g
    g.close()


def commands(dev: FakeSmpDevice, code: int) -> list[smp.Frame]:
    return [f for f in dev.received if f.command == code]


def test_has_gripper_and_state(grip: SchunkGripper) -> None:
    assert grip.has_gripper()
    s = grip.state()
    assert (s.position, s.velocity, s.current, s.mode, s.error) == (0.040, 0.0, 0.0, IDLE, "")


def test_reference_then_move(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.model.referenced = False
    r = grip.move_to_position(0.05)
    assert not r and "module refused MOVE POS: NOT REFERENCED (0x06)" in r.error
    dev.model.w = 0.012
    r = grip.go_home(timeout=3)
    assert r and r.position == pytest.approx(0.040)
    assert len(commands(dev, smp.CMD_REFERENCE)) == 1
    assert grip.move_to_position(0.05)


def test_move_to_position(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    t0 = time.monotonic()
    r = grip.move_to_position(0.060, timeout=3)
    assert r.ok and r.position == pytest.approx(0.060, abs=1e-6)
    elapsed = time.monotonic() - t0
    assert elapsed < 1.0  # 0.32 s simulated at 5x, plus polling
    [cmd] = commands(dev, smp.MOVE_POS)
    assert struct.unpack("<f", cmd.payload)[0] == pytest.approx(60.0)  # mm on the wire
    assert grip.state().mode == IDLE


def test_move_outside_stroke_rejected_without_sending(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    for target in (-0.001, 0.0701, 1.0):
        r = grip.move_to_position(target)
        assert not r and "outside the stroke 0.000..0.070 m" in r.error
    assert commands(dev, smp.MOVE_POS) == []


def test_move_to_position_blocked_by_object(grip: SchunkGripper) -> None:
    r = grip.move_to_position(0.020, timeout=3)
    assert not r and "blocked at 0.0300 m" in r.error
    assert grip.state().mode == GRIPPING


def test_current_move_grips_object(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    r = grip.move_current(-1.0, timeout=3)
    assert r.ok and r.position == pytest.approx(0.030, abs=1e-6)
    [cmd] = commands(dev, smp.MOVE_CUR)
    assert struct.unpack("<f", cmd.payload)[0] == -1.0
    s = grip.state()
    assert s.mode == GRIPPING and s.current == -1.0 and s.position == pytest.approx(0.030)
    assert dev.model.force == pytest.approx(40.0)


def test_current_move_opens_to_stroke_end(grip: SchunkGripper) -> None:
    r = grip.move_current(2.0, timeout=3)
    assert r and r.position == pytest.approx(0.070)
    assert grip.state().mode == IDLE


def test_current_refused_by_module(grip: SchunkGripper) -> None:
    r = grip.move_current(-9.0)
    assert not r and "module refused MOVE CUR: INFO WRONG PARAMETER (0x1E)" in r.error


def test_state_observable_while_moving_and_stop(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.time_scale = 1.0
    dev.model.w = 0.0
    r = stopped_mid_move(grip, lambda: grip.move_to_position(0.070, 5), 0.070, 0.002)
    assert not r and "stopped by a stop command" in r.error
    assert commands(dev, smp.CMD_STOP)


def test_error_and_acknowledge(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.inject_error(0xDA)
    s = grip.state()
    assert s.mode == ERROR and s.error == "ERROR TOW (0xDA)"
    r = grip.move_current(-1.0)
    assert not r and "ERROR TOW (0xDA)" in r.error
    assert grip.acknowledge()
    assert grip.state().mode == IDLE
    assert grip.move_current(-1.0, timeout=3)


def test_error_during_motion_fails_the_motion(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.time_scale = 1.0
    threading.Timer(0.15, dev.inject_error, args=(0xDE,)).start()
    r = grip.move_current(-0.5, timeout=3)
    assert not r and "module error ERROR CURRENT (0xDE)" in r.error


@pytest.mark.parametrize("split", [1, 3])
def test_framing_split_across_reads(dev: FakeSmpDevice, grip: SchunkGripper, split: int) -> None:
    dev.split = split
    assert grip.has_gripper()
    assert grip.move_current(-1.0, timeout=3)
    assert grip.state().position == pytest.approx(0.030)


def test_fragmented_replies(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.fragment_size = 4
    s = grip.state()
    assert s.mode == IDLE and s.position == pytest.approx(0.040)
    assert grip.move_to_position(0.05, timeout=3)


def test_garbage_before_replies(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.garbage = b"\x00\xff\x07\x0c\xf0\x55"  # includes a false frame start
    assert grip.has_gripper()
    assert grip.move_to_position(0.035, timeout=3)


def test_bad_crc(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.corrupt_crc = True
    t0 = time.monotonic()
    assert not grip.has_gripper()
    assert time.monotonic() - t0 < 2 * RT + 0.3  # one retry
    s = grip.state()
    assert s.mode == ERROR and "bad CRC" in s.error
    r = grip.move_to_position(0.05)
    assert not r and "bad CRC" in r.error
    dev.corrupt_crc = False
    assert grip.has_gripper()


def test_slow_reply_within_timeout_ok_beyond_timeout_fails(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.delay = RT / 4
    assert grip.has_gripper()
    dev.delay = RT * 2.5  # the retry's window closes before the first reply comes
    r = grip.move_to_position(0.05)
    assert not r and "no reply to MOVE POS within 0.200 s" in r.error
    dev.delay = 0.0


def test_silent_module(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.silent = True
    t0 = time.monotonic()
    assert not grip.has_gripper()
    r = grip.go_home(timeout=1)
    assert not r and "no reply to CMD REFERENCE" in r.error
    assert time.monotonic() - t0 < 6 * RT + 0.5  # has_gripper, reference, the stop after it
    dev.silent = False
    assert grip.has_gripper()


def test_module_stops_answering_mid_motion(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.time_scale = 1.0
    threading.Timer(0.2, setattr, args=(dev, "silent", True)).start()
    t0 = time.monotonic()
    r = grip.move_current(-0.5, timeout=5)
    assert not r and "no reply to GET STATE" in r.error
    assert time.monotonic() - t0 < 0.2 + 2 * RT + 0.5


def test_unplugged_mid_motion(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.time_scale = 1.0
    threading.Timer(0.2, dev.unplug).start()
    t0 = time.monotonic()
    r = grip.move_current(-0.5, timeout=2)
    assert not r and "serial port" in r.error
    assert time.monotonic() - t0 < 2
    assert not grip.has_gripper()
    assert grip.state().mode == ERROR
    assert not grip.stop()


def test_motion_timeout_sends_stop(dev: FakeSmpDevice, grip: SchunkGripper) -> None:
    dev.time_scale = 0.2
    t0 = time.monotonic()
    r = grip.move_to_position(0.010, timeout=0.3)
    assert not r and "not finished within 0.300 s" in r.error
    assert time.monotonic() - t0 < 0.3 + 2 * RT
    assert commands(dev, smp.CMD_STOP)


def test_no_such_port() -> None:
    g = SchunkGripper("/dev/does-not-exist", response_timeout=RT)
    assert not g.has_gripper()
    r = g.move_current(-1)
    assert not r and "cannot open serial port /dev/does-not-exist" in r.error
    assert g.state().mode == ERROR


def test_wrong_module_id(dev: FakeSmpDevice) -> None:
    g = SchunkGripper(dev.port, module_id=13, response_timeout=RT)
    assert not g.has_gripper()
    g.close()


def test_go_home_with_explicit_home_position() -> None:
    from rob6_gripper.sim import GripperParams

    # a module whose reference run ends at 0 mm; home_position adds the move to 4 cm
    with FakeSmpDevice(params=GripperParams(home_position=0.0), time_scale=SCALE) as d:
        g = SchunkGripper(d.port, response_timeout=RT, poll_interval=0.01, home_position=0.040)
        r = g.go_home(timeout=3)
        assert r and r.position == pytest.approx(0.040)
        assert [f.command for f in d.received if f.command != smp.GET_STATE] == \
            [smp.CMD_REFERENCE, smp.MOVE_POS]
        g.close()
