"""The life cycle every rob6 service shares: bus, ownership, logging, verbosity, shutdown.

Start-up failures end in one line on stderr naming the cause and the fix (the
traceback goes to the log at debug level) and an exit code: ``EXIT_REFUSED`` (78) for
what a restart cannot fix (another owner runs, a port is taken, a bad setting), 1 for
anything else.
"""

from __future__ import annotations

import ctypes
import gc
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable

import msgspec

from . import logs
from .bus import Bus
from .config import BusSettings
from .errors import ServiceError
from .messages import SERVICES, Verbosity
from .ownership import EXIT_REFUSED, OWNER_SERVICES, Claim, ClaimRefused

log = logging.getLogger("rob6.service")

#: what each service needs before it announces itself, so that "alive" means it can
#: serve: the planner moves through the driver and chooses configurations with the
#: kinematics; the gateway needs everything a client command can reach
NEEDS: dict[str, tuple[str, ...]] = {
    "planner": ("driver", "kinematics"),
    "gateway": ("driver", "planner", "kinematics", "gripper"),
    "ros": ("driver", "planner"),
}
NEEDS_WAIT_S = 30.0
#: how long a stopping service waits for the threads it started to end
THREADS_END_S = 5.0


class StartupError(ServiceError):
    """Why rob6 or one of its services cannot start, in one line naming the cause and what
    to do (no traceback). ``rob6 run`` prints it and exits 1; a service whose ``setup``
    raises it exits ``EXIT_REFUSED``: a restart cannot fix it."""


def needed(name: str) -> tuple[str, ...]:
    """The services ``name`` waits for: its needs among those this deployment runs.

    ``rob6 run --service ...`` starts a subset and says which in ``ROB6_SERVICES``;
    a container deployment runs them all.
    """
    running = [s.strip() for s in os.environ.get("ROB6_SERVICES", ",".join(SERVICES)).split(",")]
    return tuple(s for s in NEEDS.get(name, ()) if s in running)


def missing_needs(bus: Bus, name: str) -> list[str]:
    return [s for s in needed(name) if not bus.instances(s)]


def wait_for_needs(bus: Bus, name: str, stop: threading.Event, timeout: float = NEEDS_WAIT_S) -> None:
    """Until what ``name`` needs is alive, ``stop`` is set, or ``timeout`` passed."""
    deadline = time.monotonic() + timeout
    while (missing := missing_needs(bus, name)) and not stop.wait(0.02):
        if time.monotonic() > deadline:  # serve anyway: their commands answer "<service> unavailable"
            log.warning("%s: %s not alive after %.0f s; starting without", name, ", ".join(missing), timeout)
            return


#: prctl(2)'s option that asks for a signal when the parent goes
_PR_SET_PDEATHSIG = 1


def follow_launcher() -> None:
    """A process that ``rob6 run`` started ends when the launcher does, even if it is killed.

    The launcher puts its children in a process group of their own (a terminal's Ctrl-C
    reaches the launcher alone, which stops them in order), so the kernel must tell them
    when it is gone: SIGTERM, the same clean stop as the launcher's. Nothing elsewhere
    (``ROB6_LAUNCHER_PID`` unset: a container, a service started by hand).
    """
    launcher = os.environ.get("ROB6_LAUNCHER_PID")
    if not launcher or not sys.platform.startswith("linux"):
        return
    ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != int(launcher):  # it went before the request above was made
        sys.exit(0)


