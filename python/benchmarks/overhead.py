"""Per-call cost of the Python package against the same call in Rust and against
Pinocchio's Python API, side by side in one process (medians of repeated batches).

    .venv/bin/python python/benchmarks/overhead.py [--leg minitaur] [--batches 15]

Every contender gets inputs prepared once (numpy arrays) and returns new arrays, as a
user's Python loop does. Contenders, at one assembled state with rates and torques:

- `legmodels` forward dynamics (`leg.forward_dynamics(q, qd, u)`: M, N, J, J̇q̇ and the
  KKT solve) and mass matrix (`leg.mass_matrix(q)`);
- the same forward dynamics called in Rust (`leg._rust_forward_dynamics_ns`: no Python in
  the loop) — the difference is the Python call's overhead;
- Pinocchio 4.1's Python `pin.constraintDynamics` (closures as CONTACT_3D constraints
  between the `<closure>_a` / `_b` frames of the leg's exported URDF, proximal settings
  as in xtask/pinocchio_derivatives.cpp) and `pin.crba` (mass matrix only). Its q̈ is
  checked equal to ours (1e-8 relative) before timing, so both do the same work.
"""

import argparse
import json
import pathlib
import subprocess
import sys
import timeit
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

import legmodels

ROOT = pathlib.Path(__file__).resolve().parents[2]
DRAKE = "{http://drake.mit.edu}"


def pinocchio_leg(name, leg):
    """Pinocchio's model of the exported URDF, with armature, gravity, and the closures."""
    urdf = ROOT / "target" / "exports" / f"{name}.urdf"
    urdf.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run(["cargo", "xtask", "export", name, "--format", "urdf", "--out", str(urdf)],
                   cwd=ROOT, check=True, capture_output=True)
    model = pin.buildModelFromUrdf(str(urdf))
    for t in ET.parse(urdf).getroot().iter("transmission"):
        act = t.find("actuator")
        rotor = float(act.find(f"{DRAKE}rotor_inertia").get("value"))
        gear = float(act.find(f"{DRAKE}gear_ratio").get("value"))
        model.armature[model.joints[model.getJointId(t.find("joint").get("name"))].idx_v] = rotor * gear * gear
    model.gravity.linear = np.array([leg.get("gravity_x"), leg.get("gravity_y"), 0.0])
    ir = json.loads((ROOT / "generated" / "ir" / f"{name}.json").read_text())
    closures = ir["model"]["closures"]
    cmodels = []
    for c in closures:
        fa = model.frames[model.getFrameId(f"{c}.a")]
        fb = model.frames[model.getFrameId(f"{c}.b")]
        first, second = (fb, fa) if fa.parentJoint == 0 else (fa, fb)
        cmodels.append(pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, first.parentJoint,
                                                first.placement, second.parentJoint, second.placement,
                                                pin.ReferenceFrame.LOCAL_WORLD_ALIGNED))
    joints = ir["model"]["joints"]
    qidx = [model.joints[model.getJointId(j)].idx_q for j in joints]
    vidx = [model.joints[model.getJointId(j)].idx_v for j in joints]
    return model, cmodels, qidx, vidx, ir["model"]["joint_kinds"]


def median_seconds(call, number, batches):
    return float(np.median(timeit.repeat(call, number=number, repeat=batches))) / number


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--leg", default="minitaur", choices=sorted(legmodels.models))
    parser.add_argument("--batches", type=int, default=15)
    parser.add_argument("--number", type=int, default=20000)
    args = parser.parse_args()

    leg = legmodels.models[args.leg]()
    q = leg.assembled_home()
    qd = leg.consistent_velocity(q, np.linspace(0.5, -0.5, leg.nu)) if leg.nu == leg.mobility else np.zeros(leg.nq)
    u = np.linspace(0.1, -0.1, leg.nu)
    damping = np.array([leg.get(f"{j}_damping") if f"{j}_damping" in leg.parameter_names else 0.0 for j in leg.joint_names])
    if np.any(damping):
        sys.exit(f"{args.leg}: joint damping is not modelled in the Pinocchio peer; pick a leg without it")

    model, cmodels, qidx, vidx, kinds = pinocchio_leg(args.leg, leg)
    data = model.createData()
    # Pinocchio's Python API takes its own std::vector types, converted once here.
    cm = pin.StdVec_RigidConstraintModel()
    cd = pin.StdVec_RigidConstraintData()
    for c in cmodels:
        cm.append(c)
        cd.append(c.createData())
    cmodels, cdatas = cm, cd
    pin.initConstraintDynamics(model, data, cmodels, cdatas)
    settings = pin.ProximalSettings(1e-14, 1e-8, 20)
    qp = pin.neutral(model)
    for k, a, kind in zip(qidx, q, kinds):
        if kind == "prismatic":
            qp[k] = a
        else:
            qp[k], qp[k + 1] = np.cos(a), np.sin(a)
    vp = np.zeros(model.nv)
    vp[vidx] = qd
    tau = np.zeros(model.nv)
    for k, i in enumerate(leg.actuated):
        tau[vidx[i]] = u[k]

    ours, _ = leg.forward_dynamics(q, qd, u)
    theirs = pin.constraintDynamics(model, data, qp, vp, tau, cmodels, cdatas, settings)[vidx]
    err = np.abs(ours - theirs).max() / np.abs(ours).max()
    if err > 1e-8:
        sys.exit(f"{args.leg}: Pinocchio's q̈ differs from ours by {err:.1e} (relative); not timing different work")

    n, b = args.number, args.batches
    rows = [
        ("legmodels forward_dynamics (Python)", median_seconds(lambda: leg.forward_dynamics(q, qd, u), n, b)),
        ("forward dynamics in Rust (same build)", float(np.median([leg._rust_forward_dynamics_ns(q, qd, u, 10 * n) for _ in range(b)])) * 1e-9),
        ("pin.constraintDynamics (Python)", median_seconds(lambda: pin.constraintDynamics(model, data, qp, vp, tau, cmodels, cdatas, settings), n, b)),
        ("legmodels mass_matrix (Python)", median_seconds(lambda: leg.mass_matrix(q), n, b)),
        ("pin.crba (Python)", median_seconds(lambda: pin.crba(model, data, qp), n, b)),
    ]
    print(f"{args.leg}: q̈ equal to Pinocchio's to {err:.1e}; median per call of {b} batches of {n}")
    print(f"{'call':42} {'ns':>9}  vs ours (Python)")
    ref = rows[0][1]
    for label, s in rows:
        print(f"{label:42} {s * 1e9:9.0f}  {s / ref:6.2f}×")
    print(f"Python call overhead: {(rows[0][1] - rows[1][1]) * 1e9:.0f} ns per forward dynamics call")


if __name__ == "__main__":
    main()
