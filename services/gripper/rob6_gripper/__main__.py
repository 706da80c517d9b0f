"""rob6-gripper: the serial gripper of the Adept setups, or its physical simulation."""

from __future__ import annotations

from collections.abc import Callable

import click

from rob6 import service
from rob6.bus import Bus
from rob6.config import BusSettings, bus_options

from .backend import GripperBackend
from .service import GripperService


@click.command()
@bus_options
@click.option("--serial-port", envvar="ROB6_GRIPPER_PORT", default=None,
              help="Serial device of a Schunk gripper (SMP); without it the gripper is simulated "
                   "[env ROB6_GRIPPER_PORT].")
@click.option("--baud", envvar="ROB6_GRIPPER_BAUD", default=9600, show_default=True, type=int)
@click.option("--module-id", envvar="ROB6_GRIPPER_MODULE_ID", default=12, show_default=True, type=int)
@click.option("--sim-object", envvar="ROB6_GRIPPER_OBJECT", default=None, type=float,
              help="Simulation: width (m) of the object between the jaws [env ROB6_GRIPPER_OBJECT].")
def main(settings: BusSettings, log_level: str, serial_port: str | None, baud: int, module_id: int,
         sim_object: float | None) -> None:
    """Serve the gripper commands of one robot."""
    backend: GripperBackend
    if serial_port:
        from .schunk import SchunkGripper
        backend = SchunkGripper(serial_port, baudrate=baud, module_id=module_id)
    else:
        from .sim import SimGripper
        backend = SimGripper(object_width=sim_object)

    def setup(bus: Bus) -> Callable[[], None]:
        gripper = GripperService(bus, backend)
        gripper.start()
        return gripper.stop

    service.run(settings, "gripper", log_level, setup)


if __name__ == "__main__":
    main()
