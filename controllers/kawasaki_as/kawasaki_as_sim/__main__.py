"""kawasaki-as-sim command line: start the simulated Kawasaki controller."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import click

from .arm import outside_range
from .aslang import AsSyntaxError
from .asrun import PC_STEPS_PER_TICK
from .convention import to_controller
from .server import START, Config, Controller, event, run

#: the file a lab loads: inside the wheel (pyproject.toml's force-include), or deploy/kawasaki in the repository
PACKAGED = Path(__file__).resolve().parent / "rob6.as"
REPOSITORY = Path(__file__).resolve().parents[3] / "deploy" / "kawasaki" / "rob6.as"


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
@click.option("--program", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="The AS file the controller loads (default: rob6's deploy/kawasaki/rob6.as).")
@click.option("--start", "start", multiple=True,
              help="An operator command run at start, in order (default: " + "; ".join(START) + ").")
@click.option("--host", default="127.0.0.1", show_default=True, help="Address of the program's port.")
@click.option("--port", default=49200, show_default=True, type=click.IntRange(0, 65535),
              help="Where the program's port appears on this host (0: any free port).")
@click.option("--state-port", default=49201, show_default=True, type=click.IntRange(0, 65535),
              help="Where the program's state port (its kport + 1) appears on this host (0: any free port).")
@click.option("--pc-steps", default=PC_STEPS_PER_TICK, show_default=True, type=click.IntRange(1, 100000),
              help="Steps all PC programs together run per 4 ms tick (a guess until a first session measures it).")
@click.option("--as-port", default=49200, show_default=True, type=click.IntRange(8192, 65535),
              help="The port the program listens on (its kport).")
@click.option("--control", default="127.0.0.1:0", show_default=True,
              help="HOST:PORT of the JSON fault-injection channel.")
@click.option("--start-pose", default="0 0 0 0 0 0", show_default=True,
              help="Initial joints, rob6 convention, degrees (six numbers).")
def main(program: Path | None, start: tuple[str, ...], host: str, port: int, state_port: int, pc_steps: int,
         as_port: int, control: str, start_pose: str) -> None:
    """A simulated Kawasaki FS03N controller executing an AS program (rob6's rob6.as), for
    testing rob6's kawasaki link."""
    control_host, control_port = _host_port(control)
    path = program or (PACKAGED if PACKAGED.exists() else REPOSITORY)
    if not path.exists():
        raise click.UsageError(f"no AS program at {PACKAGED} or {REPOSITORY}: give --program")
    cfg = Config(program=path, host=host, port=port, state_port=state_port, pc_steps=pc_steps, as_port=as_port, control_host=control_host,
                 control_port=control_port, start_pose_ctrl=_pose(start_pose), start=start or START)

    def ready(addr: tuple[str, int, int], ctl_addr: tuple[str, int]) -> None:
        print(f"kawasaki-as-sim ready: port {addr[0]}:{addr[1]}, state port {addr[2]}, "
              f"control {ctl_addr[0]}:{ctl_addr[1]}", flush=True)

    def on_signals(ctl: Controller) -> None:
        def done(*_: object) -> None:
            ctl.done = True
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, done)

    try:
        run(cfg, ready, on_signals)
        event("stopped")
    except AsSyntaxError as exc:
        click.echo(f"kawasaki-as-sim: {path}: STEP syntax error: {exc}", err=True)
        sys.exit(3)
    except RuntimeError as exc:
        click.echo(f"kawasaki-as-sim: the program did not start: {exc}", err=True)
        sys.exit(3)
    except OSError as exc:
        click.echo(f"kawasaki-as-sim: cannot listen: {exc}", err=True)
        sys.exit(1)


if __name__ == "__main__":
    main()
