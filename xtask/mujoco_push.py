"""A floating robot standing under our balance QP and pushed, ours beside MuJoCo; run by
`cargo xtask test` for every floating robot that can stand.

usage: python mujoco_push.py LEGS_BINARY ROBOT MJCF_FILE OUT_DIR [FX,FY,FZ]

Ours: `legs sim ROBOT --duration 2` (the default push, 5 % of the weight sideways, or
`--push FX,FY,FZ` where given; from 0.5 s for 0.1 s; RK4 at 1 ms, every contact held, the loops closed exactly).

MuJoCo: the robot's exported MJCF (its toes small spheres on a floor plane, its loops
`connect` equalities; soft contacts and soft loops), at our time step (1 ms, RK4), from
our first row's state. The same controller closes the loop: each step MuJoCo's state goes
to `legs sim ROBOT --serve` (the balance QP holding where ours stands, the state put on
the closures first, as the controller's model holds them), and its torques go back on
the motor joints; the same push acts on the body frame's origin over the same steps
(`xfrc_applied` at the body's centre of mass with the push's moment about it).

Prints, for each: the body's largest sideways excursion and where it ends, the largest
loop gap (ours from trajectory.csv; MuJoCo's: the largest distance between a `connect`
equality's two points; a rod's tendon equality is not measured), and each toe's normal force just before the push beside ours;
and how far MuJoCo's body went from ours. Exits 1 where ours leaves a gap above 1e-12 m,
MuJoCo's run is not finite, MuJoCo's body strays more than 2 cm from ours, or its toes
carry other than the robot's weight (to 2 %) before the push. A robot that cannot stand
(fewer than three contact points) is said not applicable and passes. Where ours stops
because a held foot would slip or lift (`sim` holds every contact), the two are compared
until then, and the stop is printed.
"""

import csv
import pathlib
import subprocess
import sys

import mujoco
import numpy as np

from legs_eval import ours
from mujoco_spatial_check import Map, ball_quaternion, rate_map

DURATION = 2.0
OURS_TOL = 1e-12
APART_TOL = 0.02  # m: MuJoCo's body from ours
WEIGHT_TOL = 0.02  # of the weight: MuJoCo's toes' load before the push
ANSWER_SHARE = 0.25  # MuJoCo's largest excursion along the push against ours
ANSWER_TOL = 1e-3  # m: the two bodies' answers to the push, each from where it stood


