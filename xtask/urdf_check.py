"""Cross-check of the exported URDF with Pinocchio, run by `cargo xtask test`.

usage: python urdf_check.py LEGS_BINARY MODEL URDF_FILE [FLOATING_URDF_FILE]

Loads the URDF (planar or spatial) with Pinocchio's parser (urdfdom), sets the joint
armature from the transmissions' `<drake:rotor_inertia>` and `<drake:gear_ratio>` and
gravity from the spec,
then for random states compares Pinocchio's mass matrix (`crba`) and bias forces (`rnea`
with zero acceleration) with the generated model's `M` and `N` (from `legs eval --json`),
and its `foot.point` frame with our foot; at an assembled pose, the frames `<closure>.a` and
`<closure>.b` must coincide (a rod's stay its length apart). On a spatial leg without rods,
Pinocchio's `constraintDynamics` against our forward dynamics too (see
`constraint_dynamics`). A floating robot's second URDF, its body the root link
(`export::spatial::urdf_floating`), is loaded on Pinocchio's own free joint
(`JointModelFreeFlyer`) and its `constraintDynamics` compared with our body's velocity
derivative (see `free_flyer`). Prints one line per model; exits 1 on a mismatch.
"""

import json
import pathlib
import sys
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import numpy as np
import pinocchio as pin

from legs_eval import ours

STATES = 20
REL_TOL = 1e-9
DRAKE = "{http://drake.mit.edu}"


def worse(a, b):
    """The larger of two errors, NaN counted as infinitely large (Python's `max` keeps
    the first of a NaN and a number, so a NaN would pass)."""
    return max(a, b) if np.isfinite(b) else np.inf


def closure_constraints(model, data, ir, held=None):
    """The closures as 3-D point constraints (CONTACT_3D between the frames `<c>.a`
    and `<c>.b`), initialised on `data`. A revolute closure, which Pinocchio has no
    5-D constraint for (pinocchio#2729), is two: at its point and at the frames
    `<c>.a.axis`, `<c>.b.axis` along its axes (six rows, one implied: a hinge). With
    `held` (a configuration), every contact point `<c>.point` held to the world where it
    is there, one more each."""
    cm, cd = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
    revolute = ir["model"].get("revolute_closures", [])
    pairs = []
    for k, c in enumerate(ir["model"]["closures"]):
        pairs.append((f"{c}.a", f"{c}.b"))
        if k in revolute:
            pairs.append((f"{c}.a.axis", f"{c}.b.axis"))
    for a, b in pairs:
        fa = model.frames[model.getFrameId(a)]
        fb = model.frames[model.getFrameId(b)]
        first, second = (fb, fa) if fa.parentJoint == 0 else (fa, fb)
        cm.append(pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, first.parentJoint, first.placement,
                                           second.parentJoint, second.placement, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED))
    if held is not None:
        pin.framesForwardKinematics(model, data, held)
        for c in ir["model"]["contacts"]:
            i = model.getFrameId(f"{c}.point")
            f = model.frames[i]
            cm.append(pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, f.parentJoint, f.placement,
                                               0, data.oMf[i], pin.ReferenceFrame.LOCAL_WORLD_ALIGNED))
    for m in cm:
        cd.append(m.createData())
    pin.initConstraintDynamics(model, data, cm, cd)
    return cm, cd


