"""Recording and replay throughput.

    python bench/bench_recording.py            # small table
    python bench/bench_recording.py --quick    # shorter runs

``bench_burst``: a producer submits joint-state-sized records as fast as it can;
reports the submit cost, the writer throughput (records written per second until
everything is on disk) and the peak backlog. ``bench_sustained``: a producer paced
at ``rate`` records/s for ``seconds``; reports drops (target 0 at 50,000/s) and the
peak backlog. Both with a client session open (every record goes to the session
file *and* the system file) or not. ``bench_replay``: replays a recorded session of
``lines`` commands as fast as possible against a local fake server (lines/s).

``bench_writers``: MCAP writers on their own, one file and two (a session open), with
joint-state payloads already encoded: the recorder's (``rob6_recorder_native.Writer``, through
its queue and thread), foxglove-sdk's and the ``mcap`` package's. ``live_table(table)`` (for ``bench/__main__.py``):
gateway round trips with the live view off and on (a Foxglove viewer in a process of its
own, ``bench/viewer.py``, subscribed to every channel), same run.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import msgspec

from bench.tables import Table
from harness.fake_server import FakeServer  # the replay target: a fake rob6 server
from rob6_recorder.session_replay import load_script, replay
from rob6_recorder.writer import CHUNK_SIZE, ZSTD_LEVEL, Recorder


def _state(i: int) -> dict[str, Any]:
    return {"t": i * 0.012, "cycle": i, "q": [10.123456 + i * 1e-4, -20.5, 30.25, 0.0, 45.0, -90.0],
            "qd": [0.01, 0.0, -0.02, 0.0, 0.0, 0.0], "moving": True, "mode": "trajectory"}


def _recorder(directory: Path, max_backlog: int = 1_000_000, warn_backlog: int = 1_000_000) -> Recorder:
    return Recorder(directory, "kr16", "robot1", max_backlog=max_backlog, warn_backlog=warn_backlog).start()


def bench_burst(n: int = 200_000, session: bool = True) -> dict[str, Any]:
    d = Path(tempfile.mkdtemp(prefix="rob6-bench-"))
    try:
        rec = _recorder(d)
        t = time.time_ns()
        if session:
            rec.submit("/session/1/client_in", t, {"session": 1, "cid": "x", "text": "Hello Robot\n"})
        states = [_state(i) for i in range(n)]
        start = time.perf_counter()
        for i, s in enumerate(states):
            rec.submit("/driver/joint_state", t + i * 20_000, s)
        submitted = time.perf_counter()
        rec.close()
        done = time.perf_counter()
        st = rec.stats()
        size = sum(p.stat().st_size for p in d.glob("*.mcap"))
        return {"case": f"burst {n} ({'session+system' if session else 'system'})",
                "submit_us": (submitted - start) / n * 1e6,
                "msgs_per_s": n / (done - start), "dropped": st.dropped,
                "max_backlog": st.max_backlog_seen, "bytes_per_msg": size / n}
    finally:
        shutil.rmtree(d, ignore_errors=True)


def bench_sustained(rate: int = 50_000, seconds: float = 3.0, session: bool = True) -> dict[str, Any]:
    d = Path(tempfile.mkdtemp(prefix="rob6-bench-"))
    try:
        rec = _recorder(d, max_backlog=100_000, warn_backlog=100_000)
        t = time.time_ns()
        if session:
            rec.submit("/session/1/client_in", t, {"session": 1, "cid": "x", "text": "Hello Robot\n"})
        n = int(rate * seconds)
        states = [_state(i) for i in range(n)]
        batch = max(1, rate // 1000)  # one batch per millisecond
        start = time.perf_counter()
        i = 0
        while i < n:
            due = start + i / rate
            now = time.perf_counter()
            if due > now:
                time.sleep(due - now)
            for s in states[i:i + batch]:
                rec.submit("/driver/joint_state", time.time_ns(), s)
            i += batch
        produced = time.perf_counter()
        rec.close()
        done = time.perf_counter()
        st = rec.stats()
        return {"case": f"sustained {rate}/s x {seconds:g} s ({'session+system' if session else 'system'})",
                "submit_us": float("nan"), "msgs_per_s": n / (produced - start),
                "dropped": st.dropped, "max_backlog": st.max_backlog_seen,
                "drain_s": done - produced}
    finally:
        shutil.rmtree(d, ignore_errors=True)


def bench_replay(lines: int = 2000) -> dict[str, Any]:
    d = Path(tempfile.mkdtemp(prefix="rob6-bench-"))
    try:
        fc = ("0.000000 -0.173648 -0.984808 1741.140107 0.000000 -0.984808 0.173648 -307.009978 "
              "-1.000000 -0.000000 -0.000000 640.000000\nnoflip up lefty\n")
        with Recorder(d, "kr16", "robot1", system=False) as rec:
            t = time.time_ns()
            rec.submit("/session/1/client_in", t, {"session": 1, "cid": "h", "text": "Hello Robot\n"})
            rec.submit("/session/1/client_out", t, {"session": 1, "cid": "h", "text": "accepted\n"})
            for i in range(lines):
                cmd, reply = ("ForwardCalc 10 0 0 0 0 0\n", fc) if i % 2 else ("GetRobot\n", "kr16\n")
                rec.submit("/session/1/client_in", t + i * 1000, {"session": 1, "cid": f"c{i}", "text": cmd})
                rec.submit("/session/1/client_out", t + i * 1000 + 500,
                           {"session": 1, "cid": f"c{i}", "text": reply})
        (path,) = d.glob("*.mcap")
        load_start = time.perf_counter()
        scripts = load_script(path)
        load_s = time.perf_counter() - load_start
        def answer(_connection: int, line: bytes) -> tuple[bytes, bool]:
            if line.startswith(b"Hello Robot"):
                return b"accepted\n", False
            return (fc if line.startswith(b"ForwardCalc") else "kr16\n").encode(), False

        with FakeServer(answer) as server:
            result = asyncio.run(replay(scripts, "127.0.0.1", server.port, speed=None))
        return {"case": f"replay {lines} lines, as fast as possible",
                "lines_per_s": result.exchanges / result.elapsed, "differences": len(result.differences),
                "load_s": load_s}
    finally:
        shutil.rmtree(d, ignore_errors=True)


def bench_writers(n: int = 300_000) -> list[dict[str, Any]]:
    """Messages/s of the recorder's native writer, foxglove-sdk's and the ``mcap`` package's,
    1 and 2 files."""
    import foxglove
    from foxglove.mcap import MCAPWriteOptions
    from mcap.writer import CompressionType, Writer

    encoder = msgspec.json.Encoder()
    payloads = [encoder.encode(_state(i)) for i in range(n)]
    schema = b'{"type": "object"}'
    d = Path(tempfile.mkdtemp(prefix="rob6-bench-"))
    rows = []
    try:
        for files in (1, 2):
            with contextlib.ExitStack() as files_open:  # closed below, and on an error too
                fhs = [files_open.enter_context(open(d / f"mcap{files}_{k}.mcap", "wb")) for k in range(files)]
                writers = [Writer(fh, compression=CompressionType.ZSTD) for fh in fhs]
                channels = []
                for w in writers:
                    w.start()
                    channels.append(w.register_channel("/driver/joint_state", "json",
                                                       w.register_schema("rob6.JointState", "jsonschema", schema)))
                t = time.time_ns()
                start = time.perf_counter()
                for i, p in enumerate(payloads):
                    for w, ch in zip(writers, channels, strict=True):
                        w.add_message(ch, t + i, p, t + i, i)
                for w, fh in zip(writers, fhs, strict=True):
                    w.finish()
                    fh.close()
            rows.append({"writer": "mcap package (Python)", "files": files,
                         "msgs_per_s": n / (time.perf_counter() - start),
                         "bytes_per_msg": (d / f"mcap{files}_0.mcap").stat().st_size / n})

            contexts = [foxglove.Context() for _ in range(files)]
            sinks = [foxglove.open_mcap(d / f"fox{files}_{k}.mcap", context=c,
                                        writer_options=MCAPWriteOptions(compression_threads=0))
                     for k, c in enumerate(contexts)]
            bases = [c._create_channel("/driver/joint_state", message_encoding="json", schema=foxglove.Schema(
                name="rob6.JointState", encoding="jsonschema", data=schema)) for c in contexts]
            start = time.perf_counter()
            last = time.monotonic()
            for i, p in enumerate(payloads):
                for b in bases:
                    b.log(p, t + i)
                if i % 4096 == 0 and time.monotonic() - last >= 0.5:  # the recorder's chunk_interval
                    for sink in sinks:
                        sink.flush()
                    last = time.monotonic()
            for sink in sinks:
                sink.close()
            rows.append({"writer": "foxglove-sdk (Rust)", "files": files,
                         "msgs_per_s": n / (time.perf_counter() - start),
                         "bytes_per_msg": (d / f"fox{files}_0.mcap").stat().st_size / n})
            rows.append(_native_writer(d / f"native{files}", payloads, files))
    finally:
        shutil.rmtree(d, ignore_errors=True)
    return rows


def _native_writer(directory: Path, payloads: list[bytes], files: int) -> dict[str, Any]:
    """The recorder's writer: every payload submitted, then closed (all on disk); two files
    are a session's and the system file."""
    from rob6_recorder_native import Writer as NativeWriter

    directory.mkdir()
    n = len(payloads)
    writer = NativeWriter(
        str(directory), "kr16", "bench", urdf=None, urdf_record=None, metadata={}, system=True,
        sessions=files == 2, rotate_bytes=0, rotate_seconds=0, chunk_interval=0.5, chunk_size=CHUNK_SIZE,
        compression="zstd", zstd_level=ZSTD_LEVEL, fsync=False, max_backlog=n + 1, warn_backlog=n + 1,
        session_linger=0.5, record_schemas={})
    writer.start()
    if files == 2:
        writer.control("open_session", "1", 10.0)
    t = time.time_ns()
    start = time.perf_counter()
    for i, p in enumerate(payloads):
        writer.submit("/driver/joint_state", t + i, t + i, p)
    writer.close(60.0)
    elapsed = time.perf_counter() - start
    system_file = next(directory.glob("*_system_*.mcap"))
    return {"writer": "rob6_recorder_native (Rust)", "files": files, "msgs_per_s": n / elapsed,
            "bytes_per_msg": system_file.stat().st_size / n}


