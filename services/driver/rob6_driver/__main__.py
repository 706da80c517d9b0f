"""rob6-driver: the robot (simulated unless a hardware backend is configured)."""

from __future__ import annotations

import click

from rob6 import service
from rob6.config import bus_options
from rob6.robots import get_robot

from .service import DriverService


@click.command()
@bus_options
@click.option("--dummy/--real-time", envvar="ROB6_DUMMY", default=False, show_default=True,
              help="Instantaneous motion like the original's -d, or motion in real time [env ROB6_DUMMY=1].")
def main(settings, log_level, dummy):
    """Run the driver of one robot."""

    def setup(bus):
        driver = DriverService(bus, get_robot(settings.robot), dummy)
        driver.start()
        return driver.shutdown

    service.run(settings, "driver", log_level, setup)


if __name__ == "__main__":
    main()
