"""The ``rig`` fixture: one real-time system per (robot, link), shared by a module's flows
(parametrize indirectly, with scope="module", over tests.flows.rigs.ALL or ADEPT)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.flows.rigs import Rig, rig as start_rig


@pytest.fixture(scope="module")
def rig(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Rig]:
    robot, link = request.param
    with start_rig(robot, link, tmp_path_factory.mktemp(f"{robot}-{link}")) as started:
        yield started
