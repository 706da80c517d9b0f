"""Which published joint state the gateway's mirror keeps (``rob6.state.replaces``)."""

from __future__ import annotations

from rob6.messages import JointState
from rob6.state import replaces

AT_REST = [10.0, -60.0, 80.0, 0.0, 40.0, 0.0]
MOVED = [-10.0, -60.0, 80.0, 0.0, 40.0, 0.0]
ZERO = [0.0] * 6


def _state(cycle: int, q: list[float], instance: str = "driver-a") -> JointState:
    return JointState(t=cycle * 0.004, cycle=cycle, q=q, qd=ZERO, instance=instance)


def test_the_first_state_and_later_cycles_replace_the_kept_one() -> None:
    assert replaces(_state(1, AT_REST), None)
    assert replaces(_state(101, MOVED), _state(100, AT_REST))


def test_a_publication_from_before_a_move_arriving_after_its_reply_is_kept_out() -> None:
    # the move's reply reported cycle 120 (MOVED); the rest publication of cycle 110
    # (AT_REST) was sent before it and arrived after it, over the driver's own link
    after_the_move = _state(120, MOVED)
    assert not replaces(_state(110, AT_REST), after_the_move)
    assert not replaces(_state(120, AT_REST), after_the_move)  # the same cycle again


def test_a_restarted_driver_replaces_the_state_although_its_cycles_start_again() -> None:
    assert replaces(_state(1, AT_REST, instance="driver-b"), _state(5000, MOVED, instance="driver-a"))
