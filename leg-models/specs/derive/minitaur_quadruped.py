"""Writes leg-models/specs/minitaur_quadruped.toml from the constants of the `pybullet`
wheel's `pybullet_data/quadruped/minitaur.urdf` (U) and `pybullet_envs/bullet/minitaur.py`
(M), pybullet 3.2.7, copied here with their lines.

usage: python leg-models/specs/derive/minitaur_quadruped.py > leg-models/specs/minitaur_quadruped.toml

`--legs N` keeps M's first N legs (1, 2 or 4), for measuring how generation grows with
the robot; the built-in spec is all four.

What the spec takes from the files, and what it decides:

- Masses, joint origins and axes as U writes them; no link of U gives an inertial
  origin, so each centre of mass is at its link's origin (the lower legs' at the knee),
  as pybullet simulates them.
- U's fixed joints merge rigidly: the two rails (0.1 kg, rolled ∓5°) into the body, each
  upper leg into its motor. A spec link is then the body, a motor with its upper leg, or a
  lower leg: 17 links, 16 joints and the body's free joint.
- U's 27 inertias are placeholders of 1.0, which pybullet does not read: it takes a solid
  box of each link's collision bounds, each half-extent 1 mm larger (its collision
  margin), about the link's inertial frame (btCompoundShape::calculateLocalInertia). The
  spec takes the same boxes, so both simulators move the same bodies. The motor
  `motor_front_leftR_link` has no collision shape in U: its box is the margin alone.
- The loops are M's point-to-point constraints (M l.212-217) between the two lower legs
  of each leg: `lower_leg_<leg>R_link` at (0, 0.005, 0.2) and `lower_leg_<leg>L_link` at
  (0, 0.01, 0.2) (M l.12-13). Each loop is planar (its four axes are parallel), so one of
  its point closure's three rows is structurally redundant.
- Home: the stance M resets to (M l.187-211): every motor at direction × π/2, every
  knee at direction × (−2.1834), direction −1 on the left legs, +1 on the right.
- No rotor inertia (U has none; M's motors are direct drive), gear ratio 1.
- U's angles 1.57075 and 3.141592 are π/2 and π rounded (by 4.6e-5 and 6.5e-7 rad).
  Taken as written, a leg's two motor axes are 9e-5 rad apart, its loop is not planar and
  cannot close (by about 1e-5 m, which pybullet's soft constraint absorbs); taken as π/2
  and π, as the robot is built, the motors are coaxial and each loop closes exactly.
"""

import sys

import numpy as np

MARGIN = 0.001  # m, added to each collision half-extent by pybullet's URDF importer


def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rpy(r, p, y):
    """URDF's rpy: R = Rz(y) Ry(p) Rx(r) (p is 0 everywhere here)."""
    assert p == 0
    return rz(y) @ rx(r)


def box_inertia(m, size):
    """A solid box of `size` (each half-extent grown by the margin), about its centre."""
    x, y, z = (np.asarray(size, float) + 2 * MARGIN)
    return m / 12 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])


def merge(parts):
    """[(mass, com, inertia about com, all in one frame)] -> (mass, com, inertia about com)."""
    m = sum(p[0] for p in parts)
    c = sum(p[0] * np.asarray(p[1]) for p in parts) / m
    inertia = np.zeros((3, 3))
    for mi, ci, Ii in parts:
        d = np.asarray(ci) - c
        inertia += Ii + mi * (d @ d * np.eye(3) - np.outer(d, d))
    return m, c, inertia


def quat(R):
    """Unit quaternion [w, x, y, z] of a rotation matrix (w ≥ 0)."""
    w = np.sqrt(max(0.0, 1 + np.trace(R))) / 2
    x = np.sqrt(max(0.0, 1 + R[0, 0] - R[1, 1] - R[2, 2])) / 2
    y = np.sqrt(max(0.0, 1 - R[0, 0] + R[1, 1] - R[2, 2])) / 2
    z = np.sqrt(max(0.0, 1 - R[0, 0] - R[1, 1] + R[2, 2])) / 2
    x = np.copysign(x, R[2, 1] - R[1, 2])
    y = np.copysign(y, R[0, 2] - R[2, 0])
    z = np.copysign(z, R[1, 0] - R[0, 1])
    return np.array([w, x, y, z])


