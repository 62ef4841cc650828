"""Cross-check of a spatial leg against MuJoCo, run by `cargo xtask test`.

usage: python mujoco_spatial_check.py LEGS_BINARY MODEL MJCF_FILE

MJCF_FILE is the leg exported (`cargo xtask export MODEL --format mjcf`) or the file it
was imported from (`cargo xtask import`): joints are matched by name through the
importer's rule (lower case, every other character `_`), a free joint is removed, its body held at its pose
as written (`--fix-base`), and MuJoCo's equalities and joints that reach outside the leg
(`--root`) are left out. At random states near home, put on the closures by
`legs eval --project`, it compares:

- the mass matrix: ours is `Tᵀ M_mj T`, T mapping our rates to MuJoCo's velocities
  (the identity on a hinge or slide; on a ball joint, whose qpos is the quaternion of
  R_x(α) R_y(β) R_z(γ) and qvel the angular velocity in the link's frame, ω = E(β, γ) of
  the three angles' rates);
- the bias forces: ours (C q̇ + G, springs in G) is `Tᵀ (qfrc_bias − qfrc_spring + M_mj Ṫ q̇)`;
- the closure rows: our J is `efc_J T` (MuJoCo's `connect` rows, dense, and a rod's
  row, the length of a spatial tendon held by a tendon equality);
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


def identifier(name):
    """The importer's rule for names (xtask/src/commands/import/mod.rs, `identifier`)."""
    out = "".join(c.lower() if c.isascii() and c.isalnum() else "_" for c in name)
    if not (out[:1].isascii() and out[:1].islower()):
        out = "n_" + out
    return out


class Map:
    """Our coordinates to MuJoCo's, by joint name."""

    def __init__(self, m, t, base=None):
        self.m, self.joints, self.balls = m, t["joints"], set(t["ball_joints"])
        self.free = t.get("free_joint")
        self.base = base
        self.n = len(self.joints)
        self.by_name = {}
        for i in range(m.njnt):
            j = m.joint(i)
            self.by_name[j.name] = j
            self.by_name.setdefault(identifier(j.name), j)

    def groups(self):
        """(our first coordinate, count, MuJoCo joint)."""
        i = 0
        while i < self.n:
            if i == self.free:
                # A floating robot's body: MuJoCo's free joint, named for its link (an
                # unnamed one, as Menagerie's Cassie's, is the file's only free joint).
                name = self.joints[i].rsplit(".", 1)[0]
                free = [self.m.joint(k) for k in range(self.m.njnt) if self.m.jnt_type[k] == mujoco.mjtJoint.mjJNT_FREE]
                yield i, 6, self.by_name.get(name) or (free[0] if len(free) == 1 else self.by_name[name])
                i += 6
            elif i in self.balls:
                yield i, 3, self.by_name[self.joints[i].rsplit(".", 1)[0]]
                i += 3
            else:
                yield i, 1, self.by_name[self.joints[i]]
                i += 1

    def dofs(self):
        """MuJoCo's velocity coordinates of our joints."""
        out = []
        for _, k, j in self.groups():
            out.extend(range(j.dofadr[0], j.dofadr[0] + k))
        return out

    def base_body(self):
        """The body held as the base: the one `load` welded, else a free joint's."""
        if self.base is not None:
            return self.base
        if self.free is not None:
            return None  # a floating robot's chart is centred on the world
        held = [i for i in range(self.m.njnt) if self.m.jnt_type[i] == mujoco.mjtJoint.mjJNT_FREE]
        return self.m.jnt_bodyid[held[0]] if held else None

    def base_rotation(self, d):
        """The base frame in the world: a held free body's, else the world's."""
        b = self.base_body()
        return np.eye(3) if b is None else np.array(d.xmat[b]).reshape(3, 3)

    def base_position(self, d):
        b = self.base_body()
        return np.zeros(3) if b is None else np.array(d.xpos[b])

    def held(self):
        """MuJoCo's free joints (held at their pose as written): their qpos and dof addresses."""
        return [
            (self.m.jnt_qposadr[i], self.m.jnt_dofadr[i])
            for i in range(self.m.njnt)
            if self.m.jnt_type[i] == mujoco.mjtJoint.mjJNT_FREE
        ]

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
            elif k == 6:
                # Our chart is centred on MuJoCo's world: the body at δ, turned by the
                # ball joint's angles; MuJoCo's qvel is ṗ = δ̇ in the world, then ω in the
                # body, ω = E(β, γ) of the angles' rates.
                a, b, g = q[i + 3:i + 6]
                E, Eb, Eg = rate_map(b, g)
                d.qpos[qa:qa + 3] = q[i:i + 3]
                d.qpos[qa + 3:qa + 7] = ball_quaternion(a, b, g)
                d.qvel[va:va + 3] = qd[i:i + 3]
                d.qvel[va + 3:va + 6] = E @ qd[i + 3:i + 6]
                T[va:va + 3, i:i + 3] = np.eye(3)
                T[va + 3:va + 6, i + 3:i + 6] = E
                Tdot_qd[va + 3:va + 6] = (Eb * qd[i + 4] + Eg * qd[i + 5]) @ qd[i + 3:i + 6]
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


