"""Real rob6server clients' sessions, as they send and as they read, on every (robot, link):
rob-chess (Scala, a fixed number of lines per command), RobPraktikum (Java, send one line
and wait for one), a client that writes several commands at once and reads after, and a
followme/BauklotzProjekt session (kinematics, PTP, a 250 Hz Alter stream, DisableAlter,
PTP again). Every reply is checked byte for byte (positions numerically where the link
carries them with less precision), and each session's MCAP file must hold the complete
exchange log. Real time: each flow moves for a few seconds; nothing is timed."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.flows.flow import Flow, assert_recorded, fmt, numbers
from tests.flows.rigs import ADEPT, ALL, Rig, rig_id

pytestmark = pytest.mark.slow

#: millimetres: a Cartesian position read back after a move (IK rounding, link precision)
POSE_TOL = 1e-2
#: the gripper's replies on success (docs/COMPATIBILITY.md, Gripper replies)
GO_HOME = ["Start moving to home position", "Gripper at 0.0400 m", "true"]


def open_flow(rig: Rig) -> Flow:
    flow = Flow(rig.system.port)
    assert flow.one("Hello Robot") == "accepted"
    return flow


def quit_flow(rig: Rig, flow: Flow) -> None:
    """Quit as the clients do, and the session's recording is the whole exchange."""
    assert flow.one("Quit") == "bye!"
    assert flow.client.closed()
    flow.close()
    assert_recorded(rig.log_dir, flow)


def assert_at(rig: Rig, reply: str, q: list[float] | np.ndarray) -> None:
    """A GetPositionJoints reply: the commanded joints byte for byte on the simulation,
    within the link's precision on a controller."""
    if rig.link == "sim":
        assert reply == fmt(q)
    else:
        assert np.allclose(numbers(reply), q, atol=rig.tol), (reply, q)


def scala(values: list[float]) -> str:
    """A Scala List[Double] joined with blanks, as rob-chess builds its lines."""
    return " ".join(repr(float(x)) for x in values)


def java_row_wise(pose: np.ndarray) -> str:
    """RobPraktikum's MoveRTHomRowWise arguments: Java's Double.toString of each element,
    with no blank between a row's last element and the next row's first ("1000.50.5").
    A C++ istream (and rob6) still reads the twelve numbers when the concatenated row starts
    with a value below 1 or a minus sign, as a rotation's first column does."""
    m = np.where(np.abs(pose) < 1e-3, 0.0, np.round(pose, 4)).reshape(3, 4)  # no E notation
    assert np.all(m[1:, 0] < 1.0), "a row starting with 1.0 would be read as another number"
    return "".join(" ".join(repr(float(x)) for x in row) for row in m)


@pytest.mark.parametrize("rig", ADEPT, ids=rig_id, indirect=True, scope="module")
def test_rob_chess_reads_a_fixed_number_of_lines(rig: Rig) -> None:
    """Scala: recv(1) for the greeting, command(cmd, n) reads n lines; GripperGoHome and
    GripperMoveToPosition are judged by their third line."""
    with open_flow(rig) as flow:
        assert flow.one("SetAdeptSpeed 50") == "true"
        assert flow.one("SetAdeptFine 50") == "true"
        assert flow.fixed("GripperGoHome", 3) == GO_HOME
        assert flow.fixed("GripperMoveToPosition 0.0025", 3) == [
            "Start moving to position 0.0025 m", "Gripper at 0.0025 m", "true"]
        assert flow.one("MovePTPJoints " + scala(rig.start)) == "true"
        assert_at(rig, flow.one("GetPositionJoints"), rig.start)
        status = flow.one("GetStatus")
        assert len(status.split()) == 3, status
        pose = numbers(flow.one("GetPositionHomRowWise"))
        target = pose.copy()
        target[[3, 7, 11]] += [30.0, -20.0, -40.0]  # above the next square
        assert flow.one(f"MoveMinChangeRowWiseStatus {fmt(target)} {status}") == "true"
        assert np.allclose(numbers(flow.one("GetPositionHomRowWise")), target, atol=POSE_TOL)
        assert flow.one("GetStatus") == status
        assert flow.fixed("GripperMove -1", 2) == ["Start moving with amperage -1.000", "true"]
        assert flow.fixed("GripperMoveToPosition 0.03", 3) == [
            "Start moving to position 0.0300 m", "Gripper at 0.0300 m", "true"]
        assert flow.fixed("GripperGoHome", 3) == GO_HOME
        assert flow.one("GetRobot") == "ad850"  # still in step
        flow.quiet()
        quit_flow(rig, flow)


@pytest.mark.parametrize("rig", ADEPT, ids=rig_id, indirect=True, scope="module")
def test_robpraktikum_sends_and_waits_for_one_line(rig: Rig) -> None:
    """Java: sendAndReceive reads one line; the suction cup is switched with DirectAdeptCmd
    signal, a Cartesian target goes in as Alter (EnableAlter, MoveRTHomRowWise, DisableAlter)."""
    with open_flow(rig) as flow:
        assert flow.one("SetAdeptSpeed 5") == "true"  # connectToRobot
        assert flow.one("SetAdeptSpeed 100") == "true"  # the speed chosen in the app
        assert flow.one("MovePTPJoints 2 -45 125 0 6 0") == "true"  # becherPos
        assert_at(rig, flow.one("GetPositionJoints"), [2.0, -45.0, 125.0, 0.0, 6.0, 0.0])
        assert flow.one("DirectAdeptCmd signal 5, -6") == "true"  # ansaugen
        assert {5, -6} <= rig.outputs()
        pose = numbers(flow.one("GetPositionHomRowWise"))
        pose[3] += 20.0
        assert flow.one("EnableAlter") == "true"
        assert flow.one("MoveRTHomRowWise " + java_row_wise(pose)) == "true"
        assert flow.one("DisableAlter") == "true"
        assert flow.one("DirectAdeptCmd signal -5, 6") == "true"  # loslassen
        assert {-5, 6} <= rig.outputs()
        assert flow.one("MovePTPJoints 0 -150 150 0 0 0") == "true"  # endPos
        assert_at(rig, flow.one("GetPositionJoints"), [0.0, -150.0, 150.0, 0.0, 0.0, 0.0])
        flow.quiet()
        quit_flow(rig, flow)


