"""What the safety zones cost: one setpoint's check against the driver's cycle, a 5 s PTP's check against its planning.

The baseline of each row is measured in the same run: the 4 ms RSI cycle the check must fit
in, the motion core's own step without a cell, and the Ruckig plan of the same PTP. Two
cells: each robot's default (the floor, self-collision) and a busy one (ten boxes around
the arm, a tool of a capsule and a sphere).
"""

from __future__ import annotations

import socket
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from harness.ports import free_port
from harness.system import running
from rob6.cell import CellModel, Guard, default_cell, load_cell
from rob6.cell.file import DEFAULT_FILE
from rob6.messages import Cell, LinkQuery
from rob6.robots import get_robot
from rob6.units import UNIT_CYCLE_S
from rob6_driver.limits import Limits
from rob6_driver.motion import MotionCore
from rob6_driver.zones import ZoneGuard
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import JointLimits, TrajectoryPlanner
from tests.controllers.rsi_controller import SYSTEM_TIMEOUT, install

from .links import ControllerSim
from .tables import Table

RSI_CYCLE_MS = 4.0
BUSY = "10 boxes and a tool"
#: the long PTP whose check runs beside the RSI cycle (issue 56's figure: a 22 s PTP)
LONG_PTP_S = 22.0
ROBOT = "kr16"
#: q(s) = (0, s, 90, 0, -s, 0): the flange points down, lower as s grows (tests/cell/zone_rig.py)
HOVER = np.array([0.0, -55.0, 90.0, 0.0, 55.0, 0.0])
#: the flange 40 mm above the floor, pointing down
LOW = np.array([0.0, -19.16, 90.0, 0.0, 19.16, 0.0])


def busy_cell() -> str:
    """Ten keep-out boxes around a kr16 (none in its way at HOVER) and a tool."""
    boxes = []
    for k in range(10):
        angle = np.radians(36.0 * k + 18.0)
        x, y = 2000.0 * np.cos(angle), 2000.0 * np.sin(angle)
        boxes.append(f"  - {{name: box{k}, keep: out, box: {{min: [{x - 100:.0f}, {y - 100:.0f}, 0], "
                     f"max: [{x + 100:.0f}, {y + 100:.0f}, 900]}}}}")
    return ("margin_mm: 5\nzones:\n" + "\n".join(boxes) + "\ntool:\n"
            "  - {name: gripper, capsule: {from: [0, 0, -12], to: [0, 0, -125], radius: 12}}\n"
            "  - {name: tool tip, sphere: {center: [0, 0, -150], radius: 25}}\n")


def _cells() -> dict[str, Cell]:
    robot = get_robot(ROBOT)
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "busy.yaml"
        path.write_text(busy_cell())
        return {"default (floor, self-collision)": default_cell(robot), BUSY: load_cell(path)}


def _us(fn: Callable[[], object], count: int) -> tuple[float, float]:
    samples = []
    for _ in range(count):
        start = time.perf_counter()
        fn()
        samples.append((time.perf_counter() - start) * 1e6)
    return _p50_p99(samples)


def _p50_p99(samples: list[float]) -> tuple[float, float]:
    return float(np.percentile(samples, 50)), float(np.percentile(samples, 99))


