"""A FollowJointTrajectory goal through a box of the cell, from the independent rmw_zenoh peer:
aborted with INVALID_GOAL and the words an old client gets, and nothing moves."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from harness.client import Client
from harness.system import System, running
from tests.cell.zone_rig import HOVER_S, Rig, rig

zsdk = pytest.importorskip("zenoh_ros2_sdk")
from tests.ros.peer import Peer, connect  # noqa: E402

pytestmark = pytest.mark.slow
SUCCEEDED, ABORTED, INVALID_GOAL = 4, 6, -1


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[System, Rig]]:
    directory = tmp_path_factory.mktemp("kr16")
    r = rig("kr16")
    with running("kr16", dummy=False, extra_env={"ROB6_CELL": str(r.write(directory))}) as system:
        session = connect(system.router_port, tmp_path_factory.mktemp("msg"))
        yield system, r
        session.close()


def _joints(client: Client) -> list[float]:
    return [float(v) for v in client.ask("GetPositionJoints").split()]


def test_a_goal_through_the_table_is_aborted_and_nothing_moves(lab: tuple[System, Rig]) -> None:
    system, r = lab
    peer = Peer()
    try:
        with system.client() as client:
            assert client.ask("MovePTPJoints " + " ".join(map(str, r.q(HOVER_S))), timeout=60) == "true\n"
            start = _joints(client)
            through = r.q(r.s_at(-40.0))
            response, goal_id = peer.goal([(0.0, start), (1.5, through), (3.0, start)])
            assert response.accepted  # and ended at once, with the reason
            result = peer.wait_result(goal_id)
            assert (result.status, result.result.error_code) == (ABORTED, INVALID_GOAL)
            assert result.result.error_string.startswith("path enters keep-out 'table' at ")
            assert "(tool tip " in result.result.error_string and "mm inside)" in result.result.error_string
            assert _joints(client) == start
            # the same goal above the table runs
            above = r.q(r.s_at(40.0))
            response, goal_id = peer.goal([(0.0, start), (1.5, above), (3.0, start)])
            result = peer.wait_result(goal_id)
            assert (result.status, result.result.error_code) == (SUCCEEDED, 0), result.result.error_string
    finally:
        peer.close()
