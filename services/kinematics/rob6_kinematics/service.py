"""The kinematics service: stateless FK/IK requests, so any number of replicas can serve.

Every request carries what it depends on (current joints, limits, weights), so a
replica on another machine answers exactly like one beside the driver.
"""

from __future__ import annotations

import math

import numpy as np

from rob6.bus import Bus, Context
from rob6.messages import (
    BackwardCalcRequest,
    FkReply,
    FkRequest,
    ForwardCalcReply,
    ForwardCalcRequest,
    IkBatchReply,
    IkBatchRequest,
    JointsReply,
    SelectRequest,
)
from rob6.robots import RobotModel

from . import selection
from .calc import Kinematics


class KinematicsService:
    def __init__(self, robot: RobotModel):
        self.kin = Kinematics(robot)

    def fk(self, req: FkRequest, _ctx: Context) -> FkReply:
        q = np.asarray(req.joints, dtype=float).reshape(-1, 6)
        poses = self.kin.fk(q).reshape(-1, 12)
        return FkReply(poses=poses.tolist(), status=[self.kin.status(row) for row in q])

    def forward_calc(self, req: ForwardCalcRequest, _ctx: Context) -> ForwardCalcReply:
        result = self.kin.forward_calc(req.numbers, req.turn_min, req.turn_max)
        if result is None:
            return ForwardCalcReply()
        pose, status = result
        return ForwardCalcReply(pose=pose, status=status)

    def backward_calc(self, req: BackwardCalcRequest, _ctx: Context) -> JointsReply:
        return JointsReply(joints=self.kin.backward_calc(
            req.pose, req.pattern, req.current, req.turn_min, req.turn_max, req.max_change,
            req.weights))

    def ik_batch(self, req: IkBatchRequest, _ctx: Context) -> IkBatchReply:
        solutions = self.kin.ik(np.asarray(req.poses, dtype=float).reshape(-1, 12))
        rows = [[None if any(math.isnan(v) for v in branch) else branch for branch in pose]
                for pose in solutions.tolist()]
        return IkBatchReply(branches=list(self.kin.BRANCHES), solutions=rows)

    def select(self, req: SelectRequest, _ctx: Context) -> JointsReply:
        return JointsReply(joints=selection.select(
            self.kin, req.pose, req.pattern, req.current, req.turn_min, req.turn_max,
            req.max_change, req.weights, req.allowed))

    def serve(self, bus: Bus) -> None:
        bus.serve({"fk": self.fk, "forward_calc": self.forward_calc, "backward_calc": self.backward_calc,
                   "ik_batch": self.ik_batch, "select": self.select}, workers=2,
                  inline=("forward_calc", "backward_calc", "select"))
