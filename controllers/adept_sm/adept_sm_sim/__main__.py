"""adept-sm-sim command line: start the simulated Adept controller."""

from __future__ import annotations

import asyncio
import signal
import sys

import click

from .convention import ACCEL_TIME_S, limit_violation, rob6_to_controller
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


def _ranges(value: str) -> tuple[range, ...]:
    out = []
    for part in value.replace(" ", "").split(","):
        first, sep, last = part.partition("-")
        if not first.isdigit() or (sep and not last.isdigit()):
            raise click.BadParameter(f"--installed: expected ranges like 1-8,1001-1012, got {value!r}")
        out.append(range(int(first), int(last if sep else first) + 1))
    return tuple(out)


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
@click.option("--monitor-speed", default=100.0, show_default=True, type=click.FloatRange(1.0, 100.0),
              help="The pendant's monitor speed, percent: every motion planned at 100 % and lasting 100/s times as long.")
@click.option("--accel-time", default=ACCEL_TIME_S, show_default=True, type=click.FloatRange(0.01, 5.0),
              help="Seconds from rest to full speed at 100 % (the Viper's ACCEL 100, to be measured).")
@click.option("--min-move-s", default=0.0, show_default=True, type=click.FloatRange(0.0, 5.0),
              help="V+'s shortest joint motion, seconds at 100 % (to be measured; 0: none).")
@click.option("--connect-read", default="client", show_default=True, type=click.Choice(["client", "notice"]),
              help="The four bytes the program reads on a new motion connection: the client's first "
                   "(client) or something V+ delivers itself (notice).")
@click.option("--restart-s", default=0.5, show_default=True, type=click.FloatRange(0.0, 60.0),
              help="Seconds the supervisor (task.controll) takes to restart an ended motion or state task.")
@click.option("--installed", default="1-8,1001-1012", show_default=True,
              help="The digital signals the controller has, as ranges (soft signals 2001-2512 always).")
def main(host: str, motion_port: int, state_port: int, io_port: str, control: str, byte_order: str,
         start_pose: str, state_period: float, monitor_speed: float, accel_time: float, min_move_s: float,
         connect_read: str, restart_s: float, installed: str) -> None:
    """A simulated Adept Viper s850 controller running the ROS-Industrial V+ server
    (simple_message over TCP), for testing rob6's simple_message link."""
    control_host, control_port = _host_port(control)
    io = None if io_port == "off" else _port(io_port, "--io-port")
    cfg = Config(
        host=host, motion_port=motion_port, state_port=state_port, io_port=io,
        control_host=control_host, control_port=control_port, byte_order=byte_order,
        start_pose_ctrl=_pose(start_pose), state_period=state_period, monitor_speed=monitor_speed,
        accel_time_s=accel_time, min_move_s=min_move_s,
        connect_read=connect_read, restart_s=restart_s, installed=_ranges(installed),
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
