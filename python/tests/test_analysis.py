"""The design measures from Python (`Leg.design_measures`, `foot_inverse_inertia`,
`impact_mitigation`, `workspace`) against numpy computations from the leg's own terms
(constraint and foot Jacobians, mass matrix, gravity), the five-bar's analytic workspace,
and the forward kinematics of every pose the workspace returns."""

import tomllib
import itertools
import pathlib

import numpy as np
import pytest

import legmodels

ROOT = pathlib.Path(__file__).resolve().parents[2]
def _gravity(spec):
    g = spec["gravity"]
    return g["value"] if isinstance(g, dict) else g


def _legs():
    """The specs of legs, without the floating robots (a link on a free joint): those
    are driven through the Rust crate's `robot` module and have no Python class yet."""
    for p in sorted((ROOT / "leg-models" / "specs").glob("*.toml")):
        spec = tomllib.loads(p.read_text())
        if not any(link.get("joint") == "free" for link in spec.get("links", [])):
            yield p, spec


# The planar legs (a spec's gravity has two entries); the spatial ones are below.
SPECS = sorted(p.stem for p, spec in _legs() if len(_gravity(spec)) == 2)


def measures_or_reason(leg, q, torque, speed):
    try:
        return leg.design_measures(q, torque, speed), None
    except legmodels.AnalysisError as e:
        return None, str(e)


def constraint_rows(leg, q, fixed):
    """The closure Jacobian with a row for each joint in `fixed` (held at rest)."""
    rows = [leg.constraint_jacobian(q)] if leg.nc else []
    for j in fixed:
        e = np.zeros((1, leg.nq))
        e[0, j] = 1.0
        rows.append(e)
    return np.vstack(rows) if rows else np.zeros((0, leg.nq))


def delassus(m, a, jf):
    """J_f (M⁻¹ − M⁻¹ Aᵀ (A M⁻¹ Aᵀ)⁺ A M⁻¹) J_fᵀ: the foot's velocity response to a unit
    impulse with the constraints `a` (rows) kept (the Delassus matrix), from numpy."""
    m_inv = np.linalg.inv(m)
    p = m_inv - m_inv @ a.T @ np.linalg.pinv(a @ m_inv @ a.T, rcond=1e-12) @ a @ m_inv
    return jf @ p @ jf.T


def inverse_inertia(leg, q, fixed):
    """Λ⁻¹ of the leg at `q` with the joints in `fixed` held."""
    return delassus(leg.mass_matrix(q), constraint_rows(leg, q, fixed), leg.foot_jacobian(q))


