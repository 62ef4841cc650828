"""Spatial kinematics for derive.py (DESIGN.md §3.3): a tree of links on revolute and
prismatic joints about any axis, in 3-D. Imported by derive.py for a spec whose gravity
has three entries; the planar legs never reach this module.

Each link's frame sits at its joint point. At q = 0 it is its parent's frame moved by
`origin` and turned by the constant `orientation`; a revolute joint then turns it by q
about the unit `axis` of its own frame (Rodrigues' formula: one sine and cosine per
joint), a prismatic joint slides it by q along that axis. `R[i]` is the link's
orientation in the base frame, `joint[i]` its joint point there, `z[i]` its joint axis
there (`R[i] a_i`, which the joint's own rotation leaves fixed).

The emitted terms use the geometric Jacobians: a point's column of joint k is
`z_k × (x − o_k)` (revolute) or `z_k` (prismatic), a link's angular column `z_k` for each
revolute joint above it, and M = Σ m J_vᵀ J_v + J_ωᵀ (R I Rᵀ) J_ω over the centres of mass.
The Lagrange peer (`lagrangian`) differentiates positions and orientations instead:
v = ∂c/∂q q̇ and ω from Rᵀ Ṙ, so it checks the Jacobians rather than sharing them.
"""

import casadi as cs


def _vec(sym, names):
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


class SpatialKinematics:
    """The interface derive.py reads of a leg's kinematics (as `LinkKinematics`):
    `position`, `jacobian` and `bias` of points, `joint` positions, `mass_matrix`,
    `gravity_forces`, `potential_energy` and `coriolis_points`."""

    def __init__(self, model, sym, q, qd):
        self.links = links = model["links"]
        self.sym, self.q, self.qd = sym, q, qd
        self.gravity = _vec(sym, model["gravity"])
        n = len(links)
        self.R, self.joint, self.z = [None] * n, [None] * n, [None] * n
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
            self.z[i] = cs.mtimes(self.R[i], _const(axis))

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
        """∂x/∂q: z_k × (x − o_k) for a revolute joint k above the point, z_k for a
        prismatic one."""
        n = len(self.links)
        cols = [cs.SX(3, 1) for _ in range(n)]
        if ref["link"] is not None:
            x = self.position(ref)
            for k in self.path(ref["link"]):
                if self.links[k]["joint"] == "revolute":
                    cols[k] = cs.cross(self.z[k], x - self.joint[k])
                else:
                    cols[k] = self.z[k]
        return cs.horzcat(*cols)

    def angular_jacobian(self, i):
        """ω_i = J_ω q̇: the axes z_k of the revolute joints above link i."""
        n = len(self.links)
        cols = [cs.SX(3, 1) for _ in range(n)]
        for k in self.path(i):
            if self.links[k]["joint"] == "revolute":
                cols[k] = self.z[k]
        return cs.horzcat(*cols)

    def bias(self, ref):
        """J̇ q̇ = ∂(J q̇)/∂q q̇, the point's acceleration at q̈ = 0."""
        return cs.jtimes(cs.mtimes(self.jacobian(ref), self.qd), self.q, self.qd)

    def com(self, i):
        return {"link": i, "point": self.links[i]["com"]}

    def world_inertia(self, i):
        R = self.R[i]
        return cs.mtimes(cs.mtimes(R, _inertia(self.sym, self.links[i]["inertia"])), R.T)

    def mass_matrix(self):
        """Σ m J_vᵀ J_v + J_ωᵀ (R I Rᵀ) J_ω over the links' centres of mass, and the
        reflected rotor inertia I·N² on the actuated joints' diagonal."""
        n = len(self.links)
        M = cs.SX(n, n)
        for i, link in enumerate(self.links):
            Jv, Jw = self.jacobian(self.com(i)), self.angular_jacobian(i)
            M += self.sym[link["mass"]] * cs.mtimes(Jv.T, Jv)
            M += cs.mtimes(cs.mtimes(Jw.T, self.world_inertia(i)), Jw)
            rotor = link["rotor"]
            if rotor is not None:
                M[i, i] += self.sym[rotor[0]] * self.sym[rotor[1]] ** 2
        return M

    def coriolis_points(self):
        """C q̇ = Σ m J_vᵀ (J̇_v q̇) + J_ωᵀ (I_w J̇_ω q̇ + ω × I_w ω), the Newton–Euler form."""
        n = len(self.links)
        C = cs.SX(n, 1)
        for i, link in enumerate(self.links):
            com = self.com(i)
            Jv, Jw = self.jacobian(com), self.angular_jacobian(i)
            C += self.sym[link["mass"]] * cs.mtimes(Jv.T, self.bias(com))
            omega = cs.mtimes(Jw, self.qd)
            Iw = self.world_inertia(i)
            alpha = cs.jtimes(omega, self.q, self.qd)
            C += cs.mtimes(Jw.T, cs.mtimes(Iw, alpha) + cs.cross(omega, cs.mtimes(Iw, omega)))
        return C

    def gravity_forces(self):
        """G = ∂V/∂q = −Σ m J_vᵀ g over the centres of mass."""
        n = len(self.links)
        G = cs.SX(n, 1)
        for i, link in enumerate(self.links):
            G -= self.sym[link["mass"]] * cs.mtimes(self.jacobian(self.com(i)).T, self.gravity)
        return G

    def potential_energy(self):
        """V = −Σ m g·c."""
        V = cs.SX(0)
        for i, link in enumerate(self.links):
            V -= self.sym[link["mass"]] * cs.dot(self.gravity, self.position(self.com(i)))
        return V


def lagrangian(model, sym, q, qd):
    """The notes' Lagrange form in 3-D: kinetic and potential energy from the positions
    and orientations alone (v = ċ, [ω]ₓ = Rᵀ Ṙ in the link frame), and the point function
    of the same chain. Returns (T, V, point)."""
    kin = SpatialKinematics(model, sym, q, qd)
    T, V = cs.SX(0), cs.SX(0)
    for i, link in enumerate(model["links"]):
        c = kin.position(kin.com(i))
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
