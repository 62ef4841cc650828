"""CasADi derivation of a leg model, run by `cargo xtask gen` (generation step only).

Reads on stdin the normalized model that xtask built from a validated spec (links, the
parameter names that stand for every geometric quantity, closures, foot, gravity) and
writes on stdout the derived terms as straight-line programs in SSA form: one
instruction per value, operands referring to earlier instructions, outputs listing the
value of every entry in column-major order. Errors go to stderr with exit code 1.

Mathematics: shared/DESIGN.md §3. Each branch (a subtree hanging from the base) is an
open chain with Lagrangian L_i = T_i - V_i; L = sum L_i - V_springs; M = d2L/dqd2;
N = (d2L/dqd dq) qd - dL/dq; the closure residual phi is point a minus point b per
closure; J = dphi/dq and Jdot qd = d(J qd)/dq qd. Joints are revolute (q turns the link)
or prismatic (q slides it along a fixed axis of the parent); contact points get their
positions, J_c and Jc_dot qd (§3.1). The emitted terms are those quantities in
link-local closed form (`LinkKinematics`, `coriolis`); the Lagrange derivatives stay as
CasADi's C peer and agree with them to rounding.
"""

import hashlib
import json
import math
import sys

import casadi as cs

import derive_spatial

UNARY = {
    cs.OP_NEG: "neg",
    cs.OP_SQ: "sq",
    cs.OP_TWICE: "twice",
    cs.OP_INV: "inv",
    cs.OP_SQRT: "sqrt",
    cs.OP_SIN: "sin",
    cs.OP_COS: "cos",
    cs.OP_TAN: "tan",
    cs.OP_ASIN: "asin",
    cs.OP_ACOS: "acos",
    cs.OP_ATAN: "atan",
    cs.OP_SINH: "sinh",
    cs.OP_COSH: "cosh",
    cs.OP_TANH: "tanh",
    cs.OP_EXP: "exp",
    cs.OP_LOG: "log",
    cs.OP_FABS: "abs",
}
BINARY = {
    cs.OP_ADD: "add",
    cs.OP_SUB: "sub",
    cs.OP_MUL: "mul",
    cs.OP_DIV: "div",
    cs.OP_POW: "pow",
    cs.OP_CONSTPOW: "pow",
    cs.OP_ATAN2: "atan2",
    cs.OP_FMIN: "min",
    cs.OP_FMAX: "max",
}
OP_NAMES = {getattr(cs, n): n for n in dir(cs) if n.startswith("OP_")}


class DerivationError(Exception):
    pass


def rotate(angle, v):
    c, s = cs.cos(angle), cs.sin(angle)
    return cs.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1])



def _is_constant(e, state):
    return not cs.depends_on(e, state)


