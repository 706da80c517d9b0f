"""What the bus lets a service publish live: the topics in ``rob6.bus.LIVE_TOPICS``, where
the recorder finds what to subscribe to, and nothing else (a publication outside them
would never be recorded)."""

from __future__ import annotations

import queue
import threading

import pytest
import zenoh

from harness.system import zenoh_router
from rob6.bus import LIVE_TOPICS, Bus
from rob6.config import BusSettings
from rob6.messages import Verbosity


def test_a_topic_outside_the_live_topics_is_refused_and_one_inside_is_published() -> None:
    with zenoh_router("live-topics") as settings:
        def bus(service: str) -> Bus:
            return Bus(BusSettings(robot_id=settings.robot_id, connect=settings.connect,
                                   instance=f"{service}-1"), service)

        gateway, recorder = bus("gateway"), bus("recorder")
        try:
            # a subscription reaches the publishing session a moment after it is made: Zenoh's
            # matching listener, declared before it, says when it has
            matched = threading.Event()

            def on_matching(status: zenoh.MatchingStatus) -> None:
                if status.matching:
                    matched.set()

            probe = gateway.session.declare_publisher(gateway.key("control/verbosity"))
            listener = probe.declare_matching_listener(on_matching)
            received: queue.SimpleQueue[tuple[str, bytes]] = queue.SimpleQueue()
            for suffix in LIVE_TOPICS:
                recorder.subscribe(suffix, lambda key, payload: received.put((key, payload)))
            with pytest.raises(ValueError, match="LIVE_TOPICS"):
                gateway.publish("control/new_thing", Verbosity(level=1))
            assert matched.wait(10), "the recorder's subscription never reached the gateway"
            listener.undeclare()
            probe.undeclare()
            gateway.publish("control/verbosity", Verbosity(level=3))
            key, payload = received.get(timeout=10)
            assert key.endswith("/control/verbosity") and payload == b'{"level":3}'
        finally:
            gateway.close()
            recorder.close()
