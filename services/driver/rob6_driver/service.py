"""The driver service: owns the robot, runs the controller cycle, publishes joint state."""

from __future__ import annotations

import logging
import threading
import time

from rob6.bus import Bus
from rob6.messages import Empty, JointState, PingReply
from rob6.robots import RobotModel

log = logging.getLogger("rob6.driver")


class DriverService:
    def __init__(self, bus: Bus, robot: RobotModel, dummy: bool):
        self.bus = bus
        self.robot = robot
        self.dummy = dummy
        self._epoch = time.monotonic()
        self._lock = threading.Lock()
        self._q = [0.0] * 6
        self._qd = [0.0] * 6
        self._cycle = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="driver-cycle", daemon=True)

    def robot_time(self) -> float:
        return time.monotonic() - self._epoch

    def state(self) -> JointState:
        with self._lock:
            return JointState(t=self.robot_time(), cycle=self._cycle, q=list(self._q), qd=list(self._qd))

    def _run(self) -> None:
        period = self.robot.cycle_s
        deadline = time.monotonic()
        while not self._stop.is_set():
            deadline += period
            with self._lock:
                self._cycle += 1
            self.bus.publish("driver/state", self.state())
            delay = deadline - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
            else:
                deadline = time.monotonic()  # missed: start afresh rather than burst

    # ---- operations ----------------------------------------------------------
    def ping(self, _req: Empty, _ctx) -> PingReply:
        return PingReply(robot_time=self.robot_time(), wall_time=time.time())

    def get_state(self, _req: Empty, _ctx) -> JointState:
        return self.state()

    def start(self) -> None:
        self._thread.start()
        self.bus.serve({"ping": self.ping, "state": self.get_state})

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