class LinkKinematics:
    """A planar tree in link-local terms. Each link's frame is at its joint point, turned
    by its absolute angle; `rel[i]` is (cos q_i, sin q_i) of a revolute joint (None, the
    identity, for a prismatic one), `abs[i]` the absolute orientation composed from the
    parent's by angle addition, `offset[i]` the joint point in the parent's frame (the
    base's for a base link), `segment[i]` that offset turned into the base frame and
    `joint[i]` the joint point in the base frame. 2-vectors are lists of two scalars."""

    def __init__(self, model, sym, q, qd):
        self.links = links = model["links"]
        self.sym, self.q, self.qd = sym, q, qd
        self.state = cs.vertcat(q, qd)
        self.gravity = self.vec(model["gravity"])
        n = len(links)
        self.rel, self.abs, self.offset, self.segment, self.joint = [None] * n, [None] * n, [None] * n, [None] * n, [None] * n
        self.axis, self.omega = [None] * n, [None] * n
        for i, link in enumerate(links):
            parent = link["parent"]
            d = self.vec(link["origin"])
            if link["joint"] == "prismatic":
                a = [cs.SX(x) for x in link["axis"]]
                self.axis[i] = a
                self.offset[i] = [d[0] + q[i] * a[0], d[1] + q[i] * a[1]]
            else:
                self.offset[i] = d
                self.rel[i] = (cs.cos(q[i]), cs.sin(q[i]))
            spin = qd[i] if link["joint"] == "revolute" else cs.SX(0)
            if parent is None:
                self.abs[i] = self.rel[i]
                self.segment[i] = self.offset[i]
                self.joint[i] = self.offset[i]
                self.omega[i] = spin
            else:
                self.abs[i] = self.compose(self.abs[parent], self.rel[i])
                self.segment[i] = self.rot(self.abs[parent], self.offset[i])
                self.joint[i] = self.add(self.joint[parent], self.segment[i])
                self.omega[i] = self.omega[parent] + spin

    def vec(self, pair):
        return [self.sym[pair[0]], self.sym[pair[1]]]

    def constant(self, *xs):
        return all(_is_constant(x, self.state) for x in xs)

    @staticmethod
    def add(a, b):
        return [a[0] + b[0], a[1] + b[1]]

    @staticmethod
    def dot(a, b):
        return a[0] * b[0] + a[1] * b[1]

    @staticmethod
    def cross(a, b):
        return a[0] * b[1] - a[1] * b[0]

    @staticmethod
    def compose(a, b):
        if a is None:
            return b
        if b is None:
            return a
        return (a[0] * b[0] - a[1] * b[1], a[1] * b[0] + a[0] * b[1])

    @staticmethod
    def rot(rc, v):
        if rc is None:
            return list(v)
        c, s = rc
        return [c * v[0] - s * v[1], s * v[0] + c * v[1]]

    def dot_rot(self, r, rc, v):
        """r · (R v), as c (r·v) − s (r×v) when r and v are parameters only."""
        if rc is not None and self.constant(*r, *v):
            c, s = rc
            return c * self.dot(r, v) - s * self.cross(r, v)
        return self.dot(r, self.rot(rc, v))

    def cross_rot(self, r, rc, v):
        """r × (R v), as c (r×v) + s (r·v) when r and v are parameters only."""
        if rc is not None and self.constant(*r, *v):
            c, s = rc
            return c * self.cross(r, v) + s * self.dot(r, v)
        return self.cross(r, self.rot(rc, v))

    def own_inertia(self, i):
        """Mass, first moment m c (link frame) and inertia about the joint I + m |c|²."""
        link = self.links[i]
        m, inertia = self.sym[link["mass"]], self.sym[link["inertia"]]
        c = self.vec(link["com"])
        return m, [m * c[0], m * c[1]], inertia + m * self.dot(c, c)

    def grouped_sum(self, terms):
        """Σ terms, the parameter-only ones added first (one prepared value), then the rest."""
        constant = [t for t in terms if self.constant(t)]
        varying = [t for t in terms if not self.constant(t)]
        total = None
        for t in constant + varying:
            total = t if total is None else total + t
        return total if total is not None else cs.SX(0)

    def composite_terms(self):
        """Each subtree's mass, first moment and inertia about its joint, in its link's
        frame, as lists of terms (summed by `grouped_sum`)."""
        comp = []
        for i in range(len(self.links)):
            m, h, inertia = self.own_inertia(i)
            comp.append([[m], [[h[0]], [h[1]]], [inertia]])
        for j in reversed(range(len(self.links))):
            parent = self.links[j]["parent"]
            if parent is None:
                continue
            m, h, inertia = self.summed(comp[j])
            r, rc = self.offset[j], self.rel[j]
            rh = self.rot(rc, h)
            pm, ph, pi = comp[parent]
            pm.append(m)
            ph[0] += [rh[0], m * r[0]]
            ph[1] += [rh[1], m * r[1]]
            pi += [inertia, m * self.dot(r, r), 2 * self.dot_rot(r, rc, h)]
        return comp

    def summed(self, c):
        m, h, inertia = c
        return self.grouped_sum(m), [self.grouped_sum(h[0]), self.grouped_sum(h[1])], self.grouped_sum(inertia)

    def motion_force(self, i, m, h, inertia):
        """The force I S_i of an inertia (m, h, I) moved along joint i: (moment, force)."""
        if self.links[i]["joint"] == "revolute":
            return inertia, [-h[1], h[0]]
        a = self.axis[i]
        return self.cross(h, a), [m * a[0], m * a[1]]

    def project(self, i, moment, force):
        """S_iᵀ f of a force at joint i (its frame)."""
        if self.links[i]["joint"] == "revolute":
            return moment
        return self.dot(self.axis[i], force)

    def mass_matrix(self):
        """M by the composite-rigid-body recursion: M_ii = S_iᵀ I_i^c S_i, and M_ji for each
        ancestor j the same force carried up the chain. Reflected rotor inertia on the
        diagonal."""
        n = len(self.links)
        terms = self.composite_terms()
        comp = [self.summed(c) for c in terms]
        M = [[None] * n for _ in range(n)]
        for i in range(n):
            moment, force = self.motion_force(i, *comp[i])
            rotor = self.links[i]["rotor"]
            extra = [self.sym[rotor[0]] * self.sym[rotor[1]] ** 2] if rotor is not None else []
            # A revolute joint's M_ii is I_i^c: its terms, with the reflected rotor inertia
            # among the constant ones.
            own = terms[i][2] if self.links[i]["joint"] == "revolute" else [self.project(i, moment, force)]
            M[i][i] = self.grouped_sum(own + extra)
            j = i
            while self.links[j]["parent"] is not None:
                r, rc = self.offset[j], self.rel[j]
                moment = moment + self.cross_rot(r, rc, force)
                force = self.rot(rc, force)
                j = self.links[j]["parent"]
                M[i][j] = M[j][i] = self.project(j, moment, force)
        return cs.vertcat(*[cs.horzcat(*[M[r][c] if M[r][c] is not None else cs.SX(0) for c in range(n)]) for r in range(n)])

    def frame_moments(self):
        """The first moments each frame carries, for gravity: `H_f = h_f + Σ_c m_c r_c` over
        the children c of link f (m_c the mass of c's subtree, r_c its joint offset), and
        `H_base` for the base links' offsets. Then V = −g·H_base − Σ_f g·(R_f H_f)."""
        n = len(self.links)
        subtree_mass = [self.sym[link["mass"]] for link in self.links]
        for j in reversed(range(n)):
            parent = self.links[j]["parent"]
            if parent is not None:
                subtree_mass[parent] = subtree_mass[parent] + subtree_mass[j]
        H = [self.own_inertia(i)[1] for i in range(n)]
        base = [cs.SX(0), cs.SX(0)]
        for j, link in enumerate(self.links):
            moved = [subtree_mass[j] * self.offset[j][0], subtree_mass[j] * self.offset[j][1]]
            if link["parent"] is None:
                base = self.add(base, moved)
            else:
                H[link["parent"]] = self.add(H[link["parent"]], moved)
        return subtree_mass, H, base

    def gravity_forces(self):
        """G = ∂V/∂q. A revolute joint j turns every frame f of its subtree, and
        ∂(−g·R_f H_f)/∂θ_f = −g·(ẑ × R_f H_f) = g × (R_f H_f): G_j = Σ_f g × (R_f H_f). A
        prismatic joint j moves its subtree's mass m_j along R a_j: G_j = −m_j g·(R a_j)."""
        n = len(self.links)
        subtree_mass, H, _ = self.frame_moments()
        turn = [self.cross_rot(self.gravity, self.abs[f], H[f]) for f in range(n)]
        # Subtree sums, leaves first.
        total = list(turn)
        for j in reversed(range(n)):
            parent = self.links[j]["parent"]
            if parent is not None:
                total[parent] = total[parent] + total[j]
        G = []
        for j, link in enumerate(self.links):
            if link["joint"] == "revolute":
                G.append(total[j])
            else:
                parent = link["parent"]
                rc = self.abs[parent] if parent is not None else None
                G.append(-subtree_mass[j] * self.dot_rot(self.gravity, rc, self.axis[j]))
        return cs.vertcat(*G)

    def potential_energy(self):
        """V = −Σ m g·x_c = −g·H_base − Σ_f g·(R_f H_f)."""
        _, H, base = self.frame_moments()
        V = -self.dot(self.gravity, base)
        for f in range(len(self.links)):
            V -= self.dot_rot(self.gravity, self.abs[f], H[f])
        return V

    def path(self, ref):
        """The links from a point's link up to the base."""
        i, out = ref["link"], []
        while i is not None:
            out.append(i)
            i = self.links[i]["parent"]
        return out

    def local_segment(self, ref):
        return self.rot(self.abs[ref["link"]], self.vec(ref["point"]))

    def position(self, ref):
        if ref["link"] is None:  # fixed in the base frame
            return cs.vertcat(*self.vec(ref["point"]))
        return cs.vertcat(*self.add(self.joint[ref["link"]], self.local_segment(ref)))

    def jacobian(self, ref):
        """∂x/∂q: ẑ × (x − o_j) for a revolute joint j on the path, R a_j for a prismatic one."""
        n = len(self.links)
        cols = [[cs.SX(0), cs.SX(0)] for _ in range(n)]
        if ref["link"] is not None:
            below = self.local_segment(ref)  # x − o_k
            for k in self.path(ref):
                parent = self.links[k]["parent"]
                if self.links[k]["joint"] == "revolute":
                    cols[k] = [-below[1], below[0]]
                else:
                    cols[k] = self.rot(self.abs[parent] if parent is not None else None, self.axis[k])
                below = self.add(below, self.segment[k])
        return cs.horzcat(*[cs.vertcat(*c) for c in cols])

    def bias(self, ref):
        """J̇ q̇, the acceleration at q̈ = 0: −Θ̇² w for each segment w turning with its frame's
        absolute angle Θ, and 2 Θ̇ q̇_k ẑ × (R a_k) for a prismatic joint k."""
        if ref["link"] is None:
            return cs.vertcat(cs.SX(0), cs.SX(0))
        i = ref["link"]
        w = self.local_segment(ref)
        acc = [-(self.omega[i] ** 2) * w[0], -(self.omega[i] ** 2) * w[1]]
        for k in self.path(ref):
            parent = self.links[k]["parent"]
            if parent is None:
                continue  # the base's offset does not turn (a base slider's q̈ is zero)
            spin = self.omega[parent]
            w = self.segment[k]
            acc = self.add(acc, [-(spin**2) * w[0], -(spin**2) * w[1]])
            if self.links[k]["joint"] == "prismatic":
                ra = self.rot(self.abs[parent], self.axis[k])
                coriolis = 2 * spin * self.qd[k]
                acc = self.add(acc, [-coriolis * ra[1], coriolis * ra[0]])
        return cs.vertcat(*acc)


