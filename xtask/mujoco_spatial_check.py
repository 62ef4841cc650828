"""Cross-check of a spatial leg against MuJoCo, run by `cargo xtask test`.

usage: python mujoco_spatial_check.py LEGS_BINARY MODEL MJCF_FILE

At random states near home, put on the closures by `legs eval --project`, compares with
MuJoCo on the exported MJCF (`cargo xtask export MODEL --format mjcf`):

- the mass matrix: ours is `Tᵀ M_mj T`, T mapping our rates to MuJoCo's velocities
  (the identity on a hinge or slide; on a ball joint, whose qpos is the quaternion of
  R_x(α) R_y(β) R_z(γ) and qvel the angular velocity in the link's frame, ω = E(β, γ) of
  the three angles' rates);
- the bias forces: ours (C q̇ + G, springs in G) is `Tᵀ (qfrc_bias − qfrc_spring + M_mj Ṫ q̇)`;
- the closure rows: our J is `efc_J T` (MuJoCo's `connect` rows, dense), and J̇ q̇ the
  same rows of MuJoCo's site accelerations at zero joint acceleration;
- the foot: the site `foot.point` against our foot position.

Every difference is relative to the largest entry, below 1e-9. Then MuJoCo runs 1 s
from home with the motors off and its soft loops must stay closed within 1 mm; the gap
it leaves is printed beside ours (`phi` after `--project`). Exits 1 on a mismatch.
"""

import json
import pathlib
import sys

import mujoco
import numpy as np

from legs_eval import ours

STATES = 10
REL_TOL = 1e-9
CLOSURE_TOL = 1e-3  # m; MuJoCo's equality constraints are soft


def ball_quaternion(a, b, g):
    def mul(p, q):
        return np.array([
            p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
            p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
            p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
            p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
        ])
    qx = np.array([np.cos(a / 2), np.sin(a / 2), 0, 0])
    qy = np.array([np.cos(b / 2), 0, np.sin(b / 2), 0])
    qz = np.array([np.cos(g / 2), 0, 0, np.sin(g / 2)])
    return mul(mul(qx, qy), qz)


def rate_map(b, g):
    """E(β, γ): ω in the link's frame from (α̇, β̇, γ̇); and its derivatives by β, γ."""
    sb, cb, sg, cg = np.sin(b), np.cos(b), np.sin(g), np.cos(g)
    E = np.array([[cb * cg, sg, 0], [-cb * sg, cg, 0], [sb, 0, 1]])
    Eb = np.array([[-sb * cg, 0, 0], [sb * sg, 0, 0], [cb, 0, 0]])
    Eg = np.array([[-cb * sg, cg, 0], [-cb * cg, -sg, 0], [0, 0, 0]])
    return E, Eb, Eg


class Map:
    """Our coordinates to MuJoCo's, by joint name."""

    def __init__(self, m, t):
        self.m, self.joints, self.balls = m, t["joints"], set(t["ball_joints"])
        self.n = len(self.joints)

    def groups(self):
        """(our first coordinate, count, MuJoCo joint)."""
        i = 0
        while i < self.n:
            if i in self.balls:
                yield i, 3, self.m.joint(self.joints[i].rsplit(".", 1)[0])
                i += 3
            else:
                yield i, 1, self.m.joint(self.joints[i])
                i += 1

    def state(self, d, q, qd):
        """Sets MuJoCo's qpos, qvel; returns T and Ṫ q̇."""
        T = np.zeros((self.m.nv, self.n))
        Tdot_qd = np.zeros(self.m.nv)
        for i, k, j in self.groups():
            qa, va = j.qposadr[0], j.dofadr[0]
            if k == 1:
                d.qpos[qa] = q[i]
                d.qvel[va] = qd[i]
                T[va, i] = 1.0
            else:
                a, b, g = q[i:i + 3]
                E, Eb, Eg = rate_map(b, g)
                d.qpos[qa:qa + 4] = ball_quaternion(a, b, g)
                d.qvel[va:va + 3] = E @ qd[i:i + 3]
                T[va:va + 3, i:i + 3] = E
                Tdot_qd[va:va + 3] = (Eb * qd[i + 1] + Eg * qd[i + 2]) @ qd[i:i + 3]
        return T, Tdot_qd


def close(what, ours_value, theirs, failures):
    ours_value, theirs = np.asarray(ours_value, float), np.asarray(theirs, float)
    scale = max(np.abs(theirs).max(initial=0.0), 1e-12)
    err = np.abs(ours_value - theirs).max(initial=0.0) / scale
    if not err <= REL_TOL:
        failures.append(f"{what}: relative error {err:.2e}")
    return err


def main():
    legs, name, mjcf = sys.argv[1:4]
    m = mujoco.MjModel.from_xml_path(mjcf)
    m.opt.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    d = mujoco.MjData(m)
    ir = json.loads((pathlib.Path(__file__).parent.parent / "generated" / "ir" / f"{name}.json").read_text())
    home = np.array(ir["model"]["home"])
    rng = np.random.default_rng(30)
    failures, worst = [], {}
    for trial in range(STATES):
        # Our home pose moved at random, then put on the closures by ours.
        q = home + 0.1 * rng.uniform(-1, 1, len(home))
        qd = rng.uniform(-2, 2, len(home))
        t = ours(legs, name, q, qd, project=True)
        mp = Map(m, t)
        q, qd = np.array(t["q"]), np.array(t["qd"])
        T, Tdot_qd = mp.state(d, q, qd)
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        checks = [
            ("M", t["M"], T.T @ full @ T),
            ("N", t["N"], T.T @ (d.qfrc_bias - d.qfrc_spring + full @ Tdot_qd)),
            ("foot", t["foot"], d.site("foot.point").xpos),
        ]
        rows = len(t["phi"])
        if rows:
            # MuJoCo's connect rows come first among its constraints.
            efc = np.array(d.efc_J).reshape(d.nefc, m.nv)[:rows]
            checks.append(("J", t["J"], efc @ T))
        for key, a, b in checks:
            worst[key] = max(worst.get(key, 0.0), close(f"#{trial} {key}", a, b, failures))
    # MuJoCo's own run from home, motors off: the gap its soft loops leave after 1 s.
    t = ours(legs, name, home, np.zeros_like(home), project=True)
    Map(m, t).state(d, np.array(t["q"]), np.zeros_like(home))
    mujoco.mj_forward(m, d)
    sites = [(m.site(f"{m.equality(i).name}.a").id, m.site(f"{m.equality(i).name}.b").id) for i in range(m.neq)]
    for _ in range(int(round(1.0 / m.opt.timestep))):
        mujoco.mj_step(m, d)
    gap = max((float(np.linalg.norm(d.site_xpos[a] - d.site_xpos[b])) for a, b in sites), default=0.0)
    if not gap <= CLOSURE_TOL:
        failures.append(f"MuJoCo's loops opened {gap:.2e} m in 1 s")
    if failures:
        print(f"{name}: MuJoCo disagrees: " + "; ".join(failures[:5]))
        sys.exit(1)
    figures = ", ".join(f"{k} {v:.1e}" for k, v in worst.items())
    ours_gap = float(np.abs(t["phi"]).max(initial=0.0))
    print(
        f"{name}: MuJoCo agrees at {STATES} assembled states (worst relative difference: {figures}); "
        f"loop gap after 1 s passive from home: MuJoCo {gap:.2e} m, ours at its start {ours_gap:.1e} m"
    )


if __name__ == "__main__":
    main()
