"""The Python API under hostile input (issue 29): property tests with Hypothesis over arrays
of every shape, dtype, layout and value, parameters, settings and callables that misbehave;
and one test per class of failure found, each of which failed before its fix.

The property: every call either returns finite arrays of the documented shape, or raises one
of the package's errors (or ValueError / TypeError for an argument) with a one-line message
of bounded length. Never a Rust panic (`PanicException`), a crash, a hang or a NaN result."""

import os
import pickle
import signal
import threading
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import legmodels

ALLOWED = (legmodels.LegError, ValueError, TypeError, OverflowError)
FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def said_well(e):
    """A refusal: one line, short, no control characters."""
    message = str(e)
    assert message and "\n" not in message and "\x1b" not in message, repr(message)
    assert len(message) < 400, len(message)


def call(f, *args, **kwargs):
    """`f(...)`, or None when it refused as it should; anything else fails the test."""
    try:
        return f(*args, **kwargs)
    except ALLOWED as e:
        said_well(e)
        return None


# Arrays of every dtype numpy has for numbers (and some it has for other things), any
# shape up to 3-D, any value, C or Fortran order, strided views.
DTYPES = st.one_of(
    hnp.floating_dtypes(),
    hnp.integer_dtypes(),
    hnp.unsigned_integer_dtypes(),
    hnp.complex_number_dtypes(),
    hnp.boolean_dtypes(),
    st.just(np.dtype("U3")),
    st.just(np.dtype(object)),
)


@st.composite
def arrays(draw, length=None):
    dtype = draw(DTYPES)
    if length is not None and draw(st.booleans()):
        shape = (length,)
    else:
        shape = draw(hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=6))
    if dtype.kind == "U":
        a = np.full(shape, "1.0", dtype=dtype)
    elif dtype.kind == "O":
        a = np.empty(shape, dtype=object)
        a.fill(draw(st.sampled_from([1.0, None, "x", [1.0]])))
    else:
        a = draw(hnp.arrays(dtype, shape))
    if a.ndim >= 1 and a.shape[0] > 1 and draw(st.booleans()):
        a = a[::-1]  # a negative stride
    if a.ndim >= 2 and draw(st.booleans()):
        a = np.asfortranarray(a)
    return a


def finite_result(x, shape):
    x = np.asarray(x)
    assert x.shape == shape, (x.shape, shape)
    assert np.all(np.isfinite(x)), x


@FAST
@given(q=arrays(4), qd=arrays(4), u=arrays(2))
def test_forward_dynamics_takes_any_array(q, qd, u):
    leg = legmodels.Minitaur()
    out = call(leg.forward_dynamics, q, qd, u)
    if out is not None:
        qdd, forces = out
        finite_result(qdd, (4,))
        finite_result(forces, (2,))


@FAST
@given(q=arrays(4), qd=arrays(4))
def test_terms_take_any_array(q, qd):
    leg = legmodels.Minitaur()
    for f, args, shape in [
        (leg.mass_matrix, (q,), (4, 4)),
        (leg.bias_forces, (q, qd), (4,)),
        (leg.constraint_jacobian, (q,), (2, 4)),
        (leg.foot_position, (q,), (2,)),
    ]:
        out = call(f, *args)
        if out is not None:
            # The terms are straight-line arithmetic: NaN in, NaN out is allowed only when
            # the input held one; finite in must be finite out or refused.
            x = np.asarray(out)
            assert x.shape == shape
            arrays_in = [np.asarray(a, dtype=float) for a in args]
            if all(np.all(np.isfinite(a)) and np.all(np.abs(a) < 1e3) for a in arrays_in):
                assert np.all(np.isfinite(x)), (f.__name__, args, x)


@FAST
@given(
    theta=arrays(2),
    max_step=st.floats(allow_nan=True, allow_infinity=True),
)
def test_assembly_takes_any_input(theta, max_step):
    leg = legmodels.Minitaur()
    home = leg.assembled_home()
    out = call(leg.assemble_along, home, theta, max_step=max_step)
    if out is not None:
        finite_result(out, (4,))
        assert np.max(np.abs(leg.closure_residual(out))) < 1e-9


