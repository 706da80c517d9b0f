"""adept-sm-sim command line: start the simulated Adept controller."""

from __future__ import annotations

import asyncio
import signal
import sys

import click

from .convention import limit_violation, rob6_to_controller
from .server import Config, Controller, event, run


def _host_port(value: str) -> tuple[str, int]:
    host, sep, port = value.rpartition(":")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise click.BadParameter(f"expected HOST:PORT, got {value!r}")
    return host, int(port)


def _port(value: str, option: str) -> int:
    if not value.isdigit() or int(value) > 65535:
        raise click.BadParameter(f"{option}: expected a port 0..65535 or off, got {value!r}")
    return int(value)


def _pose(value: str) -> tuple[float, ...]:
    try:
        q = tuple(float(x) for x in value.replace(",", " ").split())
    except ValueError:
        raise click.BadParameter(f"six numbers expected, got {value!r}") from None
    if len(q) != 6:
        raise click.BadParameter(f"six joint values expected, got {len(q)}")
    ctrl = rob6_to_controller(q)
    reason = limit_violation(ctrl)
    if reason:
        raise click.BadParameter(f"{reason} (the controller's convention; rob6 joints: {value})")
    return ctrl


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address of the motion, state and I/O ports.")
@click.option("--motion-port", default=11000, show_default=True, type=click.IntRange(0, 65535),
              help="JOINT_TRAJ_PT in (0: any free port).")
@click.option("--state-port", default=11002, show_default=True, type=click.IntRange(0, 65535),
              help="JOINT_POSITION and STATUS out (0: any free port).")
@click.option("--io-port", default="11001", show_default=True,
              help="The V+ program's digital I/O port (0: any free port; off: none).")
@click.option("--control", default="127.0.0.1:0", show_default=True,
              help="HOST:PORT of the JSON fault-injection channel.")
@click.option("--byte-order", default="big", show_default=True,
              type=click.Choice(["big", "little"]),
              help="simple_message byte order; the V+ program writes big-endian.")
@click.option("--start-pose", default="0 0 0 0 0 0", show_default=True,
              help="Initial joints, rob6 convention, degrees (six numbers).")
@click.option("--state-period", default=0.1, show_default=True,
              type=click.FloatRange(0.001, 60.0), help="Seconds between state messages.")
@click.option("--timing", default="vplus", show_default=True,
              type=click.Choice(["vplus", "duration"]),
              help="vplus: ignore velocity and duration, move at full speed like the V+ "
                   "program; duration: honour them.")
@click.option("--monitor-speed", default=100.0, show_default=True,
              type=click.FloatRange(1.0, 100.0), help="The pendant's monitor speed, percent.")
@click.option("--queue-depth", default=1, show_default=True, type=click.IntRange(1, 10000),
              help="Points queued beyond the one moving (V+ runs one motion ahead: 1).")
@click.option("--status-fields", default="full", show_default=True,
              type=click.Choice(["full", "vplus"]),
              help="full: report errors and motion_possible; vplus: exactly what the V+ "
                   "program sends (no errors, motion_possible = not in motion).")
def main(host: str, motion_port: int, state_port: int, io_port: str, control: str, byte_order: str,
         start_pose: str, state_period: float, timing: str, monitor_speed: float, queue_depth: int,
         status_fields: str) -> None:
    """A simulated Adept Viper s850 controller running the ROS-Industrial V+ server
    (simple_message over TCP), for testing rob6's simple_message link."""
    control_host, control_port = _host_port(control)
    io = None if io_port == "off" else _port(io_port, "--io-port")
    cfg = Config(
        host=host, motion_port=motion_port, state_port=state_port, io_port=io,
        control_host=control_host, control_port=control_port, byte_order=byte_order,
        start_pose_ctrl=_pose(start_pose), state_period=state_period, timing=timing,
        monitor_speed=monitor_speed, queue_depth=queue_depth, status_fields=status_fields,
    )
    try:
        asyncio.run(_main(cfg))
        event("stopped")
    except OSError as exc:  # a port in use, an address not on this machine
        click.echo(f"adept-sm-sim: cannot listen: {exc}", err=True)
        sys.exit(1)


async def _main(cfg: Config) -> None:
    def ready(addr: dict[str, tuple[str, int]], ctl: Controller) -> None:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, ctl.done.set)
        line = (f"adept-sm-sim ready: motion {_fmt(addr['motion'])}, "
                f"state {_fmt(addr['state'])}, control {_fmt(addr['control'])}")
        if "io" in addr:
            line += f", io {_fmt(addr['io'])}"
        print(line, flush=True)

    await run(cfg, ready)


def _fmt(addr: tuple[str, int]) -> str:
    return f"{addr[0]}:{addr[1]}"


if __name__ == "__main__":
    main()
