"""rob6-planner: limits, configuration choice and Ruckig trajectories for one robot."""

from __future__ import annotations

import click

from rob6 import service
from rob6.bus import Bus
from rob6.config import BusSettings, bus_options
from rob6.robots import get_robot

from .service import PlannerService


@click.command()
@bus_options
@click.option("--alter-timeout", envvar="ROB6_ALTER_TIMEOUT", default=0.5, show_default=True, type=float,
              help="In Alter mode the robot stops when no target arrives for this many seconds.")
def main(settings: BusSettings, log_level: str, alter_timeout: float) -> None:
    """Plan and supervise the motions of one robot."""

    def setup(bus: Bus) -> None:
        PlannerService(bus, get_robot(settings.robot), alter_timeout).serve()

    service.run(settings, "planner", log_level, setup)


if __name__ == "__main__":
    main()
