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
2.5 ms (MuJoCo's 1 ms step and soft contact); then it hops for 2 s in both under our
hopping controller (in MuJoCo through `legs sim --serve`, asked each step with MuJoCo's
state and contacts), and the apex heights must agree within 1 cm hop by hop (a leg that
makes fewer than three hops in 2 s in ours is reported and not compared). Prints one line per model; exits 1 on a mismatch.
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


HOPS = 3  # at least, in 2 s
APEX_TOL = 1e-2  # m: MuJoCo's soft contact takes and returns energy differently


def hop_closed_loop(legs, name, m, d, joints, qadr, vadr, ir):
    """Our hopping controller on both simulators for 2 s from the same state: ours
    (`legs sim NAME`) and MuJoCo, its torques asked each step from the same controller
    (`legs sim NAME --serve`) with MuJoCo's state and contacts (a contact is on the
    ground while MuJoCo has it touching the floor, anchored where it touched down). The
    apex heights of the body in both, or None where our hopping controller does not apply
    (it is refused)."""
    import csv
    import tempfile

    with tempfile.TemporaryDirectory() as out:
        run = subprocess.run(
            [legs, "sim", name, "--duration", "2", "--out", out], capture_output=True, text=True
        )
        if run.returncode != 0 and not (pathlib.Path(out) / "trajectory.csv").exists():
            return None
        summary = json.loads((pathlib.Path(out) / "summary.json").read_text())
        if summary["stopped"] is not None:
            print(f"{name}: our hopping run stopped ({summary['stopped']['cause']}): not compared in MuJoCo")
            return None
        with open(pathlib.Path(out) / "trajectory.csv") as f:
            rows = list(csv.DictReader(f))
    if summary["hops"] is None or summary["hops"] < HOPS:
        print(f"{name}: our hopping run made {summary['hops']} hops in 2 s (fewer than {HOPS}): not compared in MuJoCo")
        return None
    h = summary["height_joint"]
    motors = [k[2:] for k in rows[0] if k.startswith("u_")]
    ours_apex = [
        float(a[f"q_{h}"])
        for a, b in zip(rows, rows[1:])
        if all(a[k] == "flight" for k in a if k.startswith("mode_"))
        and float(a[f"qd_{h}"]) > 0.0 >= float(b[f"qd_{h}"])
    ]
    n = ir["model"]["ground_normal"]
    tangent = np.array([n[1], -n[0]])
    contacts = [m.geom(f"{c}.geom").id for c in ir["model"]["contacts"]]
    floor = m.geom("floor").id
    server = subprocess.Popen(
        [legs, "sim", name, "--serve"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1
    )
    mujoco.mj_resetData(m, d)
    d.qpos[qadr] = [float(rows[0][f"q_{j}"]) for j in joints]
    d.qvel[vadr] = [float(rows[0][f"qd_{j}"]) for j in joints]
    mujoco.mj_forward(m, d)
    hq, hv = m.joint(h).qposadr[0], m.joint(h).dofadr[0]
    act = [m.actuator(j).id for j in motors]
    anchors = [None] * len(contacts)
    mj_apex = []
    try:
        for _ in range(int(round(2.0 / m.opt.timestep))):
            touching = {
                g
                for i in range(d.ncon)
                for g in (d.contact[i].geom1, d.contact[i].geom2)
                if floor in (d.contact[i].geom1, d.contact[i].geom2)
            }
            flags = []
            for k, g in enumerate(contacts):
                if g in touching:
                    if anchors[k] is None:
                        anchors[k] = float(tangent @ d.geom_xpos[g][:2])
                    flags += [1.0, anchors[k]]
                else:
                    anchors[k] = None
                    flags += [0.0, 0.0]
            state = [d.time, *d.qpos[qadr], *d.qvel[vadr], *flags]
            server.stdin.write(" ".join(repr(float(x)) for x in state) + "\n")
            answer = server.stdout.readline().strip()
            if not answer or answer.startswith("error"):
                print(f"{name}: the controller in MuJoCo at t = {d.time:.3f} s: {answer or 'no answer'}")
                break
            d.ctrl[act] = [float(x) for x in answer.split()]
            v0 = d.qvel[hv]
            mujoco.mj_step(m, d)
            if not np.all(np.isfinite(d.qpos)):
                break
            if not touching and v0 > 0.0 >= d.qvel[hv]:
                mj_apex.append(float(d.qpos[hq]))
    finally:
        server.stdin.close()
        server.wait()
    return ours_apex, mj_apex


def main():
    if len(sys.argv) != 4:
        sys.exit(f"usage: {sys.argv[0]} LEGS_BINARY MODEL MJCF_FILE  (e.g. target/debug/legs my_leg my_leg.xml, the file from `cargo xtask export my_leg --format mjcf`)")
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
                a = m.site(f"{m.equality(e).name}.a").id
                b = m.site(f"{m.equality(e).name}.b").id
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
        hop = hop_closed_loop(legs, name, m, d, joints, qadr, vadr, ir)
        if hop is not None:
            ours_apex, mj_apex = hop
            n = min(len(ours_apex), len(mj_apex))
            diff = max((abs(a - b) for a, b in zip(ours_apex[:n], mj_apex[:n])), default=None)
            if n < HOPS or diff is None or diff > APEX_TOL:
                print(f"{name}: apexes under our hopping controller, ours {ours_apex}, MuJoCo {mj_apex}")
                ok = False
            else:
                landing += (
                    f"; hopping under our controller in both: first {n} apexes "
                    + ", ".join(f"{a:.4f}/{b:.4f}" for a, b in zip(ours_apex[:n], mj_apex[:n]))
                    + f" m (ours/MuJoCo), at most {diff * 1e3:.1f} mm apart"
                )
    print(
        f"{name:<16} MuJoCo {mujoco.__version__}: max relative difference M {worst_m:.1e}, N {worst_n:.1e} "
        f"over {STATES} states; closure in a 1 s MuJoCo run {closure:.1e} m{landing} -> {'ok' if ok else 'MISMATCH'}"
    )
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
