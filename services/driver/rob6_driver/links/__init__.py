"""Links from the driver's motion core to the plant.

A link owns the controller clock: it calls ``MotionCore.step()`` once per cycle and
delivers the setpoint. ``sim`` takes every setpoint as reached (the default); ``rsi``
drives a KUKA KR C4 over RSI, where every packet from the controller is one cycle
(``rsi.py``, its codec ``rsi_codec.py``); ``simple_message`` streams the setpoints as
ROS-Industrial simple_message points to an Adept V+ controller (``simple_message.py``,
its codec ``simple_message_codec.py``, the V+ program's I/O port ``adept_io.py``);
``kawasaki`` streams them as points to rob6's own AS program on a Kawasaki controller
(``kawasaki.py``, its codec and the FS03N's joint convention ``kawasaki_codec.py``). The two
TCP links are thin subclasses of ``StreamedPointsLink`` (``streamed_points.py``: health,
arrival, merging late points, reconnecting), with ``streaming.py``'s socket helpers; none
of them touches the motion core. The two text codecs (Kawasaki, RSI) read a number as
``wire_numbers.py`` says.

What the service needs from a link is small: ``start``/``stop``, the plant's state for
each published joint state (``state``, ``late``, ``missed``, ``q_actual``, ``outputs``) and
a status report (``status``), ``settle`` after a motion the core has finished (a
robot that lags behind its setpoints: has it arrived?), and ``signal`` for a plant with
digital outputs (the Adept's V+ SIGNAL; numbers checked by the service). A link calls
``core.offline(reason)`` when the plant cannot be reached and ``core.online(q_actual)``
when it can again.
"""

from __future__ import annotations

import logging
import queue
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy.typing as npt

from rob6.messages import LinkEvent, LinkStatus

from ..motion import CoreState

#: called with the core's state after every cycle (the service publishes it)
Publish = Callable[[CoreState], None]

log = logging.getLogger("rob6.driver")


class Link(ABC):
    """The plant as the service sees it."""

    kind = ""
    #: connected | lost | waiting
    state = "connected"
    #: late packets the controller counted so far (all runs)
    late = 0
    #: controller cycles that ran without the driver (no packet reached it, or the cycle came too late)
    missed = 0
    #: where the plant says the robot is (deg), or None when it only follows the setpoint
    q_actual: list[float] | None = None

    @abstractmethod
    def start(self) -> None:
        """Begin following the plant (its clock drives the core from now on)."""

    @abstractmethod
    def stop(self) -> None:
        """Stop following the plant and release its sockets and threads."""

    @abstractmethod
    def status(self, reset: bool = False) -> LinkStatus:
        """The link's state and statistics; ``reset`` starts the latency statistics afresh."""

    def signal(self, signals: list[int]) -> str:
        """Switch digital outputs (V+ SIGNAL: n on, -n off, in this order); "" when done,
        else why not. Links of robots without V+ outputs refuse."""
        return f"the {self.kind} link has no digital outputs"

    def outputs(self) -> list[int]:
        """The outputs switched so far, V+ style (5 on, -6 off), by number."""
        return []

    def signal_bound_s(self, count: int) -> float:
        """The longest ``signal`` of ``count`` outputs waits (its own timeouts), seconds."""
        return 0.0

    @property
    def settle_bound_s(self) -> float:
        """The longest ``settle`` waits (its own timeouts), seconds, unless it says otherwise
        through its ``waiting``."""
        return 0.0

    def settle(self, q_final: npt.ArrayLike, timeout: float | None = None,
               waiting: Callable[[float, str], None] | None = None) -> str:
        """After a motion ended at ``q_final`` (deg): wait until the robot is there.
        "" when it is, else why not (the motion then fails with that error). Links
        whose robot is where the setpoint is (sim, rsi) return at once. ``waiting(seconds,
        what)``: told when the wait grows beyond ``settle_bound_s`` (an arm still coming)."""
        return ""

    # ---- events: logged and published off the link's real-time thread
    on_event: Callable[[LinkEvent], None] | None = None
    _reports: queue.SimpleQueue[tuple[int, LinkEvent] | None]

    def _report_loop(self) -> None:
        """Log and publish the events the link queued in ``_reports``, until a None."""
        while (item := self._reports.get()) is not None:
            level, event = item
            log.log(level, "driver: %s", event.message)
            if self.on_event is not None:
                try:
                    self.on_event(event)
                except Exception:
                    log.debug("publishing a link event failed", exc_info=True)


class Outputs:
    """The digital outputs a link has switched: thread-safe, V+ style (n on, -n off).

    ``as_list`` is read with every published joint state (the driver's cycle), so the
    list is made when an output switches, not when it is read."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._on: dict[int, bool] = {}
        self._list: list[int] = []

    def switched(self, signal: int) -> None:
        with self._lock:
            self._on[abs(signal)] = signal > 0
            self._list = [n if on else -n for n, on in sorted(self._on.items())]

    def as_list(self) -> list[int]:
        """The outputs by number; a new list after each switch, never changed in place."""
        return self._list
