"""Cross-check of the generated models against MuJoCo, run by `cargo xtask test`.

usage: python mujoco_check.py LEGS_BINARY MODEL MJCF_FILE

For random states, compares MuJoCo's mass matrix (`mj_fullM`, armature
included) and bias forces (`qfrc_bias` = C q̇ + G, less the joint and tendon springs'
`qfrc_spring`) of the exported MJCF with the generated
model's `M` and `N` from `legs eval --json` (relative error below 1e-9); then assembles
the leg with `legs eval --project` (near its home pose), lets MuJoCo simulate it for 1 s with the motors off
and checks that its (soft) closure constraints hold. A leg with contact points is dropped
in both (ours: `legs sim --controller passive`, the hybrid simulator; MuJoCo: its soft
contact against the exported floor) and the first touchdown times must agree within
2.5 ms (MuJoCo's 1 ms step and soft contact). Prints one line per model; exits 1 on a
mismatch.
"""

import json
import pathlib
import subprocess
import sys

import mujoco
import numpy as np

from legs_eval import ours

STATES = 20
REL_TOL = 1e-9
CLOSURE_TOL = 1e-3  # m; MuJoCo's equality constraints are soft


def main():
    legs, name, mjcf = sys.argv[1:4]
    m = mujoco.MjModel.from_xml_path(mjcf)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(7)
    probe = ours(legs, name, [0.0] * m.njnt, [0.0] * m.njnt)
    joints = probe["joints"]
    qadr = [m.joint(j).qposadr[0] for j in joints]
    vadr = [m.joint(j).dofadr[0] for j in joints]
    worst_m = worst_n = 0.0
    for _ in range(STATES):
        q = rng.uniform(-np.pi, np.pi, len(joints))
        qd = rng.uniform(-3.0, 3.0, len(joints))
        t = ours(legs, name, q, qd)
        d.qpos[qadr] = q
        d.qvel[vadr] = qd
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        mm = full[np.ix_(vadr, vadr)]
        # Our N holds the springs' forces (∂V/∂q); MuJoCo applies them as passive forces.
        nn = d.qfrc_bias[vadr] - d.qfrc_spring[vadr]
        em = np.abs(mm - np.array(t["M"])).max() / max(np.abs(mm).max(), 1e-300)
        en = np.abs(nn - np.array(t["N"])).max() / max(np.abs(nn).max(), 1e-300)
        worst_m, worst_n = max(worst_m, em), max(worst_n, en)
    ok = worst_m < REL_TOL and worst_n < REL_TOL

    # The `home` keyframe holds the spec's home pose, joint by joint.
    ir = json.loads((pathlib.Path(__file__).parent.parent / "generated" / "ir" / f"{name}.json").read_text())
    key = m.key("home").qpos
    home_off = max(abs(key[a] - h) for a, h in zip(qadr, ir["model"]["home"]))
    if home_off > 0.0:
        print(f"{name}: the MJCF's home keyframe differs from the spec's home pose by {home_off:.3e} rad")
        ok = False

    closure = 0.0
    if m.neq > 0:
        ir = json.loads((pathlib.Path(__file__).parent.parent / "generated" / "ir" / f"{name}.json").read_text())
        home, actuated = ir["model"]["home"], ir["model"]["actuated"]
        # Near the spec's home pose, the motors moved a little, onto the closures (every
        # joint free: this works on a leg whose motors over-determine it too).
        near = [h + (0.05 if i in actuated else 0.0) for i, h in enumerate(home)]
        start = ours(legs, name, near, [0.0] * len(near), project=True)
        d.qpos[qadr] = start["q"]
        d.qvel[:] = 0.0
        d.ctrl[:] = 0.0
        mujoco.mj_forward(m, d)
        for _ in range(int(1.0 / m.opt.timestep)):
            mujoco.mj_step(m, d)
            for e in range(m.neq):
                a = m.site(f"{m.equality(e).name}_a").id
                b = m.site(f"{m.equality(e).name}_b").id
                closure = max(closure, float(np.abs(d.site_xpos[a] - d.site_xpos[b]).max()))
        ok = ok and closure < CLOSURE_TOL and bool(np.all(np.isfinite(d.qpos)))
    landing = ""
    if ir["model"]["contacts"]:
        # A passive drop in both: our hybrid simulator (`legs sim --controller passive`,
        # released 3 cm above home) and MuJoCo from its first state; the first touchdown
        # times agree to MuJoCo's step and soft contact.
        import csv
        import tempfile

        with tempfile.TemporaryDirectory() as out:
            subprocess.run(
                [legs, "sim", name, "--controller", "passive", "--duration", "0.6", "--out", out],
                capture_output=True,
                text=True,
            )
            try:
                with open(pathlib.Path(out) / "events.csv") as f:
                    ours_td = next(float(r["t"]) for r in csv.DictReader(f) if r["kind"] == "Touchdown")
                with open(pathlib.Path(out) / "trajectory.csv") as f:
                    first = next(csv.DictReader(f))
            except (OSError, StopIteration):
                print(f"{name}: our passive drop did not touch down within 0.6 s")
                ok = False
                ours_td, first = None, None
        if first is not None:
            mujoco.mj_resetData(m, d)  # time 0, after the closure run above
            d.qpos[qadr] = [float(first[f"q_{j}"]) for j in joints]
            d.qvel[:] = 0.0
            d.ctrl[:] = 0.0
            mujoco.mj_forward(m, d)
            floor = m.geom("floor").id
            mj_td = None
            for _ in range(int(0.6 / m.opt.timestep)):
                mujoco.mj_step(m, d)
                if any(floor in (d.contact[i].geom1, d.contact[i].geom2) for i in range(d.ncon)):
                    mj_td = d.time
                    break
            if mj_td is None or abs(mj_td - ours_td) > 2.5e-3:
                print(f"{name}: touchdown in MuJoCo at {mj_td} s, ours at {ours_td} s")
                ok = False
            landing = f"; passive drop: first touchdown {ours_td:.4f} s ours, {mj_td} s MuJoCo (soft contact)"
    print(
        f"{name:<16} MuJoCo {mujoco.__version__}: max relative difference M {worst_m:.1e}, N {worst_n:.1e} "
        f"over {STATES} states; closure in a 1 s MuJoCo run {closure:.1e} m{landing} -> {'ok' if ok else 'MISMATCH'}"
    )
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