def end_threads(timeout: float = THREADS_END_S) -> None:
    """The last step of a stop: every other thread of the process ends first.

    From here on SIGTERM and SIGINT are ignored: the process is ending anyway, and at
    the interpreter's exit Python puts back their default action, so a second stop
    signal (the launcher's, after a client's Shutdown had already stopped the service)
    would kill it then (exit code -15) instead of letting it end with 0.

    A daemon thread still running when the interpreter exits keeps whatever it references
    alive through finalization, and the native modules then report their objects as
    leaked (nanobind: ``leaked 6 instances ... ruckig.Trajectory``). The service's cleanup
    and the bus's close tell each thread to end; this waits for them, then collects what
    is left in reference cycles while every module is still there.
    """
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, signal.SIG_IGN)
    deadline = time.monotonic() + timeout
    for thread in _threads():
        thread.join(max(0.0, deadline - time.monotonic()))
    left = [t.name for t in _threads()]
    if left:
        log.warning("still running after %.0f s of stopping: %s", timeout, ", ".join(left))
    gc.collect()


def _threads() -> list[threading.Thread]:
    """The threads of the process a stop waits for: not this one, and not the stand-ins Python
    makes for a native thread that called into it (Zenoh's, foxglove's: ``_DummyThread``,
    which cannot be joined and which their library ends)."""
    return [t for t in threading.enumerate() if t is not threading.current_thread()
            and t is not threading.main_thread() and not isinstance(t, threading._DummyThread)]


def fail(name: str, message: str, code: int) -> None:
    """Say why the start failed in one line and exit."""
    print(message if message.startswith("rob6") else f"rob6-{name}: {message}", file=sys.stderr, flush=True)
    sys.exit(code)


def claim(bus: Bus, on_conflict: Callable[[str], None]) -> Claim | None:
    """Claim an owner service's role (see rob6.ownership); exits with one line if refused."""
    if bus.service not in OWNER_SERVICES:
        return None
    try:
        return Claim(bus, on_conflict)
    except ClaimRefused as exc:
        bus.close()
        fail(bus.service, str(exc), EXIT_REFUSED)
    return None  # not reached


def run(settings: BusSettings, name: str, log_level: str,
        setup: Callable[[Bus], Callable[[], None] | None]) -> None:
    """Open the bus, claim the role, let ``setup(bus)`` declare the service, run until told to stop.

    Stops on SIGTERM/SIGINT, a ``Shutdown`` published by the gateway, or an earlier
    owner of the role appearing (exit ``EXIT_REFUSED``); ``setup`` may return a
    cleanup function, called before the session closes.
    """
    logs.configure(name, log_level)
    follow_launcher()
    exit_code = _serve(settings, name, setup)
    end_threads()  # the service's objects are unreachable now: gone before the interpreter
    if exit_code:
        sys.exit(exit_code)


def _serve(settings: BusSettings, name: str, setup: Callable[[Bus], Callable[[], None] | None]) -> int:
    """``run``'s service, from the bus's opening to its close; the exit code."""
    stop = threading.Event()
    exit_code = 0
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())

    def stand_down(_message: str) -> None:
        nonlocal exit_code
        exit_code = EXIT_REFUSED
        stop.set()

    bus = Bus(settings, name)
    ownership = claim(bus, stand_down)

    def on_verbosity(_key: str, payload: bytes) -> None:
        logs.set_verbosity(msgspec.json.decode(payload, type=Verbosity).level)

    with logs.to_bus(bus):
        bus.subscribe("control/verbosity", on_verbosity)
        bus.subscribe("control/shutdown", lambda *_: stop.set())
        wait_for_needs(bus, name, stop)
        cleanup = None
        try:
            try:
                cleanup = setup(bus)
            except StartupError as exc:
                fail(name, str(exc), EXIT_REFUSED)
            except Exception as exc:
                log.debug("%s failed to start", name, exc_info=True)
                fail(name, f"failed to start: {type(exc).__name__}: {exc} (ROB6_LOG_LEVEL=DEBUG shows where)", 1)
            log.info("%s %s up (robot %s, id %s)", name, bus.instance, settings.robot, settings.robot_id)
            stop.wait()
        finally:
            log.info("%s %s stopping", name, bus.instance)
            if cleanup:
                cleanup()
            if ownership is not None:
                ownership.release()
    bus.close()
    return exit_code