def same_span(what, ours_value, theirs, failures):
    """How far either matrix's rows lie outside the other's row space, relative to the
    rows' size; a failure above REL_TOL."""
    a, b = np.asarray(ours_value, float), np.asarray(theirs, float)

    def outside(x, y):
        u, sv, vt = np.linalg.svd(y, full_matrices=False)
        basis = vt[sv > 1e-9 * sv.max()]
        rest = x - (x @ basis.T) @ basis
        return np.abs(rest).max(initial=0.0) / max(np.abs(x).max(initial=0.0), 1e-12)

    err = max(outside(a, b), outside(b, a))
    if not err <= REL_TOL:
        failures.append(f"{what}: rows outside the other's span by {err:.2e} (relative)")
    return err


def load(mjcf, floating=False):
    """The model of `mjcf` as our leg sees it, and the body held as its base (None: the
    world). A free joint is removed (its body welded where the file writes it, each
    keyframe's seven entries for it dropped): held by MuJoCo itself, not reset after each
    step, so that inside a step the base does not float. A floating robot's (`floating`:
    ours has a free joint too) is kept: it is one of the compared coordinates. Joint limits and contacts are
    off: our leg has neither. Where the file's mesh files are not here (Menagerie's
    `cassie.xml` without its `assets/`), its mesh geoms, meshes, textures and materials
    are dropped first: they are drawing only where every such body gives its
    `<inertial>`, which is checked, so the dynamics compared is the file's own."""
    spec = mujoco.MjSpec.from_file(mjcf)
    folder = pathlib.Path(mjcf).parent / (spec.meshdir or "")
    if not all((folder / mesh.file).exists() for mesh in spec.meshes):
        for g in list(spec.geoms):
            if g.type == mujoco.mjtGeom.mjGEOM_MESH:
                if not g.parent.explicitinertial:
                    sys.exit(f"{mjcf}: body `{g.parent.name}` takes its inertia from a mesh whose file is not in {folder}")
                spec.delete(g)
        for x in list(spec.meshes) + list(spec.textures) + list(spec.materials):
            spec.delete(x)
        print(f"{pathlib.Path(mjcf).name}: its mesh files are not in {folder}: drawn geoms dropped (the bodies' inertials are given)")
    first = spec.compile()
    free = [j for j in range(first.njnt) if first.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and not floating]
    held = None
    if free:
        drop = set()
        for j in free:
            a = first.jnt_qposadr[j]
            drop.update(range(a, a + 7))
        held = first.body(first.jnt_bodyid[free[0]]).name
        keys = [(k, [x for i, x in enumerate(k.qpos) if i not in drop]) for k in spec.keys if len(k.qpos)]
        for k, _ in keys:
            k.qpos = []
        for j in list(spec.joints):
            if j.type == mujoco.mjtJoint.mjJNT_FREE:
                spec.delete(j)
        for k, qpos in keys:
            k.qpos = qpos
    m = spec.compile()
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_LIMIT | mujoco.mjtDisableBit.mjDSBL_CONTACT
    base = None if held is None else mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, held)
    return m, base