def state_operations(exprs, state, inputs):
    """Operations of the CSE'd function of `exprs` that depend on `state` (the rest depends
    on parameters only, and the emitter computes it once per parameter set)."""
    f = cs.Function("count", inputs, cs.cse([cs.densify(e) for e in exprs]))
    state_inputs = {k for k, x in enumerate(inputs) if any(x is s for s in state)}
    varying, count = {}, 0
    for k in range(f.n_instructions()):
        op, args, res = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
        if op == cs.OP_INPUT:
            varying[res[0]] = args[0] in state_inputs
        elif op == cs.OP_CONST:
            varying[res[0]] = False
        elif op != cs.OP_OUTPUT:
            varying[res[0]] = any(varying[a] for a in args if a >= 0)
            count += varying[res[0]]
    return count


def coriolis(M, q, qd):
    """C q̇ from M by its Christoffel symbols, grouped on the products q̇_j q̇_k:
    (C q̇)_i = Σ_{j≤k} c_ijk q̇_j q̇_k with c_ijk = ∂M_ij/∂q_k + ∂M_ik/∂q_j − ∂M_jk/∂q_i
    (j < k) and c_ijj = ∂M_ij/∂q_j − ½ ∂M_jj/∂q_i. Structurally zero symbols are left out."""
    n = q.size1()
    D = [cs.jacobian(M[:, c], q) for c in range(n)]  # D[c][r, k] = ∂M_rc/∂q_k

    def d(r, c, k):
        return D[c][r, k]

    def combine(terms):
        """Σ sign·term, with a term and its negative left out when they are the same
        expression (M is symmetric, so ∂M_ik/∂q_j and ∂M_jk/∂q_i often are)."""
        terms = [(w, t) for w, t in terms if not t.is_zero()]
        kept = []
        for w, t in terms:
            match = next((x for x in kept if x[0] == -w and cs.is_equal(x[1], t, 64)), None)
            if match is not None:
                kept = [x for x in kept if x is not match]
            else:
                kept.append((w, t))
        total = None
        for w, t in kept:
            term = t if w == 1 else -t if w == -1 else w * t
            total = term if total is None else total + term
        return total

    out = []
    for i in range(n):
        total = cs.SX(0)
        for j in range(n):
            for k in range(j, n):
                if j < k:
                    coef = combine([(1, d(i, j, k)), (1, d(i, k, j)), (-1, d(j, k, i))])
                else:
                    coef = combine([(1, d(i, j, j)), (-0.5, d(j, j, i))])
                if coef is None or coef.is_zero():
                    continue
                total = total + coef * (qd[j] * qd[k])
        out.append(total)
    return cs.vertcat(*out)


