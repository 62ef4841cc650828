"""Cross-check of the exported URDF with Pinocchio, run by `cargo xtask test`.

usage: python urdf_check.py LEGS_BINARY MODEL URDF_FILE

Loads the URDF with Pinocchio's parser (urdfdom), sets the joint armature from the
transmissions' `<drake:rotor_inertia>` and `<drake:gear_ratio>` and gravity from the spec,
then for random states compares Pinocchio's mass matrix (`crba`) and bias forces (`rnea`
with zero acceleration) with the generated model's `M` and `N` (from `legs eval --json`),
and its `foot.point` frame with our foot; at an assembled pose, the frames `<closure>.a` and
`<closure>.b` must coincide. Prints one line per model; exits 1 on a mismatch.
"""

import json
import pathlib
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

from legs_eval import ours

STATES = 20
REL_TOL = 1e-9
DRAKE = "{http://drake.mit.edu}"


def main():
    legs, name, urdf = sys.argv[1:4]
    model = pin.buildModelFromUrdf(urdf)
    data = model.createData()
    ir = json.loads((pathlib.Path(__file__).parent.parent / "generated" / "ir" / f"{name}.json").read_text())
    params = {p["name"]: p["default"] for p in ir["model"]["params"]}
    model.gravity.linear = np.array([params["gravity_x"], params["gravity_y"], 0.0])
    # Reflected rotor inertia from the transmissions' extension elements.
    for t in ET.parse(urdf).getroot().iter("transmission"):
        joint = t.find("joint").get("name")
        act = t.find("actuator")
        rotor = float(act.find(f"{DRAKE}rotor_inertia").get("value"))
        gear = float(act.find(f"{DRAKE}gear_ratio").get("value"))
        model.armature[model.joints[model.getJointId(joint)].idx_v] = rotor * gear * gear
    joints = ir["model"]["joints"]
    # URDF `continuous` joints are Pinocchio's unbounded revolute joints: (cos q, sin q) in
    # the configuration, one entry in the velocity; a prismatic joint has one of each.
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
        foot = data.oMf[foot_frame].translation[:2]
        m_ours, n_ours = np.array(t["M"]), np.array(t["N"])
        worst["M"] = max(worst["M"], np.abs(mp[np.ix_(idx, idx)] - m_ours).max() / np.abs(m_ours).max())
        worst["N"] = max(worst["N"], np.abs(np_ - n_ours).max() / max(np.abs(n_ours).max(), 1e-300))
        worst["foot"] = max(worst["foot"], np.abs(foot - np.array(t["foot"])).max())
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
        for c in ir["model"]["closures"]:
            a = data.oMf[model.getFrameId(f"{c}.a")].translation
            b = data.oMf[model.getFrameId(f"{c}.b")].translation
            closure = max(closure, float(np.abs(a - b).max()))
        ok = ok and closure < 1e-12
    print(
        f"{name}: Pinocchio loads the URDF; M {worst['M']:.1e}, N {worst['N']:.1e} (relative), "
        f"foot {worst['foot']:.1e} m, closure frames {closure:.1e} m at an assembled pose "
        f"{'ok' if ok else 'MISMATCH'}"
    )
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
