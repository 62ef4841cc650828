"""The Python package against the Rust runtime and against physics.

Every term of every generated leg equals what the Rust command line (`legs eval --json`)
prints at the same state; derivatives agree with central differences; a simulation
without torques or damping keeps its energy; bad input raises the runtime's errors."""

import tomllib
import pathlib
import pickle
import re
import subprocess
import sys

import numpy as np
import pytest

import legmodels
from conftest import ROOT, rust_eval

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


# Every leg, planar (a spec's gravity has two entries) and spatial (three).
SPECS = sorted(p.stem for p, _ in _legs())
SPATIAL = sorted(p.stem for p, spec in _legs() if len(_gravity(spec)) == 3)


def test_every_spec_is_a_class():
    assert sorted(legmodels.models) == SPECS
    for name, cls in legmodels.models.items():
        assert cls.name == name
        leg = cls()
        assert len(leg.home()) == cls.nq and len(cls.actuated) == cls.nu
        assert cls.dimension == (3 if name in SPATIAL else 2)
        assert len(leg.foot_position(leg.home())) == cls.dimension


def assembled_state(leg, rng):
    """A state on the closures near home, with rates along them (motors' rates random)."""
    for _ in range(50):
        theta = leg.home()[leg.actuated] + rng.uniform(-0.15, 0.15, leg.nu)
        try:
            q = leg.assemble(theta)
            qd = leg.consistent_velocity(q, rng.uniform(-1.0, 1.0, leg.nu))
        except legmodels.LegError:
            continue
        return q, qd
    # Motors that over-determine the leg (a pinned toe: mobility 1, two motors) cannot be
    # set independently, nor fix one that has more freedom than motors (a spatial leg's
    # rod spins freely): a pose near home projected onto the closures, rates projected
    # onto their tangent.
    assert leg.mobility != leg.nu, f"{leg.name}: no assembled state near home"
    q = leg.project_position(leg.home() + rng.uniform(-0.05, 0.05, leg.nq))
    return q, leg.project_velocity(q, rng.uniform(-1.0, 1.0, leg.nq))


def close(ours, theirs, what, rtol=1e-12):
    ours, theirs = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    assert ours.shape == theirs.shape, (what, ours.shape, theirs.shape)
    scale = max(np.abs(theirs).max(initial=0.0), 1e-300)
    assert np.abs(ours - theirs).max(initial=0.0) <= rtol * scale, what


@pytest.mark.parametrize("name", SPECS)
def test_terms_equal_the_rust_runtime(legs, name):
    cls = legmodels.models[name]
    leg = cls()
    rng = np.random.default_rng(7)
    for k in range(3):
        if k == 0 and cls.nc > 0:
            q, qd = assembled_state(leg, rng)
        else:
            q, qd = rng.uniform(-np.pi, np.pi, cls.nq), rng.uniform(-2.0, 2.0, cls.nq)
        u = rng.uniform(-0.5, 0.5, cls.nu)
        rust = rust_eval(legs, name, q, qd, u, derivatives=True)
        close(leg.mass_matrix(q), rust["M"], "M")
        close(leg.bias_forces(q, qd), rust["N"], "N")
        close(leg.gravity_forces(q), rust["G"], "G")
        close(leg.constraint_jacobian(q), np.array(rust["J"]).reshape(cls.nc, cls.nq), "J")
        close(leg.constraint_bias(q, qd), rust["Jdot_qdot"], "J̇q̇")
        close(leg.closure_residual(q), rust["phi"], "φ")
        close(leg.foot_position(q), rust["foot"], "foot")
        close(leg.foot_jacobian(q), rust["foot_jacobian"], "foot Jacobian")
        close(leg.kinetic_energy(q, qd), rust["kinetic"], "T")
        close(leg.potential_energy(q), rust["potential"], "V")
        terms = leg.dynamics_terms(q, qd)
        close(terms["mass_matrix"], rust["M"], "terms M")
        close(terms["bias_forces"], rust["N"], "terms N")
        if "qdd" in rust and rust.get("qdd") is not None:
            qdd, forces = leg.forward_dynamics(q, qd, u)
            close(qdd, rust["qdd"], "q̈")
            close(forces, rust["F"], "F")
        if rust.get("dqdd_dq") is not None:
            d = leg.forward_dynamics_derivatives(q, qd, u)
            for ours, theirs in [("qdd_q", "dqdd_dq"), ("qdd_qd", "dqdd_dqd"), ("qdd_u", "dqdd_du")]:
                close(d[ours], np.array(rust[theirs]).reshape(d[ours].shape), ours)
        if rust.get("A_tilde") is not None:
            a, b = leg.actuated_reduction(q, qd)
            close(a, rust["A_tilde"], "Ã")
            close(b, rust["b_tilde"], "b̃")


