"""The driver's stop on a straight joint path: one jerk-limited brake along the line, so the arm stops on poses the cell checked.

A point-to-point move is a straight line in joint space. Braked joint by joint, Ruckig may
leave that line (when it cannot synchronise the joints' phases it brakes each on its own,
and the arm was seen 19 mm off the checked path). Braked along the line, the stop is the
path itself, time-scaled (KUKA's STOP 1 and STOP 2 brake on the programmed path the same
way): one degree of freedom ``s`` along the unit direction ``u``, with the limits of the
joints projected onto it (``|u_j| * s' <= vmax_j`` ...). The motion core
(``rob6_driver.motion``) brakes with it whenever ``line_brake`` gives one, and the guard
(``rob6.cell.guard``) takes a straight path's stop to be the rest of the path on the same
condition, so both rest on this one function.
"""

from __future__ import annotations

import numpy as np
import ruckig

#: how far (deg) a velocity may be off the line and still count as along it
ON_LINE_TOL = 1e-6


class LineBrake:
    """A brake along a line in joint space: ``at_time`` answers as a Ruckig trajectory does
    (positions, velocities, accelerations of the six joints)."""

    def __init__(self, q0: np.ndarray, unit: np.ndarray, trajectory: ruckig.Trajectory) -> None:
        self.q0, self.unit, self._trajectory = q0.copy(), unit.copy(), trajectory
        self.duration = float(trajectory.duration)
        self.length = float(trajectory.at_time(self.duration)[0][0])  # how far along the line it stops (deg)

    def at_time(self, t: float) -> tuple[list[float], list[float], list[float]]:
        s, sd, sdd = (float(v[0]) for v in self._trajectory.at_time(min(max(t, 0.0), self.duration)))
        return (self.q0 + s * self.unit).tolist(), (sd * self.unit).tolist(), (sdd * self.unit).tolist()

    def extrema(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) per joint of the whole brake: it moves one way along the line."""
        end = self.q0 + self.length * self.unit
        return np.minimum(self.q0, end), np.maximum(self.q0, end)


def line_brake(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, end: np.ndarray, vmax: np.ndarray,
               amax: np.ndarray, jmax: np.ndarray) -> LineBrake | None:
    """The brake along the line from ``q`` to ``end`` (deg) from velocity ``qd`` and
    acceleration ``qdd`` (deg/s, deg/s^2) along it, with the joints' limits; None when the
    state is not along the line towards ``end``, or when the brake would not come to rest
    before ``end``."""
    direction = end - q
    length = float(np.linalg.norm(direction))
    if length < ON_LINE_TOL:
        return None
    unit = direction / length
    sd, sdd = float(qd @ unit), float(qdd @ unit)
    scale = 1.0 + float(np.abs(qd).max()) + float(np.abs(qdd).max())
    if sd < 0.0 or np.abs(qd - sd * unit).max() > ON_LINE_TOL * scale or np.abs(qdd - sdd * unit).max() > ON_LINE_TOL * scale:
        return None
    along = np.abs(unit) > 1e-12
    limit = [float(np.min(lim[along] / np.abs(unit[along]))) for lim in (vmax, amax, jmax)]
    if min(limit) <= 0.0:
        return None
    otg, inp = ruckig.Ruckig(1), ruckig.InputParameter(1)
    inp.control_interface = ruckig.ControlInterface.Velocity
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [sd], [sdd]
    inp.target_velocity, inp.target_acceleration = [0.0], [0.0]
    inp.max_velocity = [max(limit[0], abs(sd))]
    inp.max_acceleration = [max(limit[1], abs(sdd))]
    inp.max_jerk = [limit[2]]
    trajectory = ruckig.Trajectory(1)
    try:
        result = otg.calculate(inp, trajectory)
    except RuntimeError:
        return None
    if result not in (ruckig.Result.Working, ruckig.Result.Finished):
        return None
    brake = LineBrake(q, unit, trajectory)
    if brake.length < -ON_LINE_TOL or brake.length > length + ON_LINE_TOL:
        return None
    return brake