def planar_lagrangian(model, sym, q, qd):
    """The notes' Lagrange form of a planar leg: the kinetic and potential energy of each
    branch from absolute angles and joint positions, and the point function of the same
    chain. Returns (T, V, point)."""
    links = model["links"]
    n = len(links)

    def vec(pair):
        return cs.vertcat(sym[pair[0]], sym[pair[1]])

    # Absolute angle and joint position of every link, from relative angles.
    angle = [None] * n
    joint = [None] * n
    for i, link in enumerate(links):
        parent = link["parent"]
        # A revolute joint turns the link by q about the joint point; a prismatic one
        # slides the joint point by q along a unit axis of the parent's frame.
        offset = vec(link["origin"])
        if link["joint"] == "prismatic":
            offset = offset + q[i] * cs.vertcat(*[cs.SX(a) for a in link["axis"]])
        turn = q[i] if link["joint"] == "revolute" else cs.SX(0)
        if parent is None:
            angle[i] = turn
            joint[i] = offset
        else:
            angle[i] = angle[parent] + turn
            joint[i] = joint[parent] + rotate(angle[parent], offset)

    def point(ref):
        i = ref["link"]
        if i is None:  # fixed in the base frame
            return vec(ref["point"])
        return joint[i] + rotate(angle[i], vec(ref["point"]))

    # The Lagrangian of each branch (the links under one base joint), then their sum.
    gravity = vec(model["gravity"])
    branch_of = [None] * n
    for i, link in enumerate(links):
        branch_of[i] = i if link["parent"] is None else branch_of[link["parent"]]
    kinetic = {b: 0 for b in set(branch_of)}
    potential = {b: 0 for b in set(branch_of)}
    for i, link in enumerate(links):
        b = branch_of[i]
        com = point({"link": i, "point": link["com"]})
        v_com = cs.jtimes(com, q, qd)
        omega = cs.jtimes(angle[i], q, qd)
        mass, inertia = sym[link["mass"]], sym[link["inertia"]]
        kinetic[b] += 0.5 * mass * cs.dot(v_com, v_com) + 0.5 * inertia * omega**2
        if link["rotor"] is not None:
            rotor_inertia, gear_ratio = sym[link["rotor"][0]], sym[link["rotor"][1]]
            kinetic[b] += 0.5 * rotor_inertia * gear_ratio**2 * qd[i] ** 2
        potential[b] += -mass * cs.dot(gravity, com)
    return kinetic, potential, point