@pytest.mark.parametrize("name", SPECS)
def test_derivatives_against_central_differences(name):
    cls = legmodels.models[name]
    leg = cls()
    rng = np.random.default_rng(3)
    q, qd = (assembled_state(leg, rng) if cls.nc else (leg.home(), rng.uniform(-1, 1, cls.nq)))
    u = rng.uniform(-0.3, 0.3, cls.nu)
    d = leg.forward_dynamics_derivatives(q, qd, u)
    h = 1e-6
    for i in range(cls.nq):
        e = np.zeros(cls.nq)
        e[i] = h
        fd_q = (leg.forward_dynamics(q + e, qd, u)[0] - leg.forward_dynamics(q - e, qd, u)[0]) / (2 * h)
        fd_qd = (leg.forward_dynamics(q, qd + e, u)[0] - leg.forward_dynamics(q, qd - e, u)[0]) / (2 * h)
        scale = max(np.abs(d["qdd_q"]).max(), 1.0)
        assert np.abs(fd_q - d["qdd_q"][:, i]).max() < 1e-5 * scale, (name, i)
        assert np.abs(fd_qd - d["qdd_qd"][:, i]).max() < 1e-5 * max(np.abs(d["qdd_qd"]).max(), 1.0), (name, i)


def test_parameters_by_name():
    leg = legmodels.Minitaur()
    heavier = legmodels.Minitaur(lower_a_mass=leg.get("lower_a_mass") * 2)
    q = leg.home()
    assert heavier.get("lower_a_mass") == 2 * leg.get("lower_a_mass")
    assert not np.allclose(heavier.mass_matrix(q), leg.mass_matrix(q))
    leg.set("lower_a_mass", heavier.get("lower_a_mass"))
    np.testing.assert_array_equal(leg.mass_matrix(q), heavier.mass_matrix(q))
    assert leg.params["lower_a_mass"] == heavier.get("lower_a_mass")
    assert set(leg.params) == set(leg.parameter_names)


