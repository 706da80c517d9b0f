"""rob6-driver command line: check the link options and run the driver service.

rob6-driver: the robot, simulated (``--link sim``, the default), a KUKA KR C4 over
RSI (``--link rsi``: this PC is the UDP server the controller's RSI context sends to), or
an Adept V+ controller over ROS-Industrial simple_message (``--link simple_message``, or
``adept``: this PC is the client of the controller's motion and state ports), or a Kawasaki
controller running rob6's AS program (``--link kawasaki``: this PC is the client of its port)."""

from __future__ import annotations

from collections.abc import Callable

import click

from rob6 import service
from rob6.bus import Bus
from rob6.cell import CellError, default_cell, load_cell
from rob6.config import LINKS, BusSettings, bus_options
from rob6.ownership import EXIT_REFUSED
from rob6.robots import get_robot

from .links.adept_io import DEFAULT_OUTPUTS
from .links.kawasaki import DEFAULT_PERIOD_S as DEFAULT_KAS_PERIOD_S, DEFAULT_PORT as DEFAULT_KAS_PORT, KawasakiSettings
from .links.rsi import DEFAULT_LISTEN, DEFAULT_SEN_TYPE, parse_address
from .links.simple_message import (
    DEFAULT_BYTE_ORDER,
    DEFAULT_HOST,
    DEFAULT_IO_PORT,
    DEFAULT_MOTION_PORT,
    DEFAULT_PERIOD_S,
    DEFAULT_STATE_PORT,
    AdeptSettings,
)
from .service import DriverService


@click.command()
@bus_options
@click.option("--cell", envvar="ROB6_CELL", default=None, type=click.Path(dir_okay=False),
              help="The robot's cell: safety zones, tool, self-collision (YAML, docs/SAFETY_ZONES.md); "
                   "default: the floor at the base, self-collision on [env ROB6_CELL].")
@click.option("--dummy/--real-time", envvar="ROB6_DUMMY", default=False, show_default=True,
              help="Instantaneous motion like the original's -d, or motion in real time [env ROB6_DUMMY=1].")
@click.option("--link", envvar="ROB6_LINK", default="sim", show_default=True, type=click.Choice(LINKS),
              help="The robot: the simulation, a KUKA KR C4 over RSI, an Adept over simple_message "
                   "(simple_message, also called adept), or a Kawasaki running rob6's AS program "
                   "(kawasaki) [env ROB6_LINK].")
@click.option("--rsi-listen", envvar="ROB6_RSI_LISTEN", default=DEFAULT_LISTEN, show_default=True,
              help="UDP HOST:PORT the controller's RSI packets come to [env ROB6_RSI_LISTEN].")
@click.option("--rsi-sentype", envvar="ROB6_RSI_SENTYPE", default=DEFAULT_SEN_TYPE, show_default=True,
              help="The Type of the answer's <Sen> element, as in the RSI configuration [env ROB6_RSI_SENTYPE].")
@click.option("--sm-host", envvar="ROB6_SM_HOST", default=DEFAULT_HOST, show_default=True,
              help="simple_message: the controller's address [env ROB6_SM_HOST].")
@click.option("--sm-motion-port", envvar="ROB6_SM_MOTION_PORT", default=DEFAULT_MOTION_PORT, show_default=True,
              type=int, help="simple_message: the controller's motion port [env ROB6_SM_MOTION_PORT].")
@click.option("--sm-state-port", envvar="ROB6_SM_STATE_PORT", default=DEFAULT_STATE_PORT, show_default=True,
              type=int, help="simple_message: the controller's state port [env ROB6_SM_STATE_PORT].")
@click.option("--sm-io-port", envvar="ROB6_SM_IO_PORT", default=DEFAULT_IO_PORT, show_default=True,
              type=int, help="simple_message: the V+ program's digital I/O port, for DirectAdeptCmd signal "
                             "[env ROB6_SM_IO_PORT].")
@click.option("--sm-byte-order", envvar="ROB6_SM_BYTE_ORDER", default=DEFAULT_BYTE_ORDER, show_default=True,
              type=click.Choice(["big", "little"]),
              help="simple_message: the controller's byte order (the Adept V+ program: big) "
                   "[env ROB6_SM_BYTE_ORDER].")