def derive(model):
    """Returns {function name: (input names, [(output name, kind, expression)])}."""
    sym = {p["name"]: cs.SX.sym(p["name"]) for p in model["params"]}
    params = cs.vertcat(*[sym[p["name"]] for p in model["params"]])
    links = model["links"]
    n = len(links)
    q = cs.SX.sym("q", n)
    qd = cs.SX.sym("qd", n)

    spatial = model.get("dimension", 2) == 3
    if spatial:
        T_lagrange, V_lagrange, point = derive_spatial.lagrangian(model, sym, q, qd)
        kinetic, potential = {None: T_lagrange}, {None: V_lagrange}
    else:
        kinetic, potential, point = planar_lagrangian(model, sym, q, qd)
    # Springs: ½ k (q_a − q_b − rest)², or ½ k (q_a − rest)² on one joint.
    V_springs = 0
    G_springs = cs.SX(n, 1)
    for spring in model["springs"]:
        a, b = spring["a"], spring["b"]
        k, rest = sym[spring["stiffness"]], sym[spring["rest"]]
        stretch = q[a] - (q[b] if b is not None else 0) - rest
        V_springs += 0.5 * k * stretch**2
        G_springs[a] += k * stretch
        if b is not None:
            G_springs[b] -= k * stretch
    L = sum(kinetic[b] - potential[b] for b in kinetic) - V_springs

    # Lagrange's equations of L as written in the notes: what a CasADi user gets by
    # differentiating L (CasADi's C code of these is the benchmarks' peer).
    dL_dqd = cs.gradient(L, qd)
    M_lagrange = cs.jacobian(dL_dqd, qd)
    N_lagrange = cs.jtimes(dL_dqd, q, qd) - cs.gradient(L, q)
    def rod_length(c):
        return sym[c["distance"]] if c.get("distance") else None

    # And the closure's J = ∂φ/∂q and J̇ q̇ of the same kinematics, as the notes write them: a
    # point closure's rows are a − b, a rod's one row (|a − b|² − L²) / (2L).
    def closure_rows(c, d):
        L_rod = rod_length(c)
        return d if L_rod is None else (cs.dot(d, d) - L_rod**2) / (2 * L_rod)

    # (The Lagrange form's closure Jacobian is formed below, once a revolute closure's
    # turning rows can be written.)

    # The terms our generator emits, in link-local form (DESIGN.md §3): the mass matrix by
    # the composite-rigid-body recursion in each link's frame, the gravity forces from each
    # subtree's first moment and the gravity vector, C q̇ (below) from that M or from the
    # centres of mass, and point Jacobians and J̇ q̇ from the chain's segments.
    # Products of parameters are grouped apart from the joint angles' sines and cosines
    # (`c·(r·h) − s·(r×h)`), so that the emitter can compute them once per parameter set;
    # the entries of M then reduce to constants times sines and cosines of relative angles.
    # One sine and cosine per revolute joint; absolute orientations by angle addition.
    lk = (derive_spatial.RecursiveKinematics if spatial else LinkKinematics)(model, sym, q, qd)

    def turning_rows(c):
        """A revolute closure's two rows beyond its point: (R_a a)·(R_b u), (R_a a)·(R_b w),
        zero while link a's axis stays along link b's."""
        r = c["revolute"]
        rot = lambda ref: cs.SX.eye(3) if ref["link"] is None else lk.R[ref["link"]]
        along = cs.mtimes(rot(c["a"]), cs.SX(r["a"]))
        return cs.vertcat(*[cs.dot(along, cs.mtimes(rot(c["b"]), cs.SX(r[k]))) for k in ("u", "w")])

    if model["closures"]:
        phi_lagrange = cs.vertcat(
            *[
                cs.vertcat(closure_rows(c, point(c["a"]) - point(c["b"])), *([turning_rows(c)] if c.get("revolute") else []))
                for c in model["closures"]
            ]
        )
        J_lagrange = cs.jacobian(phi_lagrange, q)
        Jdot_qd_lagrange = cs.jtimes(cs.jtimes(phi_lagrange, q, qd), q, qd)
    else:
        J_lagrange, Jdot_qd_lagrange = cs.SX(0, n), cs.SX(0, 1)
    M = lk.mass_matrix()
    G = lk.gravity_forces() + G_springs
    M_qd = cs.mtimes(M, qd)
    T = 0.5 * cs.dot(qd, M_qd)
    V = lk.potential_energy() + V_springs
    D = cs.vertcat(*[sym[link["damping"]] * qd[i] for i, link in enumerate(links)])
    point = lk.position
    joint = [o if spatial else cs.vertcat(*o) for o in lk.joint]

    def stacked(refs):
        """Positions, Jacobian and J̇ q̇ of points (two rows each)."""
        if not refs:
            return cs.SX(0, 1), cs.SX(0, n), cs.SX(0, 1)
        return (
            cs.vertcat(*[lk.position(r) for r in refs]),
            cs.vertcat(*[lk.jacobian(r) for r in refs]),
            cs.vertcat(*[lk.bias(r) for r in refs]),
        )

    closures = model["closures"]
    if closures:
        rows = []
        for c in closures:
            pa, Ja, ba = stacked([c["a"]])
            pb, Jb, bb = stacked([c["b"]])
            d, Jd, bd = pa - pb, Ja - Jb, ba - bb
            L_rod = rod_length(c)
            if c.get("revolute"):
                # The point's three rows, then the axes' two, differentiated by CasADi.
                turn = turning_rows(c)
                J_turn = cs.jacobian(turn, q)
                rows.append((cs.vertcat(d, turn), cs.vertcat(Jd, J_turn), cs.vertcat(bd, cs.jtimes(cs.mtimes(J_turn, qd), q, qd))))
            elif L_rod is None:
                rows.append((d, Jd, bd))
            else:
                # φ = (dᵀd − L²)/(2L): φ̇ = dᵀ J_d q̇ / L, φ̈ = J q̈ + (ḋᵀḋ + dᵀ J̇_d q̇) / L.
                dd = cs.mtimes(Jd, qd)
                rows.append((closure_rows(c, d), cs.mtimes(d.T, Jd) / L_rod, (cs.dot(dd, dd) + cs.dot(d, bd)) / L_rod))
        phi, J, Jdot_qd = (cs.vertcat(*[r[i] for r in rows]) for i in range(3))
        closure_points = cs.horzcat(*[cs.horzcat(point(c["a"]), point(c["b"])) for c in closures])
    else:
        phi, J, Jdot_qd = cs.SX(0, 1), cs.SX(0, n), cs.SX(0, 1)
        closure_points = cs.SX(model.get("dimension", 2), 0)

    # C q̇ two ways, the same values: by the Christoffel symbols of the link-local M (compact
    # for short chains), or Σ m_k J_kᵀ (J̇_k q̇) over the centres of mass (a planar link's
    # rotation adds nothing, J_ω being constant), which grows more slowly with depth. The
    # one whose fused terms (M, N, J, J̇q̇) take fewer state-dependent operations is emitted.
    C_christoffel = coriolis(M, q, qd)
    if spatial:
        C_points = lk.coriolis_points()
    else:
        C_points = cs.SX(n, 1)
        for i, link in enumerate(links):
            com = {"link": i, "point": link["com"]}
            C_points += sym[link["mass"]] * cs.mtimes(lk.jacobian(com).T, lk.bias(com))
    N = min(
        (C_christoffel + G, C_points + G),
        key=lambda N: state_operations([M, N, J, Jdot_qd], [q, qd], [q, qd, params]),
    )

    foot, Jf, Jf_dot_qd = stacked([model["foot"]])
    tips = cs.horzcat(*[point({"link": i, "point": l["length"]}) for i, l in enumerate(links)])

    # The leg's size at q, which the runtime's tolerances scale with: the largest
    # coordinate of any joint or link tip in the base frame (max |x|, the first NaN-free).
    sizes = cs.vec(cs.fabs(cs.horzcat(*joint, tips)))
    leg_size = sizes[0]
    for k in range(1, sizes.numel()):
        leg_size = cs.fmax(leg_size, sizes[k])

    # Contact points: base-frame positions stacked (rows 2k, 2k + 1 are x, y of contact k),
    # their Jacobian and J̇_c q̇; the runtime projects them on the ground.
    xc, Jc, Jc_dot_qd = stacked([c["point"] for c in model["contacts"]])

    # Directional derivatives for the linearized dynamics (DESIGN.md §3.2): with the
    # accelerations `a` and the forces `f` (closures) and `lambda` (contacts, base frame)
    # as inputs, the products M a, Jᵀ f, J a are differentiated instead of M and J, so
    # every output is a matrix, never a tensor. J̇ = ∂(J q̇)/∂q: J's rows are gradients, so
    # ∂J_ij/∂q_k is symmetric in j, k.
    a = cs.SX.sym("a", n)
    f = cs.SX.sym("f", J.size1())
    lam = cs.SX.sym("lambda", Jc.size1())

    def dq(e):
        return cs.jacobian(e, q)

    Ma, Jtf, Ja = cs.mtimes(M, a), cs.mtimes(J.T, f), cs.mtimes(J, a)
    Jdot = dq(cs.mtimes(J, qd))
    Jc_dot = dq(cs.mtimes(Jc, qd))

    inputs = {"q": q, "qd": qd, "p": params, "a": a, "f": f, "lambda": lam}
    Q, QQ = ["q", "p"], ["q", "qd", "p"]
    terms = {
        "mass_matrix": (Q, [("mass_matrix", "matrix", M)]),
        "bias_forces": (QQ, [("bias_forces", "vector", N)]),
        "gravity_forces": (Q, [("gravity_forces", "vector", G)]),
        "damping_forces": (["qd", "p"], [("damping_forces", "vector", D)]),
        "closure_residual": (Q, [("closure_residual", "vector", phi)]),
        "constraint_jacobian": (Q, [("constraint_jacobian", "matrix", J)]),
        "constraint_bias": (QQ, [("constraint_bias", "vector", Jdot_qd)]),
        "foot_position": (Q, [("foot_position", "vector", foot)]),
        "foot_jacobian": (Q, [("foot_jacobian", "matrix", Jf)]),
        "foot_bias": (QQ, [("foot_bias", "vector", Jf_dot_qd)]),
        "kinetic_energy": (QQ, [("kinetic_energy", "scalar", T)]),
        "potential_energy": (Q, [("potential_energy", "scalar", V)]),
        "joint_positions": (Q, [("joint_positions", "matrix", cs.horzcat(*joint))]),
        "link_tips": (Q, [("link_tips", "matrix", tips)]),
        "closure_points": (Q, [("closure_points", "matrix", closure_points)]),
        "leg_size": (Q, [("leg_size", "scalar", leg_size)]),
        "contact_positions": (Q, [("contact_positions", "vector", xc)]),
        "contact_jacobian": (Q, [("contact_jacobian", "matrix", Jc)]),
        "contact_bias": (QQ, [("contact_bias", "vector", Jc_dot_qd)]),
        "dynamics_terms": (
            QQ,
            [
                ("mass_matrix", "matrix", M),
                ("bias_forces", "vector", N),
                ("constraint_jacobian", "matrix", J),
                ("constraint_bias", "vector", Jdot_qd),
            ],
        ),
        "mass_matrix_derivative": (["q", "a", "p"], [("mass_matrix_derivative", "matrix", dq(Ma))]),
        "bias_forces_derivatives": (
            QQ,
            [("bias_forces_q", "matrix", dq(N)), ("bias_forces_qd", "matrix", cs.jacobian(N, qd))],
        ),
        "constraint_derivatives": (
            ["q", "qd", "a", "f", "p"],
            [
                ("force_q", "matrix", dq(Jtf)),
                ("jacobian_q", "matrix", dq(Ja)),
                ("bias_q", "matrix", dq(Jdot_qd)),
                ("jacobian_rate", "matrix", Jdot),
            ],
        ),
        "contact_derivatives": (
            ["q", "qd", "a", "lambda", "p"],
            [
                ("force_q", "matrix", dq(cs.mtimes(Jc.T, lam))),
                ("jacobian_q", "matrix", dq(cs.mtimes(Jc, a))),
                ("bias_q", "matrix", dq(Jc_dot_qd)),
                ("jacobian_rate", "matrix", Jc_dot),
            ],
        ),
        # The fused form the runtime uses: one program, shared subexpressions. D q̇ is
        # linear in q̇ with constant D, so it enters only the q̇ derivative.
        "dynamics_derivatives": (
            ["q", "qd", "a", "f", "p"],
            [
                ("dynamics_q", "matrix", dq(Ma + N - Jtf)),
                ("dynamics_qd", "matrix", cs.jacobian(N + D, qd)),
                ("constraint_q", "matrix", dq(Ja + Jdot_qd)),
                ("jacobian_rate", "matrix", Jdot),
            ],
        ),
    }
    peer = {
        "q": q,
        "qd": qd,
        "p": params,
        "M": M_lagrange,
        "N": N_lagrange,
        "M_closed": M,
        "N_closed": N,
        "D": D,
        "J": J,
        "Jdot_qd": Jdot_qd,
        "J_lagrange": J_lagrange,
        "Jdot_qd_lagrange": Jdot_qd_lagrange,
    }
    points = cs.horzcat(cs.horzcat(*joint), tips, closure_points, foot)
    # Each revolute closure's (R_a â)·(R_b b̂): its turning rows vanish for antiparallel axes
    # too, which home_check refuses (the exports' second points would sit apart).
    def axes_dot(c):
        r = c["revolute"]
        b = [r["u"][1] * r["w"][2] - r["u"][2] * r["w"][1], r["u"][2] * r["w"][0] - r["u"][0] * r["w"][2], r["u"][0] * r["w"][1] - r["u"][1] * r["w"][0]]
        rot = lambda ref: cs.SX.eye(3) if ref["link"] is None else lk.R[ref["link"]]
        return cs.dot(cs.mtimes(rot(c["a"]), cs.SX(r["a"])), cs.mtimes(rot(c["b"]), cs.SX(b)))

    revolute = [c for c in closures if c.get("revolute")]
    axes = cs.vertcat(*[axes_dot(c) for c in revolute]) if revolute else cs.SX(0, 1)
    numeric = cs.Function("home_check", [q, params], [phi, J, points, M, axes])
    return inputs, terms, peer, numeric


