"""PyBullet's own Minitaur standing and pushed, beside ours: the figures of
docs/figures.md ("PyBullet's own Minitaur"), run by hand.

usage: .venv/bin/pip install -r xtask/requirements-pybullet.txt
       .venv/bin/python xtask/pybullet_minitaur.py [LEGS_BINARY]

PyBullet: the `pybullet` wheel's `pybullet_data/quadruped/minitaur.urdf` on its plane, set
up by the wheel's own `pybullet_envs/bullet/minitaur.py` (`Minitaur`, its defaults: the
knees' point-to-point constraints, the motors held at their standing angles by PyBullet's
position control), as its gym environment steps it (300 solver iterations), at its
environment's step (10 ms) and at 1 ms. Standing 2 s; pushed on the base from 0.5 s for
0.1 s by 5 % of its weight sideways (+y), as `legs sim minitaur_quadruped` pushes ours.
Prints the largest gap of a knee constraint's two points, the body's largest sideways
excursion and its offset at the end, and the toes' normal forces beside the weight.
With LEGS_BINARY, ours (`legs sim minitaur_quadruped --duration 2`) is printed beside.
"""

import csv
import importlib
import pathlib
import subprocess
import sys
import tempfile
import types

import numpy as np
import pybullet
import pybullet_data

DURATION = 2.0
PUSH_AT, PUSH_FOR, PUSH_SHARE = 0.5, 0.1, 0.05


def load_minitaur_class():
    folder = pathlib.Path(pybullet.__file__).parent / "pybullet_envs" / "bullet"
    if not folder.is_dir():
        spec = importlib.util.find_spec("pybullet_envs")
        folder = pathlib.Path(spec.submodule_search_locations[0]) / "bullet"
    package = types.ModuleType("pb_bullet")
    package.__path__ = [str(folder)]
    sys.modules["pb_bullet"] = package
    return importlib.import_module("pb_bullet.minitaur").Minitaur


def run(dt):
    client = pybullet
    client.resetSimulation()
    client.setPhysicsEngineParameter(numSolverIterations=300)
    client.setTimeStep(dt)
    client.setGravity(0, 0, -9.81)
    plane = client.loadURDF(str(pathlib.Path(pybullet_data.getDataPath()) / "plane.urdf"))
    robot = load_minitaur_class()(pybullet_client=client, urdf_root=pybullet_data.getDataPath(), time_step=dt)
    q = robot.quadruped
    mass = sum(client.getDynamicsInfo(q, link)[0] for link in range(-1, client.getNumJoints(q)))
    weight = 9.81 * mass
    push = np.array([0.0, PUSH_SHARE * weight, 0.0])
    constraints = [client.getConstraintUniqueId(i) for i in range(client.getNumConstraints())]

    def gap():
        worst = 0.0
        for c in constraints:
            info = client.getConstraintInfo(c)
            points = []
            for body, link, pivot in ((info[0], info[1], info[6]), (info[2], info[3], info[7])):
                state = client.getLinkState(body, link, computeForwardKinematics=True)
                points.append(np.array(state[0]) + np.array(client.getMatrixFromQuaternion(state[1])).reshape(3, 3) @ np.array(pivot))
            worst = max(worst, float(np.linalg.norm(points[0] - points[1])))
        return worst

    steps = int(round(DURATION / dt))
    first, count = int(round(PUSH_AT / dt)), int(round(PUSH_FOR / dt))
    start = None
    gaps, side, loads = [], [], None
    for i in range(steps):
        if i in range(first, first + count):
            position = client.getBasePositionAndOrientation(q)[0]
            client.applyExternalForce(q, -1, push.tolist(), position, client.WORLD_FRAME)
        client.stepSimulation()
        position = np.array(client.getBasePositionAndOrientation(q)[0])
        if i + 1 == first:
            # Settled, just before the push: where it stands, and what its toes carry.
            start = position
            loads = sum(c[9] for c in client.getContactPoints(bodyA=q, bodyB=plane))
        gaps.append(gap())
        side.append(position[1])
    end = np.array(client.getBasePositionAndOrientation(q)[0])
    return {
        "weight": weight,
        "push": push[1],
        "gap": max(gaps),
        "gap_end": gaps[-1],
        "excursion": max(abs(s - start[1]) for s in side),
        "end": float(np.linalg.norm(end - start)),
        "carried": loads,
    }


def main():
    pybullet.connect(pybullet.DIRECT)
    for dt in (0.01, 0.001):
        r = run(dt)
        print(f"PyBullet's Minitaur at {1e3 * dt:g} ms: weight {r['weight']:.3f} N, pushed {r['push']:.3f} N; largest knee gap {1e3 * r['gap']:.3f} mm ({1e3 * r['gap_end']:.3f} mm at 2 s); body sideways at most {1e3 * r['excursion']:.3f} mm from where it stood before the push, {1e3 * r['end']:.3f} mm from it at the end; toes carry {r['carried']:.3f} N before the push")
    if len(sys.argv) > 1:
        with tempfile.TemporaryDirectory() as out:
            done = subprocess.run([sys.argv[1], "sim", "minitaur_quadruped", "--duration", str(DURATION), "--out", out], capture_output=True, text=True)
            if done.returncode != 0:
                sys.exit(f"legs sim failed: {done.stderr.strip()}")
            rows = list(csv.DictReader(open(pathlib.Path(out) / "trajectory.csv")))
        y = np.array([float(r["body_y"]) for r in rows])
        gap = max(float(r["closure_residual"]) for r in rows)
        carried = sum(float(rows[0][k]) for k in rows[0] if k.startswith("F_") and k.endswith("_z"))
        print(f"ours (legs sim minitaur_quadruped, 1 ms RK4, the balance QP): largest closure residual {gap:.1e} m; body sideways at most {1e3 * float(np.abs(y - y[0]).max()):.3f} mm, {1e3 * abs(float(y[-1] - y[0])):.4f} mm at the end; toes carry {carried:.3f} N at rest")


if __name__ == "__main__":
    main()
