"""rob6-kinematics: forward and inverse kinematics; run as many replicas as you like."""

from __future__ import annotations

import click

from rob6 import service
from rob6.config import BusSettings, bus_options
from rob6.robots import get_robot

from .service import KinematicsService


@click.command()
@bus_options
def main(settings: BusSettings, log_level: str) -> None:
    """Serve FK/IK for one robot type (several replicas may serve the same robot)."""
    kinematics = KinematicsService(get_robot(settings.robot))
    service.run(settings, "kinematics", log_level, kinematics.serve)


if __name__ == "__main__":
    main()
