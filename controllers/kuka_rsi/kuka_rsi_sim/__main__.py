"""kuka-rsi-sim: a KUKA KR C4 with RobotSensorInterface, for rob6's RSI link without a robot."""

from __future__ import annotations

import signal
import sys
from pathlib import Path
from types import FrameType
from typing import NoReturn

import click

from . import krl
from .context import KSS_RSI, RSI_NAMES, generation
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
@click.option("--program", "program", required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="the KRL program the operator selects (KRC:\\R1\\Program\\<name>.src; its .dat beside it)")
@click.option("--sensor-interface", "sensor_dir", required=True,
              type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="the controller's C:\\KRC\\ROBOTER\\Config\\User\\Common\\SensorInterface: "
                   "RSI contexts and Ethernet configurations")
@click.option("--kss", type=click.Choice(sorted(KSS_RSI)), default="8.6",
              help="the KUKA System Software release: it decides the RSI generation (8.3, 8.4: RSI 3.x; "
                   "8.5: 4.0; 8.6: 4.1; 8.7: 5.x) and so which context format RSI_CREATE loads")
@click.option("--robot", type=click.Choice(sorted(MACHINES)), default="kr16rt",
              help="robot type: its machine data (kr3: the KR 3 R540 of a KR C4)")
@click.option("--rob6", "rob6", default=None, metavar="HOST:PORT",
              help="send to this address instead of IP_NUMBER:PORT of the Ethernet configuration "
                   "(the stand-in's network is not the lab's)")
@click.option("--bind", default="0.0.0.0:0", metavar="HOST[:PORT]", help="the controller's own RSI address")
@click.option("--control", default="127.0.0.1:0", metavar="HOST:PORT",
              help="TCP control channel (newline-delimited JSON); port 0 picks a free one")
@click.option("--start-pose", default=",".join(f"{v:g}" for v in HOME), metavar="A1,..,A6",
              help="axis angles (deg) where the arm stands at power-on")
@click.option("--t1/--aut", "t1", default=False,
              help="operating mode: T1 makes each RSI_ON wait for the operator to confirm its warning "
                   "(control request confirm)")
@click.option("--timeout", type=click.IntRange(min=1), default=None,
              help="replace the ETHERNET object's Timeout of the context (a stand-in on a host that is no "
                   "real-time PC; a lab runs the file's value)")
@click.option("--cycle-ms", type=click.IntRange(min=1, max=1000), default=None,
              help="for tests only: replace the cycle RSI_ON chooses (4 ms #IPO_FAST, 12 ms #IPO)")
@click.option("--auto-ack", type=click.FloatRange(min=0), default=None,
              help="after the program stopped (a fault) or ended, start it again after this many seconds "
                   "like an operator would [default: wait for a restart request]")
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
def main(program: Path, sensor_dir: Path, kss: str, robot: str, rob6: str | None, bind: str, control: str,
         start_pose: str, t1: bool, timeout: int | None, cycle_ms: int | None, auto_ack: float | None, lose_s: float | None,
         drop_every: int | None, delay_ms: float | None, duplicate_every: int | None, reorder_every: int | None,
         vanish_s: float | None) -> None:
    """A KUKA KR C4 running the installed KRL program and RSI context against the rob6 PC.

    It selects and starts --program as an operator would; the program's RSI_CREATE loads
    the context from --sensor-interface in the format of the --kss release's RSI, and while
    RSI is on the controller sends <Rob> every cycle and reads <Sen> as the Ethernet
    configuration says. See controllers/kuka_rsi/README.md.
    """
    machine = MACHINES[robot]
    pose = _numbers(start_pose, "--start-pose")
    if len(pose) != 6:
        raise click.BadParameter(f"need 6 axis angles, got {len(pose)}", param_hint="--start-pose")
    for n, (v, lo, hi) in enumerate(zip(pose, machine.lower, machine.upper, strict=True)):
        if not lo <= v <= hi:
            raise click.BadParameter(f"A{n + 1} = {v:g} is outside {lo:g} .. {hi:g} of {robot}",
                                     param_hint="--start-pose")
    faults = {k: v for k, v in dict(lose_s=lose_s, drop_every=drop_every, delay_ms=delay_ms,
                                    duplicate_every=duplicate_every, reorder_every=reorder_every).items()
              if v is not None}
    opts = Options(
        machine=machine,
        kss=kss,
        generation=generation(kss),
        program=program,
        sensor_dir=sensor_dir,
        rob6=None if rob6 is None else _address(rob6, "--rob6"),
        bind=_address(bind, "--bind", default_host="0.0.0.0"),
        control=_address(control, "--control"),
        start_pose=tuple(pose),
        timeout=timeout,
        cycle_ms=cycle_ms,
        t1=t1,
        auto_ack=auto_ack,
        faults=faults,
        vanish_s=vanish_s,
    )

    def stop(signum: int, _frame: FrameType | None) -> NoReturn:
        raise Shutdown(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    try:
        sim = Simulator(opts)
    except krl.KrlError as e:
        raise click.ClickException(f"program {program.name} cannot be selected: {e}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise click.ClickException(f"cannot start: {e}") from None
    host, port = sim.control_address
    print(f"kuka-rsi-sim ready: control {host}:{port}, KSS {kss} ({RSI_NAMES[opts.generation]}), "
          f"program {program.stem}", flush=True)
    log(f"{robot}, KSS {kss}, {'T1' if t1 else 'AUT'}, the arm at " + " ".join(f"{v:g}" for v in pose))
    try:
        sim.serve()
    except Shutdown as e:
        log(f"{e}: exiting")
    finally:
        sim.close()
    sys.exit(0)


if __name__ == "__main__":
    main()