@FAST
@given(
    steps=st.one_of(st.integers(min_value=-5, max_value=50), st.integers(min_value=2**40)),
    dt=st.floats(allow_nan=True, allow_infinity=True),
    method=st.sampled_from(["rk4", "euler", "semi_implicit_euler", "rk5", "", "RK4"]),
    kp=st.floats(allow_nan=True, allow_infinity=True),
    limit=st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True)),
)
def test_simulation_settings_are_checked(steps, dt, method, kp, limit):
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    torque_limit = None if limit is None else [limit, limit]
    t0 = time.monotonic()
    try:
        record = leg.simulate(
            q, np.zeros(4), steps, dt, controller="pd_gravity", setpoint=q[leg.actuated],
            kp=kp, torque_limit=torque_limit, method=method,
        )
    except legmodels.SimulationError as e:
        said_well(e)
        record = e.record
    except ALLOWED as e:
        said_well(e)
        return
    finally:
        assert time.monotonic() - t0 < 30, "bounded work"
    assert len(record["t"]) <= 51
    assert np.all(np.isfinite(record["q"]))


@FAST
@given(
    name=st.text(max_size=200),
    value=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=5), st.none()),
)
def test_parameters_by_any_name_and_value(name, value):
    out = call(lambda: legmodels.Minitaur(**{name: value}))
    if out is not None:
        assert np.isfinite(out.get(name))


BAD_RESULTS = [
    None, "u", [1.0], [1.0, 2.0, 3.0], [np.nan, 0.0], [np.inf, 0.0], np.zeros((2, 2)),
    np.zeros(2, dtype=complex) + 1j, object(), [1e308, 1e308],
]


@pytest.mark.parametrize("result", BAD_RESULTS, ids=range(len(BAD_RESULTS)))
def test_a_torque_callable_that_misbehaves(result):
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    calls = []

    def torque(t, q, qd):
        calls.append(t)
        return result if len(calls) > 3 else np.zeros(2)

    try:
        record = leg.simulate(q, np.zeros(4), 20, 1e-3, torque=torque)
    except ALLOWED as e:
        said_well(e)
        # The steps before the bad torque are kept.
        assert hasattr(e, "record") and len(e.record["t"]) >= 1, e
        return
    assert np.all(np.isfinite(record["q"]))


# ---- one test per class of issue 29 not covered in test_legmodels.py ----


def test_every_class_and_leg_pickles():
    """Every class was named `Leg`, so none pickled (class 'wrong words', and issue 32)."""
    for name, cls in legmodels.models.items():
        assert cls.__name__ == cls.__qualname__ != "Leg", (name, cls.__name__)
        assert getattr(legmodels, cls.__name__) is cls
        assert pickle.loads(pickle.dumps(cls)) is cls
    leg = legmodels.Minitaur(lower_a_mass=0.123456789, baumgarte=(3.0, 4.0))
    again = pickle.loads(pickle.dumps(leg))
    assert type(again) is legmodels.Minitaur
    assert again.params == leg.params
    q = leg.assembled_home()
    qd = np.array([0.3, -0.2, 0.1, 0.4])
    for a, b in zip(leg.forward_dynamics(q, qd, [0.1, 0.2]), again.forward_dynamics(q, qd, [0.1, 0.2])):
        assert np.array_equal(a, b)  # bit for bit, the Baumgarte terms included