def quat_matrix(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def ball_angles(q):
    """(α, β, γ) with R = R_x(α) R_y(β) R_z(γ) the rotation of the unit quaternion `q`."""
    r = quat_matrix(q)
    return np.array([np.arctan2(-r[1, 2], r[2, 2]), np.arcsin(np.clip(r[0, 2], -1, 1)), np.arctan2(-r[0, 1], r[0, 0])])


class Robot:
    """MuJoCo's model with our coordinates mapped onto it (`Map`, by joint name)."""

    def __init__(self, mjcf, t):
        self.m = mujoco.MjModel.from_xml_path(str(mjcf))
        self.m.opt.timestep = 1e-3
        self.d = mujoco.MjData(self.m)
        self.map = Map(self.m, t)
        self.n = len(t["joints"])
        self.free = t["free_joint"]
        body = self.map.by_name[t["joints"][self.free].rsplit(".", 1)[0]]
        self.body = self.m.jnt_bodyid[body.id]

    def set(self, pos, quat, q, v):
        """MuJoCo's state from ours: the body's pose in the world, the chart's q (centred)
        and v (the body's velocity in its own frame, then the joints' rates)."""
        d = self.d
        for i, k, j in self.map.groups():
            qa, va = j.qposadr[0], j.dofadr[0]
            if k == 6:
                d.qpos[qa:qa + 3] = pos
                d.qpos[qa + 3:qa + 7] = quat
                d.qvel[va:va + 3] = quat_matrix(quat) @ v[i:i + 3]
                d.qvel[va + 3:va + 6] = v[i + 3:i + 6]
            elif k == 3:
                a, b, g = q[i:i + 3]
                d.qpos[qa:qa + 4] = ball_quaternion(a, b, g)
                d.qvel[va:va + 3] = rate_map(b, g)[0] @ v[i:i + 3]
            else:
                d.qpos[qa] = q[i]
                d.qvel[va] = v[i]
        mujoco.mj_forward(self.m, d)

    def state(self):
        """Ours from MuJoCo's: position, quaternion, the chart's q (centred), v."""
        d = self.d
        q, v = np.zeros(self.n), np.zeros(self.n)
        pos = quat = None
        for i, k, j in self.map.groups():
            qa, va = j.qposadr[0], j.dofadr[0]
            if k == 6:
                pos, quat = d.qpos[qa:qa + 3].copy(), d.qpos[qa + 3:qa + 7].copy()
                v[i:i + 3] = quat_matrix(quat).T @ d.qvel[va:va + 3]
                v[i + 3:i + 6] = d.qvel[va + 3:va + 6]
            elif k == 3:
                q[i:i + 3] = ball_angles(d.qpos[qa:qa + 4])
                v[i:i + 3] = np.linalg.solve(rate_map(q[i + 1], q[i + 2])[0], d.qvel[va:va + 3])
            else:
                q[i] = d.qpos[qa]
                v[i] = d.qvel[va]
        return pos, quat, q, v

    def gap(self):
        """The largest distance between a `connect` equality's two points (m)."""
        m, d = self.m, self.d
        worst = 0.0
        for e in range(m.neq):
            if m.eq_type[e] != mujoco.mjtEq.mjEQ_CONNECT:
                continue
            o1, o2 = m.eq_obj1id[e], m.eq_obj2id[e]
            if m.eq_objtype[e] == mujoco.mjtObj.mjOBJ_SITE:
                # Two sites (the export's): the points are the sites.
                a, b = d.site_xpos[o1], d.site_xpos[o2]
            else:
                # Two bodies (a file's `body1`/`body2`): anchors in each body's frame.
                a = d.xpos[o1] + d.xmat[o1].reshape(3, 3) @ m.eq_data[e, 0:3]
                b = d.xpos[o2] + d.xmat[o2].reshape(3, 3) @ m.eq_data[e, 3:6]
            worst = max(worst, float(np.linalg.norm(a - b)))
        return worst

    def normal_forces(self, contacts):
        """Each contact point's normal force (N): the contacts of its sphere `NAME.geom`."""
        m, d = self.m, self.d
        out = dict.fromkeys(contacts, 0.0)
        f = np.zeros(6)
        for c in range(d.ncon):
            for g in (d.contact[c].geom1, d.contact[c].geom2):
                name = m.geom(g).name
                if name.endswith(".geom") and name[:-5] in out:
                    mujoco.mj_contactForce(m, d, c, f)
                    out[name[:-5]] += f[0]
        return out


def main():
    if len(sys.argv) not in (5, 6):
        sys.exit(f"usage: {sys.argv[0]} LEGS_BINARY ROBOT MJCF_FILE OUT_DIR [FX,FY,FZ]")
    legs, name, mjcf, out = sys.argv[1], sys.argv[2], sys.argv[3], pathlib.Path(sys.argv[4])
    push = ["--push", sys.argv[5]] if len(sys.argv) == 6 else []
    run = subprocess.run([legs, "sim", name, "--duration", str(DURATION), "--out", str(out), *push], capture_output=True, text=True)
    if "fewer than three contact points" in run.stderr:
        print(f"{name}: not applicable ({run.stderr.strip().removeprefix('error: ')})")
        return
    stopped = None
    if run.returncode != 0:
        if "the simulation stopped" not in run.stderr:
            sys.exit(f"{name}: legs sim failed: {run.stderr.strip()}")
        # Ours holds every contact: where a foot would slip or lift it stops, and the
        # scenes are compared up to there.
        stopped = run.stderr.strip().removeprefix("error: ")
    with open(out / "trajectory.csv") as f:
        rows = list(csv.DictReader(f))
    if len(rows) < 2:
        sys.exit(f"{name}: ours has {len(rows)} rows: {stopped}")
    header = list(rows[0].keys())
    joints = [h[2:] for h in header if h.startswith("q_")]
    motors = [h[2:] for h in header if h.startswith("u_")]
    contacts = [h[2:-2] for h in header if h.startswith("F_") and h.endswith("_z")]
    col = lambda r, names: np.array([float(r[n]) for n in names])
    body = lambda r: col(r, ["body_x", "body_y", "body_z"])
    pushes = [col(r, ["push_x", "push_y", "push_z"]) for r in rows]
    first = rows[0]
    q0, v0 = col(first, [f"q_{j}" for j in joints]), col(first, [f"v_{j}" for j in joints])
    t = ours(legs, name, q0, np.zeros(len(q0)))
    robot = Robot(mjcf, t)
    robot.set(body(first), col(first, ["body_qw", "body_qx", "body_qy", "body_qz"]), q0, v0)
    motor_dofs = [robot.map.by_name[mname].dofadr[0] for mname in motors]

    server = subprocess.Popen([legs, "sim", name, "--serve"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    m, d = robot.m, robot.d
    theirs, gaps, before_push = [], [], None
    pushed = [i for i, p in enumerate(pushes) if np.any(p)]
    if not pushed:
        sys.exit(f"{name}: ours stopped before the push: {stopped}")
    push_start = pushed[0]
    try:
        for i in range(len(rows)):
            pos, quat, q, v = robot.state()
            line = " ".join(repr(float(x)) for x in [*pos, *quat, *q, *v])
            server.stdin.write(line + "\n")
            server.stdin.flush()
            answer = server.stdout.readline().strip()
            if answer.startswith("error") or not answer:
                sys.exit(f"{name}: the balance QP on MuJoCo's state at t = {d.time:.3f} s: {answer or 'no answer'}")
            d.qfrc_applied[:] = 0.0
            d.qfrc_applied[motor_dofs] = [float(x) for x in answer.split()]
            d.xfrc_applied[:] = 0.0
            push = pushes[i]
            d.xfrc_applied[robot.body, 0:3] = push
            d.xfrc_applied[robot.body, 3:6] = np.cross(d.xpos[robot.body] - d.xipos[robot.body], push)
            if i == push_start:
                before_push = robot.normal_forces(contacts)
            mujoco.mj_step(m, d)
            theirs.append(d.qpos[robot.map.by_name[t["joints"][robot.free].rsplit(".", 1)[0]].qposadr[0]:][:3].copy())
            gaps.append(robot.gap())
    finally:
        server.stdin.close()
        server.wait()

    failures = []
    # MuJoCo resets a diverging state to qpos0 (finite) and counts a warning.
    if not np.all(np.isfinite(d.qpos)) or d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
        sys.exit(f"{name}: MuJoCo's run diverged")
    ours_body = np.array([body(r) for r in rows])
    # Ours after each step: the next row's start (the last step's end is not a row).
    ours_after = ours_body[1:]
    theirs = np.array(theirs)
    apart = float(np.abs(theirs[:-1] - ours_after).max())
    side = pushes[push_start] / np.linalg.norm(pushes[push_start])
    # Each body's answer to the push, from where each stood at its start (MuJoCo's has
    # settled into its soft contacts by then): after step i, from step push_start on.
    ours_answer = ours_after[push_start:] - ours_body[push_start]
    theirs_answer = theirs[push_start:len(ours_after)] - theirs[push_start - 1]
    answer_apart = float(np.abs(theirs_answer - ours_answer).max(initial=0.0))
    ours_most = float((ours_answer @ side).max(initial=0.0))
    theirs_most = float((theirs_answer @ side).max(initial=0.0))
    whole_push = len(rows) > pushed[-1] + 1 and not stopped
    start = ours_body[0]
    ours_gap = max(float(r["closure_residual"]) for r in rows)
    weight = sum(float(first[f"F_{c}_z"]) for c in contacts)
    print(f"{name}: pushed {np.linalg.norm(pushes[push_start]):.3g} N from {push_start / 1000:.3f} s for {sum(1 for p in pushes if np.any(p))} steps; 1 ms steps, RK4, the balance QP closing both loops")
    print(f"  body along the push, largest: ours {1e3 * float(((ours_body - start) @ side).max()):.3f} mm, MuJoCo {1e3 * float(((theirs - start) @ side).max()):.3f} mm; at the end: ours {1e3 * float(np.linalg.norm(ours_body[-1] - start)):.4f} mm, MuJoCo {1e3 * float(np.linalg.norm(theirs[-1] - start)):.4f} mm from where ours stood (MuJoCo's {1e3 * float(np.linalg.norm(theirs[push_start - 1] - start)):.4f} mm just before the push: its soft contacts and loops settled); MuJoCo's body from ours at most {1e3 * apart:.3f} mm")
    print(f"  the push's answer, each from where it stood: along the push at most ours {1e3 * ours_most:.3f} mm, MuJoCo {1e3 * theirs_most:.3f} mm; the two answers at most {1e3 * answer_apart:.3f} mm apart")
    rods = sum(1 for e in range(m.neq) if m.eq_type[e] == mujoco.mjtEq.mjEQ_TENDON)
    print(f"  largest loop gap: ours {ours_gap:.1e} m, MuJoCo {max(gaps):.2e} m" + (f" (its {rods} rods' tendon equalities not measured)" if rods else ""))
    if stopped:
        print(f"  ours: {stopped}; compared until then")
    # Ours over the step before the push (the pushed step's forces carry the push).
    ours_before = {c: float(rows[push_start - 1][f"F_{c}_z"]) for c in contacts}
    print("  normal forces just before the push (N), ours / MuJoCo: " + ", ".join(f"{c} {ours_before[c]:.2f} / {before_push[c]:.2f}" for c in contacts))
    if ours_gap > OURS_TOL:
        failures.append(f"our loop gap {ours_gap:.1e} m is above {OURS_TOL:.0e} m")
    if not apart <= APART_TOL:
        failures.append(f"MuJoCo's body strays {apart:.3f} m from ours")
    if whole_push and not abs(theirs_most - ours_most) <= ANSWER_SHARE * ours_most:
        failures.append(f"MuJoCo's body goes {1e3 * theirs_most:.3f} mm along the push, ours {1e3 * ours_most:.3f} mm")
    if whole_push and not answer_apart <= ANSWER_TOL:
        failures.append(f"the two bodies' answers to the push are {1e3 * answer_apart:.3f} mm apart")
    carried = sum(before_push.values())
    if not abs(carried - weight) <= WEIGHT_TOL * weight:
        failures.append(f"MuJoCo's toes carry {carried:.3f} N before the push, the weight is {weight:.3f} N")
    if failures:
        sys.exit(f"{name}: " + "; ".join(failures))


if __name__ == "__main__":
    main()
