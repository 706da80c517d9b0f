"""rob6-driver: the robot, simulated (``--link sim``, the default) or a KUKA KR C4 over
RSI (``--link rsi``: this PC is the UDP server the controller's RSI context sends to)."""

from __future__ import annotations

import click

from rob6 import service
from rob6.config import LINKS, bus_options
from rob6.ownership import EXIT_REFUSED
from rob6.robots import get_robot

from .links.rsi import DEFAULT_LISTEN, DEFAULT_SEN_TYPE, parse_address
from .service import DriverService


@click.command()
@bus_options
@click.option("--dummy/--real-time", envvar="ROB6_DUMMY", default=False, show_default=True,
              help="Instantaneous motion like the original's -d, or motion in real time [env ROB6_DUMMY=1].")
@click.option("--link", envvar="ROB6_LINK", default="sim", show_default=True, type=click.Choice(LINKS),
              help="The robot: the simulation, or a KUKA KR C4 over RSI [env ROB6_LINK].")
@click.option("--rsi-listen", envvar="ROB6_RSI_LISTEN", default=DEFAULT_LISTEN, show_default=True,
              help="UDP HOST:PORT the controller's RSI packets come to [env ROB6_RSI_LISTEN].")
@click.option("--rsi-sentype", envvar="ROB6_RSI_SENTYPE", default=DEFAULT_SEN_TYPE, show_default=True,
              help="The Type of the answer's <Sen> element, as in the RSI configuration [env ROB6_RSI_SENTYPE].")
def main(settings, log_level, dummy, link, rsi_listen, rsi_sentype):
    """Run the driver of one robot."""
    robot = get_robot(settings.robot)
    if link == "rsi":
        if not robot.is_kuka:
            service.fail("driver", f"--link rsi drives KUKA robots (kr3, kr16, kr3rt, kr16rt), not {robot.name}; "
                         "use --link sim", EXIT_REFUSED)
        if dummy:
            service.fail("driver", "--link rsi moves a real robot in real time: --dummy is not possible",
                         EXIT_REFUSED)
        try:
            parse_address(rsi_listen)
        except ValueError as exc:
            service.fail("driver", str(exc), EXIT_REFUSED)

    def setup(bus):
        try:
            driver = DriverService(bus, robot, dummy, link=link, rsi_listen=rsi_listen, rsi_sen_type=rsi_sentype)
        except OSError as exc:
            raise service.StartupError(f"cannot listen for RSI on udp/{rsi_listen}: {exc.strerror or exc}; "
                                       "is another driver running? Set ROB6_RSI_LISTEN") from None
        driver.start()
        return driver.shutdown

    service.run(settings, "driver", log_level, setup)


if __name__ == "__main__":
    main()
