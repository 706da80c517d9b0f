"""No lost records: a recorder SIGKILLed mid-session and restarted by the launcher still
gets every client exchange of the session and every joint state the driver published (the
gateway's and the driver's trace batches come from an advanced publisher that keeps 30 s of
them; the restarted recorder's advanced subscriber
asks for that history, and for what the history left out the cache is asked directly:
rob6.bus.trace ``_TraceSubscription._repair``), and what it could not get it says on
``/recorder/status``.

The gateway numbers the exchanges of a session (``seq`` 1, 2, ...): every number must be
in the MCAP files (the killed recorder's unfinished files and the new recorder's). The
driver publishes a state at least every ``REST_STATE_PERIOD_S`` (the next cycle after
it): no longer gap between two recorded ones (they are traced too, ``Bus.publish_state``)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from harness.system import System, running
from rob6.robots import get_robot
from rob6_driver.service import REST_STATE_PERIOD_S
from rob6_recorder.reader import Record, read_records

PERIOD = 0.004  # s between client lines


def _records(directory: Path, topic_end: str, kind: str = "") -> list[Record]:
    """The records on topics ending in ``topic_end`` of every file (``kind``: of the
    session files, ``_session``, or of the system files, ``_system``, only)."""
    out = []
    for path in sorted(directory.glob(f"*{kind}*.mcap" if kind else "*.mcap")):
        out += [r for r in read_records(path) if r.topic.endswith(topic_end)]
    return out


def _recorder_restarted(system: System, killed: int, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while system.pids().get("recorder") in (None, killed):
        assert time.monotonic() < deadline, "the launcher did not restart the recorder"
        time.sleep(0.05)


def test_recorder_killed_and_restarted_mid_session_loses_no_client_record(tmp_path: Path) -> None:
    with running("kr16", log_dir=str(tmp_path), restart=True) as system:
        with system.client() as client:
            exchanges = 1  # the handshake line

            def ask(line: str, reply: str) -> None:  # at 250 Hz, like an Alter session
                nonlocal exchanges
                started = time.monotonic()
                assert client.ask(line) == reply
                exchanges += 1
                time.sleep(max(0.0, PERIOD - (time.monotonic() - started)))

            end = time.monotonic() + 1.5  # over a second of records written before the kill
            while time.monotonic() < end:
                ask("GetRobot", "kr16\n")
            killed = system.pids()["recorder"]
            os.kill(killed, signal.SIGKILL)
            restarted = False
            until = None
            # the session goes on while no recorder runs, and for 5 s after one is started again
            while until is None or time.monotonic() < until:
                ask("CM_PING", "PONG\n")
                if not restarted and system.pids().get("recorder") not in (None, killed):
                    restarted, until = True, time.monotonic() + 5.0
                assert exchanges < 20_000, "the launcher did not restart the recorder"
            for _ in range(50):
                ask("GetRobot", "kr16\n")
            assert client.ask("Quit") == "bye!\n"
            exchanges += 1
        _recorder_restarted(system, killed)
        time.sleep(2.0)  # the last batches and the session file's end
    status = [r.data for r in _records(tmp_path, "/recorder/status")]
    lost, replayed = {}, {}
    for kind in ("_session", "_system"):  # each record is in its session's file and the system file
        seqs = [r.data.get("seq") for r in _records(tmp_path, "/client_in", kind)]
        missing = sorted(set(range(1, exchanges + 1)) - set(seqs))
        lost[kind] = missing
        replayed[kind] = len(seqs) - len(set(seqs))
        print(f"\n{kind[1:]} files: {exchanges} exchanges, {len(missing)} missing, "
              f"{len(seqs) - len(set(seqs))} recorded twice (the restarted recorder's history)")
    print(f"status: {status}")
    for path in sorted(tmp_path.glob("*.mcap")):
        seqs = [r.data.get("seq") for r in read_records(path) if r.topic.endswith("/client_in")]
        print(f"{path.name}: seq {min(seqs, default=None)}..{max(seqs, default=None)} ({len(seqs)} records)")
    for kind, missing in lost.items():  # what the history left out, the repair asked for (rob6.bus)
        assert not missing, f"{kind[1:]} files: {len(missing)} of {exchanges} client records lost: {missing[:20]}"
    cycles = sorted({r.data["cycle"] for r in _records(tmp_path, "/driver/joint_state", "_system")})
    cycle_s = get_robot("kr16").cycle_s
    longest = max(b - a for a, b in zip(cycles, cycles[1:], strict=False)) * cycle_s
    assert (cycles[-1] - cycles[0]) * cycle_s > 5.0, "the joint states do not cover the session"
    assert longest <= REST_STATE_PERIOD_S + cycle_s + 1e-9, f"no joint state for {longest:.3f} s"
    # what the recorder knew it missed is on its status channel: nothing here
    assert not [s for s in status if s.get("missed")], status
    # the driver's cell in the killed recorder's file and in its successor's, which found the driver up
    systems = sorted(tmp_path.glob("*_system_*.mcap"))
    assert len(systems) >= 2 and all(len(list(read_records(p, ["/cell"]))) == 1 for p in systems), systems
