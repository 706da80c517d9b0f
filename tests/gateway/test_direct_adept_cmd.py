"""DirectAdeptCmd never reaches a controller: off by default, and when allowed it says
that no link can carry raw V+ commands (deploy/adept/README.md), without a bus request."""

from __future__ import annotations

import asyncio
from typing import cast

from rob6.bus import Bus
from rob6.robots import get_robot
from rob6_gateway.commands import Gateway, Options
from rob6_gateway.state import Session
from tests.reliability.fuzz import _DeadBus  # every bus request would fail loudly


def ask(robot: str, line: str, **options: bool) -> str | None:
    gateway = Gateway(cast(Bus, _DeadBus()), get_robot(robot), Options(**options))
    return asyncio.run(gateway.execute(Session(number=1, peer="test"), line))


def test_allowed_it_says_no_link_carries_v_plus_commands():
    assert ask("ad850", "DirectAdeptCmd SPEED 50", allow_direct_adept_cmd=True) == (
        "ERROR: DirectAdeptCmd: raw V+ commands cannot reach the controller (neither the simulation "
        "nor the simple_message link has a V+ command channel); nothing was sent\nfalse\n")


def test_off_by_default_and_false_on_other_robots():
    reply = ask("ad850", "DirectAdeptCmd SPEED 50")
    assert reply is not None and reply.startswith("ERROR: DirectAdeptCmd is disabled on this server")
    assert ask("kr16", "DirectAdeptCmd SPEED 50", allow_direct_adept_cmd=True) == "false\n"