def pinocchio_leg(urdf, ir):
    """Pinocchio's model of an exported URDF, set up as ours: gravity from the spec, the
    joint armature from the transmissions' `<drake:rotor_inertia>` and `<drake:gear_ratio>`,
    and the maps between our coordinates and Pinocchio's (also used by loop_gaps.py)."""
    model = pin.buildModelFromUrdf(urdf)
    params = {p["name"]: p["default"] for p in ir["model"]["params"]}
    model.gravity.linear = np.array([params["gravity_x"], params["gravity_y"], params.get("gravity_z", 0.0)])
    for t in ET.parse(urdf).getroot().iter("transmission"):
        joint = t.find("joint").get("name")
        act = t.find("actuator")
        rotor = float(act.find(f"{DRAKE}rotor_inertia").get("value"))
        gear = float(act.find(f"{DRAKE}gear_ratio").get("value"))
        model.armature[model.joints[model.getJointId(joint)].idx_v] = rotor * gear * gear
    joints = ir["model"]["joints"]
    # URDF `continuous` joints are Pinocchio's unbounded revolute joints: (cos q, sin q) in
    # the configuration, one entry in the velocity; a prismatic joint has one of each. A
    # spatial leg's ball joint is exported as three continuous joints named for its angles.
    qidx = [model.joints[model.getJointId(j)].idx_q for j in joints]
    idx = [model.joints[model.getJointId(j)].idx_v for j in joints]
    assert model.nv == len(joints), (model.nv, joints)
    kinds = ir["model"]["joint_kinds"]

    def configuration(q):
        qp = pin.neutral(model)
        for k, a, kind in zip(qidx, q, kinds):
            if kind == "prismatic":
                qp[k] = a
            else:
                qp[k], qp[k + 1] = np.cos(a), np.sin(a)
        return qp

    def spring_forces(q):
        """URDF has no springs: ∂V/∂q of the spec's, added to Pinocchio's bias forces."""
        g = np.zeros(len(joints))
        for s in ir["model"]["springs"]:
            a, b = s["a"], s["b"]
            stretch = q[a] - (q[b] if b is not None else 0.0) - params[f"{s['name']}_rest"]
            force = params[f"{s['name']}_stiffness"] * stretch
            g[a] += force
            if b is not None:
                g[b] -= force
        return g

    damping = np.zeros(model.nv)
    for j in ET.parse(urdf).getroot().iter("joint"):
        d = j.find("dynamics")
        if d is not None and j.get("type") != "fixed":
            damping[model.joints[model.getJointId(j.get("name"))].idx_v] = float(d.get("damping"))

    def constraints(data):
        return closure_constraints(model, data, ir)

    def torques(q, qd, u):
        """Pinocchio's τ for our state and motor torques: the motors, and the damping and
        springs it does not model."""
        vp = np.zeros(model.nv)
        vp[idx] = qd
        tau = np.zeros(model.nv)
        for k, a in enumerate(ir["model"]["actuated"]):
            tau[idx[a]] += u[k]
        tau -= damping * vp
        tau[idx] -= spring_forces(q)
        return tau

    return SimpleNamespace(model=model, params=params, idx=idx, configuration=configuration,
                           spring_forces=spring_forces, constraints=constraints, torques=torques)


def main():
    if len(sys.argv) not in (4, 5):
        sys.exit(f"usage: {sys.argv[0]} LEGS_BINARY MODEL URDF_FILE [FLOATING_URDF_FILE]  (e.g. target/debug/legs my_leg my_leg.urdf, the file from `cargo xtask export my_leg --format urdf`)")
    legs, name, urdf = sys.argv[1:4]
    ir = json.loads((pathlib.Path(__file__).parent.parent / "generated" / "ir" / f"{name}.json").read_text())
    leg = pinocchio_leg(urdf, ir)
    model, params, idx = leg.model, leg.params, leg.idx
    configuration, spring_forces = leg.configuration, leg.spring_forces
    data = model.createData()
    joints = ir["model"]["joints"]
    # A planar leg lies in the x-y plane; a spatial leg's gravity has three components.
    dim = ir["model"].get("dimension", 2)
    rng = np.random.default_rng(5)
    worst = {"M": 0.0, "N": 0.0, "foot": 0.0}
    foot_frame = model.getFrameId("foot.point")
    for _ in range(STATES):
        q = rng.uniform(-np.pi, np.pi, len(joints))
        qd = rng.uniform(-3.0, 3.0, len(joints))
        t = ours(legs, name, q, qd)
        qp, vp = configuration(q), np.zeros(model.nv)
        vp[idx] = qd
        mp = pin.crba(model, data, qp)
        mp = np.triu(mp) + np.triu(mp, 1).T
        np_ = pin.rnea(model, data, qp, vp, np.zeros(model.nv))[idx] + spring_forces(q)
        pin.framesForwardKinematics(model, data, qp)
        foot = data.oMf[foot_frame].translation[:dim]
        m_ours, n_ours = np.array(t["M"]), np.array(t["N"])
        worst["M"] = worse(worst["M"], np.abs(mp[np.ix_(idx, idx)] - m_ours).max() / np.abs(m_ours).max())
        worst["N"] = worse(worst["N"], np.abs(np_ - n_ours).max() / max(np.abs(n_ours).max(), 1e-300))
        worst["foot"] = worse(worst["foot"], np.abs(foot - np.array(t["foot"])).max())
    ok = worst["M"] < REL_TOL and worst["N"] < REL_TOL and worst["foot"] < 1e-12
    closure = 0.0
    if ir["model"]["closures"]:
        home, actuated = ir["model"]["home"], ir["model"]["actuated"]
        # Near the spec's home pose, the motors moved a little, onto the closures (every
        # joint free: this works on a leg whose motors over-determine it too).
        near = [h + (0.05 if i in actuated else 0.0) for i, h in enumerate(home)]
        start = ours(legs, name, near, [0.0] * len(near), project=True)
        qp = configuration(start["q"])
        pin.framesForwardKinematics(model, data, qp)
        rods = ir["model"].get("distance_closures", [])
        for k, c in enumerate(ir["model"]["closures"]):
            a = data.oMf[model.getFrameId(f"{c}.a")].translation
            b = data.oMf[model.getFrameId(f"{c}.b")].translation
            # A rod's frames are its length apart; a point closure's coincide.
            gap = abs(np.linalg.norm(a - b) - params[f"{c}_distance"]) if k in rods else float(np.abs(a - b).max())
            closure = max(closure, gap)
            if k in ir["model"].get("revolute_closures", []):
                # A revolute closure's points along its axes coincide too.
                a = data.oMf[model.getFrameId(f"{c}.a.axis")].translation
                b = data.oMf[model.getFrameId(f"{c}.b.axis")].translation
                closure = max(closure, float(np.abs(a - b).max()))
        ok = ok and closure < 1e-12
    dynamics = ""
    if ir["model"].get("distance_closures"):
        dynamics = "; constraintDynamics not compared: Pinocchio has no rod (distance) constraint"
    elif ir["model"]["closures"] and dim == 3:
        ok_fd, dynamics = constraint_dynamics(legs, name, ir, leg)
        ok = ok and ok_fd
    if len(sys.argv) == 5:
        if ir["model"].get("distance_closures"):
            # Its rods are closures too: on the free flyer they would be left out.
            dynamics += ", on its free flyer either"
        else:
            ok_ff, said = free_flyer(legs, name, ir, leg, sys.argv[4])
            ok, dynamics = ok and ok_ff, dynamics + said
    print(
        f"{name}: Pinocchio loads the URDF; M {worst['M']:.1e}, N {worst['N']:.1e} (relative), "
        f"foot {worst['foot']:.1e} m, closure frames {closure:.1e} m at an assembled pose{dynamics} "
        f"{'ok' if ok else 'MISMATCH'}"
    )
    sys.exit(0 if ok else 1)


