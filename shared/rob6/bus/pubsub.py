"""Publish and subscribe on ``rob6/<id>/<suffix>``: states, control and logs, stamped by publisher.

Publish and subscribe: messages on ``rob6/<id>/<suffix>`` (states, control, logs),
each stamped with its publisher's instance, and subscriptions that follow an owner's.

Every publication carries its instance id as the Zenoh attachment; a subscription made
with ``owner=`` drops samples any instance but the followed one publishes, so a stray
second driver is never mixed in.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TypeVar

import msgspec
import zenoh

from .codec import _encoder
from .liveliness import Liveliness

log = logging.getLogger("rob6.bus")

#: every suffix published live on ``rob6/<id>/<suffix>`` (``publish``), and nothing else may
#: be: a subscriber that wants them all (the recorder) subscribes to these, not to ``**``,
#: which would also bring it each state at 250 Hz and each trace batch a second time
LIVE_TOPICS = frozenset({"driver/state", "driver/clearance", "gripper/state", "control/verbosity",
                         "control/shutdown", "planner/config"})

T = TypeVar("T")


class PubSub(Liveliness):
    """Publications and subscriptions of the bus (a mixin of ``Bus``)."""

    def _init_pubsub(self) -> None:
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._foreign_warned: set[tuple[str, str]] = set()

    def publish(self, suffix: str, data: object, *, reliable: bool = False) -> None:
        """Publish a message struct, dict or raw JSON bytes on ``rob6/<id>/<suffix>``.

        ``reliable`` blocks rather than drops under congestion (logs, traces); state
        streams drop, because only the latest sample matters to a controller.
        """
        if self._closed.is_set():  # shutting down: nothing is listening any more
            return
        publisher = self._publishers.get(suffix)
        if publisher is None:
            if suffix not in LIVE_TOPICS:
                raise ValueError(f"{suffix!r} is not in rob6.bus.LIVE_TOPICS (add it there, so it is recorded)")
            congestion = zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
            publisher = self._publishers[suffix] = self.session.declare_publisher(
                self.key(suffix), congestion_control=congestion)
        publisher.put(data if isinstance(data, bytes) else _encoder.encode(data), attachment=self._attachment)

    def subscribe(self, suffix: str, on_message: Callable[[str, bytes], None], *,
                  owner: str | None = None) -> zenoh.Subscriber[None]:
        """Call ``on_message(key, payload)`` for every sample; it must not block.

        ``owner``: an owner service; only what its followed instance publishes is passed
        on, anything else is logged (once per publisher) and dropped.
        """
        def callback(sample: zenoh.Sample) -> None:
            try:
                if owner is not None and not self._from_owner(owner, suffix, sample):
                    return
                on_message(str(sample.key_expr), sample.payload.to_bytes())
            except Exception:
                log.exception("subscriber of %s failed", suffix)

        subscriber = self.session.declare_subscriber(self.key(suffix), zenoh.handlers.Callback(callback))
        self._declared.append(subscriber)
        return subscriber

    def subscribe_latest(self, suffix: str, *, owner: str, keep: int = 8) -> Latest:
        """The samples of ``rob6/<id>/<suffix>`` kept in Zenoh until taken (``Latest.take``),
        the newest ``keep`` of them: no Python runs for each sample, for a stream read less
        often than it is published. Like ``subscribe``, only what the followed instance of
        ``owner`` publishes is passed on."""
        subscriber = self.session.declare_subscriber(self.key(suffix), zenoh.handlers.RingChannel(keep))
        self._declared.append(subscriber)
        return Latest(self, suffix, owner, subscriber)

    def _from_owner(self, service: str, suffix: str, sample: zenoh.Sample) -> bool:
        attachment = sample.attachment
        sender = attachment.to_bytes().decode(errors="replace") if attachment is not None else "?"
        followed = self.owner(service)
        if sender == followed:
            return True
        if followed is None:  # its liveliness token has not arrived yet (start-up)
            return False
        if (suffix, sender) not in self._foreign_warned and len(self._foreign_warned) < 100:
            self._foreign_warned.add((suffix, sender))
            log.warning("ignoring %s from %s: this %s follows the %s %s", self.key(suffix), sender,
                        self.service, service, followed)
        return False


def decode(typ: type[T], payload: bytes) -> T:
    """Decode a published message of type ``typ``."""
    return msgspec.json.decode(payload, type=typ)


class Latest:
    """``PubSub.subscribe_latest``: what arrived since the last take."""

    def __init__(self, bus: PubSub, suffix: str, owner: str, subscriber: zenoh.Subscriber[zenoh.Handler[zenoh.Sample]]) -> None:
        self._bus = bus
        self._suffix = suffix
        self._owner = owner
        self._subscriber = subscriber

    def take(self) -> list[bytes]:
        """The payloads that arrived since the last take (the newest ``keep``), oldest first."""
        payloads = []
        while (sample := self._subscriber.try_recv()) is not None:
            if self._bus._from_owner(self._owner, self._suffix, sample):
                payloads.append(sample.payload.to_bytes())
        return payloads