def test_bad_input_raises_with_the_runtime_message():
    leg = legmodels.Minitaur()
    with pytest.raises(legmodels.ParameterError, match="did you mean `lower_a_mass`"):
        legmodels.Minitaur(lower_a_mas=1.0)
    with pytest.raises(legmodels.ParameterError, match="finite"):
        legmodels.Minitaur(lower_a_mass=float("nan"))
    with pytest.raises(legmodels.ParameterError, match="`lower_a_mass` is a mass, an inertia or a damping and cannot be negative"):
        legmodels.Minitaur(lower_a_mass=-0.1)
    # The spec's rules at run time (the new user's trial: these were accepted).
    with pytest.raises(legmodels.ParameterError, match="gear ratio and must be positive"):
        legmodels.Minitaur(upper_a_gear_ratio=0.0)
    with pytest.raises(legmodels.ParameterError, match="cannot be negative"):
        legmodels.Minitaur(upper_a_damping=-1.0)
    with pytest.raises(legmodels.ParameterError, match="at most 1e6 in magnitude"):
        legmodels.Minitaur(lower_a_mass=1e308)
    assert legmodels.AssemblyError.__name__ == "AssemblyError"
    # A complex array lost its imaginary part with only numpy's warning.
    q = leg.assembled_home()
    with pytest.raises(ValueError, match="`q` is a complex array"):
        leg.forward_dynamics(q.astype(complex) + 1j, np.zeros(4), np.zeros(2))
    with pytest.raises(ValueError, match="`u` is a complex array"):
        leg.forward_dynamics(q, np.zeros(4), np.zeros(2, dtype=complex))
    # A hostile name is echoed escaped and short: one line, no escape codes.
    hostile = "bad\nname\u2028\x1b[31m" + "x" * 100_000
    with pytest.raises(legmodels.ParameterError) as e:
        legmodels.Minitaur(**{hostile: 1.0})
    message = str(e.value)
    assert "\n" not in message and "\u2028" not in message and "\x1b" not in message, message
    assert len(message) < 200, len(message)
    with pytest.raises(ValueError) as e:
        leg.simulate(leg.home(), np.zeros(4), 10, 1e-3, controller=hostile)
    assert "\n" not in str(e.value) and len(str(e.value)) < 300, str(e.value)
    with pytest.raises(ValueError, match="unknown `controller`"):
        leg.simulate(leg.home(), np.zeros(4), 10, 1e-3, controller="foot_fl")
    with pytest.raises(ValueError, match="`q` has 2 entries, this leg needs 4"):
        leg.mass_matrix([0.0, 0.0])
    straight = [-np.pi / 2, 0.0, -np.pi / 2, 0.0]
    with pytest.raises(legmodels.DynamicsError, match="singular"):
        leg.forward_dynamics(straight, np.zeros(4), np.zeros(2))
    with pytest.raises(legmodels.AssemblyError):
        leg.foot_inverse([0.0, -5.0])  # 5 m below a 0.3 m leg
    # A negative or NaN torque limit drove every motor at it, or clipped nothing.
    for bad in ([-0.01, -0.01], [np.nan, np.nan], [1.0, -1.0]):
        with pytest.raises(ValueError, match="`torque_limit`: the torque limit of motor"):
            leg.simulate(leg.assembled_home(), np.zeros(4), 10, 1e-3, torque=lambda t, q, qd: np.zeros(2), torque_limit=bad)
    # A continuation step that never arrives (0 hung), walks backwards or is unbounded.
    for bad in (0.0, -0.05, 1e-12):
        with pytest.raises(legmodels.AssemblyError, match="continuation step"):
            leg.assemble_along(leg.assembled_home(), [-0.6, -2.5], max_step=bad)
    with pytest.raises(ValueError, match="controller"):
        leg.simulate(leg.home(), np.zeros(4), 10, 1e-3, controller="mpc", setpoint=[0, 0])
    with pytest.raises(ValueError, match="dt"):
        leg.simulate(leg.home(), np.zeros(4), 10, -1e-3)
    # A Python torque function that raises stops the run and its error comes through.
    def broken(t, q, qd):
        raise RuntimeError("motor driver fault")
    with pytest.raises(RuntimeError, match="motor driver fault"):
        leg.simulate(leg.assembled_home(), np.zeros(4), 10, 1e-3, torque=broken)


def test_a_failed_simulation_keeps_its_record():
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    # Torques that drive the leg into its singular straight pose within the run.
    with pytest.raises(legmodels.SimulationError) as stopped:
        leg.simulate(q, np.zeros(4), 20000, 1e-3, torque=[50.0, -50.0])
    record = stopped.value.record
    assert 1 < len(record["t"]) < 20001
    assert record["q"].shape == (len(record["t"]), 4)


def test_a_run_larger_than_the_record_budget_is_refused_at_once():
    # It killed the interpreter (10**10 steps: "memory allocation of 1200000000120 bytes
    # failed"), panicked (2**62) or ran for minutes (2**64 - 1).
    for leg in (legmodels.Minitaur(), legmodels.TwoLink()):
        q = leg.assembled_home()
        for steps in (10**10, 2**62, 2**64 - 1):
            with pytest.raises(legmodels.SimulationError, match="more than the budget of 512 MiB") as stopped:
                leg.simulate(q, np.zeros(len(q)), steps, 1e-3)
            assert len(stopped.value.record["t"]) == 0
    hopper = legmodels.MinitaurHopper()
    with pytest.raises(legmodels.SimulationError, match="more than the budget of 512 MiB"):
        hopper.simulate_hybrid(hopper.assembled_home(), np.zeros(hopper.nq), 10**10, 1e-3)


