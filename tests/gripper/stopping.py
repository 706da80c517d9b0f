"""Test helper: a move stopped from another thread mid-way, which every gripper backend allows."""

from __future__ import annotations

import threading
from collections.abc import Callable

from rob6_gripper.backend import MOVING, GripperBackend, GripperStatus, Result
from tests.motion.link_session import wait_until


def stopped_mid_move(gripper: GripperBackend, move: Callable[[], Result], target: float, way: float) -> Result:
    """Run ``move`` (towards ``target``, metres, from 0) on a thread; once the gripper is seen
    ``way`` metres on its way, a stop is accepted; the blocked call then returns: its result."""
    result: dict[str, Result] = {}
    th = threading.Thread(target=lambda: result.setdefault("r", move()))
    th.start()

    def on_its_way() -> GripperStatus | None:
        s = gripper.state()
        return s if s.mode == MOVING and s.position >= way else None
    # as far as it got, not a fixed time: a thread started late on a busy machine is still
    # seen moving (a fixed 0.15-0.25 s wait could look before the move began)
    s = wait_until(on_its_way, timeout=5.0, what=f"the gripper {way * 1000:.0f} mm on its way")
    assert s.mode == MOVING and s.velocity > 0 and 0.0 < s.position < target
    assert gripper.stop()
    th.join(2)
    assert not th.is_alive()
    return result["r"]
