"""Spatial kinematics for derive.py (DESIGN.md §3.3): a tree of links on revolute and
prismatic joints about any axis, in 3-D. Imported by derive.py for a spec whose gravity
has three entries; the planar legs never reach this module.

Each link's frame sits at its joint point. At q = 0 it is its parent's frame moved by
`origin` and turned by the constant `orientation`; a revolute joint then turns it by q
about the unit `axis` of its own frame (Rodrigues' formula: one sine and cosine per
joint), a prismatic joint slides it by q along that axis.

The emitted terms come from recursions in the links' own frames (`RecursiveKinematics`:
velocities passed down the tree, Newton–Euler for C q̇ and G, composite rigid bodies for
M). The Lagrange peer (`lagrangian`) differentiates positions and orientations composed in
the base frame instead (`WorldChain`: v = ∂c/∂q q̇ and ω from Rᵀ Ṙ), so it checks the
recursions rather than sharing them.
"""

import casadi as cs


def _vec(sym, names):
    """The parameters `names` as a vector; none (a ball joint's inner frames): zero."""
    if not names:
        return cs.SX(3, 1)
    return cs.vertcat(*[sym[n] for n in names])


def _const(v):
    return cs.vertcat(*[cs.SX(x) for x in v])


def _matrix(rows):
    return cs.vertcat(*[cs.horzcat(*[cs.SX(x) for x in row]) for row in rows])


def _skew(a):
    return cs.vertcat(
        cs.horzcat(cs.SX(0), -a[2], a[1]),
        cs.horzcat(a[2], cs.SX(0), -a[0]),
        cs.horzcat(-a[1], a[0], cs.SX(0)),
    )


def _axis_rotation(axis, angle):
    """R(θ) = I + sin θ [a]ₓ + (1 − cos θ) [a]ₓ² of a constant unit axis a: its entries
    are constants times sin θ and 1 − cos θ."""
    K = _skew(_const(axis))
    K2 = cs.mtimes(K, K)
    s, c = cs.sin(angle), cs.cos(angle)
    R = cs.SX.eye(3)
    for r in range(3):
        for col in range(3):
            terms = cs.SX(1 if r == col else 0)
            if float(K[r, col]) != 0.0:
                terms = terms + s * K[r, col]
            if float(K2[r, col]) != 0.0:
                terms = terms + (1 - c) * K2[r, col]
            R[r, col] = terms
    return R


def _inertia(sym, entries):
    """The 3 × 3 tensor of `[xx, yy, zz, xy, xz, yz]` parameter names (None: zero)."""
    e = [sym[n] if n is not None else cs.SX(0) for n in entries]
    xx, yy, zz, xy, xz, yz = e
    return cs.vertcat(cs.horzcat(xx, xy, xz), cs.horzcat(xy, yy, yz), cs.horzcat(xz, yz, zz))


class WorldChain:
    """Positions and orientations in the base frame composed link by link (`R[i]`,
    `joint[i]`), for the Lagrange peer: it differentiates these, so it shares nothing
    with the recursions of `RecursiveKinematics` but the chain's geometry."""

    def __init__(self, model, sym, q):
        self.links = links = model["links"]
        self.sym = sym
        self.gravity = _vec(sym, model["gravity"])
        n = len(links)
        self.R, self.joint = [None] * n, [None] * n
        for i, link in enumerate(links):
            parent = link["parent"]
            offset = _vec(sym, link["origin"])
            O = _matrix(link["orientation"]) if link.get("orientation") is not None else None
            axis = link["axis"]
            if link["joint"] == "revolute":
                turn = _axis_rotation(axis, q[i])
                rel = cs.mtimes(O, turn) if O is not None else turn
            else:
                slide = _const(axis) if O is None else cs.mtimes(O, _const(axis))
                offset = offset + q[i] * slide
                rel = O if O is not None else cs.SX.eye(3)
            if parent is None:
                self.R[i] = rel
                self.joint[i] = offset
            else:
                self.R[i] = cs.mtimes(self.R[parent], rel)
                self.joint[i] = self.joint[parent] + cs.mtimes(self.R[parent], offset)

    def position(self, ref):
        if ref["link"] is None:  # fixed in the base frame
            return _vec(self.sym, ref["point"])
        i = ref["link"]
        return self.joint[i] + cs.mtimes(self.R[i], _vec(self.sym, ref["point"]))