def bench_live(count: int = 2000) -> dict[str, dict[str, list[float]]]:
    """Gateway round trips (s) with the live view off, then on with a Foxglove client
    subscribed to every channel the live view advertises."""
    from bench.latency import measure
    from bench.viewer import Viewer
    from harness.ports import free_port
    from harness.system import running

    commands = {"GetPositionJoints": ("GetPositionJoints", 1), "PingRobot": ("PingRobot 1 0", 1),
                "ForwardCalc": ("ForwardCalc 10 -20 30 40 50 60", 2),
                "MovePTPJoints": ("MovePTPJoints 0 -90 90 0 0 0", 1)}
    results: dict[str, dict[str, list[float]]] = {}
    for case in ("off", "on"):
        port = free_port()
        env = {"ROB6_LIVE_PORT": str(port) if case == "on" else "0"}
        with tempfile.TemporaryDirectory() as logs, running("kr16", dummy=True, log_dir=logs,
                                                            extra_env=env) as system:
            viewer = Viewer(f"ws://127.0.0.1:{port}") if case == "on" else None
            try:
                with system.client() as client:
                    measure(client, "GetRobot", 1, 50, warmup=0)  # session channels appear
                    if viewer is not None:  # everything advertised by now, bus traffic included
                        viewer.subscribe_all()
                    results[case] = {name: measure(client, cmd, lines, count)
                                     for name, (cmd, lines) in commands.items()}
            finally:
                received = viewer.close() if viewer is not None else 0
            if viewer is not None:
                results[case]["_received"] = [float(received)]
    return results


