"""How long a caller waits for a reply: the quick-call default and the deadlines of replies that wait for the arm.

A quick call (a read, a setting, one pose, an Alter target) is answered at once: its
caller waits ``QUICK_S`` (``rob6.messages.Op.timeout``). A reply that waits for
something (the arm to arrive or to stop, the gripper, the link's check that the robot
is there) is bounded by that instead: the service that waits tells its caller right
away how long and for what (``rob6.bus.Context.waiting``), and the caller's deadline
becomes that plus ``HOP_S``. A service relays what the one it calls announced, so the
gateway waits as long as the driver said, plus a hop for each service in between: the
innermost party that gives up is the first, and its error names what it waited for.

docs/COMPATIBILITY.md lists every command whose reply waits, with these deadlines.
"""

from __future__ import annotations

from collections.abc import Iterable

#: a call that waits for nothing but the service's own work (the default of every bus
#: operation).
#: The work takes well under a millisecond, but on a starved robot PC (4-8 busy processes on
#: 2 cores, `make bench`'s busy table) a reply was seen 197 ms late: at 0.2 s such a reply
#: became an ERROR a quiet machine would not give. A hung instance is still named within 1 s.
QUICK_S = 1.0
#: what a waiting call (``Op.waits``: a motion, a mode, a stop, the gripper, the outputs)
#: has before its service announces what it waits for. The service checks the request
#: first (the driver checks a whole trajectory against the limits, under the lock its
#: cycle shares, before it announces the motion it took): on a starved machine (a compose
#: stack of 8 containers starting their health checks on 2 cores) a move's announcement
#: came later than QUICK_S. Its caller waits for seconds anyway; a hung service is named
#: after this long.
ANNOUNCE_S = 5.0
#: each hop outward waits this much longer than the service it called, so the service
#: that waited is the one that reports, naming what it waited for
HOP_S = 0.5
#: a controller cycle may start late on a busy machine, and the simulation's clock then
#: runs slower than wall time (rob6_driver.loop): what the arm does in d s may take up to
#: d * (1 + CLOCK_SLACK) s of wall time
CLOCK_SLACK = 0.5
#: on top of every wait for the arm: the reply's way back, a scheduling hiccup
SLACK_S = 1.0

#: a single-pose kinematics call, which may go to a replica on another host: a lost TCP
#: segment on the way stalls the exchange for TCP's retransmission timeout (>= 200 ms on
#: Linux, doubling on a second loss), so the 0.2 s default turned 5-12 % of the calls into
#: errors under 5 % packet loss (deploy/MULTI_HOST.md section 8)
REMOTE_POSE_S = 1.0
#: a batch of poses (a LIN move's line, sampled)
IK_BATCH_S = 5.0
#: the planner's work before a point-to-point move (or a Cartesian Alter target) starts:
#: where the robot is (a quick call), its pose there (DoAlterCart) and the configuration
#: choice for the target (remote poses), the trajectory itself
PLAN_PTP_S = QUICK_S + 2 * REMOTE_POSE_S + SLACK_S
# the planner does not announce it: its caller waits ANNOUNCE_S before any announcement
assert PLAN_PTP_S <= ANNOUNCE_S
#: a configuration change: the planner's own work, then its quick call to the driver
#: (the driver enforces the limits too)
CONFIG_CHANGE_S = QUICK_S + HOP_S
#: ... before a LIN move starts: the start pose, then the line solved once and again for
#: each time scaling (rob6_planner.lin_planner.LinOptions.max_retries + 1 times at most)
LIN_SOLVES = 10
PLAN_LIN_S = QUICK_S + REMOTE_POSE_S + LIN_SOLVES * IK_BATCH_S + SLACK_S


def arm_s(seconds: float) -> float:
    """The wall-clock bound on ``seconds`` of the arm's (controller clock) motion."""
    return seconds * (1.0 + CLOCK_SLACK) + SLACK_S


def stop_s(vmax: Iterable[float], amax: Iterable[float], jmax: Iterable[float]) -> float:
    """The longest controlled stop under these limits (deg/s, deg/s^2, deg/s^3, per axis),
    in the controller's seconds: from full speed with full acceleration, the acceleration
    ramps to the braking one (2 a/j), then the speed to 0 (v/a). Axes with a zero limit
    are held, not braked. Plain Python: rob6-shared has no numpy (the router, gateway,
    gripper and recorder images do not carry it)."""
    return max((float(v) / float(a) + 2.0 * float(a) / float(j)
                for v, a, j in zip(vmax, amax, jmax, strict=True) if a > 1e-9 and j > 1e-9), default=0.0)
