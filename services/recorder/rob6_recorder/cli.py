"""``rob6-log``: inspect, export, recover and replay rob6 recordings.

    rob6-log summary FILE [--json]
    rob6-log export FILE --csv OUTDIR
    rob6-log recover FILE [-o OUT | --in-place]
    rob6-log doctor FILE
    rob6-log replay SESSION.mcap --to HOST:PORT [--speed X | --as-fast-as-possible]
                    [--robot TYPE] [--tolerance 1e-5] [--session N]
    rob6-log replay-joints FILE [--speed X]      (prints JSON lines; the service
                                                  publishes them on the bus)
    rob6-log play FILE [--port 8765] [--speed X] [--paused] [--loop]
                                                 (into the live view: watch it in Foxglove)

Until the console script is declared, run it as ``python -m rob6_recorder.cli``.
Exit codes: 0 ok, 1 differences / damaged file, 2 usage or connection error.
"""

from __future__ import annotations

import asyncio
import json
import logging
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from rob6.config import DEFAULT_LIVE_PORT

from .inspect import export_csv, format_summary, summarize
from .reader import NotMcap, ScanReport, scan

if TYPE_CHECKING:
    from .session_replay import ReplayResult


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", is_flag=True, help="Log at INFO level.")
def main(verbose: bool) -> None:
    """Inspect, export, recover and replay rob6 MCAP recordings."""
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")


def _existing(path: str) -> Path:
    p = Path(path)
    if not p.is_file():
        raise click.UsageError(f"no such file: {path}")
    return p


@main.command()
@click.argument("file")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
def summary(file: str, as_json: bool) -> None:
    """Sessions, command counts, errors, durations, robot, records per topic."""
    try:
        s = summarize(_existing(file))
    except NotMcap as exc:
        raise click.ClickException(str(exc)) from exc
    if as_json:
        click.echo(json.dumps(s.as_dict(), indent=2))
    else:
        click.echo(format_summary(s))


@main.command()
@click.argument("file")
@click.option("--csv", "outdir", required=True, type=click.Path(file_okay=False),
              help="Directory for commands.csv, joint_states.csv, log.csv.")
def export(file: str, outdir: str) -> None:
    """Export the command log and joint states as CSV."""
    try:
        counts = export_csv(_existing(file), outdir)
    except NotMcap as exc:
        raise click.ClickException(str(exc)) from exc
    for name, n in counts.items():
        click.echo(f"{Path(outdir) / name}: {n} rows")


@main.command()
@click.argument("file")
@click.option("-o", "--output", help="Output file (default: FILE with .recovered.mcap).")
@click.option("--in-place", is_flag=True, help="Replace FILE; keep the original as FILE.unfinished.")
def recover(file: str, output: str | None, in_place: bool) -> None:
    """Rebuild an unfinished/damaged recording into a readable, indexed file."""
    from .recover import recover as do_recover, recover_in_place

    src = _existing(file)
    try:
        if in_place:
            result = recover_in_place(src)
        else:
            out = Path(output) if output else src.with_name(src.stem + ".recovered.mcap")
            result = do_recover(src, out)
    except NotMcap as exc:
        raise click.ClickException(str(exc)) from exc
    click.echo(result.describe())


@main.command()
@click.argument("file")
def doctor(file: str) -> None:
    """Check a recording: finished?, readable up to where?, damaged chunks? (exit 1 if not clean)."""
    report = ScanReport()
    messages = 0
    try:
        for _ in scan(_existing(file), report):
            pass
    except NotMcap as exc:
        raise click.ClickException(str(exc)) from exc
    messages = report.messages
    state = "complete" if report.complete else ("truncated" if report.truncated else "unfinished")
    click.echo(f"{file}: {state}; {messages} messages in {report.chunks} chunks "
               f"({report.bad_chunks} damaged); readable up to {report.good_until} of "
               f"{report.size} bytes")
    if report.error and not report.complete:
        click.echo(f"  {report.error}")
    if not report.complete or report.bad_chunks:
        click.echo(f"  run: rob6-log recover {file}")
        sys.exit(1)


def _host_port(value: str) -> tuple[str, int]:
    host, sep, port = value.rpartition(":")
    if not sep or not port.isdigit():
        raise click.BadParameter("expected HOST:PORT", param_hint="--to")
    return host or "127.0.0.1", int(port)


@main.command()
@click.argument("file")
@click.option("--to", "target", required=True, help="Server to replay against, HOST:PORT.")
@click.option("--speed", type=float, default=1.0, show_default=True,
              help="Pacing factor on the recorded timing (2 = twice as fast).")
@click.option("--as-fast-as-possible", "afap", is_flag=True,
              help="Ignore the recorded timing: next line as soon as the reply is complete.")
@click.option("--robot", help="Robot type the target runs (warns if it differs from the "
                              "recording's; a transcript's folder name otherwise).")
@click.option("--session", help="Replay only this session of the recording.")
@click.option("--tolerance", type=float, default=1e-5, show_default=True,
              help="Absolute tolerance for numbers.")
@click.option("--timeout", type=float, default=5.0, show_default=True,
              help="Seconds to wait for a reply's expected lines.")