def _ptp(start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    robot = get_robot(ROBOT)
    plan = TrajectoryPlanner(robot).plan_ptp(start, end, MotionSettings(robot))
    assert plan.ok and plan.trajectory is not None
    return plan.trajectory.q, plan.trajectory.qd, plan.trajectory.qdd


def setpoint_rows(count: int) -> list[tuple[object, ...]]:
    """One setpoint's check, over every setpoint of two PTPs: one far from every zone, one
    ending 40 mm above the floor; as Alter's are checked (no path known ahead) and as a
    straight trajectory's are (its poses known clear), with the way from the setpoint before."""
    robot = get_robot(ROBOT)
    limits = Limits.defaults(robot)
    moves = {"a PTP far from every zone": _ptp(HOVER, HOVER + np.array([60.0, 10.0, -10.0, 30.0, -10.0, 45.0])),
             "a PTP ending 40 mm above the floor": _ptp(HOVER, LOW)}
    rows: list[tuple[object, ...]] = []
    for name, cell in _cells().items():
        guard = Guard(CellModel(robot, cell))
        for move, (q, qd, qdd) in moves.items():
            for how, along in (("Alter (nothing known ahead)", None), ("trajectory (straight, poses clear)", q[-1])):
                samples = []
                for _ in range(max(1, count // len(q))):
                    for k in range(len(q)):
                        start = time.perf_counter()
                        guard.setpoint(q[k], qd[k], qdd[k], limits.vmax, limits.amax, limits.jmax, along=along,
                                       prev=q[k - 1] if k else None)
                        samples.append((time.perf_counter() - start) * 1e6)
                p50, p99 = _p50_p99(samples)
                rows.append((name, move, how, f"{p50:.0f}", f"{p99:.0f}", f"{max(samples):.0f}",
                             f"{100 * p99 / 1000 / RSI_CYCLE_MS:.1f} %"))
    return rows


def core_rows(count: int) -> list[tuple[object, ...]]:
    """The motion core's whole step in an Alter stream, without a cell and with each."""
    robot = get_robot(ROBOT)
    rows: list[tuple[object, ...]] = []
    guards = {"no cell": None, **{name: ZoneGuard(robot, cell) for name, cell in _cells().items()}}
    for name, zones in guards.items():
        core = MotionCore(robot, q0=HOVER.tolist(), zones=zones)
        core.enable_alter(synchronized=True)
        samples = []
        for k in range(count):
            core.set_target((HOVER + np.array([10.0, 0, 0, 0, 0, 0]) * np.sin(k / 200)).tolist(), True)
            start = time.perf_counter()
            core.step()
            samples.append((time.perf_counter() - start) * 1e6)
        p50, p99 = _p50_p99(samples)
        rows.append((name, f"{p50:.0f}", f"{p99:.0f}", f"{100 * p99 / 1000 / RSI_CYCLE_MS:.1f} %"))
    return rows


def path_rows(repeat: int) -> list[tuple[object, ...]]:
    """A 5 s PTP's check, beside its Ruckig plan."""
    robot = get_robot(ROBOT)
    config = MotionSettings(robot)
    planner = TrajectoryPlanner(robot)
    start, end = np.array([-35.0, -90.0, 90.0, 0.0, 60.0, 0.0]), np.array([35.0, -60.0, 100.0, 30.0, 30.0, 45.0])
    plan = planner.plan_ptp(start, end, config)  # some 5 s
    assert plan.ok and plan.trajectory is not None
    trajectory = plan.trajectory
    limits = JointLimits.from_config(config)
    planning = _us(lambda: planner.plan_ptp(start, end, config), repeat)
    rows: list[tuple[object, ...]] = [("(baseline) its Ruckig plan and samples", f"{trajectory.duration:.2f} s",
                                       f"{planning[0] / 1000:.2f}", f"{planning[1] / 1000:.2f}")]
    for name, cell in _cells().items():
        guard = Guard(CellModel(robot, cell))

        def check(guard: Guard = guard) -> object:
            return guard.path(trajectory.q, trajectory.qd, trajectory.qdd, trajectory.dt, limits.vmax, limits.amax,
                              limits.jmax)

        assert check() is None
        p50, p99 = _us(check, repeat)
        rows.append((f"check, {name}", f"{len(trajectory.q)} samples", f"{p50 / 1000:.2f}", f"{p99 / 1000:.2f}"))
    return rows


def rsi_long_ptp(cell_name: str) -> dict[str, float]:
    """A 22 s PTP on kr16rt over RSI (kuka-rsi-sim, KSS 8.6) with the cell ``cell_name``
    (``_cells``): the late packets the controller counted from the move's request to its end
    (the driver checks the trajectory's poses as it takes it, beside the RSI thread), and what
    that check costs."""
    robot = get_robot("kr16rt")
    udp = free_port(socket.SOCK_DGRAM)
    start, end = np.array([-60.0, -80.0, 100.0, 0.0, 30.0, 0.0]), np.array([60.0, -80.0, 100.0, 0.0, 30.0, 0.0])
    speed = [120.0 / LONG_PTP_S * UNIT_CYCLE_S] * 6  # deg per 12 ms: 120 deg of A1 in some 22 s
    with tempfile.TemporaryDirectory() as logs:
        cell = Path(logs) / "cell.yaml"
        cell.write_text(busy_cell() if cell_name == BUSY else DEFAULT_FILE.read_text())
        with running("kr16rt", dummy=False, log_dir=logs, extra_env={
                "ROB6_LINK": "rsi", "ROB6_RSI_LISTEN": f"127.0.0.1:{udp}", "ROB6_CELL": str(cell)}) as system:
            bus = system.bus("bench")
            program, sensor = install(Path(logs) / "kr-c4", "8.6", "kr16rt")
            kuka = ControllerSim("kuka_rsi_sim", "--program", str(program), "--sensor-interface", str(sensor),
                                 "--kss", "8.6", "--robot", "kr16rt", "--rob6", f"127.0.0.1:{udp}",
                                 "--timeout", str(SYSTEM_TIMEOUT), "--start-pose", ",".join(f"{v:g}" for v in start))
            try:
                while bus.request("driver", "link", LinkQuery()).state != "connected":
                    time.sleep(0.05)
                with system.client() as client:
                    assert client.ask("SetJointsMaxSpeed " + " ".join(f"{v:f}" for v in speed)) == "true\n"
                    before = kuka.status()["late_total"]
                    began = time.monotonic()
                    assert client.ask("MovePTPJoints " + " ".join(f"{v:g}" for v in end), timeout=120) == "true\n"
                    took = time.monotonic() - began
                    late = kuka.status()["late_total"] - before
            finally:
                kuka.close()
                bus.close()
    config = MotionSettings(robot)
    config.speed = speed
    plan = TrajectoryPlanner(robot).plan_ptp(start, end, config)
    assert plan.ok and plan.trajectory is not None
    q = plan.trajectory.q
    zones = ZoneGuard(robot, _cells()[cell_name])
    check = _us(lambda: zones.trajectory(q, robot.cycle_s), 5)
    return {"seconds": took, "late": late, "samples": len(q), "check_ms": check[0] / 1000}


def zones_table(table: Table, count: int = 2000) -> None:
    table(f"Safety zones: one setpoint's check (FK, distances, the brake; {ROBOT}), us, against the "
          f"{RSI_CYCLE_MS:g} ms RSI cycle", ("cell", "setpoints of", "checked as", "p50", "p99", "max", "p99 of the cycle"),
          setpoint_rows(count))
    table(f"Safety zones: the driver's whole step in an Alter stream ({ROBOT}, fast-forward), us",
          ("cell", "p50", "p99", "p99 of the cycle"), core_rows(count))
    table(f"Safety zones: the planner's check of a PTP ({ROBOT}), ms", ("what", "length", "p50", "p99"),
          path_rows(max(20, count // 100)))
    runs = {name: rsi_long_ptp(name) for name in _cells()}
    table("Safety zones: a long PTP over RSI (kr16rt, kuka-rsi-sim)",
          ("cell", "PTP", "samples", "the driver's check of its poses, ms (p50)", "late packets (controller)", "goal"),
          [(name, f"{run['seconds']:.1f} s", run["samples"], f"{run['check_ms']:.1f}", run["late"], "0")
           for name, run in runs.items()])


if __name__ == "__main__":
    from .tables import table

    zones_table(table)
