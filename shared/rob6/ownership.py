"""One robot, one owner: the claim a service makes before it may command the robot.

The driver, planner, gripper and gateway of a robot id exist once (``OWNER_SERVICES``);
kinematics is stateless and may have replicas, the recorder only listens. Two drivers
for one arm would be two controllers commanding it, so an owner claims its role on the
bus before it does anything else (binds a port, talks to the robot):

1. It must see a Zenoh router. Without one it cannot know whether an owner runs
   elsewhere, so it refuses instead of guessing: a process started on the far side of
   a network partition never takes the arm over.
2. It asks the network for a live owner (its ``alive`` liveliness token) and refuses
   if there is one.
3. It declares a claim token ``rob6/<id>/claim/<service>/<instance>/<epoch ms>`` and
   watches the other claims for ``SETTLE_S``. Claims are ordered by (epoch, instance):
   of two started at the same moment the earlier wins and the later refuses; both
   come to the same answer, so exactly one wins, whatever their clocks say.
4. The winner keeps its claim token for life and keeps watching. Should another
   *live* owner with an earlier claim ever appear (only possible when a partition with
   a router on each side heals after each side started an owner), the later one stands
   down: it stops its robot and exits. Exactly one remains.

A refused process exits with ``EXIT_REFUSED`` (sysexits' EX_CONFIG): restarting it
cannot help, and the launcher does not try.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import zenoh

from .bus import Bus
from .errors import RefusedError
from .messages import OWNER_SERVICES

__all__ = ["OWNER_SERVICES", "EXIT_REFUSED", "Claim", "ClaimRefused"]

log = logging.getLogger("rob6.ownership")

#: how long a claimant watches for rivals; far above a token's propagation time
SETTLE_S = 0.3
#: how long an earlier claim without a live owner may take to vanish (a dead process' claim)
STALE_CLAIM_S = 2.0
#: a rival claim older than this is an owner that already runs, not one starting with us
RUNNING_AFTER_S = 5.0
#: how long a claimant waits for its first router link
ROUTER_WAIT_S = 10.0
EXIT_REFUSED = 78


class ClaimRefused(RefusedError):
    """This process may not own the role (another owner exists, or none can be ruled out)."""


class Claim:
    """A won claim: watches for an earlier live owner for the rest of the process' life."""

    def __init__(self, bus: Bus, on_conflict: Callable[[str], None], *,
                 settle_s: float = SETTLE_S, router_wait_s: float = ROUTER_WAIT_S):
        self.bus = bus
        self.service = bus.service
        self.me = bus.instance
        self.epoch = time.time_ns() // 1_000_000
        self._on_conflict = on_conflict
        self._lock = threading.Lock()
        self._claims: dict[str, int] = {}  # instance -> claim epoch, rivals included
        self._won = False
        self._stood_down = False
        _wait_for_router(bus, router_wait_s)
        holder = _live_owner(bus, self.service)
        if holder:
            raise ClaimRefused(already_running(bus, holder))
        liveliness = bus.session.liveliness()
        self._subscriber = liveliness.declare_subscriber(
            bus.key("claim", self.service, "*", "*"), zenoh.handlers.Callback(self._on_claim), history=True)
        # the one-shot query above can miss an owner whose token has not reached this new
        # session yet (in peer mode the router leaves peers to link to each other); a
        # subscription with history gets it as soon as it arrives, like the claims
        alive: set[str] = set()

        def on_alive(sample: zenoh.Sample) -> None:
            instance = str(sample.key_expr).rsplit("/", 1)[-1]
            if sample.kind == zenoh.SampleKind.PUT:
                alive.add(instance)
            else:
                alive.discard(instance)

        alive_subscriber = liveliness.declare_subscriber(
            bus.key("alive", self.service, "*"), zenoh.handlers.Callback(on_alive), history=True)
        self._token = liveliness.declare_token(bus.key("claim", self.service, self.me, str(self.epoch)))
        time.sleep(settle_s)
        # an earlier claim without a live owner is a rival still starting (its claim stays) or
        # the claim of a process that just died, say the one this process restarts (its token
        # goes within moments): give it STALE_CLAIM_S to show which, or a restart would refuse
        deadline = time.monotonic() + STALE_CLAIM_S
        while True:
            with self._lock:
                earlier = sorted((e, i) for i, e in self._claims.items()
                                 if i != self.me and (e, i) < (self.epoch, self.me))
            if not earlier or alive - {self.me} or time.monotonic() >= deadline:
                break
            time.sleep(0.05)
        alive_subscriber.undeclare()
        holder = next(iter(sorted(alive - {self.me})), None) or _live_owner(bus, self.service)
        if holder or earlier:
            self.release()
            # a claim token lives as long as its owner: one much older than this start is an
            # owner that runs (its alive token may not have reached this new session yet)
            if holder or self.epoch - earlier[0][0] > RUNNING_AFTER_S * 1000:
                raise ClaimRefused(already_running(bus, holder or earlier[0][1]))
            raise ClaimRefused(f"rob6: a {self.service} for {bus.settings.robot_id} is starting at the same time "
                          f"on {earlier[0][1]}; that one wins; stop it or use another ROB6_ROBOT_ID")
        with self._lock:
            self._won = True
        bus.on_liveliness(self._on_alive)
        log.info("%s %s owns robot %s (claim %d)", self.service, self.me, bus.settings.robot_id, self.epoch)

    def _on_claim(self, sample: zenoh.Sample) -> None:
        parts = str(sample.key_expr).split("/")  # rob6/<id>/claim/<service>/<instance>/<epoch>
        if len(parts) != 6 or not parts[5].isdigit():
            return
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._claims[parts[4]] = int(parts[5])
            else:
                self._claims.pop(parts[4], None)
        self._check()

    def _on_alive(self, service: str, _instance: str, alive: bool) -> None:
        if service == self.service and alive:
            self._check()

    def _check(self) -> None:
        """After winning: an earlier live owner means this one stands down."""
        with self._lock:
            if not self._won or self._stood_down:
                return
            live = set(self.bus.instances(self.service)) - {self.me}
            rivals = sorted((self._claims[i], i) for i in live if i in self._claims)
            if not rivals:
                return
            epoch, other = rivals[0]
            earlier = (epoch, other) < (self.epoch, self.me)
            self._stood_down = earlier
        if earlier:
            message = (f"rob6: two {self.service}s for {self.bus.settings.robot_id} after a network partition: "
                       f"{other} claimed it first; this one ({self.me}) stops")
            log.critical(message)
            self._on_conflict(message)
        else:
            log.error("a second %s (%s) appeared for %s; it claimed later and stands down",
                      self.service, other, self.bus.settings.robot_id)

    def release(self) -> None:
        try:  # the session may already be closed: then both fail
            self._token.undeclare()
        except Exception:
            log.debug("undeclaring the claim token failed", exc_info=True)
        try:
            self._subscriber.undeclare()
        except Exception:
            log.debug("undeclaring the claim subscriber failed", exc_info=True)


def already_running(bus: Bus, holder: str) -> str:
    return (f"rob6: a {bus.service} for {bus.settings.robot_id} is already running on {holder}; "
            f"stop it or use another ROB6_ROBOT_ID")


def _wait_for_router(bus: Bus, timeout: float) -> None:
    if not bus.settings.connect:
        return  # a deliberately router-less setup (tests of a single process)
    deadline = time.monotonic() + timeout
    while not bus.session.info.routers_zid():
        if time.monotonic() >= deadline:
            raise ClaimRefused(f"rob6: no Zenoh router reachable at {', '.join(bus.settings.connect)}; "
                          f"a {bus.service} claims robot {bus.settings.robot_id} only where it can see "
                          f"whether another one runs (start the router, or check ROB6_ZENOH_CONNECT)")
        time.sleep(0.02)


def _live_owner(bus: Bus, service: str) -> str | None:
    """The instance holding ``service``'s alive token, asked of the whole network."""
    replies = bus.session.liveliness().get(bus.key("alive", service, "*"), timeout=2.0)
    holders = []
    for reply in replies:
        if reply.ok is not None:
            holders.append(str(reply.ok.key_expr).rsplit("/", 1)[-1])
    others = [h for h in holders if h != bus.instance]
    return others[0] if others else None
