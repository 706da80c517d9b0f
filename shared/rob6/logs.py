"""Logging for every rob6 process: console output plus a copy of each record on the bus.

The protocol's verbosity (SetVerbosity 0..4) maps to log levels; the gateway publishes
changes on ``rob6/<id>/control/verbosity`` and every process follows.
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from .messages import LogRecord

if TYPE_CHECKING:
    from .bus import Bus

#: the protocol's verbosity levels: 0 nothing, 1 errors, 2 +warnings, 3 +communication, 4 all
VERBOSITY_LEVELS = {0: logging.CRITICAL + 10, 1: logging.ERROR, 2: logging.WARNING,
                    3: logging.INFO, 4: logging.DEBUG}


def configure(service: str, level: str | int = "WARNING") -> None:
    logging.basicConfig(
        stream=sys.stderr,
        format=f"%(asctime)s {service} %(levelname)s %(name)s: %(message)s",
        level=level,
        force=True,
    )


def set_verbosity(level: int) -> None:
    logging.getLogger().setLevel(VERBOSITY_LEVELS[level])


@contextmanager
def to_bus(bus: Bus) -> Iterator[None]:
    """Every record goes to the bus too while the block runs (``BusLogHandler``); after it,
    the root logger no longer holds the bus, so a stopped service's objects can go."""
    handler = BusLogHandler(bus)
    logging.getLogger().addHandler(handler)
    try:
        yield
    finally:
        logging.getLogger().removeHandler(handler)


class BusLogHandler(logging.Handler):
    """Sends every record to the recorder (``/log``) with the traces: batched, from the bus's
    trace thread, kept in its publisher's cache for a recorder that was away. Logging never
    waits for the network, and no record is lost while the recorder restarts."""

    def __init__(self, bus: Bus) -> None:
        super().__init__()
        self.bus = bus

    def emit(self, record: logging.LogRecord) -> None:
        self.bus.trace(f"log/{self.bus.service}", LogRecord(
            t=record.created if record.created else time.time(),
            service=self.bus.service, instance=self.bus.instance,
            level=record.levelname, name=record.name, message=record.getMessage(),
        ))
