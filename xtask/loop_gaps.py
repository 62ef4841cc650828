"""Loop gaps over 1 s on an imported spatial leg: ours beside MuJoCo's on the file the leg
came from and beside Pinocchio's regularized `constraintDynamics` on our URDF. Run by
`cargo xtask test` where the source file is present (Menagerie's `cassie.xml` for
`cassie_leg`).

usage: python loop_gaps.py LEGS_BINARY MODEL SOURCE_MJCF URDF_FILE OUT_DIR

Two runs of 1 s each, the base held (MuJoCo's free joint removed, its body welded where
the file writes it; joint limits and contacts off, as our leg has neither), each
simulator at its own step:
- passive: the motors off, from the file's keyframe named in the spec's header
  (`--keyframe`). Ours (`legs sim --controller passive`, RK4 at 1 ms with projection) starts
  from it put on the closures; MuJoCo (the file's `timestep`) once from the keyframe as the
  file writes it (its loops as open as the file leaves them) and once from our closed start;
  Pinocchio (`constraintDynamics`, CONTACT_3D per closure, μ = 1e-8, 100 iterations,
  semi-implicit Euler at MuJoCo's step, its default of no Baumgarte correction) from our
  closed start.
- tracking: ours under `sim`'s default controller for the leg; MuJoCo and Pinocchio are
  given our motor torques sample by sample (open loop, each held for our 1 ms), from our
  closed start; how far MuJoCo's motor joints drift from ours is printed too.

Prints the largest gap of any closure point over each run, in m; exits 1 if ours exceeds
1e-12 m, or if either peer's run is not finite.
"""

import csv
import json
import pathlib
import subprocess
import sys

import mujoco
import numpy as np
import pinocchio as pin

from legs_eval import ours
from mujoco_spatial_check import Map, load
from urdf_check import pinocchio_leg

DURATION = 1.0
OURS_TOL = 1e-12


def sim(legs, name, out, *extra):
    """Our run: the samples of trajectory.csv as columns, and summary.json."""
    run = subprocess.run([legs, "sim", name, "--duration", str(DURATION), "--out", str(out), *extra],
                         capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"{name}: legs sim failed: {run.stderr.strip()}")
    with open(out / "trajectory.csv") as f:
        rows = list(csv.DictReader(f))
    summary = json.loads((out / "summary.json").read_text())
    return rows, summary


def column(rows, prefix, names):
    return np.array([[float(r[f"{prefix}{n}"]) for n in names] for r in rows])


class MuJoCoRun:
    """MuJoCo on the source file, the free body held at its pose as written, the gap the
    leg's own `connect` rows leave (those that touch only its joints)."""

    def __init__(self, mjcf):
        self.m, self.base = load(mjcf)
        self.d = mujoco.MjData(self.m)

    def start(self, t, key=None):
        m, d = self.m, self.d
        if key is None:
            mujoco.mj_resetData(m, d)
        else:
            mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, key))
        self.map = Map(m, t, self.base)
        if key is None:
            self.map.state(d, np.array(t["q"]), np.zeros(len(t["q"])))
        mujoco.mj_forward(m, d)
        dofs = set(self.map.dofs())
        self.eqs = []
        for e in range(m.neq):
            b1, b2 = m.eq_obj1id[e], m.eq_obj2id[e]
            # The leg's `connect`s: both bodies moved only by its joints (a body-anchored
            # point pair, what `gap` measures).
            if m.eq_type[e] != mujoco.mjtEq.mjEQ_CONNECT or m.eq_objtype[e] != mujoco.mjtObj.mjOBJ_BODY:
                continue
            if all(self.moved_by_leg(b, dofs) for b in (b1, b2)):
                self.eqs.append(e)
        return self.gap()

    def moved_by_leg(self, body, dofs):
        """Whether only the leg's joints move `body` (and at least one does)."""
        m = self.m
        touched = False
        while body > 0:
            for j in range(m.body_jntadr[body], m.body_jntadr[body] + m.body_jntnum[body]):
                if m.jnt_dofadr[j] not in dofs:
                    return False
                touched = True
            body = m.body_parentid[body]
        return touched

    def gap(self):
        m, d = self.m, self.d
        worst = 0.0
        for e in self.eqs:
            a = d.xpos[m.eq_obj1id[e]] + d.xmat[m.eq_obj1id[e]].reshape(3, 3) @ m.eq_data[e, 0:3]
            b = d.xpos[m.eq_obj2id[e]] + d.xmat[m.eq_obj2id[e]].reshape(3, 3) @ m.eq_data[e, 3:6]
            worst = max(worst, float(np.linalg.norm(a - b)))
        return worst

    def run(self, torques=None, follow=None):
        """1 s; `torques(t)` gives the generalized forces on our coordinates (0 if None).
        `follow = (times, joints, q)`: our run's values of those hinge joints at its
        samples, and the largest difference of MuJoCo's from them is returned too."""
        m, d = self.m, self.d
        dofs = self.map.dofs()
        worst, apart = self.gap(), 0.0
        if follow is not None:
            times, joints, q_ours = follow
            adr = [self.map.by_name[j].qposadr[0] for j in joints]
        for step in range(int(round(DURATION / m.opt.timestep))):
            d.qfrc_applied[:] = 0.0
            if torques is not None:
                d.qfrc_applied[dofs] = torques(step * m.opt.timestep)
            mujoco.mj_step(m, d)
            worst = max(worst, self.gap())
            if follow is not None:
                k = int(round(d.time / (times[1] - times[0])))
                if k < len(times) and abs(times[k] - d.time) < 1e-9:
                    apart = max(apart, float(np.abs(d.qpos[adr] - q_ours[k]).max()))
        if not np.all(np.isfinite(d.qpos)):
            return float("nan"), apart
        return worst, apart