# Relative accuracy of an assembled pose (times the leg's size): the runtime's default
# (`Tolerance`) and the limit `gen` checks the home pose against (gen.rs).
ASSEMBLY_TOLERANCE = 1000 * 2.220446049250313e-16


def home_check(model, numeric):
    """The spec's home pose, assembled with every joint free (minimal-norm Gauss-Newton with the
    spec's parameters), and the structure there: the rank of J, which closure rows repeat the
    others (a parallelogram closed twice), and the mobility NQ - rank J. Rust turns a home that
    does not assemble into a located spec error."""
    import numpy as np

    p = [prm["default"] for prm in model["params"]]
    home = np.array(model["home"], dtype=float)
    n = len(home)

    def evaluate(q):
        phi, J, points, _, _ = numeric(q, p)
        return np.array(phi).reshape(-1), np.array(J).reshape(-1, n), np.array(points)

    phi, J, points = evaluate(home)
    scale = max(float(np.abs(points).max()), 1e-300)
    raw = float(np.abs(phi).max()) if phi.size else 0.0
    # The row open widest at home as written: Rust names its closure in the error.
    worst_row = int(np.argmax(np.abs(phi))) if phi.size else None
    q = home.copy()
    for _ in range(100):
        if phi.size == 0 or np.abs(phi).max() <= ASSEMBLY_TOLERANCE * scale:
            break
        step = np.linalg.lstsq(J, -phi, rcond=None)[0]
        alpha, cost = 1.0, float(phi @ phi)
        while alpha > 1e-12:
            trial = q + alpha * step
            phi_t, _, _ = evaluate(trial)
            if float(phi_t @ phi_t) < cost:
                break
            alpha *= 0.5
        else:
            break
        q = trial
        phi, J, points = evaluate(q)
    residual = float(np.abs(phi).max()) if phi.size else 0.0
    redundant = []
    rank = 0
    if phi.size:
        sv = np.linalg.svd(J, compute_uv=False)
        cut = 1e-8 * max(float(sv[0]), 1e-300)
        kept = []
        for r in range(J.shape[0]):
            trial = J[kept + [r], :]
            if np.linalg.matrix_rank(trial, tol=cut) > len(kept):
                kept.append(r)
            else:
                redundant.append(r)
        rank = len(kept)
    # M must be positive definite for the runtime's Cholesky: a massless link is allowed
    # only where other links' mass moves with its joint (a floating base's intermediate
    # links). Otherwise name the joint that carries no inertia.
    M = np.array(numeric(q, p)[3])
    # Revolute closures whose axes point against each other at the assembled home.
    dots = np.array(numeric(q, p)[4]).reshape(-1)
    revolute = [k for k, c in enumerate(model["closures"]) if c.get("revolute")]
    antiparallel = [k for k, d in zip(revolute, dots) if d < 0.0]
    eigenvalues, vectors = np.linalg.eigh(0.5 * (M + M.T))
    massless_joint = None
    if eigenvalues[0] <= 1e-12 * max(float(eigenvalues[-1]), 1e-300):
        massless_joint = int(np.argmax(np.abs(vectors[:, 0])))
    return {
        "massless_joint": massless_joint,
        "antiparallel": antiparallel,
        "scale": scale,
        "raw_residual": raw,
        "worst_row": worst_row,
        "residual": residual,
        "assembled": [float(x) for x in q],
        "moved": float(np.abs(q - home).max()),
        "rank": rank,
        "redundant_rows": redundant,
        "mobility": n - rank,
    }


