"""IK throughput benchmark (for ``make bench``).

``bench_ik()`` times, on the same random reachable poses of one robot:

* ``batch_ik``   — ``Kinematics.ik`` on all poses at once (numpy, all 8 branches);
* ``single_ik``  — ``Kinematics.ik_one`` called once per pose (all 8 branches, the
  numpy-free single-pose path of BackwardCalc / IsPossible / the Cartesian moves);
* ``single_ik_numpy`` — ``Kinematics.ik`` (vectorised) called once per pose, for comparison;
* ``backward_calc`` / ``forward_calc`` — one protocol command per pose (microseconds per call);
* ``clik``       — Pinocchio's numeric CLIK (damped least squares on ``pin.log6``,
  the loop of Pinocchio's ``examples/inverse-kinematics.py`` on the flange frame),
  one solution per pose, started from q = 0.

Figures are poses per second on one core (``clik`` also reports its success rate).
``python -m rob6_kinematics.bench [robot]`` prints them.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, TypedDict

import numpy as np
import numpy.typing as npt

from rob6.robots import DEFAULT_ROBOT

from .opw import FloatArray

if TYPE_CHECKING:
    from .calc import Kinematics
    from .model import PinModel


class IkBench(TypedDict):
    """What ``bench_ik`` measured."""

    robot: str
    batch_ik_poses_per_s: float
    single_ik_poses_per_s: float
    single_ik_numpy_poses_per_s: float
    backward_calc_us: float
    forward_calc_us: float
    clik_poses_per_s: float
    clik_success_rate: float
    batch_solved_rate: float
    n_batch: int
    n_single: int
    n_clik: int


def _single_thread() -> None:
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def random_poses(kin: Kinematics, n: int, seed: int = 0) -> tuple[FloatArray, FloatArray]:
    """n poses (N,3,4) from random joints inside the turn limits, and the joints."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(kin.turn_min, -179.0)
    hi = np.minimum(kin.turn_max, 179.0)
    q = rng.uniform(lo, hi, size=(n, 6))
    return kin.fk(q), q


def clik(pm: PinModel, T_mm: FloatArray, q0: npt.ArrayLike | None = None, eps: float = 1e-4, it_max: int = 1000,
         dt: float = 1e-1, damp: float = 1e-12) -> tuple[FloatArray, bool]:
    """Pinocchio example CLIK to the flange pose T (mm). Returns (q_deg, success)."""
    import pinocchio as pin

    model, data, fid = pm.model, pm.data, pm.flange
    oMdes = pin.SE3(np.array(T_mm[:, :3]), np.array(T_mm[:, 3]) / 1000.0)
    q = pin.neutral(model) if q0 is None else np.radians(np.asarray(q0, float))
    for _ in range(it_max):
        pin.framesForwardKinematics(model, data, q)
        iMd = data.oMf[fid].actInv(oMdes)
        err = pin.log6(iMd).vector
        if np.linalg.norm(err) < eps:
            return np.degrees(q), True
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        J = -np.dot(pin.Jlog6(iMd.inverse()), J)
        v = -J.T.dot(np.linalg.solve(J.dot(J.T) + damp * np.eye(6), err))
        q = pin.integrate(model, q, v * dt)
    return np.degrees(q), False


def _best(repeat: int, fn: Callable[[], object]) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def bench_ik(robot: str = DEFAULT_ROBOT, n_batch: int = 20000, n_single: int = 2000, n_clik: int = 50,
             repeat: int = 3, seed: int = 0) -> IkBench:
    """Poses/s of batch IK, single-call IK and Pinocchio CLIK on the same poses."""
    _single_thread()
    from rob6.robots import get_robot

    from .calc import Kinematics

    kin = Kinematics(get_robot(robot))
    T, q_all = random_poses(kin, n_batch, seed)
    kin.ik(T[:10])  # warm-up

    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        Q = kin.ik(T)
        best = min(best, time.perf_counter() - t0)
    batch = n_batch / best
    solved = float(np.mean(np.isfinite(Q).all(axis=-1).any(axis=-1)))

    Ts = T[:n_single]
    Tl = Ts.reshape(-1, 12).tolist()
    single = len(Ts) / _best(repeat, lambda: [kin.ik_one(t) for t in Tl])
    single_np = len(Ts) / _best(repeat, lambda: [kin.ik(t) for t in Ts])
    zero = [0.0] * 6
    bc_us = 1e6 / len(Tl) * _best(repeat, lambda: [
        kin.backward_calc(t, "toggleHand toggleElbow toggleArm", zero) for t in Tl])
    ql = q_all[:n_single].tolist()
    fc_us = 1e6 / len(ql) * _best(repeat, lambda: [kin.forward_calc(q) for q in ql])

    pm = kin.pin
    Tc = T[:n_clik]
    ok = 0
    t0 = time.perf_counter()
    for t in Tc:
        ok += clik(pm, t)[1]
    dt = time.perf_counter() - t0
    return {
        "robot": robot,
        "batch_ik_poses_per_s": batch,
        "single_ik_poses_per_s": single,
        "single_ik_numpy_poses_per_s": single_np,
        "backward_calc_us": bc_us,
        "forward_calc_us": fc_us,
        "clik_poses_per_s": len(Tc) / dt,
        "clik_success_rate": ok / len(Tc),
        "batch_solved_rate": solved,
        "n_batch": n_batch,
        "n_single": len(Ts),
        "n_clik": len(Tc),
    }


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    res = bench_ik(argv[0] if argv else DEFAULT_ROBOT)
    for k, v in res.items():
        print(f"{k:24s} {v:,.1f}" if isinstance(v, float) else f"{k:24s} {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
