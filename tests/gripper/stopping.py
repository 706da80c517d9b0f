"""Test helper: a move stopped from another thread mid-way, which every gripper backend allows."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from rob6_gripper.backend import MOVING, GripperBackend, Result


def stopped_mid_move(gripper: GripperBackend, move: Callable[[], Result], target: float, after_s: float) -> Result:
    """Run ``move`` (towards ``target``, metres, from 0) on a thread; ``after_s`` later the gripper
    is seen on its way and a stop is accepted; the blocked call then returns: its result."""
    result: dict[str, Result] = {}
    th = threading.Thread(target=lambda: result.setdefault("r", move()))
    th.start()
    time.sleep(after_s)
    s = gripper.state()
    assert s.mode == MOVING and s.velocity > 0 and 0.0 < s.position < target
    assert gripper.stop()
    th.join(2)
    assert not th.is_alive()
    return result["r"]