def test_energy_is_kept_without_torques_or_damping():
    leg = legmodels.Minitaur()
    for n in leg.parameter_names:
        if "damping" in n:
            leg.set(n, 0.0)
    q = leg.assembled_home()
    qd = leg.consistent_velocity(q, [2.0, -1.0])
    run = leg.simulate(q, qd, 1000, 1e-4)
    drift = np.abs(run["energy"] - run["energy"][0]).max()
    assert drift < 1e-8 * max(abs(run["energy"][0]), 1e-3), drift
    assert run["closure_residual"].max() < 1e-12


def test_callable_and_constant_torques_agree():
    leg = legmodels.Atrias()
    q = leg.assembled_home()
    constant = leg.simulate(q, np.zeros(4), 200, 1e-3, torque=[0.2, -0.1])
    called = leg.simulate(q, np.zeros(4), 200, 1e-3, torque=lambda t, q, qd: np.array([0.2, -0.1]))
    np.testing.assert_array_equal(constant["q"], called["q"])


def test_controllers_track():
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    theta = q[leg.actuated]
    run = leg.simulate(q, np.zeros(4), 2000, 1e-3, controller="joint_feedback_linearization",
                       setpoint=theta, amplitude=[0.1, 0.1], frequency=[1.0, 1.0], kp=400.0)
    t = run["t"]
    want = theta[None, :] + 0.1 * np.sin(2 * np.pi * t)[:, None]
    assert np.abs(run["q"][:, leg.actuated] - want)[500:].max() < 1e-3
    # One feedback-linearizing torque gives the commanded motor acceleration.
    qd = leg.consistent_velocity(q, [0.5, -0.5])
    u = leg.feedback_linearization_torque("joint", q, qd, theta, [0, 0], [0, 0], kp=100.0)
    qdd, _ = leg.forward_dynamics(q, qd, u)
    want = 100.0 * 0 - 2 * np.sqrt(100.0) * np.array([0.5, -0.5])
    np.testing.assert_allclose(qdd[leg.actuated], want, atol=1e-9)


def test_lqr_is_stabilizing():
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    lin = leg.linearize(q, 1e-3)
    lqr = leg.lqr(q, 1e-3, np.diag([100.0, 100.0, 1.0, 1.0]), 0.1 * np.eye(2))
    closed = lin["A"] - lin["B"] @ lqr["K"]
    np.testing.assert_allclose(closed, lqr["closed_loop"], atol=1e-12)
    assert np.abs(np.linalg.eigvals(closed)).max() < 1.0


def test_hybrid_drop_lands_when_free_fall_says():
    leg = legmodels.MinitaurHopper()
    q = leg.assembled_home()
    q[0] += 0.1
    height = leg.contact_positions(q)[1]
    rec = leg.simulate_hybrid(q, np.zeros(leg.nq), 150, 1e-3)
    touchdown = next(e for e in rec["events"] if e["kind"] == "touchdown")
    g = -leg.get("gravity_y")
    assert abs(touchdown["t"] - np.sqrt(2 * height / g)) < 1e-9


