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

from .bus import open_session
from .config import BusSettings
from .ownership import EXIT_REFUSED
from .service import end_threads, fail, follow_launcher

log = logging.getLogger("rob6.router")


def run(settings: BusSettings, listen: tuple[str, ...]) -> None:
    follow_launcher()
    stop = threading.Event()
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    try:
        session = open_session(settings, mode="router", listen=listen)
    except zenoh.ZError as exc:  # almost always: the port is taken
        log.debug("the router could not start", exc_info=True)
        in_use = "in use" in str(exc).lower()
        fail("router", f"cannot listen on {', '.join(listen)}: "
                       f"{'address already in use' if in_use else exc}; is another rob6 running? "
                       f"Stop it or choose another ROB6_ROUTER_PORT / ROB6_ZENOH_LISTEN", EXIT_REFUSED)
    log.warning("zenoh router %s listening on %s", session.zid(), ", ".join(listen) or "(config file)")
    stop.wait()
    session.close()
    end_threads()
