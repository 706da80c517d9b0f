"""The interface every gripper backend implements (simulation and Schunk serial).

The gripper service calls exactly these methods.  Rules every backend keeps:

* Motion calls (``go_home``, ``move_current``, ``move_to_position``) block until the
  motion has finished -- the original rob6server answered ``true`` only then -- but
  never longer than their ``timeout`` (plus one response timeout of the transport).
  On a timeout the backend sends a stop and returns a failed :class:`Result`.
* Nothing raises for an expected failure (bad argument, device error, timeout, port
  gone): the call returns ``Result(ok=False, error="<clear sentence>")``.
* ``state()`` and ``stop()`` may be called from another thread while a motion call
  blocks; ``stop()`` ends that motion (which then returns ``ok=False``).

Units: metres, metres per second, amperes.  Position is the *opening* between the
jaws (0 = closed).  Current sign follows the protocol text (section 3.4,
``GripperMove amp``): negative closes, positive opens.
"""

from __future__ import annotations

import math
import threading
import time
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass
from typing import Any, Protocol

#: Modes reported by ``state()``.
IDLE, MOVING, GRIPPING, ERROR = "idle", "moving", "gripping", "error"
MODES = (IDLE, MOVING, GRIPPING, ERROR)

#: Default bound for one motion call, seconds.  The bus gives a gripper command 30 s
#: (``rob6.messages.OPS[("gripper", "command")]``); stay well inside it.
DEFAULT_TIMEOUT = 10.0


@dataclass(frozen=True)
class GripperStatus:
    """A snapshot of the gripper.  Field names match ``rob6.messages.GripperState``
    so the service can do ``GripperState(**status.as_dict())``."""

    position: float  # m, opening between the jaws
    velocity: float  # m/s, positive = opening
    current: float  # A, motor current (negative = closing)
    mode: str  # idle | moving | gripping | error
    error: str = ""

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Result:
    """Outcome of a gripper call.  ``bool(result)`` is ``result.ok``."""

    ok: bool
    error: str = ""  # empty when ok; otherwise one clear sentence for logs / reason
    position: float | None = None  # opening afterwards, when known

    def __bool__(self) -> bool:
        return self.ok


def fail(message: str, position: float | None = None) -> Result:
    return Result(False, message, position)


def check_timeout(timeout: float) -> str:
    """Return an error text if ``timeout`` is unusable, else ''."""
    if not isinstance(timeout, (int, float)) or not math.isfinite(timeout) or timeout <= 0:
        return f"invalid timeout {timeout!r}: must be a positive number of seconds"
    return ""


def check_number(name: str, value: float, unit: str) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return f"invalid {name} {value!r} {unit}: must be a finite number"
    return ""


class GripperBackend(ABC):
    """Common interface of :class:`~rob6_gripper.sim.SimGripper` and
    :class:`~rob6_gripper.schunk.SchunkGripper`."""

    #: the longest one command to the gripper waits for its answer, seconds (0: it answers
    #: at once); a motion waits its timeout and at most two such commands more
    command_bound_s = 0.0

    @abstractmethod
    def has_gripper(self) -> bool:
        """True only if a working gripper answers (never raises, bounded time)."""

    @abstractmethod
    def go_home(self, timeout: float = DEFAULT_TIMEOUT) -> Result:
        """Reference run to the home position (about 0.04 m open); blocks until done."""

    @abstractmethod
    def move_current(self, amps: float, timeout: float = DEFAULT_TIMEOUT) -> Result:
        """Drive with motor current ``amps`` (negative closes, positive opens) until the
        jaws are blocked by an object or the stroke end; blocks until they stand."""

    @abstractmethod
    def move_to_position(self, metres: float, timeout: float = DEFAULT_TIMEOUT) -> Result:
        """Move to opening ``metres``; blocks until reached.  Outside the stroke, or
        blocked by an object on the way: ``ok=False`` with the reason."""

    @abstractmethod
    def stop(self) -> Result:
        """Stop any motion (also ends a motion call blocked in another thread)."""

    @abstractmethod
    def acknowledge(self) -> Result:
        """Acknowledge (clear) a pending gripper error."""

    @abstractmethod
    def state(self) -> GripperStatus:
        """Current snapshot; never raises (an unreachable device gives mode 'error')."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release resources (serial port, threads)."""


# ---------------------------------------------------------------- clocks
class Clock(Protocol):
    """Where a backend's time comes from: :class:`RealClock` or :class:`VirtualClock`."""

    def now(self) -> float: ...

    def wait(self, cond: threading.Condition, seconds: float) -> None: ...


class RealClock:
    """Wall-clock time; waiting releases the caller's condition so other threads
    (``state()``, ``stop()``) get in."""

    def now(self) -> float:
        return time.monotonic()

    def wait(self, cond: threading.Condition, seconds: float) -> None:
        cond.wait(max(0.0, seconds))


class VirtualClock:
    """Simulated time for tests: ``wait`` jumps forward instead of sleeping, so a
    3-second motion finishes at once and exactly.  Single-threaded use only."""

    def __init__(self, start: float = 0.0) -> None:
        self.t = start

    def now(self) -> float:
        return self.t

    def advance(self, seconds: float) -> None:
        self.t += max(0.0, seconds)

    def wait(self, cond: threading.Condition, seconds: float) -> None:  # nobody else runs: cond unused
        self.advance(seconds)