def constraint_dynamics(legs, name, ir, leg):
    """A spatial leg's forward dynamics beside Pinocchio's `constraintDynamics`, the closures
    as 3-D point constraints (`RigidConstraintModel`, CONTACT_3D between the frames `<c>.a`
    and `<c>.b`), at assembled states: unregularized (μ = 0, a plain factorization of the
    constraint system) and with the proximal regularization a user reaches for (μ = 1e-8,
    100 iterations to 1e-12). Ours must equal Pinocchio's regularized q̈ to 1e-9 relative
    (its proximal iterations converge to the exact solution on these legs, redundant rows
    included); μ = 0 is reported (NaN where rounding leaves a redundant row exactly
    singular), not judged. Pinocchio models neither damping nor springs: both go into τ."""
    model, idx, configuration = leg.model, leg.idx, leg.configuration
    data = model.createData()
    cm, cd = leg.constraints(data)
    home, actuated = ir["model"]["home"], ir["model"]["actuated"]
    rng = np.random.default_rng(7)
    worst, residual, nan_free = 0.0, {"ours": 0.0, "pinocchio": 0.0}, 0
    for trial in range(5):
        near = np.array(home) + rng.uniform(-0.1, 0.1, len(home))
        t = ours(legs, name, near, rng.uniform(-1.0, 1.0, len(home)), project=True,
                 u=rng.uniform(-0.5, 0.5, len(actuated)))
        q, qd, u = np.array(t["q"]), np.array(t["qd"]), np.array(t["u"])
        qp, vp = configuration(q), np.zeros(model.nv)
        vp[idx] = qd
        tau = leg.torques(q, qd, u)
        exact = pin.constraintDynamics(model, data, qp, vp, tau, cm, cd, pin.ProximalSettings(1e-12, 0.0, 1))
        nan_free += bool(np.all(np.isfinite(exact)))
        qdd = pin.constraintDynamics(model, data, qp, vp, tau, cm, cd, pin.ProximalSettings(1e-12, 1e-8, 100))[idx]
        mine = np.array(t["qdd"])
        worst = worse(worst, np.abs(qdd - mine).max() / np.abs(mine).max())
        j, b = np.array(t["J"]), np.array(t["Jdot_qdot"])
        scale = np.abs(j) @ np.abs(mine) + np.abs(b)
        residual["ours"] = max(residual["ours"], np.abs(j @ mine + b).max() / scale.max())
        residual["pinocchio"] = max(residual["pinocchio"], np.abs(j @ qdd + b).max() / scale.max())
    ok = worst < 1e-9
    return ok, (
        f"; constraintDynamics at 5 assembled states: finite at μ = 0 in {nan_free} of 5, at μ = 1e-8 "
        f"q̈ {worst:.1e} from ours (relative), |J q̈ + J̇ q̇| (relative) ours {residual['ours']:.1e}, "
        f"Pinocchio's {residual['pinocchio']:.1e}"
    )


