"""The solo12 quadruped (example-robot-data) standing on the floor on its four feet.

solo12's URDF is read with a ``Free`` joint at the base; each foot (the rounded foot at the
end of a lower leg, a disc of radius 16 mm in the leg's plane: the half-width of the foot's
collision mesh) is a ``Contact`` sphere against the floor z = 0 with Coulomb friction
``mu = 0.8``.  Its twelve joints are held by compiled PD laws toward the standing posture of
the robot's SRDF (hip abduction 0, hip flexion +-0.8 rad, knee -+1.6 rad) plus a constant
feed-forward torque: the torques that hold the robot at rest in that posture with the
vertical foot forces that carry its weight, computed here from the kinematics alone (virtual
work: ``tau = h(q) - J^T F`` with ``h`` the holding forces of the free robot and ``F`` the
least-norm vertical foot forces whose wrench on the base balances gravity).  So the posture
is an exact equilibrium: the base stands at ``z = -(lowest foot centre below the base) + r``.

Put down touching the floor at rest, it stands there: no event, no drift, the feet carry
the statics' forces.  With the PD alone (feed-forward 0) dropped from 2 mm, the four feet
land together (one simultaneous frictional impact), stick, and the knees give until the PD
torques hold the weight: the base settles 2.8 mm below the kinematic height.  Dropped with
the feed-forward on, the legs stretch during the fall (1.5 mm) and the front feet land
18 us before the hind ones, slide on for 1.4 us and stick; the robot stands on the feet
where they landed, 0.5 mm above the kinematic height (docs/contacts.md).

Needs ``example-robot-data`` (``pip install "mbcomp[robots]"``).

Run: ``python examples/solo12_standing.py``.
"""
from __future__ import annotations

import os
import time
import warnings

import numpy as np

import mbcomp as mb
from mbcomp.files.library import robots_dir

LEGS = ("FL", "FR", "HL", "HR")
FOOT_RADIUS = 0.016          # m: half the foot collision mesh's extent in the leg's plane
FOOT_OFFSET = 0.008          # m: the foot centre's lateral offset in the lower-leg frame (URDF ankle)
SHANK = 0.16                 # m: lower-leg length to the foot centre (URDF ankle joint)
MU = 0.8
G = 9.81
# The SRDF's "straight_standing" posture: front legs HFE +0.8, KFE -1.6; hind legs mirrored.
POSTURE = {f"{leg}_{j}": (0.0 if j == "HAA" else (1.0 if leg[0] == "F" else -1.0) * v)
           for leg in LEGS for j, v in (("HAA", 0.0), ("HFE", 0.8), ("KFE", -1.6))}


def urdf_path() -> str | None:
    """solo12's URDF in example-robot-data, or None when that package is not installed."""
    base = robots_dir()
    if base is None:
        return None
    path = os.path.join(base, "solo_description", "robots", "solo12.urdf")
    return path if os.path.isfile(path) else None


def foot_point(leg: str) -> tuple[float, float, float]:
    """The foot centre (m) in the leg's lower-leg frame (the welded foot link's origin)."""
    return (0.0, FOOT_OFFSET if leg[1] == "L" else -FOOT_OFFSET, -SHANK)


def standing_state(system: mb.System, clearance: float = 0.0) -> np.ndarray:
    """The coordinates of the robot upright in ``POSTURE`` with its base above the origin,
    the lowest foot sphere ``clearance`` (m) above the floor."""
    q = np.zeros(len(system.coords))
    q[system.coords.index("base_link_free_qw")] = 1.0
    for name, value in POSTURE.items():
        q[system.coords.index(name)] = value
    lowest = min(system.body_state(f"{leg}_LOWER_LEG", q, point=foot_point(leg)).position[2] for leg in LEGS)
    q[system.coords.index("base_link_free_z")] = -lowest + FOOT_RADIUS + clearance
    return q