def test_spatial_hybrid_throw_lands_slides_and_stops_where_coulomb_says():
    """A spatial leg on the ground from Python: `sliding_mass`'s block (μ 0.5 in its spec)
    thrown level at 2 m/s from 5 cm lands at √(2h/g); the plastic impact stops the fall and
    its friction impulse μ m v_n takes μ v_n off the slide; friction μ m g then stops it
    after v⁺/(μ g), where it sticks. Meanwhile the ground force is m g with |λ_t| = μ λ_n.
    Every figure is written out here from free fall and Coulomb's law."""
    leg = legmodels.SlidingMass()
    assert leg.contact_names == ["bottom"]
    mu, g, h, v = 0.5, -leg.get("gravity_z"), 0.05, 2.0
    m = leg.mass_matrix(np.zeros(3))[0, 0]
    rec = leg.simulate_hybrid(np.array([0.0, 0.0, h]), np.array([v, 0.0, 0.0]), 600, 1e-3)
    kinds = [e["kind"] for e in rec["events"]]
    assert kinds[:1] == ["touchdown"] and "stick" in kinds, kinds
    touchdown = rec["events"][0]
    t_land = np.sqrt(2 * h / g)
    assert abs(touchdown["t"] - t_land) < 1e-9
    v_n = g * t_land
    np.testing.assert_allclose(touchdown["impulse"], [mu * m * v_n, m * v_n], rtol=1e-9)
    v_slide = v - mu * v_n
    stick = next(e for e in rec["events"] if e["kind"] == "stick")
    assert abs(stick["t"] - (t_land + v_slide / (mu * g))) < 1e-9
    # Where it stops: the flight's v t_land, then the slide's v⁺² / (2 μ g).
    x_stop = v * t_land + v_slide**2 / (2 * mu * g)
    assert abs(rec["q"][-1][0] - x_stop) < 1e-9 and abs(rec["q"][-1][2]) < 1e-12
    sliding = (rec["t"] > t_land + 1e-3) & (rec["t"] < stick["t"] - 1e-3)
    f = rec["contact_forces"][sliding]
    np.testing.assert_allclose(f[:, 2], m * g, rtol=1e-9)
    np.testing.assert_allclose(np.hypot(f[:, 0], f[:, 1]), mu * m * g, rtol=1e-9)
    # Held at rest on the ground: no acceleration, the weight on the contact.
    qdd, closure, contact = leg.forward_dynamics_with_contacts(
        np.zeros(3), np.zeros(3), np.zeros(2), [True], np.zeros(3))
    np.testing.assert_allclose(qdd, 0.0, atol=1e-12)
    np.testing.assert_allclose(contact, [0.0, 0.0, m * g], atol=1e-12)
    assert leg.contact_jacobian(np.zeros(3)).shape == (3, 3)
    with pytest.raises(ValueError, match="this leg has 1 contacts"):
        leg.forward_dynamics_with_contacts(np.zeros(3), np.zeros(3), np.zeros(2), [True, False], np.zeros(3))


def test_example_script_runs(tmp_path):
    out = tmp_path / "minitaur.png"
    subprocess.run([sys.executable, str(ROOT / "python" / "examples" / "simulate_leg.py"), "--out", str(out)], check=True)
    assert out.stat().st_size > 10_000


def _python_blocks():
    """Every ```python block of README.md and docs/*.md, as (file, index in that file, code).

    Every such block runs. A block that is not meant to run (a shell session, a fragment)
    is fenced as something else (```text, ```sh), or listed in SKIPPED_BLOCKS with why."""
    blocks = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = path.read_text()
        found = re.finditer(r"^```python[ \t]*\n(.*?)^```", text, re.DOTALL | re.MULTILINE)
        for index, m in enumerate(found):
            blocks.append((path.relative_to(ROOT).as_posix(), index, m.group(1)))
    return blocks


PYTHON_BLOCKS = _python_blocks()

# (file, index) → why the block does not run.
SKIPPED_BLOCKS = {
    ("docs/python.md", 1): "Ray's adapter: Ray is not installed here (a 70 MB wheel); run by hand with Ray 2.60 (docs/python.md)",
}


def _check_the_package_example(namespace):
    """The README's example of the package: a simulation, derivatives and a sweep."""
    assert namespace["run"]["q"].shape == (1001, 4)
    assert np.isfinite(namespace["d"]["qdd_q"]).all()
    areas = namespace["areas"]
    assert 0 < areas[0.16] < areas[0.20] < areas[0.24], areas


def _check_the_sweep_example(namespace):
    """The README's sweep: its table in the designs' order, every design analysed."""
    table = namespace["table"]
    assert table["index"].tolist() == list(range(25))
    assert (table["error"] == "").all() and np.isfinite(table["workspace_area_m2"]).all()


def _check_the_cluster_example(namespace):
    """docs/python.md's sweep: the cluster's table is the serial one, bit for bit."""
    table, serial = namespace["table"], namespace["serial"]
    for c in table.dtype.names:
        if table.dtype[c] == np.float64:
            assert np.array_equal(table[c].view(np.uint64), serial[c].view(np.uint64)), c
    assert len(namespace["rollouts"]) == 20 and (namespace["rollouts"]["error"] == "").all()


# Checks beyond running, each for the block that contains its marker.
BLOCK_CHECKS = {
    "areas = {l: legmodels.Minitaur(": _check_the_package_example,
    'table = sweep("minitaur", designs, DesignSummary(nodes=20), client=client)': _check_the_sweep_example,
    "serial = sweep(\"minitaur\", designs, task)": _check_the_cluster_example,
}


