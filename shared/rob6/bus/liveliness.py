"""Liveliness: which instances of each service are up, and which one a call goes to.

Liveliness: which instances of each service are up (their tokens), and which one a call
goes to.

Calls of a replicated service (kinematics) are spread over its live instances (least in
flight, then round robin); a retry or a hedge prefers an instance on another host. An
owner service (``OWNER_SERVICES``) has the one instance this process follows: the first
it saw alive. A call waiting for an instance that goes away is ended at once (``_track``).
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable
from typing import Protocol

import zenoh

from ..messages import OWNER_SERVICES
from .errors import _InstanceLost
from .session import BusSession

log = logging.getLogger("rob6.bus")


class _Waiter(Protocol):
    """A call waiting for an instance's reply (``rob6.bus.call._Exchange``)."""

    def end(self, outcome: tuple[bytes, str] | BaseException, instance: str) -> None: ...


def _host(instance: str) -> str:
    """The host part of an instance id (``rob6.config.default_instance``: host-suffix)."""
    return instance.rpartition("-")[0] or instance


class Liveliness(BusSession):
    """The bus's view of the live instances (a mixin of ``Bus``)."""

    def _init_liveliness(self) -> None:
        """Follow the liveliness tokens; their history arrives at once."""
        self._live: dict[str, list[str]] = {}
        self._inflight: dict[str, int] = {}
        self._pending: dict[str, set[_Waiter]] = {}  # instance -> exchanges waiting for it
        self._rotation = itertools.count()
        self._listeners: list[Callable[[str, str, bool], None]] = []
        self._live_sub = self.session.liveliness().declare_subscriber(
            self.key("alive", "**"), zenoh.handlers.Callback(self._on_liveliness), history=True)

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        parts = str(sample.key_expr).split("/")
        if len(parts) != 5:
            return
        service, instance = parts[3], parts[4]
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            instances = self._live.setdefault(service, [])
            if alive and instance not in instances:
                instances.append(instance)
            elif not alive and instance in instances:
                instances.remove(instance)
            lost = self._pending.pop(instance, set()) if not alive else set()
        for exchange in lost:
            exchange.end(_InstanceLost(f"{service} instance {instance} went away", gone=True), instance)
        for listener in list(self._listeners):
            try:
                listener(service, instance, alive)
            except Exception:  # a listener must not break the bus
                log.exception("liveliness listener failed")

    def on_liveliness(self, listener: Callable[[str, str, bool], None]) -> None:
        """Call ``listener(service, instance, alive)`` on every change; it must not block."""
        self._listeners.append(listener)

    def instances(self, service: str) -> list[str]:
        with self._lock:
            return list(self._live.get(service, ()))

    def owner(self, service: str) -> str | None:
        """The instance of an owner service this process follows: the first it saw alive."""
        with self._lock:
            live = self._live.get(service)
            return live[0] if live else None

    def wait_for(self, services: tuple[str, ...] | list[str], timeout: float) -> list[str]:
        """Wait until every service has a live instance; returns the ones still missing."""
        deadline = time.monotonic() + timeout
        while True:
            missing = [s for s in services if not self.instances(s)]
            if not missing or time.monotonic() >= deadline:
                return missing
            time.sleep(0.02)

    def _pick(self, service: str, exclude: set[str]) -> str | None:
        with self._lock:
            live = self._live.get(service, ())
            if service in OWNER_SERVICES:  # the followed one, never a second owner
                return live[0] if live and live[0] not in exclude else None
            candidates = [i for i in live if i not in exclude]
            if not candidates:
                return None
            # a retry or a hedge goes to another host where there is one: the instances of
            # one host share its network path, and a copy sent the same way would wait
            # behind the same lost TCP segment or partition
            elsewhere = [i for i in candidates if _host(i) not in {_host(t) for t in exclude}]
            candidates = elsewhere or candidates
            start = next(self._rotation) % len(candidates)
            ordered = candidates[start:] + candidates[:start]
            return min(ordered, key=lambda i: self._inflight.get(i, 0))

    def _track(self, exchange: _Waiter, instance: str, add: bool) -> None:
        with self._lock:
            if add:
                self._pending.setdefault(instance, set()).add(exchange)
                self._inflight[instance] = self._inflight.get(instance, 0) + 1
            else:
                self._pending.get(instance, set()).discard(exchange)
                self._inflight[instance] = self._inflight.get(instance, 1) - 1
