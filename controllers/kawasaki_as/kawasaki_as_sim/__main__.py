"""kawasaki-as-sim command line: start the simulated Kawasaki controller."""

from __future__ import annotations

import asyncio
import signal
import sys

import click

from .arm import outside_range
from .convention import to_controller
from .server import Config, Controller, event, run


def _host_port(value: str) -> tuple[str, int]:
    host, sep, port = value.rpartition(":")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise click.BadParameter(f"expected HOST:PORT, got {value!r}")
    return host, int(port)


def _pose(value: str) -> tuple[float, ...]:
    try:
        q = tuple(float(x) for x in value.replace(",", " ").split())
    except ValueError:
        raise click.BadParameter(f"six numbers expected, got {value!r}") from None
    if len(q) != 6:
        raise click.BadParameter(f"six joint values expected, got {len(q)}")
    ctrl = to_controller(q)
    reason = outside_range(ctrl)
    if reason:
        raise click.BadParameter(f"{reason} (the controller's convention; rob6 joints: {value})")
    return ctrl


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--host", default="127.0.0.1", show_default=True, help="Address of the PC program's port.")
@click.option("--port", default=49200, show_default=True, type=click.IntRange(0, 65535),
              help="The PC program's TCP port (0: any free port).")
@click.option("--control", default="127.0.0.1:0", show_default=True,
              help="HOST:PORT of the JSON fault-injection channel.")
@click.option("--start-pose", default="0 0 0 0 0 0", show_default=True,
              help="Initial joints, rob6 convention, degrees (six numbers).")
@click.option("--state-period", default=0.05, show_default=True, type=click.FloatRange(0.01, 0.1),
              help="Seconds between state messages (the protocol asks for 10 Hz or more).")
@click.option("--capacity", default=64, show_default=True, type=click.IntRange(3, 1000),
              help="Points the program's queue holds (at least the three a motion starts with).")
def main(host: str, port: int, control: str, start_pose: str, state_period: float, capacity: int) -> None:
    """A simulated Kawasaki FS03N controller running rob6's AS program pair (the rob6-kas
    protocol over TCP), for testing rob6's kawasaki link."""
    control_host, control_port = _host_port(control)
    cfg = Config(host=host, port=port, control_host=control_host, control_port=control_port,
                 start_pose_ctrl=_pose(start_pose), state_period=state_period, capacity=capacity)
    try:
        asyncio.run(_main(cfg))
        event("stopped")
    except OSError as exc:
        click.echo(f"kawasaki-as-sim: cannot listen: {exc}", err=True)
        sys.exit(1)


async def _main(cfg: Config) -> None:
    def ready(addr: tuple[str, int], ctl_addr: tuple[str, int], ctl: Controller) -> None:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, ctl.done.set)
        print(f"kawasaki-as-sim ready: port {addr[0]}:{addr[1]}, control {ctl_addr[0]}:{ctl_addr[1]}", flush=True)

    await run(cfg, ready)


if __name__ == "__main__":
    main()
