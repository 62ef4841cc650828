"""A simulated second of a standing, pushed floating robot: MuJoCo's time for it, beside
ours measured by criterion in the same run (`cargo xtask bench --mujoco`).

usage: python mujoco_step_bench.py LEGS_BINARY ROBOT MJCF_FILE TRAJECTORY_CSV OUT_JSON

TRAJECTORY_CSV is `legs sim ROBOT --dt DT` (the balance QP closing the loop, the push on
the body): its rows hold the torques and the push of each step. Both simulators replay
them open-loop from its first row's state, so both do the same work per step and the
controller is timed in neither (a motor servo about the recorded motion keeps MuJoCo's
robot on its feet, and ours computes the same): ours with `robot::pushed_stance_step` (criterion,
`ROBOT/second-ours`), MuJoCo here with `mujoco.rollout` (its C++ loop: the state and the
applied forces prepared once, the output preallocated) on the exported MJCF at the same
step, once with the export's integrator (RK4, as ours) and once with MuJoCo's default
(semi-implicit Euler). Each is timed 11 times; the median, the fastest and the slowest
go to OUT_JSON with, for each integrator, the largest loop gap over the second, the
body's largest distance from ours and the contacts MuJoCo found at the last step.
"""

import csv
import json
import pathlib
import statistics
import sys
import time

import mujoco
import mujoco.rollout
import numpy as np

from legs_eval import ours
from mujoco_push import Robot

REPEATS = 11
KP, KD = 200.0, 5.0  # the motor servo's gains, ours' (tests/benches/dynamics.rs)


def main():
    if len(sys.argv) != 6:
        sys.exit(f"usage: {sys.argv[0]} LEGS_BINARY ROBOT MJCF_FILE TRAJECTORY_CSV OUT_JSON")
    legs, name, mjcf, trajectory, out = sys.argv[1:6]
    with open(trajectory) as f:
        rows = list(csv.DictReader(f))
    if len(rows) < 2:
        sys.exit(f"{name}: {trajectory} has {len(rows)} rows")
    header = list(rows[0].keys())
    joints = [h[2:] for h in header if h.startswith("q_")]
    motors = [h[2:] for h in header if h.startswith("u_")]
    col = lambda r, names: np.array([float(r[n]) for n in names])
    dt = float(rows[1]["t"]) - float(rows[0]["t"])
    first = rows[0]
    q0, v0 = col(first, [f"q_{j}" for j in joints]), col(first, [f"v_{j}" for j in joints])
    robot = Robot(mjcf, ours(legs, name, q0, np.zeros(len(q0))))
    m, d = robot.m, robot.d
    m.opt.timestep = dt
    robot.set(col(first, ["body_x", "body_y", "body_z"]), col(first, ["body_qw", "body_qx", "body_qy", "body_qz"]), q0, v0)

    # Open-loop, MuJoCo's robot drifts off its feet within the second (its soft contacts
    # and loops are not ours), so a motor servo about the recorded motion keeps it there,
    # as ours does the same sum (`second-ours`): each motor's actuator made a PD servo
    # (MuJoCo computes it in its step), its reference the recorded position, the
    # recorded torque and the servo's `KD v_recorded` applied on the joint.
    motor_acts = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in motors]
    if min(motor_acts) < 0:
        sys.exit(f"{name}: {mjcf} has no actuator for every motor ({', '.join(motors)})")
    for a in motor_acts:
        m.actuator_gaintype[a] = mujoco.mjtGain.mjGAIN_FIXED
        m.actuator_gainprm[a, 0] = KP
        m.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
        m.actuator_biasprm[a, :3] = [0.0, -KP, -KD]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    initial = np.zeros(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, d, initial, spec)
    # Each step's applied forces: the motors' torques on their joints, the push on the
    # body's centre of mass with its moment about it (as mujoco_push.py applies it).
    control_spec = mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_QFRC_APPLIED | mujoco.mjtState.mjSTATE_XFRC_APPLIED
    motor_dofs = [robot.map.by_name[n].dofadr[0] for n in motors]
    lever = d.xpos[robot.body] - d.xipos[robot.body]
    control = np.zeros((len(rows), m.nu + m.nv + 6 * m.nbody))
    for i, r in enumerate(rows):
        control[i, motor_acts] = col(r, [f"q_{n}" for n in motors])
        control[i, m.nu + np.array(motor_dofs)] = col(r, [f"u_{n}" for n in motors]) + KD * col(r, [f"v_{n}" for n in motors])
        push = col(r, ["push_x", "push_y", "push_z"])
        at = m.nu + m.nv + 6 * robot.body
        control[i, at:at + 3] = push
        control[i, at + 3:at + 6] = np.cross(lever, push)
    states = np.zeros((1, len(rows), len(initial)))

    ours_body = np.array([col(r, ["body_x", "body_y", "body_z"]) for r in rows])
    body_adr = m.jnt_qposadr[m.body_jntadr[robot.body]]
    results = {"robot": name, "dt": dt, "steps": len(rows), "mujoco": mujoco.__version__}
    for label, integrator in (("rk4", mujoco.mjtIntegrator.mjINT_RK4), ("euler", mujoco.mjtIntegrator.mjINT_EULER)):
        m.opt.integrator = integrator
        times = []
        for _ in range(REPEATS):
            start = time.perf_counter()
            mujoco.rollout.rollout(m, d, initial, control, control_spec=control_spec, state=states, nstep=len(rows))
            times.append(time.perf_counter() - start)
        # The replay's physics, read back from its last run: loop gaps and the body.
        gaps, apart = [], 0.0
        for i in range(len(rows)):
            mujoco.mj_setState(m, d, states[0, i], spec)
            mujoco.mj_forward(m, d)
            gaps.append(robot.gap())
            if i + 1 < len(rows):
                apart = max(apart, float(np.linalg.norm(d.qpos[body_adr:body_adr + 3] - ours_body[i + 1])))
        results[label] = {
            "median_s": statistics.median(times),
            "fastest_s": min(times),
            "slowest_s": max(times),
            "largest_gap_m": max(gaps),
            "body_from_ours_m": apart,
            "contacts_at_end": int(d.ncon),
            "finite": bool(np.all(np.isfinite(states))),
        }
        print(f"{name}: MuJoCo {mujoco.__version__} {label}, {len(rows)} steps of {dt * 1e3:g} ms: median {1e3 * statistics.median(times):.2f} ms ({1e3 * min(times):.2f}–{1e3 * max(times):.2f}); largest loop gap {max(gaps):.2e} m; body at most {1e3 * apart:.2f} mm from ours; {d.ncon} contacts at the end")
    pathlib.Path(out).write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
