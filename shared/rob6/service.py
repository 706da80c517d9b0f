"""The life cycle every rob6 service shares: bus, ownership, logging, verbosity, shutdown.

Start-up failures end in one line on stderr naming the cause and the fix (the
traceback goes to the log at debug level) and an exit code: ``EXIT_REFUSED`` (78) for
what a restart cannot fix (another owner runs, a port is taken, a bad setting), 1 for
anything else.
"""

from __future__ import annotations

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
    logging.getLogger().addHandler(logs.BusLogHandler(bus))

    def on_verbosity(_key: str, payload: bytes) -> None:
        logs.set_verbosity(msgspec.json.decode(payload, type=Verbosity).level)

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
    if exit_code:
        sys.exit(exit_code)