def free_flyer(legs, name, ir, leg, urdf):
    """A floating robot on Pinocchio's free flyer (the URDF whose root link is the body)
    beside ours, at 5 assembled states with the chart centred on the body (the free
    joint's six q zero: the body at the origin, level), the closures as in
    `constraint_dynamics` (`closure_constraints`, the same builder) and, with contact points, every one held too (CONTACT_3D to the
    world where the point is, the rates put on them by `legs eval --stance --project`).
    Pinocchio's q̈ of a free flyer is the body's velocity derivative in its frame, then the
    joints': ours is `vdot` (`leg_models::robot::velocity_derivative` of the chart's q̈).
    Proximal settings as there (μ = 1e-8, 100 iterations to 1e-12); ours must equal it to
    1e-9 relative. The chart's six joints and the free flyer are the same coordinates at
    the centre, so the armature, damping and springs carry over by name."""
    f = ir["model"]["free_joint"]
    model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
    model.gravity = leg.model.gravity
    joints = ir["model"]["joints"]
    root = model.joints[1]
    idx = [root.idx_v + (i - f) if f <= i < f + 6 else model.joints[model.getJointId(j)].idx_v
           for i, j in enumerate(joints)]
    assert model.nv == len(joints), (model.nv, len(joints))
    for i, j in enumerate(joints):
        if not f <= i < f + 6:
            model.armature[idx[i]] = leg.model.armature[leg.idx[i]]
    data = model.createData()

    def configuration(q):
        qp = pin.neutral(model)  # the body at the origin, level
        for i, j in enumerate(joints):
            if f <= i < f + 6:
                continue
            jm = model.joints[model.getJointId(j)]
            if jm.nq == 2:
                qp[jm.idx_q], qp[jm.idx_q + 1] = np.cos(q[i]), np.sin(q[i])
            else:
                qp[jm.idx_q] = q[i]
        return qp

    home, actuated = ir["model"]["home"], ir["model"]["actuated"]
    rng = np.random.default_rng(11)
    worst = {"flight": 0.0, "stance": 0.0}
    for trial in range(5):
        near = np.array(home) + rng.uniform(-0.05, 0.05, len(home))
        u = rng.uniform(-0.5, 0.5, len(actuated))
        for phase in (["flight", "stance"] if ir["model"]["contacts"] else ["flight"]):
            held = phase == "stance"
            t = ours(legs, name, near, rng.uniform(-1.0, 1.0, len(home)), project=True, u=u)
            # Centred (the closures do not see the chart, so they stay closed), ours again
            # at that very state, the rates put on the held contacts there; where that
            # projection stepped q after all, centred once more and not projected.
            q = np.array(t["q"])
            q[f:f + 6] = 0.0
            t = ours(legs, name, q, t["qd"], project=held, u=u, stance=held)
            if np.any(np.array(t["q"][f:f + 6]) != 0.0):
                q = np.array(t["q"])
                q[f:f + 6] = 0.0
                t = ours(legs, name, q, t["qd"], u=u, stance=held)
            q, qd = np.array(t["q"]), np.array(t["qd"])
            qp, vp = configuration(q), np.zeros(model.nv)
            vp[idx] = qd
            tau_chart = leg.torques(q, qd, u)
            tau = np.zeros(model.nv)
            tau[idx] = tau_chart[leg.idx]
            cm, cd = closure_constraints(model, data, ir, qp if held else None)
            theirs = pin.constraintDynamics(model, data, qp, vp, tau, cm, cd, pin.ProximalSettings(1e-12, 1e-8, 100))[idx]
            mine = np.array((t["stance"] if held else t)["vdot"])
            worst[phase] = worse(worst[phase], np.abs(theirs - mine).max() / np.abs(mine).max())
    ok = max(worst.values()) < 1e-9
    held = f", every contact held {worst['stance']:.1e}" if ir["model"]["contacts"] else ""
    what = "the closures" if ir["model"]["closures"] else "unconstrained"
    return ok, (f"; on Pinocchio's free flyer at 5 assembled states, its q̈ (v̇) from our body's "
                f"velocity derivative (relative): {what} {worst['flight']:.1e}{held}")


if __name__ == "__main__":
    main()