def feed_forward(system: mb.System, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(tau, f)``: joint torques (N m, in ``system.coords`` order after the base) and the
    vertical foot forces (N, one per leg in ``LEGS`` order) that hold the robot at rest at
    ``q``.  From the kinematics: the generalised force of a vertical force ``f`` at a foot is
    ``f`` times the column of the foot centre's z velocities (for a sphere the contact point
    below has the same z velocity), so ``J^T f`` balances the holding forces ``h(q)`` on
    the base's six speeds (least-norm ``f``), and the joints supply the rest."""
    nv = system.nv
    jz = np.zeros((nv, len(LEGS)))
    for k in range(nv):
        e = np.zeros(nv)
        e[k] = 1.0
        for i, leg in enumerate(LEGS):
            jz[k, i] = system.body_state(f"{leg}_LOWER_LEG", q, e, point=foot_point(leg)).velocity[2]
    hold = system.holding_forces(q)
    f = np.linalg.lstsq(jz[:6], hold[:6], rcond=None)[0]
    if np.abs(jz[:6] @ f - hold[:6]).max() > 1e-9 * np.abs(hold).max():
        raise mb.SimulationError("solo12", "vertical foot forces cannot hold the base in this posture")
    return hold[6:] - jz[6:] @ f, f


def solo12(formulation: str = "lagrange", kp: float = 20.0, kd: float = 0.5, mu: float = MU) -> mb.System:
    """solo12 on a ``Free`` joint with a frictional foot ``Contact`` per leg (``LEG_foot``)
    and a compiled PD law plus feed-forward on each joint (``JOINT_pd``; ``kp`` N m/rad,
    ``kd`` N m s/rad), toward ``POSTURE``.  Raises ``ModelError`` without example-robot-data."""
    path = urdf_path()
    if path is None:
        raise mb.ModelError("solo12", "needs the package example-robot-data (pip install \"mbcomp[robots]\")")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")      # the URDF's limits, damping and meshes are not modelled
        model = mb.load_urdf(path, floating=True)
    for leg in LEGS:
        model.add(mb.Contact(f"{leg}_foot", model[f"{leg}_LOWER_LEG"], foot_point(leg), normal=(0, 0, 1),
                             friction=mu, radius=FOOT_RADIUS))
    for name, target in POSTURE.items():
        joint = model[name]
        model.add(mb.JointTorque(f"{name}_pd", joint,
                                 kp * (target - mb.Angle(joint)) - kd * mb.Speed(joint) + mb.Constant(0.0)))
    system = model.compile(formulation=formulation)
    # The feed-forward is a run-time parameter (no second compile): the PD's numbers are
    # constant1 (kp), constant2 (target), constant3 (kd), constant4 (feed-forward), so kp and
    # kd can be swept too.  The holding forces at rest in the posture do not depend on them.
    tau, _ = feed_forward(system, standing_state(system))
    return system.with_parameters({f"{name}_pd.value.constant4.value": float(value)
                                   for name, value in zip(system.coords[7:], tau)})


def main() -> None:
    if urdf_path() is None:
        print("example-robot-data is not installed: pip install \"mbcomp[robots]\"")
        return
    for formulation in ("lagrange", "dae"):
        system = solo12(formulation)
        height = standing_state(system)[2]
        # 1. Put down touching the floor at rest: PD + feed-forward hold the posture exactly.
        start = time.perf_counter()
        res = system.simulate(1.0, standing_state(system), np.zeros(system.nv), t_eval=[0.0, 0.5, 1.0])
        force = sum(res.contact_forces[f"{leg}_foot"][-1] for leg in LEGS)
        print(f"{formulation}, standing: {time.perf_counter() - start:.1f} s for 1 s, events {res.events}, "
              f"base height {res['base_link_free_z'][-1]:.9f} m (kinematic {height:.9f} m), feet carry {force} N")
        # 2. Pure PD (no feed-forward), dropped from 2 mm: lands on four feet, the knees give.
        pd_only = system.with_parameters({f"{name}_pd.value.constant4.value": 0.0 for name in POSTURE})
        start = time.perf_counter()
        res = pd_only.simulate(1.0, standing_state(pd_only, clearance=0.002), np.zeros(system.nv),
                               t_eval=np.linspace(0.0, 1.0, 101))
        force = sum(res.contact_forces[f"{leg}_foot"][-1] for leg in LEGS)
        print(f"{formulation}, dropped: {time.perf_counter() - start:.1f} s for 1 s, "
              f"events {[(round(e.time, 6), e.kind, e.contact) for e in res.events]}")
        print(f"  base height {res['base_link_free_z'][-1]:.9f} m (sag {height - res['base_link_free_z'][-1]:.6f} m), "
              f"feet carry {force} N, lowest gap {min(min(pd_only.gaps(q).values()) for q in res.q):.1e} m")

if __name__ == "__main__":
    main()