@click.option("--sm-period", envvar="ROB6_SM_PERIOD", default=DEFAULT_PERIOD_S, show_default=True, type=float,
              help="simple_message: seconds between streamed points, rounded to controller cycles "
                   "[env ROB6_SM_PERIOD].")
@click.option("--sm-outputs", envvar="ROB6_SM_OUTPUTS", default=DEFAULT_OUTPUTS, show_default=True,
              help="simple_message: the digital outputs the controller has installed, as ranges; no other "
                   "is sent (SIGNAL of one it lacks ends the V+ program's I/O task) [env ROB6_SM_OUTPUTS].")
@click.option("--kas-host", envvar="ROB6_KAS_HOST", default="127.0.0.1", show_default=True,
              help="kawasaki: the controller's address [env ROB6_KAS_HOST].")
@click.option("--kas-port", envvar="ROB6_KAS_PORT", default=DEFAULT_KAS_PORT, show_default=True, type=int,
              help="kawasaki: the port rob6's AS PC program listens on [env ROB6_KAS_PORT].")
@click.option("--kas-period", envvar="ROB6_KAS_PERIOD", default=DEFAULT_KAS_PERIOD_S, show_default=True,
              type=float, help="kawasaki: seconds between streamed points, rounded to controller cycles "
                               "[env ROB6_KAS_PERIOD].")
def main(settings: BusSettings, log_level: str, cell: str | None, dummy: bool, link: str, rsi_listen: str, rsi_sentype: str,
         sm_host: str, sm_motion_port: int, sm_state_port: int, sm_io_port: int, sm_byte_order: str,
         sm_period: float, sm_outputs: str, kas_host: str, kas_port: int, kas_period: float) -> None:
    """Run the driver of one robot."""
    robot = get_robot(settings.robot)
    try:
        robot_cell = load_cell(cell) if cell else default_cell(robot)
    except CellError as exc:
        service.fail("driver", str(exc), EXIT_REFUSED)
    sm = AdeptSettings(host=sm_host, motion_port=sm_motion_port, state_port=sm_state_port, io_port=sm_io_port,
                       byte_order=sm_byte_order, period_s=sm_period, outputs=sm_outputs)
    kas = KawasakiSettings(host=kas_host, port=kas_port, period_s=kas_period)
    if link in ("simple_message", "adept"):
        _check_link(link, robot.is_adept, "the Adept Viper s850 (ad850)", robot.name, dummy, sm.check)
    if link == "kawasaki":
        _check_link(link, robot.is_kawa, "the Kawasaki FS03N (kaw_fs)", robot.name, dummy, kas.check)
    if link == "rsi":
        _check_link(link, robot.is_kuka, "KUKA robots (kr3, kr16, kr3rt, kr16rt)", robot.name, dummy,
                    lambda: parse_address(rsi_listen))

    def setup(bus: Bus) -> Callable[[], None]:
        try:
            driver = DriverService(bus, robot, dummy, link=link, rsi_listen=rsi_listen, rsi_sen_type=rsi_sentype,
                                   sm=sm, kas=kas, cell=robot_cell)
        except CellError as exc:  # the cell's model: a tool shape in the arm's way, a check too slow for the cycle
            raise service.StartupError(str(exc)) from None
        except OSError as exc:
            raise service.StartupError(f"cannot listen for RSI on udp/{rsi_listen}: {exc.strerror or exc}; "
                                       "is another driver running? Set ROB6_RSI_LISTEN") from None
        driver.start()
        return driver.shutdown

    service.run(settings, "driver", log_level, setup)


def _check_link(link: str, fits: bool, drives: str, robot: str, dummy: bool, check: Callable[[], object]) -> None:
    """Exit (refused, one line) when ``--link link`` cannot run: the robot is not one it
    ``drives``, ``--dummy`` is asked for, or its settings fail their ``check``."""
    if not fits:
        service.fail("driver", f"--link {link} drives {drives}, not {robot}; use --link sim", EXIT_REFUSED)
    if dummy:
        service.fail("driver", f"--link {link} moves a real robot in real time: --dummy is not possible",
                     EXIT_REFUSED)
    try:
        check()
    except ValueError as exc:
        service.fail("driver", str(exc), EXIT_REFUSED)


if __name__ == "__main__":
    main()