def casadi_c(model, peer, redundant_rows):
    """CasADi's own C code generation, the benchmarks' peers, for two derivations of the
    same terms: the notes' Lagrange form (`<model>_dynamics_terms`,
    `<model>_forward_dynamics`: M and N by differentiating L, what a CasADi user following
    the notes writes) and the closed form our generator uses (`<model>_closed_dynamics_terms`,
    `<model>_closed_forward_dynamics`: the very expressions we emit, M by the composite
    rigid bodies in link frames, C q̇ by Christoffel symbols, G from the subtrees' first
    moments; what a CasADi user who wrote that form gets). Each pair is the fused terms
    (M, N, J, J̇q̇) and forward dynamics (the KKT system solved by CasADi's `solve`)."""
    name = model["name"]
    q, qd, p = peer["q"], peer["qd"], peer["p"]
    D = peer["D"]
    n, nu, nc = q.size1(), len(model["actuated"]), peer["J"].size1()
    # Closure rows that repeat the others carry no force (the runtime's convention): CasADi
    # solves the KKT system of the independent rows.
    keep = [r for r in range(nc) if r not in redundant_rows]
    u = cs.SX.sym("u", nu)
    B = cs.SX(n, nu)
    for k, a in enumerate(model["actuated"]):
        B[a, k] = 1
    dense = lambda exprs: cs.cse([cs.densify(e) for e in exprs])
    cg = cs.CodeGenerator(f"{name}_casadi", {"with_header": False})
    forms = [
        ("", peer["M"], peer["N"], peer["J_lagrange"], peer["Jdot_qd_lagrange"]),
        ("closed_", peer["M_closed"], peer["N_closed"], peer["J"], peer["Jdot_qd"]),
    ]
    # A spatial leg's KKT system solved symbolically by CasADi (and its `jacobian`) is
    # hundreds of thousands of lines of C that take minutes to compile at -O3, a form no
    # CasADi user would pick for a leg of that size: its peers are the fused terms only.
    spatial = model.get("dimension", 2) == 3
    for prefix, M, N, J, Jdot_qd in forms:
        Jk, Jdot_qd_k = J[keep, :], Jdot_qd[keep]
        fused = cs.Function(f"{name}_{prefix}dynamics_terms", [q, qd, p], dense([M, N, J, Jdot_qd]))
        if spatial:
            cg.add(fused)
            continue
        if keep:
            A = cs.blockcat([[M, -Jk.T], [Jk, cs.SX(len(keep), len(keep))]])
            b = cs.vertcat(cs.mtimes(B, u) - N - D, -Jdot_qd_k)
        else:
            A, b = M, cs.mtimes(B, u) - N - D
        x = cs.solve(A, b)
        forces = cs.SX(nc, 1)
        for k, r in enumerate(keep):
            forces[r] = x[n + k]
        fd = cs.Function(
            f"{name}_{prefix}forward_dynamics", [q, qd, u, p], dense([x[:n], forces if nc else cs.SX(0, 1)])
        )
        cg.add(fused)
        cg.add(fd)
        if not prefix:
            continue
        # The derivatives of forward dynamics as a CasADi user gets them: `jacobian` of
        # the same solution, q̈ and F with their derivatives by q, q̇ and u (what ours
        # returns). Of the closed form only, the stronger peer: the Lagrange form's C is
        # larger and slower, and compiling both would double the peers' build.
        qdd_k, forces_k = x[:n], forces if nc else cs.SX(0, 1)
        jac = [cs.jacobian(e, v) for e in (qdd_k, forces_k) for v in (q, qd, u)]
        fdd = cs.Function(
            f"{name}_{prefix}forward_dynamics_derivatives", [q, qd, u, p], dense([qdd_k, forces_k] + jac)
        )
        cg.add(fdd)
    return (
        f"/* @generated by `cargo xtask gen` from leg-models/specs/{name}.toml: CasADi's own C code of the\n"
        f"   same terms (Lagrange and closed form), for the benchmarks only. Do not edit. */\n" + cg.dump()
    )