def test_the_docs_have_their_python_examples():
    """The blocks the checks are for are found (a renamed fence would skip them silently)."""
    assert PYTHON_BLOCKS, "no ```python block in README.md or docs/"
    for marker in BLOCK_CHECKS:
        assert sum(marker in code for _, _, code in PYTHON_BLOCKS) == 1, marker


@pytest.mark.parametrize(
    "file,index", [(f, i) for f, i, _ in PYTHON_BLOCKS], ids=[f"{f}:{i}" for f, i, _ in PYTHON_BLOCKS]
)
def test_the_docs_python_examples_run(file, index):
    """Each ```python block of the README and docs/, as written there."""
    if (file, index) in SKIPPED_BLOCKS:
        pytest.skip(SKIPPED_BLOCKS[(file, index)])
    code = next(c for f, i, c in PYTHON_BLOCKS if (f, i) == (file, index))
    # As a script (`__name__` is "__main__": a block that starts worker processes guards them).
    namespace = {"__name__": "__main__"}
    exec(compile(code, f"{file} (python block {index})", "exec"), namespace)
    for marker, check in BLOCK_CHECKS.items():
        if marker in code:
            check(namespace)


@pytest.mark.parametrize("name", SPECS)
def test_controllers_apply_by_structure(name):
    """On every leg (one motor, three motors, over-actuated, floating bodies) each built-in
    controller runs or raises ControlError, as the leg's structure says: joint-space control
    needs motors that do not over-determine the leg (mobility ≥ motors), foot-space control
    as many motors as the foot has coordinates or more, determining the leg (mobility =
    motors ≥ 2 on a planar leg, ≥ 3 on a spatial one)."""
    leg = legmodels.models[name]()
    q = leg.assembled_home()
    for controller in ["joint_feedback_linearization", "pd_gravity", "foot_feedback_linearization", "foot_pd_gravity"]:
        foot = controller.startswith("foot")
        applies = leg.mobility == leg.nu >= leg.dimension if foot else leg.mobility >= leg.nu
        setpoint = leg.foot_position(q) if foot else q[leg.actuated]
        try:
            run = leg.simulate(q, np.zeros(leg.nq), 5, 1e-3, controller=controller, setpoint=setpoint)
        except legmodels.ControlError as e:
            assert not applies and str(e), (name, controller, str(e))
            continue
        assert applies, (name, controller, "ran where it should not apply")
        assert np.isfinite(run["q"]).all(), (name, controller)


@pytest.mark.parametrize("cls", [legmodels.Minitaur, legmodels.Atrias, legmodels.TwoLink])
def test_pd_gains_mean_the_error_dynamics_as_on_the_command_line(cls):
    """kp and kd are the error dynamics' (1/s², 1/s) for every controller: the PD
    controllers scale them by the motors' (the foot's) inertia at the start, as `sim`
    does at home. Unscaled, the default kp = 100 N m/rad with kd = 2√kp was a damping
    of 4000 1/s on Minitaur's motors, and the run diverged within 4 ms at any kp.
    With gravity compensated exactly, a PD reaches its setpoint with no offset."""
    leg = cls()
    q = leg.assembled_home()
    theta = q[leg.actuated]
    run = leg.simulate(q, np.zeros(leg.nq), 2000, 1e-3, controller="pd_gravity", setpoint=theta + 0.1)
    assert np.abs(run["q"][-1][leg.actuated] - theta - 0.1).max() < 1e-4
    foot = leg.foot_position(q)
    run = leg.simulate(q, np.zeros(leg.nq), 2000, 1e-3, controller="foot_pd_gravity", setpoint=foot + 0.01)
    assert np.abs(leg.foot_position(run["q"][-1]) - foot - 0.01).max() < 1e-5


