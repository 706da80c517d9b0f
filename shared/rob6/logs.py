"""Logging for every rob6 process: console output plus a copy of each record on the bus.

The protocol's verbosity (SetVerbosity 0..4) maps to log levels; the gateway publishes
changes on ``rob6/<id>/control/verbosity`` and every process follows.
"""

from __future__ import annotations

import logging
import sys
import time
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


class BusLogHandler(logging.Handler):
    """Publishes every record on ``rob6/<id>/log/<service>`` (for the recorder)."""

    def __init__(self, bus: Bus) -> None:
        super().__init__()
        self.bus = bus
        self._busy = False

    def emit(self, record: logging.LogRecord) -> None:
        if self._busy:  # a record logged while publishing one: do not recurse
            return
        self._busy = True
        try:
            self.bus.publish(f"log/{self.bus.service}", LogRecord(
                t=record.created if record.created else time.time(),
                service=self.bus.service, instance=self.bus.instance,
                level=record.levelname, name=record.name, message=record.getMessage(),
            ), reliable=True)
        except Exception:
            pass  # the bus is closing; the console handler still has the record
        finally:
            self._busy = False