def export(name, f, input_names):
    """Turns an SXFunction into an SSA straight-line program."""
    instructions = []
    work = {}  # CasADi work slot -> SSA id
    consts = {}  # exact float -> SSA id
    input_ids = {}
    outputs = [[None] * f.nnz_out(i) for i in range(f.n_out())]

    def emit(instr):
        instructions.append(instr)
        return len(instructions) - 1

    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        args = f.instruction_input(k)
        res = f.instruction_output(k)
        if op == cs.OP_INPUT:
            key = (args[0], args[1])
            if key not in input_ids:
                input_ids[key] = emit({"op": "input", "input": args[0], "index": args[1]})
            work[res[0]] = input_ids[key]
        elif op == cs.OP_OUTPUT:
            outputs[res[0]][res[1]] = work[args[0]]
        elif op == cs.OP_CONST:
            value = f.instruction_constant(k)
            if not math.isfinite(value):
                raise DerivationError(f"{name}: non-finite constant {value}")
            key = (value, math.copysign(1.0, value))
            if key not in consts:
                consts[key] = emit({"op": "const", "value": value})
            work[res[0]] = consts[key]
        elif op in UNARY:
            work[res[0]] = emit({"op": UNARY[op], "args": [work[args[0]]]})
        elif op in BINARY:
            work[res[0]] = emit({"op": BINARY[op], "args": [work[args[0]], work[args[1]]]})
        else:
            raise DerivationError(f"{name}: CasADi operation {OP_NAMES.get(op, op)} has no IR form")
    for i, entries in enumerate(outputs):
        if any(e is None for e in entries):
            raise DerivationError(f"{name}: output {i} has unassigned entries")
    return instructions, outputs


def main():
    model = json.load(sys.stdin)
    inputs, terms, peer, numeric = derive(model)
    home = home_check(model, numeric)
    functions = []
    for name, (input_names, outs) in terms.items():
        exprs = [cs.densify(e) for _, _, e in outs]
        exprs = cs.cse(exprs)
        f = cs.Function(name, [inputs[i] for i in input_names], exprs)
        instructions, entries = export(name, f, input_names)
        functions.append(
            {
                "name": name,
                "inputs": input_names,
                "outputs": [
                    {"name": oname, "kind": kind, "rows": e.size1(), "cols": e.size2(), "entries": ent}
                    for (oname, kind, e), ent in zip(outs, entries)
                ],
                "instructions": instructions,
            }
        )
    # json.dumps, not json.dump: dump streams through the pure-Python encoder, 5 of the
    # 8 s of cassie_leg's derivation; dumps takes the C encoder.
    sys.stdout.write(json.dumps(
        {
            "casadi_version": cs.__version__,
            "spec_sha256": hashlib.sha256(model["spec_text"].encode("utf-8")).hexdigest(),
            "functions": functions,
            "casadi_c": casadi_c(model, peer, home["redundant_rows"]),
            "home_check": home,
        }
    ))


if __name__ == "__main__":
    try:
        main()
    except DerivationError as e:
        print(f"derivation failed: {e}", file=sys.stderr)
        sys.exit(1)