def live_table(table: Table) -> None:
    """The live view's cost on the real-time path: p50/p99 round trips, off vs on."""
    from bench.latency import percentiles

    count = 2000
    r = bench_live(count)
    rows = []
    for name in r["off"]:
        p50_off, p99_off = percentiles(r["off"][name])
        p50_on, p99_on = percentiles(r["on"][name])
        rows.append((name, f"{p50_off:.3f}", f"{p50_on:.3f}", f"{(p50_on / p50_off - 1) * 100:+.1f} %",
                     f"{p99_off:.3f}", f"{p99_on:.3f}"))
    table(f"Live view cost (gateway round trips, ms, {count} each; on = a Foxglove client subscribed to every "
          f"channel, {r['on']['_received'][0]:,.0f} messages received)",
          ("request", "p50 off", "p50 on", "p50 change", "p99 off", "p99 on"), rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    n = 100_000 if args.quick else 300_000
    seconds = 1.5 if args.quick else 4.0
    rows = [bench_burst(n, session=False), bench_burst(n, session=True),
            bench_sustained(50_000, seconds, session=True),
            bench_sustained(80_000, seconds, session=True)]
    print(f"{'case':<48} {'submit us':>9} {'msgs/s':>10} {'dropped':>8} {'max backlog':>11}")
    for r in rows:
        print(f"{r['case']:<48} {r['submit_us']:>9.2f} {r['msgs_per_s']:>10.0f} "
              f"{r['dropped']:>8} {r['max_backlog']:>11}")
    print(f"\n{'writer':<24} {'files':>5} {'msgs/s':>10} {'bytes/msg':>9}")
    for w in bench_writers(100_000 if args.quick else 300_000):
        print(f"{w['writer']:<24} {w['files']:>5} {w['msgs_per_s']:>10.0f} {w['bytes_per_msg']:>9.1f}")
    rp = bench_replay(1000 if args.quick else 4000)
    print(f"{rp['case']:<48} {'':>9} {rp['lines_per_s']:>10.0f} lines/s, "
          f"{rp['differences']} differences, load {rp['load_s'] * 1000:.0f} ms")


if __name__ == "__main__":
    main()
