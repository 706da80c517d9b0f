"""The ``Bus`` class: the bus's jobs (the sibling modules' mixins) put together on one session.

The ``Bus`` class: the bus's jobs (mixins from the sibling modules) put together on one
session, started in order and closed."""

from __future__ import annotations

import logging
import threading
import time

from ..config import BusSettings
from .call import Calling
from .codec import _encoder
from .pubsub import PubSub
from .serve import Serving

log = logging.getLogger("rob6.bus")

#: how long a closing bus waits for its own threads (a worker finishing its request)
CLOSE_JOIN_S = 5.0


class Bus(Serving, Calling, PubSub):
    """One Zenoh session of one rob6 process (a service instance, the gateway, a tool)."""

    def __init__(self, settings: BusSettings, service: str, *, mode: str | None = None,
                 listen: tuple[str, ...] | None = None):
        super().__init__(settings, service, mode=mode, listen=listen)  # the session
        self._init_calls()
        self._init_pubsub()
        self._init_serving()
        self._init_traces()
        self._init_liveliness()  # last: the tokens' history comes at once

    def publish_state(self, suffix: str, state: object) -> None:
        """A state stream (``driver/state``, ``gripper/state``): published live for
        controllers and views, where a sample is dropped under congestion (only the latest
        matters to them), and the same bytes traced for the recorder, where none is."""
        payload = _encoder.encode(state)
        self.publish(suffix, payload)
        self.trace(suffix, payload)

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._flush_traces()  # what was traced before the close still goes out
        self._closed.set()
        try:
            self.session.close()
        except Exception:
            log.debug("closing the zenoh session failed", exc_info=True)
        self._end_threads()

    def _end_threads(self) -> None:
        """The bus's own threads end with it (the workers after their request), so none
        holds the service's objects while the interpreter exits."""
        threads = list(self._workers)
        if self._watcher is not None:
            self._watcher.wake()
            threads.append(self._watcher.thread)
        deadline = time.monotonic() + CLOSE_JOIN_S
        for thread in threads:
            if thread is not threading.current_thread():
                thread.join(max(0.0, deadline - time.monotonic()))