@pytest.mark.parametrize("name", SPATIAL)
def test_spatial_legs_swing_track_and_pickle(name):
    """A spatial leg's class: undamped and unforced, a swing keeps its energy and its loops
    (RK4 with projection); joint-space feedback linearization brings the motors to a
    setpoint 0.05 rad away where the motors do not over-determine the leg; a pickled leg
    computes bit for bit what the original does."""
    cls = legmodels.models[name]
    dampings = {n: 0.0 for n in cls.parameter_names if n.endswith("_damping")}
    leg = cls(**dampings)
    q = leg.assembled_home()
    run = leg.simulate(q, np.zeros(cls.nq), 500, 1e-4)
    energy = run["energy"]
    peak = max(leg.kinetic_energy(a, b) for a, b in zip(run["q"], run["qd"]))
    assert peak > 1e-4, (name, peak)
    assert np.abs(energy - energy[0]).max() < 1e-6 * peak, (name, np.abs(energy - energy[0]).max(), peak)
    assert run["closure_residual"].max() < 1e-10, name
    if cls.mobility >= cls.nu:
        theta = q[cls.actuated]
        run = leg.simulate(q, np.zeros(cls.nq), 1500, 1e-3, controller="joint_feedback_linearization",
                           setpoint=theta + 0.05, kp=400.0)
        assert np.abs(run["q"][-1][cls.actuated] - theta - 0.05).max() < 1e-4, name
    again = pickle.loads(pickle.dumps(leg))
    assert type(again) is cls and again.params == leg.params
    u = np.full(cls.nu, 0.1)
    for a, b in zip(leg.forward_dynamics(q, np.zeros(cls.nq), u), again.forward_dynamics(q, np.zeros(cls.nq), u)):
        assert np.array_equal(a, b)


def test_mujoco_agrees_on_a_throw_in_3d(tmp_path):
    """The same scene in MuJoCo (its soft contact, on our MJCF export with the elliptic cone)
    and ours (the exact Coulomb cone, a plastic impact): `sliding_mass`'s block thrown level
    at 2 m/s from 5 cm lands at the same time (to MuJoCo's step) and stops where ours does,
    to a millimetre. A floor whose own friction overrode the contact's (MuJoCo takes the
    larger of two geoms') stopped MuJoCo's block 18 cm short; a pyramidal cone would slide
    it off the throw's line."""
    mujoco = pytest.importorskip("mujoco")
    xml = tmp_path / "sliding_mass.xml"
    subprocess.run(["cargo", "run", "--quiet", "-p", "xtask", "--", "export", "sliding_mass",
                    "--format", "mjcf", "--out", str(xml)], cwd=ROOT, check=True)
    m = mujoco.MjModel.from_xml_path(str(xml))
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    d = mujoco.MjData(m)
    start, speed = np.array([0.0, 0.0, 0.05]), np.array([2.0, 0.3, 0.0])
    d.qpos[:], d.qvel[:] = start, speed
    landed = None
    for _ in range(int(round(1.0 / m.opt.timestep))):
        mujoco.mj_step(m, d)
        if landed is None and d.ncon > 0:
            landed = d.time
    assert landed is not None, "MuJoCo's block never touched its floor"
    leg = legmodels.SlidingMass()
    rec = leg.simulate_hybrid(start, speed, 1000, 1e-3)
    touchdown = next(e for e in rec["events"] if e["kind"] == "touchdown")
    assert abs(landed - touchdown["t"]) <= m.opt.timestep
    # Where each stops, along the ground: within 1 mm (MuJoCo's contact is soft).
    assert np.abs(rec["qd"][-1]).max() < 1e-9 and np.abs(d.qvel[:2]).max() < 1e-6
    gap = np.linalg.norm(rec["q"][-1][:2] - d.qpos[:2])
    assert gap < 1e-3, (rec["q"][-1], d.qpos)


def test_every_class_and_instance_pickles():
    for name, cls in legmodels.models.items():
        assert pickle.loads(pickle.dumps(cls)) is cls, name
        leg = cls()
        params = leg.params
        first = cls.parameter_names[0]
        leg.set(first, params[first] * 1.5 + 0.25)
        copy = pickle.loads(pickle.dumps(leg))
        assert type(copy) is cls
        assert copy.params == leg.params, name
    with_baumgarte = legmodels.Minitaur(baumgarte=(10.0, 25.0))
    assert pickle.loads(pickle.dumps(with_baumgarte)).__getnewargs_ex__() == with_baumgarte.__getnewargs_ex__()
