"""Several hosts, real network faults (issue 14): deploy/multihost/docker-compose.yml.

    .venv/bin/python -m pytest tests/deploy/multihost -s      # -s prints the figures

The robot PC (router, gateway, planner, driver, gripper), a compute host (router, two
kinematics replicas), a second compute host (one replica) and a storage host (recorder),
each its own network namespace on the lab network; faults are made with iptables/NFQUEUE
(nfq_netem.py), ``docker network disconnect`` and ``docker kill`` (harness/topology.py).
The assertions are about answers (correct, or an error within the timeout, never a hang,
never a wrong answer) and the motion; the timings are printed and measured by
``python -m bench.multihost`` (deploy/MULTI_HOST.md).

Marked ``docker`` like tests/deploy/test_compose_e2e.py (skip with ``-m 'not docker'`` or
ROB6_SKIP_DOCKER=1); skipped without a Docker engine, or without root for the faults.
With test_multi_host_rsi.py (the robot on RSI, --profile rsi): 9 tests, about 4 minutes once
the images exist.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from harness import images
from harness.client import Client
from harness.compose import run
from harness.images import TAG
from harness.topology import (
    REMOTE_KINEMATICS,
    Call,
    Load,
    Topology,
    alter_session,
    ask_true,
    backward_line,
    calls,
    cannot_run,
    percentile,
    recovery,
)

pytestmark = pytest.mark.docker

if (why := cannot_run()) is not None:
    pytest.skip(why, allow_module_level=True)

REPORT: dict[str, object] = {}
CALL_TIMEOUT = 10.0  # a reply later than this is a hang


@pytest.fixture(scope="module")
def topology(rob6_images: images.Outcome) -> Iterator[Topology]:
    REPORT["images"] = f"rob6/*:{TAG} ready in {rob6_images.seconds:.0f} s"
    topo = Topology(f"rob6mh{os.getpid()}")
    try:
        REPORT["up until healthy"] = f"{topo.up():.0f} s"
        yield topo
    finally:
        topo.down()
        print("\n--- rob6 multi-host report ---\n" + json.dumps(REPORT, indent=2))


@pytest.fixture
def client(topology: Topology) -> Iterator[Client]:
    c = topology.client()
    yield c
    c.close()


def assert_answered(results: list[Call], what: str) -> dict[str, object]:
    """Every call answered within CALL_TIMEOUT: the right joints or an ERROR line, nothing else."""
    hung = [c for c in results if not c.reply]
    wrong = [c for c in results if c.reply and not c.ok and not c.error]
    assert not hung, f"{what}: {len(hung)} calls got no reply within {CALL_TIMEOUT} s"
    assert not wrong, f"{what}: wrong answers {[c.reply for c in wrong[:5]]}"
    errors = [c for c in results if c.error]
    return {"calls": len(results), "correct": len(results) - len(errors), "errors": len(errors),
            "first error": errors[0].reply.strip() if errors else "",
            "p50 ms": round(percentile([c.seconds for c in results], 50) * 1000, 1),
            "p99 ms": round(percentile([c.seconds for c in results], 99) * 1000, 1),
            "max ms": round(max(c.seconds for c in results) * 1000, 1)}


def settle(client: Client, line: str, timeout: float = 60.0) -> None:
    """Until 20 calls in a row succeed (after a fault is cleared)."""
    deadline = time.monotonic() + timeout
    streak = 0
    while streak < 20:
        assert time.monotonic() < deadline, "the system did not come back to all-success"
        streak = streak + 1 if calls(client, line, 1)[0].ok else 0


# ---------------------------------------------------------------------- the topology
def test_every_host_serves(topology: Topology, client: Client) -> None:
    line = backward_line(client)
    results = calls(client, line, 60)
    REPORT["BackwardCalc x60, no fault"] = assert_answered(results, "no fault")
    # a busy machine may miss the kinematics deadline now and then: an ERROR, not a wrong answer
    assert sum(c.ok for c in results) >= 0.9 * len(results)
    assert len(topology.containers("kinematics-c1")) == 2 and len(topology.containers("kinematics-c2")) == 1
    # the robot PC's own services through the gateway: planner, driver
    ask_true(client, "MovePTPJoints 10 -20 30 40 50 60")
    assert client.ask("GetPositionJoints") == "10.000000 -20.000000 30.000000 40.000000 50.000000 60.000000\n"
    # each compute host serves: stop the other one's replicas, the calls still succeed
    for only in REMOTE_KINEMATICS:
        others = [c for s in REMOTE_KINEMATICS if s != only for c in topology.containers(s)]
        for _ in range(5):  # Docker's cgroup freezer sometimes fails at once ("unable to freeze")
            if run(["docker", "pause", *others], check=False).returncode == 0:
                break
            run(["docker", "unpause", *others], check=False)
            time.sleep(1.0)
        else:
            raise AssertionError(f"docker pause {others} kept failing")
        try:
            settle(client, line)
        finally:
            run(["docker", "unpause", *others])
    settle(client, line)


# ---------------------------------------------------------------------- partitions
def test_compute_host_partitioned_mid_load(topology: Topology, client: Client) -> None:
    """compute1 (its router and two replicas) loses the network for 8 s while a client calls
    BackwardCalc in a loop: every call is answered (compute2's replica, or an ERROR within the
    timeout), never a hang, never a wrong answer; all-success again after the heal."""
    line = backward_line(client)
    with Load(client, line, timeout=CALL_TIMEOUT) as load:
        time.sleep(2)
        with topology.partitioned("compute1"):
            cut = time.monotonic()
            time.sleep(8)
        healed = time.monotonic()
        deadline = healed + 30
        while time.monotonic() < deadline:
            time.sleep(0.5)
            if recovery(load.calls, healed) is not None and load.calls[-1].t - healed > 5:
                break
    during = [c for c in load.calls if cut <= c.t < healed]
    summary = assert_answered(load.calls, "compute1 partitioned")
    summary["during the partition: correct"] = f"{sum(c.ok for c in during)}/{len(during)}"
    back = recovery(load.calls, healed)
    summary["all-success again after heal"] = "never" if back is None else f"{back:.2f} s"
    REPORT["compute1 partitioned 8 s mid-load"] = summary
    assert back is not None, "BackwardCalc did not come back to all-success within 30 s of the heal"
    assert max(c.seconds for c in during) < 5, "a call waited for the partitioned host"


def test_loss_and_jitter_between_robot_pc_and_compute(topology: Topology, client: Client) -> None:
    """5 % loss and 0..20 ms jitter each way between the robot PC and both compute hosts."""
    line = backward_line(client)
    with topology.impaired(delay_ms=10, jitter_ms=10, loss=0.05):
        results = calls(client, line, 300, timeout=CALL_TIMEOUT)
    summary = assert_answered(results, "5 % loss, 20 ms jitter")
    correct, total = summary["correct"], summary["calls"]
    assert isinstance(correct, int) and isinstance(total, int)
    summary["share correct"] = f"{correct / total:.1%}"
    REPORT["BackwardCalc x300, 5 % loss + 0..20 ms jitter"] = summary
    # goal 100 %: single-pose kinematics calls have a 1 s deadline and are hedged after
    # 0.15 s to a replica on the other compute host, whose link to the robot PC is its own
    # (rob6.bus); measured 300/300 in 5 of 5 runs since. Before, both copies could wait
    # behind the same lost segment: 283/300 and 298/300 in 2 runs of 8. A busy machine may
    # still miss the deadline now and then: an ERROR line (checked above), at most 1 %
    assert correct >= 0.99 * total, summary
    settle(client, line)


def test_reordering_between_robot_pc_and_compute(topology: Topology, client: Client) -> None:
    """10 ms each way, and a quarter of the packets not delayed: they overtake the others
    (netem's reorder 25 %). TCP puts the segments back in order: every call correct."""
    line = backward_line(client)
    with topology.impaired(delay_ms=10, reorder=0.25):
        results = calls(client, line, 100, timeout=CALL_TIMEOUT)
    summary = assert_answered(results, "25 % reordered")
    REPORT["BackwardCalc x100, delay 10 ms with 25 % reordered"] = summary
    # a busy machine may still miss the 1 s deadline now and then: an ERROR line (checked above)
    errors = summary["errors"]
    assert isinstance(errors, int) and errors <= 1, summary
    settle(client, line)


def test_robot_pc_router_killed(topology: Topology, client: Client) -> None:
    """Without the robot PC's router its services keep answering (peer links over loopback);
    a call for the remote replicas is an ERROR at once, never a hang; when the router is back
    the remote replicas are reached again."""
    line = backward_line(client)
    router = topology.container("router-pc")
    run(["docker", "kill", router])
    killed = time.monotonic()
    try:
        assert client.ask("CM_PING") == "PONG\n"
        assert client.ask("MovePTPJoints 12 -20 30 40 50 60", timeout=30) == "true\n"
        assert client.ask("GetPositionJoints") == "12.000000 -20.000000 30.000000 40.000000 50.000000 60.000000\n"
        ask_true(client, "MovePTPJoints 10 -20 30 40 50 60")
        local = time.monotonic() - killed
        results = calls(client, line, 20, timeout=CALL_TIMEOUT)
        summary = assert_answered(results, "robot PC router killed")
        summary["robot PC services: CM_PING + 2 real-time PTPs of 2 deg answered in"] = f"{local:.2f} s"
    finally:
        run(["docker", "start", router])
    restarted = time.monotonic()
    REPORT["robot PC router killed"] = summary
    settle(client, line)
    summary["all-success again after docker start"] = f"{time.monotonic() - restarted:.2f} s"


# ---------------------------------------------------------------------- the motion
def _ptp(client: Client) -> None:
    ask_true(client, "MovePTPJoints 30 -70 90 10 40 20")


def test_motion_unchanged_when_every_remote_host_is_partitioned(topology: Topology, client: Client) -> None:
    """A PTP and an Alter session with compute1, compute2 and storage cut off from the robot
    PC: the joint states (recorded on the robot PC) are those of the same motions without
    faults (PTP: identical sample by sample; Alter: no fault, no missed cycle, the targets reached)."""
    from tests.deploy.multihost.probe import Sample, StateRecorder, motion, same_motion

    refused: dict[bool, int] = {}

    def session(fault: bool) -> tuple[list[Sample], list[list[float]]]:
        ask_true(client, "MovePTPJoints 0 -80 100 0 30 0")
        with StateRecorder(topology, f"states{int(fault)}") as recorder:
            if fault:
                with topology.partitioned("compute1", "compute2", "storage"):
                    _ptp(client)
                    refused[fault] = alter_session(client)
            else:
                _ptp(client)
                refused[fault] = alter_session(client)
            samples = recorder.stop()
        return samples, motion(samples)

    reference, ref_motion = session(fault=False)
    faulted, fault_motion = session(fault=True)
    settle(client, backward_line(client))
    for samples in (reference, faulted):
        assert all(s.mode != "fault" for s in samples)
    # the PTP part is deterministic: identical joint states
    ptp_ref, ptp_fault = ref_motion, fault_motion
    report: dict[str, object] = {
        "samples (reference, faulted)": [len(reference), len(faulted)],
        "moving samples": [len(ptp_ref), len(ptp_fault)],
        # a busy machine may make the driver miss cycles with or without faults: reported
        "driver cycles missed (reference, faulted)": [reference[-1].missed - reference[0].missed,
                                                      faulted[-1].missed - faulted[0].missed],
        "cycles without a sample (at rest every 100 ms; else dropped on the way) (reference, faulted)": [
            s[-1].cycle - s[0].cycle + 1 - len(s) for s in (reference, faulted)],
        "Alter targets refused (reference, faulted)": [refused[False], refused[True]],
    }
    REPORT["motion under partition of every remote host"] = report
    assert same_motion(reference, faulted, _ptp_samples(ptp_ref)), "the PTP motion differs"
    # a busy machine may refuse the odd target (the driver's reply later than the quick-call
    # deadline) with or without faults; a partition must not add to that (it refused every
    # target, 2 s in, while Zenoh held replies back for the partitioned routes: rob6.bus)
    assert refused[True] <= refused[False] + 10, f"{refused[True]} of 500 Alter targets refused under the partition"
    assert all(abs(a - b) < 1e-6 for a, b in zip(faulted[-1].q, reference[-1].q, strict=True)), \
        (faulted[-1].q, reference[-1].q)


def _ptp_samples(states: list[list[float]]) -> int:
    """Samples of the PTP part: until A1 first reaches 30 deg."""
    return next((i for i, q in enumerate(states) if abs(q[0] - 30.0) < 1e-9), len(states))


# ---------------------------------------------------------------------- recordings
def test_no_record_lost_when_storage_is_partitioned_and_the_recorder_restarted(topology: Topology, client: Client, tmp_path: Path) -> None:
    """An Alter session at 250 Hz; the storage host cut off for 10 s, then its recorder
    SIGKILLed and started again: every client exchange of the session (the gateway numbers
    them, ``seq``) must be in the recorder's files, session and system alike. The batches
    the recorder did not get wait in the publishers' caches (``TRACE_CACHE_S``)."""
    import math

    from rob6_recorder.reader import read_records

    recorder = topology.container("recorder")
    exchanges = 1  # the client fixture's "Hello Robot"
    refused = 0

    def ask(line: str) -> str:
        nonlocal exchanges
        reply = client.ask(line, timeout=30)
        exchanges += 1
        return reply

    def ask_true_counted(line: str) -> None:
        nonlocal exchanges
        ask_true(client, line)
        exchanges += 1

    ask_true_counted("MovePTPJoints 0 -80 100 0 30 0")
    ask_true_counted("EnableAlter")
    here = [float(x) for x in ask("GetPositionJoints").split()]
    k = 0

    def stream(seconds: float) -> None:
        nonlocal k, refused
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            target = list(here)
            target[0] += 3.0 * math.sin(2 * math.pi * 0.5 * k / 250)
            k += 1
            reply = ask("MoveRTJoints " + " ".join(f"{x:f}" for x in target))
            assert reply == "true\n" or reply.startswith("ERROR: driver"), reply
            if reply != "true\n":
                assert client.read_lines(1, timeout=30) == "false\n"  # ERROR: ... then false
            refused += reply != "true\n"
            time.sleep(0.004)

    stream(2.0)
    with topology.partitioned("storage"):
        stream(10.0)
    at_heal = exchanges
    stream(3.0)  # the recorder recovers the partition's records and writes them (every 0.5 s)
    run(["docker", "kill", "-s", "KILL", recorder])
    stream(1.0)
    run(["docker", "start", recorder])
    stream(5.0)
    ask_true_counted("DisableAlter")
    assert ask("Quit") == "bye!\n"
    time.sleep(3.0)  # the last batches reach the recorder
    run(["docker", "stop", "-t", "20", recorder])  # closes its files
    try:
        run(["docker", "cp", f"{recorder}:/data/logs", str(tmp_path)])
    finally:
        run(["docker", "start", recorder])
    files = sorted((tmp_path / "logs").glob("*.mcap"))
    client_in = {kind: [r.data for p in files if kind in p.name for r in read_records(p)
                        if r.topic.endswith("/client_in")] for kind in ("_session", "_system")}
    session = max(d["session"] for d in client_in["_system"])  # the newest session: this one
    status = [r.data for p in files if "_system" in p.name for r in read_records(p, ["/recorder/status"])]
    report: dict[str, object] = {"client exchanges": exchanges, "Alter targets refused": refused,
                                 "what /recorder/status said": [s for s in status if s.get("missed")][:5]
                                 or "no miss reported"}
    lost = {}
    for kind, records in client_in.items():
        seqs = [d.get("seq") for d in records if d["session"] == session]
        lost[kind] = sorted(set(range(1, exchanges + 1)) - set(seqs))
        report[f"lost ({kind[1:]} files)"] = len(lost[kind])
        report[f"recorded twice ({kind[1:]} files)"] = len(seqs) - len(set(seqs))
    gateway_log = run(["docker", "logs", "-t", topology.container("gateway")])
    gone = [line for line in (gateway_log.stdout + gateway_log.stderr).splitlines() if "went away" in line]
    report["owner instances the gateway saw go away (their calls wait up to 1 s)"] = gone[:5] or "none"
    REPORT["storage partitioned 10 s, then the recorder SIGKILLed and restarted"] = report
    for kind, missing in lost.items():  # the partition: the cache brought back every record
        partition = [seq for seq in missing if seq <= at_heal]
        assert not partition, f"{kind[1:]} files: {len(partition)} records of the partition lost: {partition[:20]}"
    for kind, missing in lost.items():  # the restart: what zenoh.ext's history left out, the repair asked for
        assert not missing, f"{kind[1:]} files: {len(missing)} of {exchanges} client records lost after the " \
                            f"partition: {missing[:20]}"
    # nothing was missed for good, so the status channel reported no miss either
    assert not [s for s in status if s.get("missed")], status[:5]