@pytest.mark.parametrize("rig", ALL, ids=rig_id, indirect=True, scope="module")
def test_pipelined_writes_are_answered_in_order(rig: Rig) -> None:
    """Several commands in one write, the replies read after: the same bytes, in the same
    order, as one command at a time; moves in the pipeline run one after the other."""
    with open_flow(rig) as flow:
        assert flow.one("MovePTPJoints " + fmt(rig.start)) == "true"
        reads = [("GetRobot", 1), ("IsKuka", 1), ("CM_PING", 1), ("GetVersion", 1), ("", 0),
                 ("SetAllowedStatus toggleHand toggleElbow toggleArm", 0), ("GetAllowedStatus", 1),
                 ("ForwardCalc " + fmt(rig.start), 2), ("GetPositionJoints", 1), ("GetStatus", 1),
                 ("MovePTPJoints 1 2 3", 2), ("Foo", 1), ("GetJointsMaxSpeed", 1)]
        one_by_one = [flow.fixed(line, count) for line, count in reads if line]
        assert one_by_one[:4] == [[rig.robot], ["true" if rig.robot == "kr16rt" else "false"], ["PONG"], ["0.1.01"]]
        assert one_by_one[4:6] == [[], ["toggleHand toggleElbow toggleArm"]]
        assert_at(rig, one_by_one[7][0], rig.start)
        assert one_by_one[9:11] == [["ERROR: incorrect joints", "false"], ["ERROR: Foo"]]
        assert flow.pipelined(reads) == one_by_one
        there = list(rig.start)
        there[0] += 10.0
        moves = flow.pipelined([("MovePTPJoints " + fmt(there), 1), ("GetPositionJoints", 1),
                                ("MovePTPJoints " + fmt(rig.start), 1), ("GetPositionJoints", 1), ("GetStatus", 1)])
        assert [moves[0], moves[2], moves[4]] == [["true"], ["true"], one_by_one[8]]
        assert_at(rig, moves[1][0], there)
        assert_at(rig, moves[3][0], rig.start)
        assert flow.pipelined([("GetRobot", 1), ("Quit", 1)]) == [[rig.robot], ["bye!"]]
        assert flow.client.closed()
        flow.close()
        assert_recorded(rig.log_dir, flow)


@pytest.mark.parametrize("rig", ALL, ids=rig_id, indirect=True, scope="module")
def test_followme_session_with_an_alter_stream(rig: Rig) -> None:
    """followme/BauklotzProjekt: where is the robot, the kinematics of a target, a PTP and a
    Cartesian PTP, then 2 s of MoveRTJoints at 250 Hz (send-and-wait), DisableAlter, and the
    next PTP must run."""
    with open_flow(rig) as flow:
        assert flow.one("GetRobot") == rig.robot
        numbers(flow.one("GetPositionJoints"))  # where it stands, as the client shows it
        assert flow.one("MovePTPJoints " + fmt(rig.start)) == "true"
        assert_at(rig, flow.one("GetPositionJoints"), rig.start)
        matrix, status = flow.fixed("ForwardCalc " + fmt(rig.start), 2)
        pose = numbers(matrix)
        assert np.allclose(numbers(flow.one("GetPositionHomRowWise")), pose, atol=POSE_TOL)
        assert flow.one("GetStatus") == status
        assert np.allclose(numbers(flow.one(f"BackwardCalc {matrix} {status}")), rig.start, atol=1e-4)
        target = pose.copy()
        target[[3, 11]] += [50.0, -30.0]
        assert flow.one(f"IsPossible {fmt(target)} {status}") == "true"
        assert flow.one(f"MovePTPHomRowWiseStatusTurn {fmt(target)} {status}") == "true"
        assert np.allclose(numbers(flow.one("GetPositionHomRowWise")), target, atol=POSE_TOL)
        assert flow.one("MovePTPJoints " + fmt(rig.start)) == "true"
        assert flow.one("EnableAlter") == "true"
        began = time.monotonic()
        for k in range(500):
            q = list(rig.start)
            q[0] += 3.0 * np.sin(2 * np.pi * 0.5 * k / 250)
            assert flow.one("MoveRTJoints " + fmt(q)) == "true", k
            delay = began + (k + 1) * 0.004 - time.monotonic()  # paced at 250 Hz, as an Alter client streams
            if delay > 0:
                time.sleep(delay)
        assert flow.one("DisableAlter") == "true"
        assert flow.one("MovePTPJoints " + fmt(rig.start)) == "true"
        assert_at(rig, flow.one("GetPositionJoints"), rig.start)
        flow.quiet()
        quit_flow(rig, flow)
