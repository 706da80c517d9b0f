"""``rob6-log play``: a recording served into the live view, played and sought from a
Foxglove WebSocket client (playback control), the arm moving as recorded."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from harness.foxglove_client import FoxgloveClient
from rob6.robots import get_robot
from rob6_recorder.writer import Recorder

TARGET = [10.0, -60.0, 80.0, 20.0, 40.0, 30.0]
STEPS = 250  # 1 s at 4 ms


def _recording(directory: Path) -> tuple[Path, int]:
    """A session: a line, its reply, the arm moving 0 -> TARGET over a second."""
    urdf = get_robot("kr16").urdf
    t0 = time.time_ns()
    with Recorder(directory, "kr16", "robot1", urdf=urdf, system=False, fsync=False) as rec:
        rec.submit("/session/1/client_in", t0, {"session": 1, "cid": "c1", "text": "MovePTPJoints 10 -60 80 20 40 30\n"})
        for i in range(STEPS + 1):
            q = [x * i / STEPS for x in TARGET]
            rec.submit("/driver/joint_state", t0 + i * 4_000_000,
                       {"t": i * 0.004, "cycle": i, "q": q, "qd": [0.0] * 6, "moving": i < STEPS,
                        "mode": "trajectory" if i < STEPS else "idle"})
        rec.submit("/session/1/client_out", t0 + STEPS * 4_000_000, {"session": 1, "cid": "c1", "text": "true\n"})
    (path,) = directory.glob("*_session1.mcap")
    return path, t0


def serve(path: Path, port: int, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "rob6_recorder.cli", "play", str(path), "--port", str(port),
                             *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _connect(port: int, process: subprocess.Popen[str]) -> FoxgloveClient:
    deadline = time.monotonic() + 15
    while True:
        try:
            return FoxgloveClient(f"ws://127.0.0.1:{port}")
        except OSError:
            if process.poll() is not None or time.monotonic() > deadline:
                raise AssertionError(process.stdout.read() if process.stdout else "play did not start") from None
            time.sleep(0.1)


@pytest.fixture
def recording(tmp_path: Path) -> tuple[Path, int]:
    return _recording(tmp_path)


def test_play_seek_and_pause(recording: tuple[Path, int], live_port: int) -> None:
    path, t0 = recording
    process = serve(path, live_port, "--paused")
    try:
        with _connect(live_port, process) as fox:
            assert fox.wait(lambda: fox.server_info)
            assert "playbackControl" in fox.server_info["capabilities"], fox.server_info
            start, end = fox.server_info["dataStartTime"], fox.server_info["dataEndTime"]  # the timeline
            assert (start["sec"] * 10**9 + start["nsec"], end["sec"] * 10**9 + end["nsec"]) == \
                (t0, t0 + STEPS * 4_000_000)
            fox.subscribe("/robot_description", "/driver/joint_state", "/tf", "/commands")
            assert fox.wait_messages("/robot_description")
            time.sleep(0.3)
            assert not fox.received("/driver/joint_state")  # paused: nothing plays

            fox.playback_control(0, speed=2.0, request_id="play")  # play at 2x
            assert fox.wait(lambda: any(s[0] == 0 for s in fox.playback_states))  # Playing
            assert fox.wait(lambda: any(all(abs(a - b) < 1e-9 for a, b in zip(s["q"], TARGET, strict=True))
                                        for _, s in fox.received("/driver/joint_state")), timeout=10)
            states = fox.received("/driver/joint_state")
            assert len(states) > STEPS // 2 and states[0][1]["q"] != states[-1][1]["q"]
            assert [t for t, _ in states] == sorted(t for t, _ in states)
            assert fox.wait(lambda: len(fox.received("/tf")) > 5)
            messages = [m["message"] for _, m in fox.wait_messages("/commands", 2)]
            assert messages == ["> MovePTPJoints 10 -60 80 20 40 30", "< true"]
            assert fox.wait(lambda: any(s[0] == 3 for s in fox.playback_states))  # Ended

            # seek to the middle, paused: the state there is sent at once
            middle = t0 + STEPS // 2 * 4_000_000
            before = len(fox.received("/driver/joint_state"))
            fox.playback_control(1, seek_ns=middle, request_id="seek")
            assert fox.wait(lambda: any(s[3] and s[1] == middle for s in fox.playback_states))
            assert fox.wait(lambda: len(fox.received("/driver/joint_state")) > before)
            t, state = fox.received("/driver/joint_state")[-1]
            assert t < middle and abs(state["q"][0] - TARGET[0] / 2) < 0.1
    finally:
        process.terminate()
        process.wait(10)


def test_play_a_system_recording(tmp_path: Path, live_port: int) -> None:
    """A file recorded by the real system plays back: the joints reach the commanded pose, and
    the cell the session file starts with is drawn (the live view derives the scene)."""
    from harness.system import running
    with running("kr16", log_dir=str(tmp_path), extra_env={"ROB6_LIVE_PORT": "0"}) as system:
        assert not any("live view:" in line for line in system.output)
        with system.client() as client:
            assert client.ask("MovePTPJoints 10 -60 80 20 40 30") == "true\n"
            client.ask("GetPositionJoints")
            assert client.ask("Quit") == "bye!\n"
        time.sleep(1.0)  # the session file is finished session_linger after the close
    (path,) = tmp_path.glob("*_session*.mcap")
    process = serve(path, live_port, "--speed", "4", "--loop")
    try:
        with _connect(live_port, process) as fox:
            fox.subscribe("/driver/joint_state", "/commands", "/tf", "/cell/scene")
            assert fox.wait(lambda: any(all(abs(a - b) < 1e-6 for a, b in zip(s["q"], TARGET, strict=True))
                                        for _, s in fox.received("/driver/joint_state")), timeout=15)
            assert fox.wait(lambda: any("zone:floor" in {e["id"] for e in scene["entities"]}
                                        for _, scene in fox.received("/cell/scene")))
            assert fox.wait(lambda: "> MovePTPJoints 10 -60 80 20 40 30" in
                            [m["message"] for _, m in fox.received("/commands")])
            assert fox.wait(lambda: fox.received("/tf"))
    finally:
        process.terminate()
        process.wait(10)
