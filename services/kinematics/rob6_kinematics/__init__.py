"""rob6 kinematics service: stateless FK/IK and configuration selection.

Library (no networking):

* ``rob6_kinematics.calc.Kinematics`` — FK/IK and the protocol semantics of
  ForwardCalc, BackwardCalc/GetJointsRowWise, IsPossible; Jacobian via Pinocchio.
* ``rob6_kinematics.opw`` — vectorised numpy FK and 8-branch closed-form IK.
* ``rob6_kinematics.model.PinModel`` — Pinocchio model built from the URDF.
* ``rob6_kinematics.urdf`` — URDF generator (``python -m rob6_kinematics.urdf``).
* ``rob6_kinematics.bench.bench_ik`` — IK throughput (``python -m rob6_kinematics.bench``).
"""