def pinocchio_run(leg, ir, q0, dt, torques=None):
    """Semi-implicit Euler on Pinocchio's `constraintDynamics` (μ = 1e-8, 100 iterations);
    `torques(t)` gives our motor torques (motors off if None). The largest gap between
    each closure's frames `<c>.a` and `<c>.b`."""
    model = leg.model
    data = model.createData()
    cm, cd = leg.constraints(data)
    settings = pin.ProximalSettings(1e-12, 1e-8, 100)
    frames = [(model.getFrameId(f"{c}.a"), model.getFrameId(f"{c}.b")) for c in ir["model"]["closures"]]
    qp, vp = leg.configuration(q0), np.zeros(model.nv)
    nu = len(ir["model"]["actuated"])
    # Our angles beside Pinocchio's (cos, sin) pairs, for the springs in τ: each moves by
    # dt v, as pin.integrate moves a revolute joint.
    q = np.array(q0, float)

    def gap():
        pin.framesForwardKinematics(model, data, qp)
        return max(float(np.linalg.norm(data.oMf[a].translation - data.oMf[b].translation)) for a, b in frames)

    worst = gap()
    for step in range(int(round(DURATION / dt))):
        u = np.zeros(nu) if torques is None else torques(step * dt)
        tau = leg.torques(q, vp[leg.idx], u)
        a = pin.constraintDynamics(model, data, qp, vp, tau, cm, cd, settings)
        vp = vp + dt * a
        qp = pin.integrate(model, qp, dt * vp)
        q = q + dt * vp[leg.idx]
        if not np.all(np.isfinite(qp)):
            return float("nan")
        worst = max(worst, gap())
    return worst


def main():
    legs, name, mjcf, urdf, out = sys.argv[1:6]
    out = pathlib.Path(out)
    root = pathlib.Path(__file__).parent.parent
    ir = json.loads((root / "generated" / "ir" / f"{name}.json").read_text())
    header = (root / "leg-models" / "specs" / f"{name}.toml").read_text().splitlines()[0]
    words = header.split()
    key = words[words.index("--keyframe") + 1].rstrip("`") if "--keyframe" in words else None
    joints, actuated = ir["model"]["joints"], ir["model"]["actuated"]

    passive, passive_summary = sim(legs, name, out / "passive", "--controller", "passive")
    tracking, tracking_summary = sim(legs, name, out / "tracking")
    motor_names = [joints[a] for a in actuated]
    u_track = column(tracking, "u_", motor_names)
    times = np.array([float(r["t"]) for r in tracking])

    def held(t):
        return u_track[min(int(np.searchsorted(times, t + 1e-12, side="right")) - 1, len(u_track) - 1)]

    # Our starts (the keyframe put on the closures), with the joints' names and kinds.
    start = ours(legs, name, [float(passive[0][f"q_{j}"]) for j in joints], [0.0] * len(joints))
    figures, failures = {}, []
    figures["ours passive"] = passive_summary["max_closure_residual_m"]
    figures["ours tracking"] = tracking_summary["max_closure_residual_m"]
    for k in ("ours passive", "ours tracking"):
        if not figures[k] <= OURS_TOL:
            failures.append(f"{k}: our loops opened {figures[k]:.1e} m")

    mj = MuJoCoRun(mjcf)
    if key is not None:
        at_key = mj.start(start, key)
        figures[f"MuJoCo passive from `{key}` (open {at_key:.2e} m there)"] = mj.run()[0]
    mj.start(start)
    figures["MuJoCo passive from our start"] = mj.run()[0]
    tracking_start = ours(legs, name, [float(tracking[0][f"q_{j}"]) for j in joints], [0.0] * len(joints))
    mj.start(tracking_start)

    def mj_torques(t):
        # Motors act on hinges and slides, where MuJoCo's dof is our coordinate; a ball
        # joint's three entries stay zero.
        tau = np.zeros(len(joints))
        tau[actuated] = held(t)
        return tau
    motors = column(tracking, "q_", motor_names)
    gap, apart = mj.run(mj_torques, (times, motor_names, motors))
    figures["MuJoCo tracking, our torques"] = gap

    leg = pinocchio_leg(urdf, ir)
    dt = mj.m.opt.timestep
    figures["Pinocchio passive from our start"] = pinocchio_run(leg, ir, np.array(start["q"]), dt)
    figures["Pinocchio tracking, our torques"] = pinocchio_run(leg, ir, np.array(tracking_start["q"]), dt, held)
    for k, v in figures.items():
        if not np.isfinite(v):
            failures.append(f"{k}: the run is not finite")
    print(f"{name}: largest loop gap over {DURATION:g} s (m): " + "; ".join(f"{k} {v:.2e}" for k, v in figures.items()))
    print(f"{name}: under our torques, MuJoCo's motor joints stay within {apart:.2e} rad of ours over the run")
    if failures:
        print(f"{name}: " + "; ".join(failures))
        sys.exit(1)


if __name__ == "__main__":
    main()