def main():
    if len(sys.argv) != 4:
        sys.exit(f"usage: {sys.argv[0]} LEGS_BINARY MODEL MJCF_FILE  (e.g. target/debug/legs my_leg my_leg.xml, the file from `cargo xtask export my_leg --format mjcf`)")
    legs, name, mjcf = sys.argv[1:4]
    ir = json.loads((pathlib.Path(__file__).parent.parent / "generated" / "ir" / f"{name}.json").read_text())
    m, held = load(mjcf, floating=ir["model"].get("free_joint") is not None)
    m.opt.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    d = mujoco.MjData(m)
    home = np.array(ir["model"]["home"])
    rng = np.random.default_rng(30)
    failures, worst = [], {}
    for trial in range(STATES):
        # Our home pose moved at random, then put on the closures by ours.
        q = home + 0.1 * rng.uniform(-1, 1, len(home))
        qd = rng.uniform(-2, 2, len(home))
        t = ours(legs, name, q, qd, project=True)
        mp = Map(m, t, held)
        q, qd = np.array(t["q"]), np.array(t["qd"])
        mujoco.mj_resetData(m, d)  # qpos0: a free joint at its pose as written, at rest
        T, Tdot_qd = mp.state(d, q, qd)
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        dofs = mp.dofs()
        other = [v for v in range(m.nv) if v not in dofs and not any(a <= v < a + 6 for _, a in mp.held())]
        T = T[dofs]
        Tdot_qd = Tdot_qd[dofs]
        base = mp.base_rotation(d)
        full_l = full[np.ix_(dofs, dofs)]
        bias = (d.qfrc_bias - d.qfrc_spring)[dofs]
        checks = [
            ("M", t["M"], T.T @ full_l @ T),
            ("N", t["N"], T.T @ (bias + full_l @ Tdot_qd)),
        ]
        if "foot.point" in [m.site(i).name for i in range(m.nsite)]:
            checks.append(("foot", t["foot"], base.T @ (d.site("foot.point").xpos - mp.base_position(d))))
        if len(t["phi"]):
            # MuJoCo's connect rows (3 each, in order, world frame), less those that reach
            # a joint outside the leg, turned into the base's frame (a held free body's).
            efc = np.array(d.efc_J).reshape(d.nefc, m.nv)
            rows = []
            for e in range(m.neq):
                r = [k for k in range(d.nefc) if d.efc_type[k] == mujoco.mjtConstraint.mjCNSTR_EQUALITY and d.efc_id[k] == e]
                if np.any(efc[r][:, other]):
                    continue
                if len(r) == 3:
                    rows.append(base.T @ efc[r][:, dofs] @ T)
                elif len(r) == 1 and m.eq_type[e] == mujoco.mjtEq.mjEQ_TENDON:
                    # A rod: the tendon's length row, d|a − b|/dq, ours (dᵀ J_d / L) where
                    # the rod is assembled.
                    rows.append(efc[r][:, dofs] @ T)
            theirs = np.vstack(rows) if rows else np.zeros((0, len(dofs)))
            if ir["model"].get("revolute_closures"):
                # A revolute closure is five rows of ours and two connects (six rows, one
                # implied) of MuJoCo's: the rows must span the same space, each side's
                # rows inside the other's span (relative to their size).
                worst["J"] = max(worst.get("J", 0.0), same_span(f"#{trial} J", t["J"], theirs, failures))
            else:
                checks.append(("J", t["J"], theirs))
        for key, a, b in checks:
            worst[key] = max(worst.get(key, 0.0), close(f"#{trial} {key}", a, b, failures))
    # MuJoCo's own run from home, motors off, free joints held: the gap its soft loops
    # leave after 1 s.
    t = ours(legs, name, home, np.zeros_like(home), project=True)
    mujoco.mj_resetData(m, d)
    mp = Map(m, t, held)
    mp.state(d, np.array(t["q"]), np.zeros_like(home))
    held = [(a, v, d.qpos[a : a + 7].copy()) for a, v in mp.held() if mp.free is None]
    mujoco.mj_forward(m, d)
    for _ in range(int(round(1.0 / m.opt.timestep))):
        mujoco.mj_step(m, d)
        for a, v, pose in held:
            d.qpos[a : a + 7] = pose
            d.qvel[v : v + 6] = 0.0
    mujoco.mj_forward(m, d)
    efc_pos = np.array(d.efc_pos)
    gaps = [
        float(np.linalg.norm([efc_pos[k] for k in range(d.nefc) if d.efc_type[k] == mujoco.mjtConstraint.mjCNSTR_EQUALITY and d.efc_id[k] == e]))
        for e in range(m.neq)
    ]
    gap = max(gaps, default=0.0)
    if not gap <= CLOSURE_TOL:
        failures.append(f"MuJoCo's loops opened {gap:.2e} m in 1 s")
    if failures:
        print(f"{name}: MuJoCo disagrees: " + "; ".join(failures[:5]))
        sys.exit(1)
    figures = ", ".join(f"{k} {v:.1e}" for k, v in worst.items())
    ours_gap = float(np.abs(t["phi"]).max(initial=0.0))
    print(
        f"{name}: MuJoCo agrees on {pathlib.Path(mjcf).name} at {STATES} assembled states (worst relative difference: {figures}); "
        f"loop gap after 1 s passive from home: MuJoCo {gap:.2e} m, ours at its start {ours_gap:.1e} m"
    )


if __name__ == "__main__":
    main()