def _hoistable(v, state):
    return all(not cs.depends_on(v[k], state) for k in range(v.size1()))


class RecursiveKinematics:
    """The emitted terms of a spatial leg, by recursions over the tree in each link's own
    frame (Featherstone, *Rigid Body Dynamics Algorithms*, 2008, ch. 5 and 6), the 3-D form
    of the planar `LinkKinematics`:

    - velocities and the accelerations at q̈ = 0 passed from parent to child
      (`ω_i = R_relᵀ ω_λ + a_i q̇_i`, …), so a point's J̇ q̇ is its link's bias acceleration;
    - C q̇ by the Newton–Euler pass with those accelerations (gravity off), G by the same
      pass at rest with the base accelerating by −g, M by composite rigid bodies carried
      from leaf to root in their parents' frames;
    - a point's Jacobian column of joint k as `R_k (a_k × r_k)` (revolute) or `R_k a_k`
      (prismatic), `r_k` the point in k's frame built from the point up.

    Every link's relative rotation is `R_rel = O (I + s K + (1 − c) K²)` (O its constant
    orientation, K the skew matrix of its unit axis): a parameter-only vector turned by it
    is `O v + s (O K v) + (1 − c)(O K² v)`, three parameter-only vectors the emitter
    computes once per parameter set. `joint[i]` and `R[i]` are the link's origin and
    orientation in the base frame (positions, the points to draw)."""

    def __init__(self, model, sym, q, qd):
        self.links = links = model["links"]
        self.sym, self.q, self.qd = sym, q, qd
        self.state = cs.vertcat(q, qd)
        self.gravity = _vec(sym, model["gravity"])
        n = len(links)
        self.axis = [_const(link["axis"]) for link in links]
        # R_rel's constant factors: (O, O K, O K²), O the identity where the spec has none.
        self.factors, self.rel, self.offset = [None] * n, [None] * n, [None] * n
        self.R, self.joint = [None] * n, [None] * n
        for i, link in enumerate(links):
            O = _matrix(link["orientation"]) if link.get("orientation") is not None else cs.SX.eye(3)
            offset = _vec(sym, link["origin"])
            if link["joint"] == "revolute":
                K = _skew(self.axis[i])
                s, c = cs.sin(q[i]), cs.cos(q[i])
                self.factors[i] = (O, cs.mtimes(O, K), cs.mtimes(O, cs.mtimes(K, K)), s, 1 - c)
                self.rel[i] = cs.mtimes(O, _axis_rotation(link["axis"], q[i]))
            else:
                self.factors[i] = (O, None, None, None, None)
                self.rel[i] = O
                offset = offset + q[i] * cs.mtimes(O, self.axis[i])
            self.offset[i] = offset
            parent = link["parent"]
            if parent is None:
                self.R[i], self.joint[i] = self.rel[i], offset
            else:
                self.R[i] = cs.mtimes(self.R[parent], self.rel[i])
                self.joint[i] = self.joint[parent] + cs.mtimes(self.R[parent], offset)
        self._velocities()

    # Rotations by a link's relative rotation, parameter-only work grouped for hoisting.
    def turn(self, i, v):
        """R_rel v (child frame to parent frame)."""
        O, OK, OK2, s, omc = self.factors[i]
        if s is not None and _hoistable(v, self.state):
            return cs.mtimes(O, v) + s * cs.mtimes(OK, v) + omc * cs.mtimes(OK2, v)
        return cs.mtimes(self.rel[i], v)

    def unturn(self, i, v):
        """R_relᵀ v (parent frame to child frame)."""
        return cs.mtimes(self.rel[i].T, v)

    def _velocities(self):
        """ω, origin velocity v, and at q̈ = 0 the angular acceleration α and the origin's
        acceleration A, each in its link's frame (the base at rest, not accelerating)."""
        n = len(self.links)
        zero = cs.SX(3, 1)
        self.omega, self.vel, self.alpha, self.acc = [None] * n, [None] * n, [None] * n, [None] * n
        for i, link in enumerate(self.links):
            parent = link["parent"]
            p = self.offset[i]
            if parent is None:
                w, v, al, A = zero, zero, zero, zero
            else:
                w, v, al, A = self.omega[parent], self.vel[parent], self.alpha[parent], self.acc[parent]
            motion = self.axis[i] * self.qd[i]
            A = A + cs.cross(al, p) + cs.cross(w, cs.cross(w, p))
            v = v + cs.cross(w, p)
            if link["joint"] == "prismatic":
                slide = cs.mtimes(self.rel[i], motion)  # parent frame
                A = A + 2 * cs.cross(w, slide)
            w, v, al, A = self.unturn(i, w), self.unturn(i, v), self.unturn(i, al), self.unturn(i, A)
            if link["joint"] == "revolute":
                al = al + cs.cross(w, motion)
                w = w + motion
            else:
                v = v + motion
            self.omega[i], self.vel[i], self.alpha[i], self.acc[i] = w, v, al, A

    def own_inertia(self, i):
        """Mass, first moment h = m c and the inertia about the joint point, link frame."""
        link = self.links[i]
        if link.get("massless"):
            return cs.SX(0), cs.SX(3, 1), cs.SX(3, 3)
        m = self.sym[link["mass"]]
        c = _vec(self.sym, link["com"])
        h = m * c
        about = _inertia(self.sym, link["inertia"]) - m * cs.mtimes(_skew(c), _skew(c))
        return m, h, about

    def path(self, i):
        out = []
        while i is not None:
            out.append(i)
            i = self.links[i]["parent"]
        return out

    def position(self, ref):
        if ref["link"] is None:  # fixed in the base frame
            return _vec(self.sym, ref["point"])
        i = ref["link"]
        return self.joint[i] + cs.mtimes(self.R[i], _vec(self.sym, ref["point"]))

    def jacobian(self, ref):
        """∂x/∂q, column k `R_k (a_k × r_k)` (revolute) or `R_k a_k` (prismatic)."""
        n = len(self.links)
        cols = [cs.SX(3, 1) for _ in range(n)]
        if ref["link"] is not None:
            r = _vec(self.sym, ref["point"])  # the point in link k's frame
            for k in self.path(ref["link"]):
                if self.links[k]["joint"] == "revolute":
                    cols[k] = cs.mtimes(self.R[k], cs.cross(self.axis[k], r))
                else:
                    cols[k] = cs.mtimes(self.R[k], self.axis[k])
                r = self.offset[k] + self.turn(k, r)
        return cs.horzcat(*cols)

    def bias(self, ref):
        """J̇ q̇: the point's acceleration at q̈ = 0, `R_i (A_i + α_i × r + ω_i × (ω_i × r))`."""
        if ref["link"] is None:
            return cs.SX(3, 1)
        i = ref["link"]
        r = _vec(self.sym, ref["point"])
        w = self.omega[i]
        local = self.acc[i] + cs.cross(self.alpha[i], r) + cs.cross(w, cs.cross(w, r))
        return cs.mtimes(self.R[i], local)

    def _project(self, i, moment, force):
        """S_iᵀ (n, f) at joint i (its frame)."""
        if self.links[i]["joint"] == "revolute":
            return cs.dot(self.axis[i], moment)
        return cs.dot(self.axis[i], force)

    def _carry(self, i, moment, force):
        """A force (moment about link i's joint point, force), link i's frame, expressed at
        its parent's joint point in the parent's frame."""
        f = self.turn(i, force)
        return self.turn(i, moment) + cs.cross(self.offset[i], f), f

    def _newton_euler(self, accelerations):
        """Joint forces of the links' inertial forces, `(n_i, f_i)` per link from
        `accelerations(i, m, h, I)`, summed from the leaves to the root."""
        n = len(self.links)
        moment, force = [None] * n, [None] * n
        for i in range(n):
            moment[i], force[i] = accelerations(i, *self.own_inertia(i))
        tau = [None] * n
        for i in reversed(range(n)):
            tau[i] = self._project(i, moment[i], force[i])
            parent = self.links[i]["parent"]
            if parent is not None:
                nm, nf = self._carry(i, moment[i], force[i])
                moment[parent] = moment[parent] + nm
                force[parent] = force[parent] + nf
        return cs.vertcat(*tau)

    def coriolis_points(self):
        """C q̇: the Newton–Euler pass at q̈ = 0 without gravity,
        f = m A + α × h + ω × (ω × h), n = I α + ω × (I ω) + h × A (about the joint)."""

        def inertial(i, m, h, I):
            w, al, A = self.omega[i], self.alpha[i], self.acc[i]
            f = m * A + cs.cross(al, h) + cs.cross(w, cs.cross(w, h))
            nm = cs.mtimes(I, al) + cs.cross(w, cs.mtimes(I, w)) + cs.cross(h, A)
            return nm, f

        return self._newton_euler(inertial)

    def gravity_in_frames(self):
        g = [None] * len(self.links)
        for i, link in enumerate(self.links):
            parent = link["parent"]
            g[i] = self.unturn(i, self.gravity if parent is None else g[parent])
        return g

    def gravity_forces(self):
        """G = ∂V/∂q: the Newton–Euler pass at rest with the base accelerating by −g,
        f = −m g_i, n = −h × g_i (g_i gravity in link i's frame)."""
        g = self.gravity_in_frames()
        return self._newton_euler(lambda i, m, h, I: (-cs.cross(h, g[i]), -m * g[i]))

    def potential_energy(self):
        """V = −Σ g·(m o_i + R_i h_i)."""
        V = cs.SX(0)
        for i in range(len(self.links)):
            m, h, _ = self.own_inertia(i)
            V -= cs.dot(self.gravity, m * self.joint[i] + cs.mtimes(self.R[i], h))
        return V

    def mass_matrix(self):
        """M by composite rigid bodies: each subtree's (m, h, I) in its root link's frame,
        carried to the parent by `h' = R h + m p`,
        `I' = R I Rᵀ − m [p]ₓ² − [p]ₓ [R h]ₓ − [R h]ₓ [p]ₓ`; then M_ii = S_iᵀ I_i S_i and the
        force I_i S_i carried up the chain for M_ji. Reflected rotor inertia on the diagonal."""
        n = len(self.links)
        comp = [list(self.own_inertia(i)) for i in range(n)]
        for j in reversed(range(n)):
            parent = self.links[j]["parent"]
            if parent is None:
                continue
            m, h, I = comp[j]
            p = self.offset[j]
            Rh = self.turn(j, h)
            R = self.rel[j]
            P, H = _skew(p), _skew(Rh)
            moved = cs.mtimes(cs.mtimes(R, I), R.T) - m * cs.mtimes(P, P) - cs.mtimes(P, H) - cs.mtimes(H, P)
            comp[parent][0] = comp[parent][0] + m
            comp[parent][1] = comp[parent][1] + Rh + m * p
            comp[parent][2] = comp[parent][2] + moved
        M = [[None] * n for _ in range(n)]
        for i, link in enumerate(self.links):
            m, h, I = comp[i]
            a = self.axis[i]
            if link["joint"] == "revolute":
                moment, force = cs.mtimes(I, a), cs.cross(a, h)
            else:
                moment, force = cs.cross(h, a), m * a
            M[i][i] = self._project(i, moment, force)
            rotor = link["rotor"]
            if rotor is not None:
                M[i][i] = M[i][i] + self.sym[rotor[0]] * self.sym[rotor[1]] ** 2
            j = i
            while self.links[j]["parent"] is not None:
                moment, force = self._carry(j, moment, force)
                j = self.links[j]["parent"]
                M[i][j] = M[j][i] = self._project(j, moment, force)
        return cs.vertcat(*[cs.horzcat(*[M[r][c] if M[r][c] is not None else cs.SX(0) for c in range(n)]) for r in range(n)])


def lagrangian(model, sym, q, qd):
    """The notes' Lagrange form in 3-D: kinetic and potential energy from the positions
    and orientations alone (v = ċ, [ω]ₓ = Rᵀ Ṙ in the link frame), and the point function
    of the same chain. Returns (T, V, point)."""
    kin = WorldChain(model, sym, q)
    T, V = cs.SX(0), cs.SX(0)
    for i, link in enumerate(model["links"]):
        if link.get("massless"):
            continue
        c = kin.position({"link": i, "point": link["com"]})
        v = cs.jtimes(c, q, qd)
        R = kin.R[i]
        W = cs.mtimes(R.T, cs.jtimes(R, q, qd))  # [ω]ₓ in the link frame
        omega = cs.vertcat(W[2, 1], W[0, 2], W[1, 0])
        m = sym[link["mass"]]
        I = _inertia(sym, link["inertia"])
        T += 0.5 * m * cs.dot(v, v) + 0.5 * cs.dot(omega, cs.mtimes(I, omega))
        if link["rotor"] is not None:
            T += 0.5 * sym[link["rotor"][0]] * sym[link["rotor"][1]] ** 2 * qd[i] ** 2
        V += -m * cs.dot(kin.gravity, c)
    return T, V, kin.position