def fmt(v):
    v = [0.0 if abs(float(x)) < 1e-15 else float(x) for x in np.ravel(v)]
    return "[" + ", ".join(repr(x) for x in v) + "]"


def tensor(I):
    return fmt([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


# --- U: the body and rails (U l.32-170) ---------------------------------------------
base = (3.0, np.zeros(3), box_inertia(3.0, [0.33, 0.30, 0.07]))  # AABB of its 3 boxes
rails = {}
for side, y, roll in [("right", -0.10, -0.0872665), ("left", 0.10, 0.0872665)]:
    R = rx(roll)
    rail = (0.1, np.array([0.0, y, 0.0]), R @ box_inertia(0.1, [0.34, 0.08, 0.04]) @ R.T)
    rails[side] = (np.array([0.0, y, 0.0]), R, rail)
body = merge([base, rails["right"][2], rails["left"][2]])

HALF_PI, PI = np.pi / 2, np.pi  # U's 1.57075 and 3.141592
# --- U: motors (U l.193-398): (leg, motor side) -> (rail, origin, rpy) ------------------
MOTORS = {
    ("front_right", "R"): ("right", [0.21, -0.025, 0], (HALF_PI, 0, 0)),
    ("front_right", "L"): ("right", [0.21, 0.04, 0], (HALF_PI, 0, PI)),
    ("front_left", "L"): ("left", [0.21, 0.025, 0], (HALF_PI, 0, PI)),
    ("front_left", "R"): ("left", [0.21, -0.04, 0], (HALF_PI, 0, 0)),
    ("back_right", "R"): ("right", [-0.21, -0.025, 0], (HALF_PI, 0, 0)),
    ("back_right", "L"): ("right", [-0.21, 0.04, 0], (HALF_PI, 0, PI)),
    ("back_left", "L"): ("left", [-0.21, 0.025, 0], (HALF_PI, 0, PI)),
    ("back_left", "R"): ("left", [-0.21, -0.04, 0], (HALF_PI, 0, 0)),
}
# Lower-leg box lengths (U l.438-902).
LOWER = {
    ("front_right", "R"): 0.2, ("front_right", "L"): 0.198,
    ("front_left", "R"): 0.2, ("front_left", "L"): 0.198,
    ("back_right", "R"): 0.2032, ("back_right", "L"): 0.2,
    ("back_left", "R"): 0.2032, ("back_left", "L"): 0.2,
}
UPPER_IN_MOTOR = (np.array([0.0, 0.06, -0.015]), rx(-HALF_PI))  # U l.419-426
KNEE_IN_UPPER = np.array([0.0, 0.01, 0.055])  # U l.455, axis (0, 1, 0)
PIVOT = {"R": [0.0, 0.005, 0.2], "L": [0.0, 0.01, 0.2]}  # M l.12-13
# M's order and directions (M l.16-21, 78): left legs −1, right legs +1.
LEGS = ["front_left", "back_left", "front_right", "back_right"]
DIRECTION = {"front_left": -1, "back_left": -1, "front_right": 1, "back_right": 1}
KNEE_HOME = -2.1834  # M l.189
if "--legs" in sys.argv:
    LEGS = LEGS[: int(sys.argv[sys.argv.index("--legs") + 1])]

out = []
w = out.append
w("# minitaur_quadruped (built-in, spatial, floating): Ghost Robotics' Minitaur as the `pybullet`")
w("# wheel's model of it: four five-bar legs (two coaxial motors each) on a body that floats.")
w("# Written by leg-models/specs/derive/minitaur_quadruped.py from pybullet 3.2.7's")
w("# pybullet_data/quadruped/minitaur.urdf and the loop pivots of pybullet_envs/bullet/minitaur.py;")
w("# that script's docstring says what is taken from the files and what is decided (the")
w("# URDF's inertias are placeholders of 1.0: these are pybullet's own, solid boxes of the")
w("# collision bounds). Do not edit by hand: edit the script and run it again.")
w('description = "Minitaur quadruped (pybullet\'s URDF): four five-bars on a floating body"')
w("gravity = [0.0, 0.0, -9.81]")
home = [0.0] * 6
links = []
for leg in LEGS:
    d = DIRECTION[leg]
    for side in ["R", "L"]:
        home += [d * np.pi / 2, d * KNEE_HOME]
w("# The free joint's six coordinates (the chart's, zero at its centre), then per leg (M's")
w("# order: front_left, back_left, front_right, back_right) the R motor, its knee, the L motor,")
w("# its knee: motors at direction × π/2, knees at direction × (−2.1834) (M l.187-211).")
w("home = " + fmt(home))
w("")
w("[[links]]")
w('name = "body"')
w('parent = "base"')
w('joint = "free"')
w("length = [0.21, 0.0, 0.0]")
w(f'mass = {{ value = {body[0]!r}, source = "minitaur.urdf: base 3 kg and two rails of 0.1 kg" }}')
w(f'com = {{ value = {fmt(body[1])}, source = "minitaur.urdf: no inertial origin; the rails\' merged" }}')
w(f'inertia = {{ value = {tensor(body[2])}, source = "pybullet\'s collision-bounds boxes (base .33 x .30 x .07, rails .34 x .08 x .04 rolled 5 deg), merged" }}')
for leg in LEGS:
    for side in ["R", "L"]:
        rail, origin, (r, p, y) = MOTORS[(leg, side)]
        at, R_rail, _ = rails[rail]
        origin_body = at + R_rail @ np.array(origin, float)
        R_motor = R_rail @ rpy(r, p, y)
        has_collision = (leg, side) != ("front_left", "R")
        motor_box = [0.0868, 0.0868, 0.026] if has_collision else [0.0, 0.0, 0.0]
        motor = (0.25, np.zeros(3), box_inertia(0.25, motor_box))
        u_at, u_R = UPPER_IN_MOTOR
        upper = (0.05, u_at, u_R @ box_inertia(0.05, [0.01, 0.01, 0.11]) @ u_R.T)
        m, c, I = merge([motor, upper])
        knee = u_at + u_R @ KNEE_IN_UPPER
        name = f"motor_{leg}_{side.lower()}"
        w("")
        w("[[links]]")
        w(f'name = "{name}"')
        w('parent = "body"')
        w(f"origin = {fmt(origin_body)}")
        w(f"orientation = {fmt(quat(R_motor))}")
        w("axis = [0.0, 0.0, 1.0]")
        w(f"length = {fmt(knee)}")
        w(f"mass = {m!r}")
        w(f"com = {fmt(c)}")
        note = "" if has_collision else "  # no collision shape in the URDF: its box is pybullet's margin alone"
        w(f"inertia = {tensor(I)}{note}")
        w("actuator = { rotor_inertia = 0.0, gear_ratio = 1.0 }")
        lower = LOWER[(leg, side)]
        w("")
        w("[[links]]")
        w(f'name = "lower_{leg}_{side.lower()}"')
        w(f'parent = "{name}"')
        w(f"orientation = {fmt(quat(u_R))}")
        w("axis = [0.0, 1.0, 0.0]")
        w("length = [0.0, 0.0, 0.2]")
        w("mass = 0.05")
        w("com = [0.0, 0.0, 0.0]")
        w(f"inertia = {tensor(box_inertia(0.05, [0.01, 0.01, lower]))}")
for leg in LEGS:
    w("")
    w("[[closures]]")
    w(f'name = "knee_{leg}"')
    w(f'a = {{ link = "lower_{leg}_r", point = {fmt(PIVOT["R"])} }}')
    w(f'b = {{ link = "lower_{leg}_l", point = {fmt(PIVOT["L"])} }}')
w("")
w("[foot]")
w('link = "lower_front_left_r"')
w(f"point = {fmt(PIVOT['R'])}")
for leg in LEGS:
    w("")
    w("[[contacts]]")
    w(f'name = "toe_{leg}"')
    w(f'link = "lower_{leg}_r"')
    w(f"point = {fmt(PIVOT['R'])}")
    w('friction = { value = 1.0, source = "minitaur.urdf: lateral_friction 1" }')
print("\n".join(out))
