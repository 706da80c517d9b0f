"""The life cycle every rob6 service shares: bus, logging, verbosity, shutdown, signals."""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import Callable

import msgspec

from . import logs
from .bus import Bus
from .config import BusSettings
from .messages import Verbosity

log = logging.getLogger("rob6.service")


def run(settings: BusSettings, name: str, log_level: str,
        setup: Callable[[Bus], Callable[[], None] | None]) -> None:
    """Open the bus, let ``setup(bus)`` declare the service, run until told to stop.

    Stops on SIGTERM/SIGINT or a ``Shutdown`` published by the gateway; ``setup`` may
    return a cleanup function, called before the session closes.
    """
    logs.configure(name, log_level)
    stop = threading.Event()
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    bus = Bus(settings, name)
    logging.getLogger().addHandler(logs.BusLogHandler(bus))

    def on_verbosity(_key: str, payload: bytes) -> None:
        logs.set_verbosity(msgspec.json.decode(payload, type=Verbosity).level)

    bus.subscribe("control/verbosity", on_verbosity)
    bus.subscribe("control/shutdown", lambda *_: stop.set())
    cleanup = None
    try:
        cleanup = setup(bus)
        log.info("%s %s up (robot %s, id %s)", name, bus.instance, settings.robot, settings.robot_id)
        stop.wait()
    finally:
        log.info("%s %s stopping", name, bus.instance)
        if cleanup:
            cleanup()
        bus.close()
