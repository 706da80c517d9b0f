"""DirectAdeptCmd signal over the simple_message link: the whole system (``rob6 run --robot
ad850 --link simple_message``) switches the outputs of the stand-in controller (adept-sm-sim,
a separate process) through the V+ program's I/O port, byte for byte as the program reads
it (the mode and the number as two records); the controller's outputs and the driver's
state agree afterwards. A port that cannot be reached fails with ``ERROR: driver: ...`` and
``false`` and switches nothing; the motion link is not disturbed either way."""

from __future__ import annotations

from contextlib import AbstractContextManager

import pytest

from harness.client import Client
from harness.ports import free_port
from harness.system import System, driver_state, running
from tests.controllers.adept_controller import AdeptController

pytestmark = pytest.mark.slow


def adept_system(ctl: AdeptController, io_port: int, **env: str) -> AbstractContextManager[System]:
    assert ctl.motion is not None and ctl.state is not None
    return running("ad850", dummy=False, extra_env={
        "ROB6_LINK": "simple_message", "ROB6_SM_HOST": "127.0.0.1", "ROB6_SM_MOTION_PORT": str(ctl.motion[1]),
        "ROB6_SM_STATE_PORT": str(ctl.state[1]), "ROB6_SM_IO_PORT": str(io_port), **env})


def test_signal_switches_the_controllers_outputs() -> None:
    with AdeptController("--state-period", "0.02") as ctl:
        assert ctl.io is not None
        with adept_system(ctl, ctl.io[1]) as system, Client(system.port) as client:
            assert client.ask("DirectAdeptCmd signal 5, -6") == "true\n"
            st = ctl.status()
            assert st["outputs"] == [5, -6] and st["io_requests"] == 2 and st["io_errors"] == 0
            assert driver_state(system).outputs == [5, -6]
            # malformed: refused before anything is sent
            assert client.ask("DirectAdeptCmd signal 7, 1005", lines=2).endswith("nothing was switched\nfalse\n")
            assert ctl.status()["io_requests"] == 2
            # the controller closed the kept I/O connection: rob6 reconnects and switches
            assert ctl.drop_connection("io")
            assert client.ask("DirectAdeptCmd SIGNAL -5 6 2001") == "true\n"
            st = ctl.status()
            assert st["outputs"] == [-5, 6, 2001] and st["io_requests"] == 5 and st["io_errors"] == 0
            assert driver_state(system).outputs == [-5, 6, 2001]
            # the motion link went on meanwhile
            assert client.ask("MovePTPJoints 10 -60 40 0 30 0", timeout=30) == "true\n"
            assert client.read_quiet(0.3) == ""


def test_an_unreachable_io_port_fails_and_switches_nothing() -> None:
    closed = free_port()
    with (AdeptController("--state-period", "0.02") as ctl, adept_system(ctl, closed) as system,
          Client(system.port) as client):
        reply = client.ask("DirectAdeptCmd signal 5, -6", lines=2)
        assert reply == (f"ERROR: driver: cannot reach the controller's I/O port 127.0.0.1:{closed}: "
                         "Connection refused (nothing switched)\nfalse\n")
        assert driver_state(system).outputs == [] and ctl.status()["outputs"] == []
        assert client.ask("GetRobot") == "ad850\n"


def test_an_output_the_controller_lacks_is_never_sent() -> None:
    """SIGNAL of an output the controller has not installed ends the V+ program's I/O task for
    good (adept_ros.v2 line 470; nothing restarts task 4): rob6 sends only the outputs
    ROB6_SM_OUTPUTS lists (default 1-8 and the software signals). Listed wrongly (9 here, the
    stand-in has 1-8), the task ends and every later signal goes unanswered."""
    with AdeptController("--state-period", "0.02") as ctl:
        assert ctl.io is not None
        with adept_system(ctl, ctl.io[1]) as system, Client(system.port) as client:
            assert client.ask("DirectAdeptCmd signal 5, 9", lines=2) == (
                "ERROR: driver: signal 9 is not installed on the controller (ROB6_SM_OUTPUTS=1-8,2001-2512): "
                "SIGNAL of it would end the V+ program's I/O task; nothing was switched\nfalse\n")
            assert ctl.status()["io_requests"] == 0 and ctl.status()["tasks"]["io"]
        with adept_system(ctl, ctl.io[1], ROB6_SM_OUTPUTS="1-16") as system, Client(system.port) as client:
            assert client.ask("DirectAdeptCmd signal 9", lines=2, timeout=30).endswith(
                "within 2000 ms (has its I/O task ended? a.ros() starts it again) (nothing switched)\nfalse\n")
            assert not ctl.status()["tasks"]["io"]
            assert client.ask("DirectAdeptCmd signal 5", lines=2, timeout=30).endswith("(nothing switched)\nfalse\n")
