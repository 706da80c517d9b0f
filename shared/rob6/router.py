"""A Zenoh router run by zenoh-python (router mode): no separate zenohd binary needed.

Every rob6 process connects to it; in peer mode the processes then also link
directly to each other (the router tells them where), so a restarted service is
reachable again as soon as its liveliness token appears.
"""

from __future__ import annotations

import logging
import signal
import threading

import zenoh

from .bus import zenoh_config
from .config import BusSettings

log = logging.getLogger("rob6.router")


def run(settings: BusSettings, listen: tuple[str, ...]) -> None:
    stop = threading.Event()
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    session = zenoh.open(zenoh_config(settings, mode="router", listen=listen))
    log.warning("zenoh router %s listening on %s", session.zid(), ", ".join(listen) or "(config file)")
    stop.wait()
    session.close()
