"""kuka-rsi-sim: a KUKA KR C4 with RobotSensorInterface, for rob6's RSI link without a robot."""

from __future__ import annotations

import signal
import sys
from types import FrameType
from typing import NoReturn

import click

from .machine import HOME, MACHINES
from .server import Options, Shutdown, Simulator, log


def _address(value: str, what: str, default_host: str | None = None) -> tuple[str, int]:
    host, sep, port = value.rpartition(":")
    if not sep:
        if default_host is None:
            raise click.BadParameter(f"{what} must be HOST:PORT, got {value!r}")
        host, port = value, "0"
    if not host:
        raise click.BadParameter(f"{what} must be HOST:PORT, got {value!r}")
    try:
        p = int(port)
    except ValueError:
        raise click.BadParameter(f"{what}: port {port!r} is not a number") from None
    if not 0 <= p <= 65535:
        raise click.BadParameter(f"{what}: port {p} out of range")
    return host.strip("[]"), p


def _numbers(value: str, what: str) -> list[float]:
    try:
        return [float(v) for v in value.replace(",", " ").split()]
    except ValueError:
        raise click.BadParameter(f"{what}: {value!r} is not a list of numbers") from None


@click.command(context_settings={"help_option_names": ["-h", "--help"], "show_default": True})
@click.option("--robot", type=click.Choice(sorted(MACHINES)), default="kr16rt",
              help="robot type: machine data and RSI cycle (rt: 4 ms #IPO_FAST, else 12 ms #IPO)")
@click.option("--rob6", "rob6", default="127.0.0.1:49152", metavar="HOST:PORT",
              help="the rob6 PC: IP_NUMBER and PORT of the Ethernet configuration")
@click.option("--bind", default="0.0.0.0:0", metavar="HOST[:PORT]", help="the controller's own RSI address")
@click.option("--control", default="127.0.0.1:0", metavar="HOST:PORT",
              help="TCP control channel (newline-delimited JSON); port 0 picks a free one")
@click.option("--sentype", default="ImFree", help="SENTYPE: the Type the PC's <Sen> must carry")
@click.option("--timeout", type=click.IntRange(min=1), default=100,
              help="ETHERNET object Timeout: late packets before RSI stops")
@click.option("--timeout-counts", type=click.Choice(["consecutive", "total"]), default="consecutive",
              help="what reaching Timeout means: consecutive late packets (KUKA's documented behaviour) "
                   "or all late packets of the run (a stricter check)")
@click.option("--corr-window", default=None, metavar="W | W1,..,W6",
              help="AXISCORR/AXISCORRMON window, +-degrees per axis [default: the axis range width]")
@click.option("--start-pose", default=",".join(f"{v:g}" for v in HOME), metavar="A1,..,A6",
              help="axis angles (deg) where the first run starts")
@click.option("--cycle-ms", type=click.IntRange(min=1, max=1000), default=None,
              help="override the RSI cycle of --robot")
@click.option("--restart-delay", type=click.FloatRange(min=0), default=1.0,
              help="seconds from <Stop>1</Stop> until the KRL loop starts the next run")
@click.option("--auto-ack", type=click.FloatRange(min=0), default=None,
              help="after a fault, restart after this many seconds like an operator would "
                   "[default: stay stopped until a restart request]")
@click.option("--eipos/--no-eipos", default=False, help="also send EIPos E1..E6 (no external axes: 0)")
@click.option("--lose-s", type=click.FloatRange(min=0), default=None,
              help="fault: lose every packet in both directions for the first T seconds")
@click.option("--drop-every", type=click.IntRange(min=0), default=None, help="fault: drop every Nth packet")
@click.option("--delay-ms", type=click.FloatRange(min=0), default=None,
              help="fault: delay every controller->PC packet by d ms")
@click.option("--duplicate-every", type=click.IntRange(min=0), default=None, help="fault: send every Nth packet twice")
@click.option("--reorder-every", type=click.IntRange(min=0), default=None,
              help="fault: send every Nth packet after its successor")
@click.option("--vanish-s", type=click.FloatRange(min=0, min_open=True), default=None,
              help="fault: stay silent (controller off) for the first T seconds")
def main(robot: str, rob6: str, bind: str, control: str, sentype: str, timeout: int, timeout_counts: str,
         corr_window: str | None, start_pose: str, cycle_ms: int | None, restart_delay: float, auto_ack: float | None,
         eipos: bool, lose_s: float | None, drop_every: int | None, delay_ms: float | None,
         duplicate_every: int | None, reorder_every: int | None, vanish_s: float | None) -> None:
    """A KUKA KR C4 running RSI (RobotSensorInterface) against the rob6 PC.

    Every IPO cycle it sends <Rob> (RIst, RSol, AIPos, ASPos, Delay, IPOC) to --rob6 and
    expects <Sen Type=SENTYPE><AK A1..A6/>[<Stop>1</Stop>]<IPOC/></Sen> before the next
    tick. See controllers/kuka_rsi/README.md for the behaviour and the control channel.
    """
    machine = MACHINES[robot]
    pose = _numbers(start_pose, "--start-pose")
    if len(pose) != 6:
        raise click.BadParameter(f"need 6 axis angles, got {len(pose)}", param_hint="--start-pose")
    for n, (v, lo, hi) in enumerate(zip(pose, machine.lower, machine.upper, strict=True)):
        if not lo <= v <= hi:
            raise click.BadParameter(f"A{n + 1} = {v:g} is outside {lo:g} .. {hi:g} of {robot}",
                                     param_hint="--start-pose")
    if corr_window is None:
        window = machine.range_width()
    else:
        w = _numbers(corr_window, "--corr-window")
        if len(w) == 1:
            w = w * 6
        if len(w) != 6 or any(v <= 0 for v in w):
            raise click.BadParameter("one window or six, all > 0 (degrees)", param_hint="--corr-window")
        window = tuple(w)
    faults = {k: v for k, v in dict(lose_s=lose_s, drop_every=drop_every, delay_ms=delay_ms,
                                    duplicate_every=duplicate_every, reorder_every=reorder_every).items()
              if v is not None}
    opts = Options(
        machine=machine,
        cycle_ms=cycle_ms or machine.ipo_ms,
        rob6=_address(rob6, "--rob6"),
        bind=_address(bind, "--bind", default_host="0.0.0.0"),
        control=_address(control, "--control"),
        sentype=sentype,
        timeout=timeout,
        timeout_counts=timeout_counts,
        corr_window=window,
        start_pose=tuple(pose),
        restart_delay=restart_delay,
        auto_ack=auto_ack,
        eipos=eipos,
        faults=faults,
        vanish_s=vanish_s,
    )

    def stop(signum: int, _frame: FrameType | None) -> NoReturn:
        raise Shutdown(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    try:
        sim = Simulator(opts)
    except OSError as e:
        raise click.ClickException(f"cannot open the sockets: {e}") from None
    host, port = sim.control_address
    print(f"kuka-rsi-sim ready: control {host}:{port}, sending to {opts.rob6[0]}:{opts.rob6[1]} "
          f"every {opts.cycle_ms} ms", flush=True)
    log(f"{robot}, SENTYPE {sentype}, Timeout {timeout} ({timeout_counts}), start pose "
        + " ".join(f"{v:g}" for v in pose))
    try:
        sim.serve()
    except Shutdown as e:
        log(f"{e}: exiting")
    finally:
        sim.close()
    sys.exit(0)


if __name__ == "__main__":
    main()
