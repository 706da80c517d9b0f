"""Kinematics replicas: real processes, spread by the bus client, failover without errors."""

from __future__ import annotations

import collections
import os
import signal
import subprocess
import sys
import threading
import time

import msgspec

from harness.system import System, running
from rob6.bus import trace_records
from rob6.messages import FkRequest, IkBatchRequest


def _replica(system: System) -> subprocess.Popen[bytes]:
    env = dict(os.environ, ROB6_ROBOT=system.robot, ROB6_ROBOT_ID=system.robot_id,
               ROB6_ZENOH_CONNECT=f"tcp/127.0.0.1:{system.router_port}")
    return subprocess.Popen([sys.executable, "-m", "rob6_kinematics"], env=env)


def test_requests_spread_over_replicas_and_survive_a_killed_one() -> None:
    with running("kr16", services=("kinematics",)) as system:
        bus = system.bus()
        served: collections.Counter[str] = collections.Counter()
        bus.subscribe("trace/kinematics", lambda _k, batch: served.update(
            msgspec.json.decode(record)["instance"] for _suffix, record in trace_records(batch)))
        extra = _replica(system)
        try:
            deadline = time.monotonic() + 20
            while len(bus.instances("kinematics")) < 2:
                assert time.monotonic() < deadline, "the second replica did not come up"
                time.sleep(0.05)
            poses = bus.request("kinematics", "fk", FkRequest(joints=[[10, -60, 80, 20, 40, 30]] * 200)).poses
            request = IkBatchRequest(poses=poses)
            answers, errors = [], []

            def client() -> None:
                for _ in range(150):
                    try:
                        answers.append(bus.request("kinematics", "ik_batch", request, timeout=5.0))
                    except Exception as exc:  # counted: the test demands none
                        errors.append(exc)

            threads = [threading.Thread(target=client) for _ in range(2)]
            for thread in threads:
                thread.start()
            time.sleep(0.5)
            victim = system.pids()["kinematics"]
            os.kill(victim, signal.SIGKILL)  # mid-run: requests in flight there are retried
            for thread in threads:
                thread.join(60)
            assert errors == []
            assert len(answers) == 300
            assert all(len(a.solutions) == 200 for a in answers)
            assert len(served) == 2 and min(served.values()) > 10  # both replicas served
            assert any("kinematics exited with code -9" in line for line in system.output)
        finally:
            extra.send_signal(signal.SIGTERM)
            extra.wait(5)
            bus.close()