@click.option("--quiet-ms", type=float, default=100.0, show_default=True,
              help="Wait this long for stray output when no reply line is expected.")
@click.option("--no-handshake", is_flag=True,
              help="Do not send 'Hello Robot' when the recording starts after the handshake.")
@click.option("--no-progress", is_flag=True, help="No progress bar.")
@click.option("--max-report", type=int, default=50, show_default=True,
              help="Differences shown in detail.")
def replay(file: str, target: str, speed: float, afap: bool, robot: str | None,
           session: str | None, tolerance: float, timeout: float, quiet_ms: float,
           no_handshake: bool, no_progress: bool, max_report: int) -> None:
    """Re-send a recorded session's client lines to HOST:PORT and compare the replies.

    FILE is a recording (.mcap) or a conformance transcript (.jsonl). Exit code 1
    when any reply differs, 2 when the server cannot be reached.
    """
    from .session_replay import format_report, load_script, replay as do_replay

    host, port = _host_port(target)
    if speed <= 0 and not afap:
        raise click.BadParameter("must be > 0 (or use --as-fast-as-possible)", param_hint="--speed")
    scripts = load_script(_existing(file), session=session, robot=robot)
    if not scripts or not any(s.exchanges for s in scripts):
        raise click.ClickException(f"{file}: no client session to replay"
                                   + (f" (session {session})" if session else ""))
    recorded = next((s.robot for s in scripts if s.robot), None)
    if robot and recorded and robot != recorded:
        click.echo(f"warning: {file} was recorded with robot {recorded}, target runs {robot}",
                   err=True)
    total = sum(len(s.exchanges) for s in scripts)

    async def run(progress: Callable[[int], None] | None) -> ReplayResult:
        return await do_replay(scripts, host, port, speed=None if afap else speed,
                               tolerance=tolerance, timeout=timeout, quiet=quiet_ms / 1000.0,
                               auto_handshake=not no_handshake, progress=progress)

    if no_progress:
        result = asyncio.run(run(None))
    else:
        with click.progressbar(length=total, label="replaying", file=sys.stderr,
                               show_pos=True) as bar:
            result = asyncio.run(run(bar.update))
    result.robot_recorded = recorded
    result.robot_target = robot
    click.echo(format_report(result, limit=max_report))
    if result.aborted and "cannot connect" in result.aborted:
        sys.exit(2)
    sys.exit(0 if result.ok else 1)


@main.command("replay-joints")
@click.argument("file")
@click.option("--speed", type=float, default=1.0, show_default=True,
              help="Pacing factor; 0 = as fast as possible.")
@click.option("--topic", default="/driver/joint_state", show_default=True)
def replay_joints_cmd(file: str, speed: float, topic: str) -> None:
    """Print the recorded joint states as JSON lines at the recorded pace."""
    from .playback import replay_joints

    out = sys.stdout

    def publish(state: dict[str, Any]) -> None:
        out.write(json.dumps(state, separators=(",", ":")) + "\n")
        out.flush()

    n = replay_joints(_existing(file), publish, speed=speed or None, topic=topic)
    click.echo(f"{n} joint states", err=True)


@main.command()
@click.argument("file")
@click.option("--port", envvar="ROB6_LIVE_PORT", default=DEFAULT_LIVE_PORT, show_default=True, type=int,
              help="Live-view port to serve on (0 = any free port) [env ROB6_LIVE_PORT].")
@click.option("--bind", envvar="ROB6_BIND", default="127.0.0.1", show_default=True,
              help="Address to listen on [env ROB6_BIND].")
@click.option("--speed", type=float, default=1.0, show_default=True,
              help="Pacing factor (Foxglove's speed control changes it).")
@click.option("--paused", is_flag=True, help="Start paused (press play in Foxglove).")
@click.option("--loop", is_flag=True, help="Start again at the end.")
@click.option("--exit-at-end", is_flag=True, help="Stop serving at the end (scripts, tests).")
def play(file: str, port: int, bind: str, speed: float, paused: bool, loop: bool, exit_at_end: bool) -> None:
    """Play a recording into the live view (Foxglove WebSocket), seekable from Foxglove."""
    from .playback import play as make_player

    if speed <= 0:
        raise click.UsageError("--speed must be > 0")
    try:
        player = make_player(_existing(file), host=bind, port=port, speed=speed, paused=paused, loop=loop)
    except NotMcap as exc:
        raise click.ClickException(str(exc)) from exc
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    except RuntimeError as exc:  # the port is taken
        raise click.ClickException(f"cannot serve on {bind}:{port}: {exc}") from exc
    seconds = (player.end_ns - player.start_ns) / 1e9
    click.echo(f"live view: {player.view.url} (open in Foxglove: Open connection > Foxglove WebSocket)", err=True)
    click.echo(f"playing {file}: {len(player.items)} messages, {seconds:.1f} s, at {speed:g}x"
               f"{' (paused)' if paused else ''}; Ctrl-C stops", err=True)
    signal.signal(signal.SIGTERM, lambda *_: player.stop())
    try:
        player.run(exit_at_end=exit_at_end)
    except KeyboardInterrupt:
        player.stop()


if __name__ == "__main__":
    main()