@pytest.mark.parametrize("name", SPECS)
def test_design_measures_against_numpy(name):
    """On every leg the measures apply to: G solves the closures with the motors at unit
    rates, J_θ = J_f G, κ is numpy's, the holding torque Gᵀ G(q), the largest downward
    push is feasible and tight within the limits, the vertical speed is the two-motor
    closed form, Λ⁻¹ (free and locked) the Delassus matrix; elsewhere a typed error."""
    leg = legmodels.models[name]()
    q = leg.assembled_home()
    torque, speed = 2.0, 30.0
    d, why = measures_or_reason(leg, q, torque, speed)
    if d is None:
        assert "not applicable" in why or "singular" in why, (name, why)
        # A property of the leg, not of a pose: the workspace says the same.
        with pytest.raises(legmodels.AnalysisError):
            leg.workspace(torque, speed, nodes=5)
        return
    held = list(d["held_joints"])
    act = list(leg.actuated)
    g = d["G"]
    scale = max(np.abs(g).max(), 1.0)
    if leg.nc:
        assert np.abs(leg.constraint_jacobian(q) @ g).max() < 1e-9 * scale, name
    np.testing.assert_allclose(g[act, :], np.eye(leg.nu), atol=1e-12)
    assert np.abs(g[held, :]).max(initial=0.0) == 0.0, name
    jt = leg.foot_jacobian(q) @ g
    np.testing.assert_allclose(d["foot_jacobian"], jt, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(d["foot"], leg.foot_position(q), atol=1e-14)
    hold = g.T @ leg.gravity_forces(q)
    np.testing.assert_allclose(d["holding_torque"], hold, rtol=1e-10, atol=1e-12)
    if leg.nu >= 2:
        assert d["condition"] == pytest.approx(np.linalg.cond(jt), rel=1e-9), name
        # Every force vertex is held within the limits with two limits active.
        for v in d["force_polygon"]:
            u = hold + jt.T @ v
            assert np.all(np.abs(u) <= torque * (1 + 1e-9)), (name, u)
            assert np.sum(np.isclose(np.abs(u), torque, rtol=1e-8)) >= 2, (name, u)
        f = d["vertical_force"]
        if f is not None:
            u = hold + jt.T @ np.array([0.0, -f])
            assert np.all(np.abs(u) <= torque * (1 + 1e-9)), (name, u)
            beyond = hold + jt.T @ np.array([0.0, -f * (1 + 1e-6) - 1e-9])
            assert np.any(np.abs(beyond) > torque), (name, "a larger push is held too")
        if leg.nu == 2:
            # (0, v) = J_θ θ̇ with |θ̇_k| ≤ ω: v = ω / max_k |(J_θ⁻¹)_{k,y}|.
            column = np.linalg.solve(jt, [0.0, 1.0])
            assert d["vertical_speed"] == pytest.approx(speed / np.abs(column).max(), rel=1e-9)
        # Speed vertices: J_θ times a corner of the box of motor speeds.
        corners = [jt @ (speed * np.array(s)) for s in itertools.product([-1, 1], repeat=leg.nu)]
        for v in d["speed_polygon"]:
            assert min(np.linalg.norm(v - c) for c in corners) < 1e-9 * speed, name
    else:
        assert d["condition"] == np.inf and d["force_polygon"] is None
        assert d["vertical_force"] is None and d["speed_polygon"] is None
    free = inverse_inertia(leg, q, held)
    locked = inverse_inertia(leg, q, held + act)
    s = np.abs(free).max()
    np.testing.assert_allclose(d["inverse_inertia"], free, rtol=0, atol=1e-8 * s)
    np.testing.assert_allclose(d["inverse_inertia_locked"], locked, rtol=0, atol=1e-8 * s)
    np.testing.assert_allclose(leg.foot_inverse_inertia(q), free, rtol=0, atol=1e-8 * s)
    np.testing.assert_allclose(leg.foot_inverse_inertia(q, motors_locked=True), locked, rtol=0, atol=1e-8 * s)
    assert d["effective_mass"] == pytest.approx(1.0 / free[1, 1], rel=1e-8)


@pytest.mark.parametrize("name", ["minitaur", "atrias", "digit", "five_bar_offset", "three_motor_leg", "cassie_planar"])
def test_impact_mitigation_on_a_body_against_the_augmented_system(name):
    """ξ = det(I − Λ Λ_L⁻¹) with the hip on a translating body of mass m_b, against numpy's
    Delassus matrices of the leg and body written as one system: coordinates (b_x, b_y, q),
    M_aug = [[m_t I, P], [Pᵀ, M]] with P = Σ mᵢ J_cᵢ the links' momentum Jacobian (from the
    gravity term under unit gravity along x and y), the foot's Jacobian [I, J_f], the
    closures, and for Λ_L the motors' joints held."""
    cls = legmodels.models[name]
    leg = cls()
    q = leg.assembled_home()
    m_b = 3.0
    grav = lambda gx, gy: cls(gravity_x=gx, gravity_y=gy).gravity_forces(q)
    g0 = grav(0.0, 0.0)
    p = np.vstack([g0 - grav(1.0, 0.0), g0 - grav(0.0, 1.0)])
    m_leg = sum(leg.get(f"{j}_mass") for j in leg.joint_names if f"{j}_mass" in leg.parameter_names)
    m_t = m_b + m_leg
    m_aug = np.block([[m_t * np.eye(2), p], [p.T, leg.mass_matrix(q)]])
    jf = np.hstack([np.eye(2), leg.foot_jacobian(q)])
    closures = np.hstack([np.zeros((leg.nc, 2)), leg.constraint_jacobian(q)])
    locks = np.zeros((leg.nu, 2 + leg.nq))
    for k, j in enumerate(leg.actuated):
        locks[k, 2 + j] = 1.0
    free = delassus(m_aug, closures, jf)
    locked = delassus(m_aug, np.vstack([closures, locks]), jf)
    xi = np.linalg.det(np.eye(2) - np.linalg.solve(free, locked))
    assert leg.impact_mitigation(q, body_mass=m_b) == pytest.approx(xi, rel=1e-8), name


def test_impact_mitigation_and_its_limits():
    """A fully actuated leg on a fixed base cannot move its foot with the motors locked:
    the factor needs a body, and the error says so. On a body, ξ falls as the body gets
    lighter (it takes less of the impact) and tends to 1 as it gets heavier."""
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    with pytest.raises(legmodels.AnalysisError, match="needs a body"):
        leg.impact_mitigation(q)
    masses = [0.5, 2.0, 20.0, 2e6]
    xi = [leg.impact_mitigation(q, body_mass=m) for m in masses]
    assert all(0.0 < x < 1.0 for x in xi), xi
    assert xi == sorted(xi), xi
    assert xi[-1] == pytest.approx(1.0, abs=1e-5)
    with pytest.raises(ValueError, match="body_mass"):
        leg.impact_mitigation(q, body_mass=-1.0)


def test_workspace_of_the_five_bar_is_its_annulus():
    """Minitaur's coaxial five-bar: the foot reaches the annulus between |l₂ − l₁| and
    l₁ + l₂ around the hip; every reached node's pose puts the foot on that node and closes
    the loop; the measures are finite there and NaN elsewhere."""
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    joints, tips = leg.joint_positions(q), leg.link_tips(q)
    l1, l2 = (np.linalg.norm(tips[:, j] - joints[:, j]) for j in (0, 1))
    hip = joints[:, 0]
    w = leg.workspace(2.0, 30.0, nodes=80)
    exact = np.pi * ((l1 + l2) ** 2 - (l2 - l1) ** 2)
    assert w["area"] == pytest.approx(exact, rel=0.05), (w["area"], exact)
    x, y = np.asarray(w["x"]), np.asarray(w["y"])
    step = x[1] - x[0]
    state = np.asarray(w["state"])
    reached = state == "reached"
    assert reached.sum() * step**2 == pytest.approx(w["area"], rel=1e-12)
    for iy, ix in zip(*np.nonzero(reached)):
        pose = w["poses"][iy, ix]
        np.testing.assert_allclose(leg.foot_position(pose), [x[ix], y[iy]], atol=1e-9)
        assert np.abs(leg.closure_residual(pose)).max() < 1e-9
        r = np.hypot(x[ix] - hip[0], y[iy] - hip[1])
        assert l2 - l1 - 1e-9 <= r <= l1 + l2 + 1e-9
    assert np.isfinite(w["condition"][reached]).all()
    assert np.isnan(w["condition"][~reached]).all()
    assert np.isnan(w["poses"][~reached]).all()
    assert w["foot_curves"].shape[1:] == (2, 2) and len(w["foot_curves"]) > 0
    # The workspace's edge (type I curves) lies on the annulus' circles, within a cell.
    ends = w["foot_curves"].reshape(-1, 2) - hip
    r = np.hypot(ends[:, 0], ends[:, 1])
    off = np.minimum(np.abs(r - (l1 + l2)), np.abs(r - (l2 - l1)))
    assert off.max() < 1.5 * step, off.max()


def test_workspace_options_and_bad_input():
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    theta = q[leg.actuated]
    # Motor range: every reached pose keeps its motors inside; less area than without.
    low, high = theta - 0.3, theta + 0.3
    w = leg.workspace(2.0, 30.0, nodes=40, motor_range=np.column_stack([low, high]))
    full = leg.workspace(2.0, 30.0, nodes=40)
    reached = np.asarray(w["state"]) == "reached"
    motors = w["poses"][reached][:, leg.actuated]
    # Revolute motors: in range modulo a turn (the same pose).
    wrapped = low + np.mod(motors - low, 2 * np.pi)
    assert (wrapped <= high + 1e-9).all()
    assert 0 < w["area"] < full["area"]
    assert (np.asarray(w["state"]) == "out_of_range").any()
    # A window: the grid's nodes are where it says.
    w = leg.workspace(2.0, 30.0, nodes=11, centre=[0.0, -0.2], half_width=0.05)
    np.testing.assert_allclose([w["x"][0], w["x"][-1], w["y"][0], w["y"][-1]], [-0.05, 0.05, -0.25, -0.15], atol=1e-12)
    with pytest.raises(ValueError, match="torque_limit"):
        leg.design_measures(q, -1.0, 30.0)
    with pytest.raises(ValueError, match="`speed_limit` has 3 entries, this leg needs 2"):
        leg.design_measures(q, 1.0, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="nodes"):
        leg.workspace(1.0, 1.0, nodes=1)
    with pytest.raises(ValueError, match="together"):
        leg.workspace(1.0, 1.0, nodes=5, centre=(0.0, 0.0))
    with pytest.raises(ValueError, match="motor_range"):
        leg.workspace(1.0, 1.0, nodes=5, motor_range=[(0.0, 1.0)])
    with pytest.raises(ValueError, match="motor_range"):
        leg.workspace(1.0, 1.0, nodes=5, motor_range=[(-np.inf, np.inf), (0.0, 1.0)])
    with pytest.raises(legmodels.AnalysisError, match="outside the motor range"):
        leg.workspace(1.0, 1.0, nodes=5, motor_range=[(theta[0] + 0.1, theta[0] + 1.0), (-4.0, 4.0)])
    # A pose off the closures is closed before its branches are looked for.
    np.testing.assert_allclose(leg.assembly_branches(q + 1e-4)[0], q, atol=1e-3)
    straight = [-np.pi / 2, 0.0, -np.pi / 2, 0.0]
    with pytest.raises(legmodels.AnalysisError, match="singular"):
        leg.design_measures(straight, 1.0, 1.0)
    # A one-motor linkage: its foot moves on a curve, no force polygon; a typed error
    # names why where a measure needs two motors.
    klann = legmodels.KlannLinkage()
    d = klann.design_measures(klann.assembled_home(), 1.0, 1.0)
    assert d["force_polygon"] is None and d["condition"] == np.inf
    with pytest.raises(legmodels.AnalysisError, match="not applicable"):
        klann.workspace(1.0, 1.0, nodes=5)


def test_assembly_branches_each_start_a_workspace():
    """Minitaur at its home motor angles closes two ways (the lower links' tips meet where
    two circles cross); each branch keeps the motors, closes the loop, and has its own
    workspace and stance measures."""
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    branches = leg.assembly_branches()
    assert branches.shape == (2, leg.nq)
    np.testing.assert_array_equal(branches[0], q)
    np.testing.assert_array_equal(branches[1][leg.actuated], q[leg.actuated])
    assert np.abs(leg.closure_residual(branches[1])).max() < 1e-10
    other = leg.workspace(2.0, 30.0, nodes=30, start=branches[1])
    assert other["area"] > 0
    a, b = (leg.design_measures(x, 2.0, 30.0)["effective_mass"] for x in branches)
    assert a != b


# The spatial legs (a spec's gravity has three entries): the foot in space, vertical z.
SPATIAL = sorted(p.stem for p, spec in _legs() if len(_gravity(spec)) == 3)


@pytest.mark.parametrize("name", SPATIAL)
def test_spatial_design_measures_against_numpy(name):
    """A spatial leg's measures: where its motors span the foot, G closes the loops, κ is
    numpy's, every force-polytope vertex and the largest push are held within the limits
    (three limits active at a vertex), and with three motors the polytope's and the speed
    zonotope's volumes and the vertical speed are the closed forms; on every leg, Λ⁻¹ free
    and locked are numpy's Delassus matrices; elsewhere a typed error."""
    leg = legmodels.models[name]()
    q = leg.assembled_home()
    torque, speed = 20.0, 10.0
    free = inverse_inertia(leg, q, [])
    locked = inverse_inertia(leg, q, list(leg.actuated))
    s = np.abs(leg.foot_jacobian(q) @ np.linalg.solve(leg.mass_matrix(q), leg.foot_jacobian(q).T)).max()
    assert leg.foot_inverse_inertia(q).shape == (3, 3)
    np.testing.assert_allclose(leg.foot_inverse_inertia(q), free, rtol=0, atol=1e-9 * s)
    np.testing.assert_allclose(leg.foot_inverse_inertia(q, motors_locked=True), locked, rtol=0, atol=1e-9 * s)
    d, why = measures_or_reason(leg, q, torque, speed)
    if d is None:
        assert "not applicable" in why, (name, why)
        with pytest.raises(legmodels.AnalysisError):
            leg.workspace(torque, speed, nodes=5)
        return
    g = d["G"]
    jt = leg.foot_jacobian(q) @ g
    assert jt.shape == (3, leg.nu)
    assert np.abs(leg.constraint_jacobian(q) @ g).max() < 1e-9 * max(np.abs(g).max(), 1.0)
    np.testing.assert_allclose(d["foot_jacobian"], jt, rtol=1e-10, atol=1e-12)
    hold = g.T @ leg.gravity_forces(q)
    np.testing.assert_allclose(d["inverse_inertia"], free, rtol=0, atol=1e-9 * s)
    assert d["effective_mass"] == pytest.approx(1.0 / free[2, 2], rel=1e-8)
    if leg.nu < 3:
        assert d["force_polytope"] is None and d["condition"] == np.inf
        return
    assert d["condition"] == pytest.approx(np.linalg.cond(jt), rel=1e-9), name
    assert len(d["force_polytope"]) >= 8
    for v in d["force_polytope"]:
        u = hold + jt.T @ v
        assert np.all(np.abs(u) <= torque * (1 + 1e-9)), (name, u)
        assert np.sum(np.isclose(np.abs(u), torque, rtol=1e-8)) >= 3, (name, u)
    f = d["vertical_force"]
    u = hold + jt.T @ np.array([0.0, 0.0, -f])
    assert np.all(np.abs(u) <= torque * (1 + 1e-9)), (name, u)
    beyond = hold + jt.T @ np.array([0.0, 0.0, -f * (1 + 1e-6) - 1e-9])
    assert np.any(np.abs(beyond) > torque), (name, "a larger push is held too")
    if leg.nu == 3:
        det = abs(np.linalg.det(jt))
        assert d["force_polytope_volume"] == pytest.approx((2 * torque) ** 3 / det, rel=1e-9)
        assert d["speed_zonotope_volume"] == pytest.approx(8 * speed**3 * det, rel=1e-9)
        column = np.linalg.solve(jt, [0.0, 0.0, 1.0])
        assert d["vertical_speed"] == pytest.approx(speed / np.abs(column).max(), rel=1e-9)


@pytest.mark.parametrize("name", ["abducted_five_bar", "revolute_knee_leg", "cassie_leg"])
def test_spatial_impact_mitigation_against_the_augmented_system(name):
    """ξ on a body translating in space, against numpy's Delassus matrices of the leg and
    body as one system: coordinates (b_x, b_y, b_z, q), M_aug = [[m_t I, P], [Pᵀ, M]], P from
    the gravity term under unit gravity along x, y and z; a ball joint's three coordinates
    move one link, counted once in the leg's mass."""
    cls = legmodels.models[name]
    leg = cls()
    q = leg.assembled_home()
    m_b = 5.0
    grav = lambda gx, gy, gz: cls(gravity_x=gx, gravity_y=gy, gravity_z=gz).gravity_forces(q)
    g0 = grav(0.0, 0.0, 0.0)
    p = np.vstack([g0 - grav(*e) for e in np.eye(3)])
    links = {j.split(".")[0] for j in leg.joint_names}
    m_leg = sum(leg.get(f"{j}_mass") for j in links)
    m_t = m_b + m_leg
    m_aug = np.block([[m_t * np.eye(3), p], [p.T, leg.mass_matrix(q)]])
    jf = np.hstack([np.eye(3), leg.foot_jacobian(q)])
    closures = np.hstack([np.zeros((leg.nc, 3)), leg.constraint_jacobian(q)])
    locks = np.zeros((leg.nu, 3 + leg.nq))
    for k, j in enumerate(leg.actuated):
        locks[k, 3 + j] = 1.0
    free = delassus(m_aug, closures, jf)
    locked = delassus(m_aug, np.vstack([closures, locks]), jf)
    xi = np.linalg.det(np.eye(3) - np.linalg.solve(free, locked))
    assert leg.impact_mitigation(q, body_mass=m_b) == pytest.approx(xi, rel=1e-6, abs=1e-12), name


def test_spatial_workspace_slices():
    """revolute_knee_leg's sagittal slice is the annulus π(0.45² − 0.05²) (thigh 0.2 m,
    shin 0.25 m, whatever the abduction); every reached node's pose puts the foot on the
    slice at its coordinates and closes the loop; a frontal slice is another plane through
    the same foot; a planar leg and an unknown plane are refused."""
    leg = legmodels.RevoluteKneeLeg()
    q = leg.assembled_home()
    foot = leg.foot_position(q)
    w = leg.workspace(20.0, 10.0, nodes=60)
    np.testing.assert_allclose(w["plane_axes"], [[1, 0, 0], [0, 0, 1]])
    assert w["area"] == pytest.approx(np.pi * (0.45**2 - 0.05**2), rel=0.02)
    a, b = np.asarray(w["x"]), np.asarray(w["y"])
    reached = np.asarray(w["state"]) == "reached"
    for iy, ix in list(zip(*np.nonzero(reached)))[::37]:
        pose = w["poses"][iy, ix]
        np.testing.assert_allclose(leg.foot_position(pose), [a[ix], foot[1], b[iy]], atol=1e-9)
        assert np.abs(leg.closure_residual(pose)).max() < 1e-9
    frontal = leg.workspace(20.0, 10.0, nodes=30, slice="yz")
    np.testing.assert_allclose(frontal["plane_axes"], [[0, 1, 0], [0, 0, 1]])
    assert frontal["plane_offset"] == pytest.approx(foot[0], abs=1e-12)
    with pytest.raises(ValueError, match="slice"):
        leg.workspace(20.0, 10.0, nodes=5, slice="xq")
    with pytest.raises(ValueError, match="its own plane"):
        legmodels.Minitaur().workspace(2.0, 30.0, nodes=5, slice="xz")