def test_wrong_words_are_right_now():
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    # A NaN pose was "the mass matrix is not positive definite"; now every method refuses
    # it by name, before any term is computed (mass_matrix and foot_position gave NaN).
    for f, args in [
        (leg.forward_dynamics, ([np.nan, 0, 0, 0], np.zeros(4), np.zeros(2))),
        (leg.mass_matrix, ([0, np.nan, 0, 0],)),
        (leg.foot_position, ([0, 0, np.inf, 0],)),
        (leg.bias_forces, (q, [0, 0, 0, np.nan])),
    ]:
        with pytest.raises(ValueError, match=r"\[\d\]` is (NaN|inf): every entry must be finite"):
            f(*args)
    # An angle of 1e308 rad has no precision left: refused, as the command line's --q.
    with pytest.raises(ValueError, match=r"`q\[0\]` is 1e308: a coordinate must be at most 1e9"):
        leg.mass_matrix([1e308, 0, 0, 0])
    with pytest.raises(ValueError, match="at most 1e9"):
        leg.assemble([1e308, 0.0], q)
    # Finite rates whose terms overflow were a "non-finite state".
    with pytest.raises(legmodels.DynamicsError, match="overflow"):
        leg.forward_dynamics(q, np.full(4, 1e200), np.zeros(2))
    # A negative kp was "non-finite" (k_d = 2 sqrt(k_p) = NaN).
    with pytest.raises(legmodels.ControlError, match="the gain kp of coordinate 0 is -5:"):
        leg.simulate(q, np.zeros(4), 10, 1e-3, controller="pd_gravity", setpoint=q[leg.actuated], kp=-5.0)
    with pytest.raises(legmodels.ControlError, match="the gain kd of coordinate 0 is -1:"):
        leg.simulate(q, np.zeros(4), 10, 1e-3, controller="pd_gravity", setpoint=q[leg.actuated], kd=-1.0)
    # A body of 1e308 kg was "give its mass": it is the fixed base's limit, xi -> 1.
    arm = legmodels.TwoLink()
    heavy = arm.impact_mitigation(arm.assembled_home(), body_mass=1e308)
    assert abs(heavy - 1.0) < 1e-9, heavy
    assert arm.impact_mitigation(arm.assembled_home(), body_mass=1.0) < heavy


def test_the_new_users_trial_settings():
    """Settings a new user's trial found taken without a word, or refused naming nothing."""
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    z = np.zeros(4)
    theta = q[leg.actuated]
    # A gain of 1e308 was taken and overflowed the first torque.
    with pytest.raises(legmodels.ControlError, match="the gain kp of coordinate 0 is 1e308: a gain must be zero or more and at most 1e9"):
        leg.simulate(q, z, 10, 1e-3, controller="pd_gravity", setpoint=theta, kp=1e308)
    # One torque limit for every motor, as design_measures and the command line take.
    one = leg.simulate(q, z, 50, 1e-3, controller="pd_gravity", setpoint=theta + 0.5, torque_limit=0.01)
    each = leg.simulate(q, z, 50, 1e-3, controller="pd_gravity", setpoint=theta + 0.5, torque_limit=[0.01, 0.01])
    np.testing.assert_array_equal(one["u"], each["u"])
    assert np.abs(one["u"]).max() <= 0.01 + 1e-15
    with pytest.raises(ValueError, match="torque_limit"):
        leg.simulate(q, z, 10, 1e-3, torque_limit=-1.0)
    # A motor range the wrong way round, or not one pair per motor, names the argument.
    with pytest.raises(ValueError, match="`motor_range`: the workspace grid needs each motor range"):
        leg.workspace(1.0, 1.0, nodes=5, motor_range=[(1.0, -1.0), (-4.0, 4.0)])
    with pytest.raises(ValueError, match="`motor_range` needs 2 pairs"):
        leg.workspace(1.0, 1.0, nodes=5, motor_range=(1.0, -1.0))
    # The grid's bounds are the Rust API's and the command line's: 2 to 2000 nodes.
    for bad in (1, 2001):
        with pytest.raises(ValueError, match="`nodes`: the workspace grid needs from 2 to 2000 nodes per side"):
            leg.workspace(1.0, 1.0, nodes=bad)


def test_a_pose_off_its_closures_is_refused_by_the_analysis():
    """Class 4: analysis and linearization returned numbers at poses the leg cannot take."""
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    off = q + [0.0, 0.2, 0.0, 0.0]
    limits = ([2.0, 2.0], [30.0, 30.0])
    for f in (
        lambda p: leg.design_measures(p, *limits),
        lambda p: leg.impact_mitigation(p, body_mass=2.0),
        lambda p: leg.foot_inverse_inertia(p),
        lambda p: leg.linearize(p, 1e-3),
    ):
        with pytest.raises(legmodels.LegError, match="off its closures by .* project it onto them first") as e:
            f(off)
        said_well(e.value)
        # Minitaur stretched flat (q = 0) is on its closures but singular: the closure rows
        # lose rank there (impact_mitigation gave 0.0, a Lambda^-1 with a zero row).
        with pytest.raises(legmodels.LegError, match="lose rank|degree\\(s\\) of freedom here") as e:
            f(np.zeros(4))
        said_well(e.value)
        f(q)  # on the closures: computed
    # Projected, as the message says, it is computed.
    leg.design_measures(leg.project_position(off), *limits)
    # The simulation projects its start by default (documented): not refused.
    leg.simulate(off, np.zeros(4), 2, 1e-3)


def test_ctrl_c_stops_a_simulation_with_its_record():
    """Item 2: Ctrl-C was ignored for minutes; now it raises KeyboardInterrupt at once, with
    the record so far, from a run with a controller and from one with a Python callable."""
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    runs = [
        lambda: leg.simulate(q, np.zeros(4), 1_000_000, 1e-4, controller="joint_feedback_linearization", setpoint=q[leg.actuated]),
        lambda: leg.simulate(q, np.zeros(4), 1_000_000, 1e-4, torque=lambda t, q, qd: np.zeros(2)),
    ]
    hopper = legmodels.MinitaurHopper()
    runs.append(lambda: hopper.simulate_hybrid(hopper.assembled_home(), np.zeros(hopper.nq), 1_000_000, 1e-4))
    # Python's own Ctrl-C handler, whatever the process inherited: a shell that starts a job
    # in the background (`cmd &`, no job control) starts it with SIGINT ignored, and Python
    # then installs no handler, so the signal would do nothing at all.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        for run in runs:
            timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
            t0 = time.monotonic()
            timer.start()
            try:
                with pytest.raises(KeyboardInterrupt) as stopped:
                    run()
            finally:
                timer.cancel()
            assert time.monotonic() - t0 < 10
            record = stopped.value.record
            assert 1 < len(record["t"]) < 1_000_001
            assert np.all(np.isfinite(record["q"]))
    finally:
        signal.signal(signal.SIGINT, previous)


def test_a_simulation_releases_the_gil():
    """Item 2: a run with a controller is Rust only; another Python thread runs meanwhile."""
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    done = threading.Event()

    def work():
        leg.simulate(q, np.zeros(4), 100_000, 1e-4, controller="joint_feedback_linearization", setpoint=q[leg.actuated])
        done.set()

    worker = threading.Thread(target=work)
    ticks = 0
    worker.start()
    while not done.is_set():
        ticks += 1
        time.sleep(0)
    worker.join()
    assert ticks > 100, ticks


def test_steps_and_dt_are_named_when_wrong():
    """From the new user's trial: a negative step count was "can't convert negative int to
    unsigned" (naming nothing) and dt = 1e308 ran and failed as a "non-finite state"."""
    leg = legmodels.Minitaur()
    q = leg.assembled_home()
    for steps in (-1, 1.5, "10", None):
        with pytest.raises(ValueError, match="`steps` must be a whole number of steps") as e:
            leg.simulate(q, np.zeros(4), steps, 1e-3)
        said_well(e.value)
    for dt in (1e308, 2.0, float("inf")):
        with pytest.raises(ValueError, match="`dt` must be a positive time step of at most 1 s") as e:
            leg.simulate(q, np.zeros(4), 10, dt)
        said_well(e.value)
    hopper = legmodels.MinitaurHopper()
    with pytest.raises(ValueError, match="`steps`"):
        hopper.simulate_hybrid(hopper.assembled_home(), np.zeros(hopper.nq), -5, 1e-3)
