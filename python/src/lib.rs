//! `legmodels`: every generated leg in Python (PyO3, numpy arrays in and out).
//!
//! One class per generated model (`legmodels.Minitaur`, `legmodels.Atrias`, …), each a
//! thin layer over [`leg_models::Leg`]: arguments are checked for their length and turned
//! into fixed-size vectors, the Rust method runs, and its result comes back as numpy
//! arrays (dicts for several). Runtime errors are Python exceptions carrying the
//! runtime's message, subclasses of `legmodels.LegError`. The list follows the
//! generated crate (`generated::for_each_model!`): a new spec is a new class after
//! `cargo xtask gen` and a rebuild, with nothing to write here.

use leg_models::analysis::workspace::{GridOptions, NodeState, Segment, SlicePlane};
use leg_models::analysis::{
    AnalysisError as RustAnalysisError, Body, CapacitySets, MotorLimits, Polygon,
};
use leg_models::assembly::AssemblyError as RustAssemblyError;
use leg_models::control::linearize::LinearizationError as RustLinearizationError;
use leg_models::control::reference::Sinusoid;
use leg_models::control::{
    check_torque_limits, foot_inertias, ControlError as RustControlError,
    FootFeedbackLinearization, FootPdGravity, Gains, Saturated,
};
use leg_models::dynamics::contact::{
    forward_dynamics_with_contacts, spec_friction, ContactMode, Ground, Modes,
};
use leg_models::dynamics::DynamicsError as RustDynamicsError;
use leg_models::nalgebra::{SMatrix, SVector};
use leg_models::simulate::hybrid::{
    HybridRecord, HybridSimulator, HybridState, HybridTorqueSource,
};
use leg_models::simulate::{Method, State, StepOptions, TorqueSource};
use leg_models::{ContactModel, Leg};
use leg_models::{Shown, ShownNumber};
use numpy::ndarray::{Array2, Array3};
use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

pyo3::create_exception!(
    legmodels,
    LegError,
    PyException,
    "Base of the errors the leg models raise."
);
pyo3::create_exception!(
    legmodels,
    AssemblyError,
    LegError,
    "Loop assembly failed: unreachable motor angles or foot position, a singular pose, no convergence."
);
pyo3::create_exception!(
    legmodels,
    DynamicsError,
    LegError,
    "The forward dynamics has no unique solution (singular constraints or mass matrix) or was given non-finite values."
);
pyo3::create_exception!(
    legmodels,
    ControlError,
    LegError,
    "A controller does not apply to this leg, or failed at a state."
);
pyo3::create_exception!(
    legmodels,
    LinearizationError,
    LegError,
    "A linearization or chart of the constraint manifold failed."
);
pyo3::create_exception!(
    legmodels,
    SimulationError,
    LegError,
    "A simulation stopped early; `record` holds what it computed until then."
);
pyo3::create_exception!(
    legmodels,
    AnalysisError,
    LegError,
    "A design measure does not apply to this leg (the message says why), the pose is singular or not finite, or the workspace's start is outside its motor range."
);
pyo3::create_exception!(
    legmodels,
    ParameterError,
    LegError,
    "The leg has no parameter of that name, or the value is refused (not finite, a negative mass or inertia)."
);

fn assembly_err(e: RustAssemblyError) -> PyErr {
    AssemblyError::new_err(e.to_string())
}
fn dynamics_err(e: RustDynamicsError) -> PyErr {
    DynamicsError::new_err(e.to_string())
}
fn control_err(e: RustControlError) -> PyErr {
    ControlError::new_err(e.to_string())
}
fn parameter_err(e: leg_models::ParameterError<'_>) -> PyErr {
    ParameterError::new_err(match e {
        leg_models::ParameterError::Unknown { name, leg, .. } => format!(
            "leg `{leg}` has no parameter `{}`{} (its `parameter_names` lists them)",
            Shown(name),
            e.suggestion()
                .map(|s| format!("; did you mean `{s}`?"))
                .unwrap_or_default()
        ),
        other => other.to_string(),
    })
}
fn linearization_err(e: RustLinearizationError) -> PyErr {
    LinearizationError::new_err(e.to_string())
}
fn analysis_err(e: RustAnalysisError) -> PyErr {
    AnalysisError::new_err(e.to_string())
}

/// A workspace grid's option out of range, as the `ValueError` of the argument that holds it.
fn grid_err(e: RustAnalysisError) -> PyErr {
    match e {
        RustAnalysisError::Grid { what, .. } => {
            let argument = if what.contains("nodes") {
                "nodes"
            } else if what.contains("centre") {
                "centre"
            } else if what.contains("half-width") {
                "half_width"
            } else {
                "motor_range"
            };
            PyValueError::new_err(format!("`{argument}`: {e}"))
        }
        e => analysis_err(e),
    }
}

/// `motor_range`: one `(low, high)` pair per motor.
fn motor_ranges<const N: usize>(value: &Bound<'_, PyAny>) -> PyResult<[(f64, f64); N]> {
    match value.extract::<Vec<[f64; 2]>>() {
        Ok(p) if p.len() == N => Ok(core::array::from_fn(|k| (p[k][0], p[k][1]))),
        _ => Err(PyValueError::new_err(format!(
            "`motor_range` needs {N} pairs (low, high), one per motor; got {}",
            value
                .repr()
                .map(|r| leg_models::Shown(&r.to_string()).to_string())
                .unwrap_or_else(|_| "a value that cannot be shown".into())
        ))),
    }
}

/// A spatial leg's slice plane by its axes' names (`None`: sagittal); a planar leg takes none.
fn slice_plane(slice: Option<&str>, nd: usize) -> PyResult<Option<SlicePlane>> {
    match (slice, nd) {
        (None, _) => Ok(None),
        (Some(_), 2) => Err(PyValueError::new_err("`slice`: a planar leg's workspace is its own plane (a spatial leg takes \"xz\", \"yz\" or \"xy\")")),
        (Some("xz"), _) => Ok(Some(SlicePlane::SAGITTAL)),
        (Some("yz"), _) => Ok(Some(SlicePlane::FRONTAL)),
        (Some("xy"), _) => Ok(Some(SlicePlane::TRANSVERSE)),
        (Some(other), _) => Err(PyValueError::new_err(format!("`slice`: expected \"xz\", \"yz\" or \"xy\", got {:?}", Shown(other).to_string()))),
    }
}

/// A motor limit: one positive number for every motor, or one per motor.
fn per_motor<const N: usize>(name: &str, value: &Bound<'_, PyAny>) -> PyResult<SVector<f64, N>> {
    let v: SVector<f64, N> = match value.extract::<f64>() {
        Ok(x) => SVector::from_element(x),
        Err(_) => vector(name, value)?,
    };
    if let Some(bad) = v.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
        return Err(PyValueError::new_err(format!(
            "`{name}` must be positive and finite, got {bad}"
        )));
    }
    Ok(v)
}

/// A polygon's vertices as an `n × 2` array (counter-clockwise).
fn out_polygon<'py>(py: Python<'py>, poly: &Polygon<f64>) -> Bound<'py, PyArray2<f64>> {
    out_rows(py, poly.vertices().iter().copied())
}

/// Segments as an `n × 2 × 2` array (segment, end, x/y).
fn out_segments<'py>(py: Python<'py>, segments: &[Segment]) -> Bound<'py, PyArray3<f64>> {
    let mut a = Array3::zeros((segments.len(), 2, 2));
    for (i, s) in segments.iter().enumerate() {
        for e in 0..2 {
            for c in 0..2 {
                a[[i, e, c]] = s[e][c];
            }
        }
    }
    PyArray3::from_owned_array(py, a)
}

/// A complex array is refused: numpy would drop its imaginary part with only a warning.
fn not_complex(name: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
    let kind = value
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract::<String>());
    match kind {
        Ok(k) if k == "c" => Err(PyValueError::new_err(format!(
            "`{name}` is a complex array; the leg's quantities are real"
        ))),
        _ => Ok(()),
    }
}

/// A vector argument of length `N` with every entry finite: a NaN or infinite pose, rate
/// or torque is refused by name (the terms gave NaN back, and the solves a wrong reason).
fn vector<const N: usize>(name: &str, value: &Bound<'_, PyAny>) -> PyResult<SVector<f64, N>> {
    let v = any_vector::<N>(name, value)?;
    if let Some((k, x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "`{name}[{k}]` is {x}: every entry must be finite"
        )));
    }
    Ok(v)
}

/// A pose (or motor angles) of length `N`: finite and at most `MAX_COORDINATE` (1e9) in
/// magnitude, the rule the command line's `--q` obeys too.
fn pose<const N: usize>(name: &str, value: &Bound<'_, PyAny>) -> PyResult<SVector<f64, N>> {
    let v = vector::<N>(name, value)?;
    leg_models::check_pose(v.as_slice()).map_err(|(k, x)| {
        PyValueError::new_err(format!(
            "`{name}[{k}]` is {x:e}: a coordinate must be at most {:e} in magnitude (rad, or m)",
            leg_models::MAX_COORDINATE
        ))
    })?;
    Ok(v)
}

/// A vector argument of length `N`, any values: a numpy array of floats (no copy until
/// here) or any sequence of numbers.
fn any_vector<const N: usize>(name: &str, value: &Bound<'_, PyAny>) -> PyResult<SVector<f64, N>> {
    let length = |len: usize| {
        if len == N {
            Ok(())
        } else {
            Err(PyValueError::new_err(format!(
                "`{name}` has {len} entries, this leg needs {N}"
            )))
        }
    };
    if let Ok(a) = value.cast::<PyArray1<f64>>() {
        length(a.len())?;
        // Safety: the entries are copied at once, holding the GIL (the abi3 build is not
        // free-threaded), so nothing writes the array meanwhile; numpy's borrow tracking
        // (PyReadonlyArray) cost more than the dynamics of a small leg.
        if let Ok(slice) = unsafe { a.as_slice() } {
            return Ok(SVector::from_column_slice(slice));
        }
    }
    if let Ok(a) = value.extract::<PyReadonlyArray1<'_, f64>>() {
        length(a.len())?;
        let a = a.as_array();
        return Ok(SVector::from_fn(|i, _| a[i]));
    }
    not_complex(name, value)?;
    let v: Vec<f64> = value.extract().map_err(|_| {
        PyValueError::new_err(format!(
            "`{name}` must be a 1-D array or sequence of {N} numbers"
        ))
    })?;
    length(v.len())?;
    Ok(SVector::from_column_slice(&v))
}

/// A matrix argument of `R × C`.
fn matrix<const R: usize, const C: usize>(
    name: &str,
    value: &Bound<'_, PyAny>,
) -> PyResult<SMatrix<f64, R, C>> {
    let a: PyReadonlyArray2<'_, f64> = value.extract().map_err(|_| {
        PyValueError::new_err(format!("`{name}` must be a 2-D float array of {R} × {C}"))
    })?;
    if a.shape() != [R, C] {
        return Err(PyValueError::new_err(format!(
            "`{name}` is {} × {}, this leg needs {R} × {C}",
            a.shape()[0],
            a.shape()[1]
        )));
    }
    let a = a.as_array();
    Ok(SMatrix::from_fn(|i, j| a[[i, j]]))
}

fn out_vector<'py, const N: usize>(
    py: Python<'py>,
    v: &SVector<f64, N>,
) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v.as_slice())
}

fn out_matrix<'py, const R: usize, const C: usize>(
    py: Python<'py>,
    m: &SMatrix<f64, R, C>,
) -> Bound<'py, PyArray2<f64>> {
    let a = PyArray2::zeros(py, [R, C], false);
    // Safety: a new C-contiguous array no one else holds yet.
    let out = unsafe { a.as_slice_mut() }.expect("a new array is contiguous");
    for i in 0..R {
        for j in 0..C {
            out[i * C + j] = m[(i, j)];
        }
    }
    a
}

/// Rows of vectors as an `n × N` array.
fn out_rows<'py, const N: usize>(
    py: Python<'py>,
    rows: impl ExactSizeIterator<Item = SVector<f64, N>>,
) -> Bound<'py, PyArray2<f64>> {
    let n = rows.len();
    let mut a = Array2::zeros((n, N));
    for (r, v) in rows.enumerate() {
        for c in 0..N {
            a[[r, c]] = v[c];
        }
    }
    PyArray2::from_owned_array(py, a)
}

/// The most a step may be (s): a step of 1e308 s ran and failed as a "non-finite state".
const MAX_DT: f64 = 1.0;

fn step_options(dt: f64, method: &str, project: bool) -> PyResult<StepOptions<f64>> {
    if !(dt.is_finite() && dt > 0.0 && dt <= MAX_DT) {
        return Err(PyValueError::new_err(format!(
            "`dt` must be a positive time step of at most {MAX_DT} s, got {}",
            ShownNumber(dt)
        )));
    }
    let mut opts = StepOptions::rk4(dt);
    opts.method = match method {
        "rk4" => Method::Rk4,
        "semi_implicit_euler" => Method::SemiImplicitEuler,
        other => {
            return Err(PyValueError::new_err(format!(
                "unknown `method` \"{}\": \"rk4\" or \"semi_implicit_euler\"",
                Shown(other)
            )))
        }
    };
    opts.project = project;
    Ok(opts)
}

/// A reference `setpoint + amplitude · sin(2π frequency t + phase)` per coordinate.
fn sinusoid<const N: usize>(
    setpoint: &Bound<'_, PyAny>,
    amplitude: Option<&Bound<'_, PyAny>>,
    frequency: Option<&Bound<'_, PyAny>>,
    phase: Option<&Bound<'_, PyAny>>,
) -> PyResult<Sinusoid<f64, N>> {
    Ok(Sinusoid {
        offset: vector("setpoint", setpoint)?,
        amplitude: amplitude
            .map(|a| vector("amplitude", a))
            .transpose()?
            .unwrap_or_else(SVector::zeros),
        frequency: frequency
            .map(|f| vector("frequency", f))
            .transpose()?
            .unwrap_or_else(SVector::zeros),
        phase: phase
            .map(|p| vector("phase", p))
            .transpose()?
            .unwrap_or_else(SVector::zeros),
    })
}

/// A step count: a whole number, zero or more (a negative one was numpy's
/// "can't convert negative int to unsigned", naming nothing).
fn step_count(steps: &Bound<'_, PyAny>) -> PyResult<usize> {
    steps.extract::<usize>().map_err(|_| {
        let shown = steps.repr().map(|r| r.to_string()).unwrap_or_default();
        PyValueError::new_err(format!(
            "`steps` must be a whole number of steps, zero or more, got {}",
            Shown(&shown)
        ))
    })
}

/// Torques from Python: a constant array (zero when none is given) or a callable
/// `(t, q, qd) -> u`, held without the GIL (`Py`), so that a run can release it.
enum Torques<const NU: usize> {
    Constant(SVector<f64, NU>),
    Callable(Py<PyAny>),
}

struct PythonTorques<const NQ: usize, const NU: usize> {
    torques: Torques<NU>,
    /// The first error the callable raised: the run stops and re-raises it.
    error: Option<PyErr>,
}

impl<const NQ: usize, const NU: usize> PythonTorques<NQ, NU> {
    fn new(torque: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let torques = match torque {
            None => Torques::Constant(SVector::zeros()),
            Some(t) if t.is_callable() => Torques::Callable(t.clone().unbind()),
            Some(t) => Torques::Constant(vector("torque", t)?),
        };
        Ok(PythonTorques {
            torques,
            error: None,
        })
    }

    fn call(&mut self, t: f64, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>) -> SVector<f64, NU> {
        let f = match &self.torques {
            Torques::Constant(u) => return *u,
            Torques::Callable(f) => f,
        };
        // The GIL is taken for the call only: the integration between calls runs without it.
        let result = Python::attach(|py| {
            f.bind(py)
                .call1((t, out_vector(py, q), out_vector(py, qd)))
                .and_then(|u| vector::<NU>("torque(t, q, qd)", &u))
        });
        match result {
            Ok(u) => u,
            Err(e) => {
                self.error.get_or_insert(e);
                SVector::from_element(f64::NAN)
            }
        }
    }
}

impl<const NQ: usize, const NU: usize> TorqueSource<f64, NQ, NU> for PythonTorques<NQ, NU> {
    fn torque(
        &mut self,
        t: f64,
        state: &State<f64, NQ>,
    ) -> Result<SVector<f64, NU>, RustControlError> {
        Ok(self.call(t, &state.q, &state.qd))
    }
}

/// A torque source that looks for Ctrl-C every [`Interruptible::EVERY`] calls (the run holds
/// no GIL, so Python's own check does not run): on a signal the run stops as a controller
/// error would, with its record, and the signal's exception (`KeyboardInterrupt`) is raised.
struct Interruptible<S> {
    inner: S,
    calls: u32,
    interrupt: Option<PyErr>,
}

impl<S> Interruptible<S> {
    /// About a millisecond of RK4 steps on the largest legs: Ctrl-C answers at once.
    const EVERY: u32 = 256;

    fn new(inner: S) -> Self {
        Interruptible {
            inner,
            calls: 0,
            interrupt: None,
        }
    }

    fn poll(&mut self) -> Result<(), RustControlError> {
        self.calls = self.calls.wrapping_add(1);
        if self.calls.is_multiple_of(Self::EVERY) {
            if let Err(e) = Python::attach(|py| py.check_signals()) {
                self.interrupt = Some(e);
                return Err(RustControlError::Interrupted);
            }
        }
        Ok(())
    }
}

impl<S: TorqueSource<f64, NQ, NU>, const NQ: usize, const NU: usize> TorqueSource<f64, NQ, NU>
    for Interruptible<S>
{
    fn torque(
        &mut self,
        t: f64,
        state: &State<f64, NQ>,
    ) -> Result<SVector<f64, NU>, RustControlError> {
        self.poll()?;
        self.inner.torque(t, state)
    }
}

impl<S, const NQ: usize, const NK: usize, const NU: usize, const ND: usize>
    HybridTorqueSource<f64, NQ, NK, NU, ND> for Interruptible<S>
where
    S: HybridTorqueSource<f64, NQ, NK, NU, ND>,
{
    fn torque(
        &mut self,
        t: f64,
        state: &HybridState<f64, NQ, NK, ND>,
    ) -> Result<SVector<f64, NU>, RustControlError> {
        self.poll()?;
        self.inner.torque(t, state)
    }
}

/// The exception a run ends with: the callable's own error or Ctrl-C's `KeyboardInterrupt`
/// first (with the record so far as its `record`), else the simulator's stop as
/// `SimulationError` (also with its `record`), else the record.
fn finish<'py>(
    py: Python<'py>,
    pending: Option<PyErr>,
    stopped: Option<String>,
    record: PyResult<Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let record = record?;
    let err = match (pending, stopped) {
        (Some(e), _) => e,
        (None, Some(why)) => SimulationError::new_err(why),
        (None, None) => return Ok(record),
    };
    err.value(py).setattr("record", record)?;
    Err(err)
}

/// Runs `source` in the leg's simulator without the GIL and returns the record as arrays;
/// a run that stops early raises `SimulationError` with the record so far as its `record`.
fn run_simulation<'py, L, S, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    py: Python<'py>,
    leg: &Leg<L, f64, NQ, NC, NU, NK>,
    initial: State<f64, NQ>,
    steps: usize,
    opts: StepOptions<f64>,
    source: S,
    callable_error: fn(&mut S) -> Option<PyErr>,
) -> PyResult<Bound<'py, PyDict>>
where
    L: leg_models::LegDynamics<NQ, NC, NU>,
    S: TorqueSource<f64, NQ, NU> + Send,
    Leg<L, f64, NQ, NC, NU, NK>: Sync,
{
    let mut source = Interruptible::new(source);
    let result = py.detach(|| leg.simulator(opts).run(initial, steps, &mut source));
    let record = |samples: &[leg_models::simulate::Sample<f64, NQ, NC, NU>]| -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("t", PyArray1::from_iter(py, samples.iter().map(|s| s.t)))?;
        d.set_item("q", out_rows(py, samples.iter().map(|s| s.state.q)))?;
        d.set_item("qd", out_rows(py, samples.iter().map(|s| s.state.qd)))?;
        d.set_item("u", out_rows(py, samples.iter().map(|s| s.u)))?;
        d.set_item("forces", out_rows(py, samples.iter().map(|s| s.forces)))?;
        d.set_item("energy", PyArray1::from_iter(py, samples.iter().map(|s| s.energy)))?;
        d.set_item(
            "closure_residual",
            PyArray1::from_iter(py, samples.iter().map(|s| s.closure_residual)),
        )?;
        Ok(d)
    };
    let (samples, stopped) = match &result {
        Ok(samples) => (samples.as_slice(), None),
        Err(e) => (e.samples.as_slice(), Some(e.to_string())),
    };
    let pending = source
        .interrupt
        .take()
        .or_else(|| callable_error(&mut source.inner));
    finish(py, pending, stopped, record(samples))
}

/// Runs leg `L` on the ground in `sim` from `(q, qd)` (every contact's mode found from the
/// state at rest torques) for `steps` steps without the GIL, torques as in `simulate`; the
/// record as arrays (t, q, qd, u, contact_forces: each contact's tangential rows then its
/// normal one, in the ground's frame; energy; closure_residual) and `events`, a list of
/// dicts (t, kind, contact, impulse `[Λ_t, Λ_n]`: on a spatial leg `Λ_t` is the tangential
/// impulse's magnitude, energy_lost). A run that stops early raises `SimulationError`
/// with the record so far as its `record`.
#[allow(clippy::too_many_arguments)]
fn simulate_on_ground<
    'py,
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    py: Python<'py>,
    sim: &HybridSimulator<L, f64, NQ, NC, NU, NK, ND>,
    q: &Bound<'py, PyAny>,
    qd: &Bound<'py, PyAny>,
    steps: &Bound<'py, PyAny>,
    dt: f64,
    torque: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>>
where
    L: ContactModel<NQ, NC, NU, NK, ND>,
    HybridSimulator<L, f64, NQ, NC, NU, NK, ND>: Sync,
{
    step_options(dt, "rk4", true)?;
    let steps = step_count(steps)?;
    let mut torques = PythonTorques::<NQ, NU>::new(torque)?;
    let start = sim
        .start(
            State {
                q: pose("q", q)?,
                qd: vector("qd", qd)?,
            },
            &SVector::zeros(),
        )
        .map_err(|e| SimulationError::new_err(e.to_string()))?;
    let mut source = Interruptible::new(|t: f64, hs: &HybridState<f64, NQ, NK, ND>| {
        torques.call(t, &hs.state.q, &hs.state.qd)
    });
    // Without the GIL (the callable takes it for its calls), Ctrl-C seen.
    let result = py.detach(|| sim.run(start, steps, &mut source));
    let pending = source.interrupt.take().or_else(|| torques.error.take());
    let record = |r: &HybridRecord<f64, NQ, NC, NU, NK, ND>| -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let s = &r.samples;
        d.set_item("t", PyArray1::from_iter(py, s.iter().map(|s| s.t)))?;
        d.set_item("q", out_rows(py, s.iter().map(|s| s.state.state.q)))?;
        d.set_item("qd", out_rows(py, s.iter().map(|s| s.state.state.qd)))?;
        d.set_item("u", out_rows(py, s.iter().map(|s| s.u)))?;
        d.set_item(
            "contact_forces",
            out_rows(py, s.iter().map(|s| s.contact_forces)),
        )?;
        d.set_item(
            "energy",
            PyArray1::from_iter(py, s.iter().map(|s| s.energy)),
        )?;
        d.set_item(
            "closure_residual",
            PyArray1::from_iter(py, s.iter().map(|s| s.closure_residual)),
        )?;
        let events = PyList::empty(py);
        for e in &r.events {
            let ev = PyDict::new(py);
            ev.set_item("t", e.t)?;
            ev.set_item("kind", format!("{:?}", e.kind).to_lowercase())?;
            ev.set_item("contact", L::CONTACT_NAMES[e.contact])?;
            ev.set_item("impulse", e.impulse.to_vec())?;
            ev.set_item("energy_lost", e.energy_lost)?;
            events.append(ev)?;
        }
        d.set_item("events", events)?;
        Ok(d)
    };
    let (r, stopped) = match &result {
        Ok(r) => (r, None),
        Err(stopped) => (&stopped.record, Some(stopped.to_string())),
    };
    finish(py, pending, stopped, record(r))
}

/// Three vectors returned together.
type ThreeArrays<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
);

/// `(q̈, closure forces, contact forces)` of leg `L` with the contacts `held[k]` sticking
/// at `anchors` (their ground coordinates) and the others in flight.
#[allow(clippy::too_many_arguments)]
fn held_contact_dynamics<
    'py,
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    py: Python<'py>,
    params: &L::Params<f64>,
    baumgarte: Option<leg_models::dynamics::Baumgarte<f64>>,
    q: &Bound<'py, PyAny>,
    qd: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    held: &[bool],
    anchors: &Bound<'py, PyAny>,
) -> PyResult<ThreeArrays<'py>>
where
    L: ContactModel<NQ, NC, NU, NK, ND>,
{
    if held.len() * ND != NK {
        return Err(PyValueError::new_err(format!(
            "`held` has {} entries, this leg has {} contacts",
            held.len(),
            NK / ND
        )));
    }
    let mut modes = Modes::<NK, ND>::flight();
    for (k, h) in held.iter().enumerate() {
        if *h {
            modes.set(k, ContactMode::Stick);
        }
    }
    let s = forward_dynamics_with_contacts::<L, f64, NQ, NC, NU, NK, ND>(
        params,
        &pose("q", q)?,
        &vector("qd", qd)?,
        &vector("u", u)?,
        &modes,
        &vector("anchors", anchors)?,
        &Ground::of::<L, NQ, NC, NU, NK>(),
        &spec_friction::<L, f64, NQ, NC, NU, NK, ND>(),
        baumgarte,
    )
    .map_err(dynamics_err)?;
    Ok((
        out_vector(py, &s.x),
        out_vector(py, &s.closure),
        out_vector(py, &s.contact),
    ))
}

/// No Python callable: no error of its own.
fn no_callable<S>(_: &mut S) -> Option<PyErr> {
    None
}

/// One class per leg: the methods of every leg (terms, the foot in `nd` coordinates,
/// assembly, dynamics and derivatives, reductions, simulation with joint- or foot-space
/// controllers, linearization and LQR), then `extra`, the methods of the leg's kind.
macro_rules! leg_module {
    ($module:ident, $ty:ty, $nq:expr, $nc:expr, $nu:expr, $nk:expr, $nd:expr, $np:expr, { $($extra:tt)* }) => {
        mod $module {
            use super::*;
            use leg_models::{LegDynamics, LegModel, Parameters};

            type Model = $ty;
            const NQ: usize = $nq;
            const NC: usize = $nc;
            const NU: usize = $nu;
            const NK: usize = $nk;
            /// Coordinates of the foot (2 planar, 3 spatial) and closure points.
            const ND: usize = $nd;
            const NP: usize = $np;
            type L = Leg<Model, f64, NQ, NC, NU, NK>;

            /// A generated leg: its parameters (the spec's by default, keyword arguments
            /// override them by name) and every operation of the runtime.
            #[pyclass(name = "Leg", module = "legmodels")]
            pub struct PyLeg {
                leg: L,
            }

            #[pymethods]
            impl PyLeg {
                /// `Leg(**params)`: the spec's parameters, each keyword one overridden;
                /// `baumgarte=(alpha, beta)` adds Baumgarte terms to the dynamics.
                #[new]
                #[pyo3(signature = (baumgarte = None, **params))]
                fn new(
                    baumgarte: Option<(f64, f64)>,
                    params: Option<&Bound<'_, PyDict>>,
                ) -> PyResult<Self> {
                    let mut leg = L::default();
                    if let Some((alpha, beta)) = baumgarte {
                        leg = leg.with_baumgarte(alpha, beta);
                    }
                    if let Some(params) = params {
                        for (k, v) in params.iter() {
                            let name: String = k.extract()?;
                            let value: f64 = v.extract().map_err(|_| {
                                PyValueError::new_err(format!("parameter `{}` must be a number", Shown(&name)))
                            })?;
                            leg.set_parameter(&name, value)
                                .map_err(parameter_err)?;
                        }
                    }
                    Ok(PyLeg { leg })
                }

                fn __repr__(&self) -> String {
                    format!("legmodels.{}()", class_name())
                }

                /// Pickling (a work unit shipped to another process): the class by its
                /// name and the leg's parameters and Baumgarte terms as the constructor's
                /// keywords, so an unpickled leg equals the original bit for bit.
                fn __getnewargs_ex__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyTuple>, Bound<'py, PyDict>)> {
                    let kwargs = self.params(py)?;
                    if let Some(b) = self.leg.baumgarte() {
                        kwargs.set_item("baumgarte", (b.alpha, b.beta))?;
                    }
                    Ok((PyTuple::empty(py), kwargs))
                }

                /// The spec's name.
                #[classattr]
                fn name() -> &'static str {
                    Model::NAME
                }
                /// Number of joints.
                #[classattr]
                fn nq() -> usize {
                    NQ
                }
                /// Number of closure rows (a point closure: one per coordinate; a rod: one).
                #[classattr]
                fn nc() -> usize {
                    NC
                }
                /// Coordinates of a point: 2 for a planar leg, 3 for a spatial one.
                #[classattr]
                fn dimension() -> usize {
                    ND
                }
                /// Number of contact rows (two per contact point; none yet on a spatial leg).
                #[classattr]
                fn nk() -> usize {
                    NK
                }
                /// The first coordinate of each ball joint (its three angles follow:
                /// `R_x(α) R_y(β) R_z(γ)`, singular at `β = ±π/2`); none on a planar leg.
                #[classattr]
                fn ball_joints() -> Vec<usize> {
                    <Model as LegDynamics<NQ, NC, NU>>::BALL_JOINTS.to_vec()
                }
                /// Number of motors.
                #[classattr]
                fn nu() -> usize {
                    NU
                }
                /// Degrees of freedom of the closed chain.
                #[classattr]
                fn mobility() -> usize {
                    Model::MOBILITY
                }
                /// The joints' names, in coordinate order.
                #[classattr]
                fn joint_names() -> Vec<&'static str> {
                    Model::JOINT_NAMES.to_vec()
                }
                /// Indices of the actuated joints, in the order of `u`.
                #[classattr]
                fn actuated() -> Vec<usize> {
                    Model::ACTUATED.to_vec()
                }
                /// The parameters' names.
                #[classattr]
                fn parameter_names() -> Vec<&'static str> {
                    <Model as leg_models::LegDynamics<NQ, NC, NU>>::Params::<f64>::NAMES.to_vec()
                }

                /// The parameters as a dict name → value.
                #[getter]
                fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
                    let d = PyDict::new(py);
                    let p = self.leg.params();
                    for (i, n) in <Model as leg_models::LegDynamics<NQ, NC, NU>>::Params::<f64>::NAMES.iter().enumerate() {
                        d.set_item(*n, p.get(i))?;
                    }
                    Ok(d)
                }

                /// The parameter `name`.
                fn get(&self, name: &str) -> PyResult<f64> {
                    self.leg.parameter(name).map_err(parameter_err)
                }

                /// Sets the parameter `name` (no regeneration needed).
                fn set(&mut self, name: &str, value: f64) -> PyResult<()> {
                    self.leg
                        .set_parameter(name, value)
                        .map_err(parameter_err)
                }

                /// The spec's home pose (picks the assembly mode).
                fn home<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
                    out_vector(py, &self.leg.home())
                }

                /// The home pose projected onto the closures.
                fn assembled_home<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &self.leg.assembled_home().map_err(assembly_err)?))
                }

                // ---- terms ----

                /// `M(q)`, with reflected rotor inertia.
                fn mass_matrix<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
                    Ok(out_matrix(py, &Model::mass_matrix(&pose("q", q)?, self.leg.params())))
                }
                /// `N(q, q̇) = C q̇ + G`.
                fn bias_forces<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &Model::bias_forces(&pose("q", q)?, &vector("qd", qd)?, self.leg.params())))
                }
                /// `G(q)`.
                fn gravity_forces<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &Model::gravity_forces(&pose("q", q)?, self.leg.params())))
                }
                /// Damping torques `D q̇`.
                fn damping_forces<'py>(&self, py: Python<'py>, qd: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &Model::damping_forces(&vector("qd", qd)?, self.leg.params())))
                }
                /// The closure residual `φ(q)`.
                fn closure_residual<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &Model::closure_residual(&pose("q", q)?, self.leg.params())))
                }
                /// `J(q) = ∂φ/∂q`.
                fn constraint_jacobian<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
                    Ok(out_matrix(py, &Model::constraint_jacobian(&pose("q", q)?, self.leg.params())))
                }
                /// `J̇ q̇`.
                fn constraint_bias<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &Model::constraint_bias(&pose("q", q)?, &vector("qd", qd)?, self.leg.params())))
                }
                /// The foot point (base frame).
                fn foot_position<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &Model::foot_position(&pose("q", q)?, self.leg.params())))
                }
                /// `J_f(q)`.
                fn foot_jacobian<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
                    Ok(out_matrix(py, &Model::foot_jacobian(&pose("q", q)?, self.leg.params())))
                }
                /// `J̇_f q̇`.
                fn foot_bias<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &Model::foot_bias(&pose("q", q)?, &vector("qd", qd)?, self.leg.params())))
                }
                /// Kinetic energy `½ q̇ᵀ M q̇`.
                fn kinetic_energy(&self, q: &Bound<'_, PyAny>, qd: &Bound<'_, PyAny>) -> PyResult<f64> {
                    Ok(Model::kinetic_energy(&pose("q", q)?, &vector("qd", qd)?, self.leg.params()))
                }
                /// Potential energy (gravity and springs).
                fn potential_energy(&self, q: &Bound<'_, PyAny>) -> PyResult<f64> {
                    Ok(Model::potential_energy(&pose("q", q)?, self.leg.params()))
                }
                /// Each joint's position (column `i` for joint `i`), 2 × nq.
                fn joint_positions<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
                    Ok(out_matrix(py, &Model::joint_positions(&pose("q", q)?, self.leg.params())))
                }
                /// Each link's tip, 2 × nq.
                fn link_tips<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
                    Ok(out_matrix(py, &Model::link_tips(&pose("q", q)?, self.leg.params())))
                }
                /// The closure points (columns 2k, 2k + 1: points a and b of closure k).
                fn closure_points<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
                    Ok(out_matrix(py, &Model::closure_points(&pose("q", q)?, self.leg.params())))
                }
                /// `M`, `N`, `J`, `J̇ q̇` together (dict).
                fn dynamics_terms<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyDict>> {
                    let t = self.leg.dynamics_terms(&pose("q", q)?, &vector("qd", qd)?);
                    let d = PyDict::new(py);
                    d.set_item("mass_matrix", out_matrix(py, &t.mass_matrix))?;
                    d.set_item("bias_forces", out_vector(py, &t.bias_forces))?;
                    d.set_item("constraint_jacobian", out_matrix(py, &t.constraint_jacobian))?;
                    d.set_item("constraint_bias", out_vector(py, &t.constraint_bias))?;
                    Ok(d)
                }

                // ---- assembly ----

                /// The closed pose with motor angles `theta`, Newton from `guess` (home).
                #[pyo3(signature = (theta, guess = None))]
                fn assemble<'py>(&self, py: Python<'py>, theta: &Bound<'py, PyAny>, guess: Option<&Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    let guess = match guess { Some(g) => pose("guess", g)?, None => self.leg.home() };
                    Ok(out_vector(py, &self.leg.assemble(&pose("theta", theta)?, &guess).map_err(assembly_err)?))
                }
                /// The closed pose at `theta` by continuation from the assembled `start`.
                #[pyo3(signature = (start, theta, max_step = 0.05))]
                fn assemble_along<'py>(&self, py: Python<'py>, start: &Bound<'py, PyAny>, theta: &Bound<'py, PyAny>, max_step: f64) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &self.leg.assemble_along(&pose("start", start)?, &pose("theta", theta)?, max_step).map_err(assembly_err)?))
                }
                /// The closed pose with the foot at `foot`, from `guess` (home).
                #[pyo3(signature = (foot, guess = None))]
                fn foot_inverse<'py>(&self, py: Python<'py>, foot: &Bound<'py, PyAny>, guess: Option<&Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    let guess = match guess { Some(g) => pose("guess", g)?, None => self.leg.home() };
                    let foot = vector::<ND>("foot", foot)?;
                    let q = leg_models::assembly::foot_inverse::<Model, f64, NQ, NC, NU, ND, NP>(self.leg.params(), &foot, &guess, self.leg.tolerance());
                    Ok(out_vector(py, &q.map_err(assembly_err)?))
                }
                /// Joint rates of motor rates `theta_dot` at the assembled `q`.
                fn consistent_velocity<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, theta_dot: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    Ok(out_vector(py, &self.leg.consistent_velocity(&pose("q", q)?, &vector("theta_dot", theta_dot)?).map_err(assembly_err)?))
                }
                /// The nearest pose on the closures.
                fn project_position<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    let mut q = pose("q", q)?;
                    self.leg.project_position(&mut q).map_err(assembly_err)?;
                    Ok(out_vector(py, &q))
                }
                /// `qd` less its part off the closures' tangent at the assembled `q` (the
                /// correction of least kinetic energy): rates for any leg, its motors
                /// determining it or not.
                fn project_velocity<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    let mut qd = vector("qd", qd)?;
                    self.leg.project_velocity(&pose("q", q)?, &mut qd).map_err(assembly_err)?;
                    Ok(out_vector(py, &qd))
                }

                // ---- dynamics ----

                /// `(q̈, F)`: accelerations and closure forces under motor torques `u`.
                fn forward_dynamics<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>, u: &Bound<'py, PyAny>) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>)> {
                    let a = self.leg.forward_dynamics(&pose("q", q)?, &vector("qd", qd)?, &vector("u", u)?).map_err(dynamics_err)?;
                    Ok((out_vector(py, &a.qdd), out_vector(py, &a.forces)))
                }
                /// The forward dynamics and its exact derivatives (dict: qdd, forces,
                /// qdd_q, qdd_qd, qdd_u, forces_q, forces_qd, forces_u).
                fn forward_dynamics_derivatives<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>, u: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyDict>> {
                    let x = self.leg.forward_dynamics_derivatives(&pose("q", q)?, &vector("qd", qd)?, &vector("u", u)?).map_err(dynamics_err)?;
                    let d = PyDict::new(py);
                    d.set_item("qdd", out_vector(py, &x.acceleration.qdd))?;
                    d.set_item("forces", out_vector(py, &x.acceleration.forces))?;
                    d.set_item("qdd_q", out_matrix(py, &x.qdd_q))?;
                    d.set_item("qdd_qd", out_matrix(py, &x.qdd_qd))?;
                    d.set_item("qdd_u", out_matrix(py, &x.qdd_u))?;
                    d.set_item("forces_q", out_matrix(py, &x.forces_q))?;
                    d.set_item("forces_qd", out_matrix(py, &x.forces_qd))?;
                    d.set_item("forces_u", out_matrix(py, &x.forces_u))?;
                    Ok(d)
                }
                /// Nanoseconds per call of the Rust forward dynamics at this state, over
                /// `calls` calls in Rust (no Python in the loop): the baseline of the
                /// Python overhead benchmark (python/benchmarks/overhead.py).
                fn _rust_forward_dynamics_ns(&self, q: &Bound<'_, PyAny>, qd: &Bound<'_, PyAny>, u: &Bound<'_, PyAny>, calls: usize) -> PyResult<f64> {
                    let (q, qd, u) = (pose::<NQ>("q", q)?, vector::<NQ>("qd", qd)?, vector::<NU>("u", u)?);
                    self.leg.forward_dynamics(&q, &qd, &u).map_err(dynamics_err)?;
                    let start = std::time::Instant::now();
                    for _ in 0..calls {
                        let a = self.leg.forward_dynamics(std::hint::black_box(&q), std::hint::black_box(&qd), std::hint::black_box(&u));
                        std::hint::black_box(&a);
                    }
                    Ok(start.elapsed().as_nanos() as f64 / calls.max(1) as f64)
                }

                /// `(Ã, b̃)` of the reduction `Ã θ̈ = b̃ + u` to the motor angles.
                #[pyo3(signature = (q, qd, null_space = false))]
                fn actuated_reduction<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>, null_space: bool) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>)> {
                    let (q, qd) = (pose("q", q)?, vector("qd", qd)?);
                    let r = if null_space { self.leg.actuated_reduction_null_space(&q, &qd) } else { self.leg.actuated_reduction(&q, &qd) }.map_err(control_err)?;
                    Ok((out_matrix(py, &r.a_tilde), out_vector(py, &r.b_tilde)))
                }
                /// `u = Ã v − b̃` for motor accelerations `v` and its derivatives (dict).
                fn reduction_derivatives<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>, v: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyDict>> {
                    let r = self.leg.reduction_derivatives(&pose("q", q)?, &vector("qd", qd)?, &vector("v", v)?).map_err(control_err)?;
                    let d = PyDict::new(py);
                    d.set_item("a_tilde", out_matrix(py, &r.a_tilde))?;
                    d.set_item("b_tilde", out_vector(py, &r.b_tilde))?;
                    d.set_item("torque_q", out_matrix(py, &r.torque_q))?;
                    d.set_item("torque_qd", out_matrix(py, &r.torque_qd))?;
                    Ok(d)
                }

                // ---- control ----

                /// Feedback-linearizing torque at one state (no controller state kept):
                /// `kind` "joint" tracks motor angles, "foot" the foot; the reference's
                /// position, velocity and acceleration are `target`, `rate`, `accel`.
                #[pyo3(signature = (kind, q, qd, target, rate, accel, kp, kd = None))]
                #[allow(clippy::too_many_arguments)]
                fn feedback_linearization_torque<'py>(&self, py: Python<'py>, kind: &str, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>, target: &Bound<'py, PyAny>, rate: &Bound<'py, PyAny>, accel: &Bound<'py, PyAny>, kp: f64, kd: Option<f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                    let state = State { q: pose("q", q)?, qd: vector("qd", qd)? };
                    let gains_kd = kd.unwrap_or(2.0 * kp.sqrt());
                    let u = match kind {
                        "joint" => {
                            let r = leg_models::control::reference::Setpoint::<f64, NU> { position: pose("target", target)?, velocity: vector("rate", rate)?, acceleration: vector("accel", accel)? };
                            let mut c = self.leg.joint_feedback_linearization(Gains::new(kp, gains_kd), r).map_err(control_err)?;
                            c.torque(0.0, &state)
                        }
                        "foot" => {
                            let r = leg_models::control::reference::Setpoint::<f64, ND> { position: pose("target", target)?, velocity: vector("rate", rate)?, acceleration: vector("accel", accel)? };
                            let mut c = FootFeedbackLinearization::<Model, f64, _, NQ, NC, NU, ND, NP>::new(*self.leg.params(), Gains::new(kp, gains_kd), r).map_err(control_err)?;
                            c.torque(0.0, &state)
                        }
                        other => return Err(PyValueError::new_err(format!("unknown `kind` {other:?}: \"joint\" or \"foot\""))),
                    }.map_err(control_err)?;
                    Ok(out_vector(py, &u))
                }

                // ---- simulation ----

                /// Simulates `steps` steps of `dt` from `(q, qd)`. Torques: `torque` (None:
                /// zero; an array: constant; a callable `(t, q, qd) -> u`), or a built-in
                /// `controller`: "joint_feedback_linearization", "foot_feedback_linearization",
                /// "pd_gravity" or "foot_pd_gravity", tracking `setpoint + amplitude ·
                /// sin(2π frequency t + phase)` with gains `kp`, `kd` (default 2√kp) of the error
                /// dynamics in 1/s² and 1/s (the PD controllers scale them by the motors' or
                /// the foot's inertia at `q`, as `sim` does at home), torques
                /// clipped to `±torque_limit`. Returns a dict of arrays: t, q, qd, u,
                /// forces, energy, closure_residual.
                #[pyo3(signature = (q, qd, steps, dt, torque = None, controller = None, setpoint = None, amplitude = None, frequency = None, phase = None, kp = 100.0, kd = None, torque_limit = None, method = "rk4", project = true))]
                #[allow(clippy::too_many_arguments)]
                fn simulate<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, qd: &Bound<'py, PyAny>, steps: &Bound<'py, PyAny>, dt: f64, torque: Option<&Bound<'py, PyAny>>, controller: Option<&str>, setpoint: Option<&Bound<'py, PyAny>>, amplitude: Option<&Bound<'py, PyAny>>, frequency: Option<&Bound<'py, PyAny>>, phase: Option<&Bound<'py, PyAny>>, kp: f64, kd: Option<f64>, torque_limit: Option<&Bound<'py, PyAny>>, method: &str, project: bool) -> PyResult<Bound<'py, PyDict>> {
                    let initial = State { q: pose("q", q)?, qd: vector("qd", qd)? };
                    let steps = step_count(steps)?;
                    let opts = step_options(dt, method, project)?;
                    // One number for every motor or one per motor, as `design_measures` takes; inf is none.
                    let limit: SVector<f64, NU> = match torque_limit { Some(l) => match l.extract::<f64>() { Ok(x) => SVector::from_element(x), Err(_) => any_vector("torque_limit", l)? }, None => SVector::from_element(f64::INFINITY) };
                    check_torque_limits(&limit).map_err(|e| PyValueError::new_err(format!("`torque_limit`: {e}")))?;
                    let gains_kd = kd.unwrap_or(2.0 * kp.sqrt());
                    let Some(kind) = controller else {
                        let source = Saturated::new(PythonTorques::<NQ, NU>::new(torque)?, limit).map_err(control_err)?;
                        // The callable's error comes first, with the record so far.
                        return run_simulation(py, &self.leg, initial, steps, opts, source, |s| s.inner.error.take());
                    };
                    if torque.is_some() {
                        return Err(PyValueError::new_err("give `torque` or `controller`, not both"));
                    }
                    let setpoint = || setpoint.ok_or_else(|| PyValueError::new_err(format!("controller \"{}\" needs a `setpoint`", Shown(kind))));
                    match kind {
                        "joint_feedback_linearization" | "pd_gravity" => {
                            let r = sinusoid::<NU>(setpoint()?, amplitude, frequency, phase)?;
                            let g = Gains::new(kp, gains_kd);
                            if kind == "pd_gravity" {
                                // kp, kd are the error dynamics' (1/s², 1/s), as for feedback
                                // linearization and `sim`: scaled by the motors' inertia at the
                                // start (unscaled, kp = 100 N m/rad with kd = 2√kp diverged
                                // on Minitaur at any kp).
                                g.check().map_err(control_err)?;
                                let inertia: SVector<f64, NU> = self.leg.joint_inertias(&initial.q).map_err(control_err)?;
                                let g = Gains { kp: inertia * kp, kd: inertia * gains_kd };
                                let c = Saturated::new(self.leg.pd_gravity(g, r).map_err(control_err)?, limit).map_err(control_err)?;
                                run_simulation(py, &self.leg, initial, steps, opts, c, no_callable)
                            } else {
                                let c = Saturated::new(self.leg.joint_feedback_linearization(g, r).map_err(control_err)?, limit).map_err(control_err)?;
                                run_simulation(py, &self.leg, initial, steps, opts, c, no_callable)
                            }
                        }
                        "foot_feedback_linearization" | "foot_pd_gravity" => {
                            let r = sinusoid::<ND>(setpoint()?, amplitude, frequency, phase)?;
                            let g = Gains::new(kp, gains_kd);
                            let params = *self.leg.params();
                            if kind == "foot_pd_gravity" {
                                g.check().map_err(control_err)?;
                                let inertia: SVector<f64, ND> = foot_inertias::<Model, f64, NQ, NC, NU, ND, NP>(&params, &initial.q).map_err(control_err)?;
                                let g = Gains { kp: inertia * kp, kd: inertia * gains_kd };
                                let c = FootPdGravity::<Model, f64, _, NQ, NC, NU, ND, NP>::new(params, g, r).map_err(control_err)?;
                                let c = Saturated::new(c, limit).map_err(control_err)?;
                                run_simulation(py, &self.leg, initial, steps, opts, c, no_callable)
                            } else {
                                let c = FootFeedbackLinearization::<Model, f64, _, NQ, NC, NU, ND, NP>::new(params, g, r).map_err(control_err)?;
                                let c = Saturated::new(c, limit).map_err(control_err)?;
                                run_simulation(py, &self.leg, initial, steps, opts, c, no_callable)
                            }
                        }
                        other => Err(PyValueError::new_err(format!("unknown `controller` \"{}\": \"joint_feedback_linearization\", \"foot_feedback_linearization\", \"pd_gravity\" or \"foot_pd_gravity\"", Shown(other)))),
                    }
                }

                // ---- linearization and LQR ----

                /// One step of `dt` linearized on the constraint manifold at the rest pose
                /// `q` under its holding torque: dict with A, B (chart coordinates and
                /// rates), the chart's joints `coordinates`, and `holding_torque`.
                #[pyo3(signature = (q, dt, method = "rk4"))]
                fn linearize<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, dt: f64, method: &str) -> PyResult<Bound<'py, PyDict>> {
                    let q = pose("q", q)?;
                    let opts = step_options(dt, method, true)?;
                    let chart = self.leg.chart(&q).map_err(linearization_err)?;
                    let u = self.leg.holding_torque(&chart, &q).map_err(linearization_err)?;
                    let lin = self.leg.linearize_on_chart(&chart, &State { q, qd: SVector::zeros() }, &u, &opts).map_err(linearization_err)?;
                    let d = PyDict::new(py);
                    d.set_item("A", out_matrix(py, &lin.a))?;
                    d.set_item("B", out_matrix(py, &lin.b))?;
                    d.set_item("coordinates", chart.coordinates.to_vec())?;
                    d.set_item("holding_torque", out_vector(py, &u))?;
                    Ok(d)
                }

                /// A discrete LQR about the rest pose `q` for steps of `dt`: dict with the
                /// gain K, the closed loop A − B K and the Riccati solution P.
                fn lqr<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, dt: f64, state_weights: &Bound<'py, PyAny>, torque_weights: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyDict>> {
                    let q = pose("q", q)?;
                    let opts = step_options(dt, "rk4", true)?;
                    let chart = self.leg.chart(&q).map_err(linearization_err)?;
                    let theta = chart.coordinates_of(&State { q, qd: SVector::zeros() }).0;
                    let c = self.leg.manifold_lqr(&q, &opts, &matrix("state_weights", state_weights)?, &matrix("torque_weights", torque_weights)?, leg_models::control::reference::Hold(theta), SVector::from_element(f64::INFINITY)).map_err(control_err)?;
                    let d = PyDict::new(py);
                    d.set_item("K", out_matrix(py, &c.lqr.gain))?;
                    d.set_item("closed_loop", out_matrix(py, &c.lqr.closed_loop))?;
                    d.set_item("P", out_matrix(py, &c.lqr.cost))?;
                    Ok(d)
                }
                /// Every design measure at the assembled pose `q`, with the joints' torque
                /// limits `torque_limit` (N m after the gearbox) and speed limits
                /// `speed_limit` (rad/s), each one number for every motor or one per motor.
                /// Dict: held_joints (the body's joints, held: indices), foot, motor_angles,
                /// G (q̇ = G θ̇, the held joints at rest), foot_jacobian (J_θ = J_f G),
                /// passive_rank and foot_rank (zero at the two kinds of singularity),
                /// condition (κ(J_θ); inf with fewer motors than the foot's coordinates),
                /// holding_torque; on a planar leg force_polygon and speed_polygon
                /// (vertices counter-clockwise), on a spatial one force_polytope (its
                /// vertices), force_polytope_volume (N³) and speed_zonotope_volume (m³/s³),
                /// each None where the motors do not span the foot; vertical_force (the
                /// largest downward push, along y planar and z spatial; None where there is
                /// none, inf where no motor takes any of it), vertical_speed,
                /// inverse_inertia and inverse_inertia_locked (the foot's Λ⁻¹ with the
                /// motors free and locked, 1/kg) and effective_mass (kg).
                fn design_measures<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, torque_limit: &Bound<'py, PyAny>, speed_limit: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyDict>> {
                    let q = pose("q", q)?;
                    let limits = MotorLimits { torque: per_motor("torque_limit", torque_limit)?, speed: per_motor("speed_limit", speed_limit)? };
                    let m = self.leg.design_measures(&q, &limits).map_err(analysis_err)?;
                    let kin = &m.kinematics;
                    let params = self.leg.params();
                    let hold = leg_models::analysis::holding_torque::<Model, f64, NQ, NC, NU, ND>(params, &q, kin);
                    let frame = self.leg.analysis_frame();
                    let held: Vec<usize> = (0..NQ).filter(|&j| frame.held[j]).collect();
                    let d = PyDict::new(py);
                    d.set_item("held_joints", held)?;
                    d.set_item("foot", out_vector(py, &m.foot))?;
                    d.set_item("motor_angles", out_vector(py, &m.motor_angles))?;
                    d.set_item("G", out_matrix(py, &kin.g))?;
                    d.set_item("foot_jacobian", out_matrix(py, &kin.foot_jacobian))?;
                    d.set_item("passive_rank", m.passive_rank)?;
                    d.set_item("foot_rank", m.foot_rank)?;
                    d.set_item("condition", m.condition)?;
                    d.set_item("holding_torque", out_vector(py, &hold))?;
                    let keys: &[&str] = if ND == 3 {
                        &["force_polytope", "force_polytope_volume", "speed_zonotope_volume"]
                    } else {
                        &["force_polygon", "speed_polygon"]
                    };
                    for key in keys {
                        d.set_item(*key, py.None())?;
                    }
                    match leg_models::analysis::capacity_sets::<Model, f64, NQ, NC, NU, ND>(params, &q, &frame, kin, &limits) {
                        Ok(CapacitySets::Planar { force, speed }) => {
                            d.set_item("force_polygon", out_polygon(py, &force))?;
                            d.set_item("speed_polygon", out_polygon(py, &speed))?;
                        }
                        Ok(CapacitySets::Spatial { force, speed_volume }) => {
                            d.set_item("force_polytope", out_rows(py, force.vertices().iter().copied()))?;
                            d.set_item("force_polytope_volume", force.volume())?;
                            d.set_item("speed_zonotope_volume", speed_volume)?;
                        }
                        Err(_) => {}
                    }
                    d.set_item("vertical_force", m.vertical_force)?;
                    d.set_item("vertical_speed", m.vertical_speed)?;
                    d.set_item("inverse_inertia", out_matrix(py, &m.inverse_inertia))?;
                    d.set_item("inverse_inertia_locked", out_matrix(py, &m.inverse_inertia_locked))?;
                    d.set_item("effective_mass", m.effective_mass)?;
                    Ok(d)
                }
                /// The foot's inverse operational-space inertia Λ⁻¹ (2 × 2, 3 × 3 spatial; 1/kg) at the
                /// assembled pose `q`, the motors free (rotors backdriven) or locked.
                #[pyo3(signature = (q, motors_locked = false))]
                fn foot_inverse_inertia<'py>(&self, py: Python<'py>, q: &Bound<'py, PyAny>, motors_locked: bool) -> PyResult<Bound<'py, PyArray2<f64>>> {
                    let inv = self.leg.foot_inverse_inertia(&pose("q", q)?, motors_locked).map_err(analysis_err)?;
                    Ok(out_matrix(py, &inv))
                }
                /// The impact mitigation factor ξ = det(I − Λ Λ_L⁻¹) (Wensing et al. 2017) at
                /// the assembled pose `q`: with `body_mass` (kg) the hip on a body of that
                /// mass translating in the plane (in space, spatial); without, on a fixed base (a leg with body
                /// joints of its own uses them).
                #[pyo3(signature = (q, body_mass = None))]
                fn impact_mitigation(&self, q: &Bound<'_, PyAny>, body_mass: Option<f64>) -> PyResult<f64> {
                    let body = match body_mass {
                        None => Body::Fixed,
                        Some(mass) if mass.is_finite() && mass > 0.0 => Body::Translating { mass },
                        Some(mass) => return Err(PyValueError::new_err(format!("`body_mass` must be positive and finite, got {mass}"))),
                    };
                    self.leg.impact_mitigation(&pose("q", q)?, &body).map_err(analysis_err)
                }
                /// The leg's assembly branches at the motor angles (and held body joints) of
                /// the assembled pose `q` (default: the assembled home pose): an `n × nq`
                /// array of closed poses, `q` first, each a `start` for `workspace`.
                #[pyo3(signature = (q = None, tries = 64))]
                fn assembly_branches<'py>(&self, py: Python<'py>, q: Option<&Bound<'py, PyAny>>, tries: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
                    let q = match q {
                        Some(q) => {
                            // On the closures first: it is returned as a closed pose.
                            let mut q = pose("q", q)?;
                            self.leg.project_position(&mut q).map_err(assembly_err)?;
                            q
                        }
                        None => self.leg.assembled_home().map_err(assembly_err)?,
                    };
                    let modes = leg_models::analysis::workspace::assembly_modes::<Model, NQ, NC, NU>(self.leg.params(), &q, &self.leg.analysis_frame(), tries);
                    Ok(out_rows(py, modes.into_iter()))
                }
                /// The workspace of the assembly branch of `start` (default: the assembled
                /// home pose) over a grid of `nodes × nodes` foot positions centred on
                /// `centre` with half-width `half_width` (default: on the hip of the foot's
                /// chain, as wide as the chain is long), motors within `motor_range` (one
                /// `(low, high)` per motor, a revolute one modulo a turn; default none); a
                /// spatial leg's in the plane `slice` through its stance foot ("xz", the
                /// default, "yz" or "xy"). Dict: x, y (the grid's nodes; a spatial leg's
                /// coordinates along the slice's axes, with plane_axes (2 × 3) and
                /// plane_offset (m, along their cross product)),
                /// state (`nodes × nodes` strings indexed [iy, ix]: "reached", "branch_ends",
                /// "out_of_range", "unvisited"), area (m²), the measures as `nodes × nodes`
                /// arrays (NaN where not reached or singular): condition, vertical_force,
                /// vertical_speed, effective_mass, foot_rank, passive_rank; poses
                /// (`nodes × nodes × nq`, NaN where not reached); passive_curves and
                /// foot_curves (`n × 2 × 2` segments).
                #[pyo3(signature = (torque_limit, speed_limit, nodes = 200, start = None, centre = None, half_width = None, motor_range = None, slice = None))]
                #[allow(clippy::too_many_arguments)]
                fn workspace<'py>(&self, py: Python<'py>, torque_limit: &Bound<'py, PyAny>, speed_limit: &Bound<'py, PyAny>, nodes: usize, start: Option<&Bound<'py, PyAny>>, centre: Option<[f64; 2]>, half_width: Option<f64>, motor_range: Option<&Bound<'py, PyAny>>, slice: Option<&str>) -> PyResult<Bound<'py, PyDict>> {
                    let limits = MotorLimits { torque: per_motor("torque_limit", torque_limit)?, speed: per_motor("speed_limit", speed_limit)? };
                    let start = match start {
                        Some(q) => pose("start", q)?,
                        None => self.leg.assembled_home().map_err(assembly_err)?,
                    };
                    let window = match (centre, half_width) {
                        (None, None) => None,
                        (Some(c), Some(w)) => Some((c, w)),
                        _ => return Err(PyValueError::new_err("give `centre` and `half_width` together")),
                    };
                    let motor_range = match motor_range {
                        None => None,
                        Some(r) => Some(motor_ranges::<NU>(r)?),
                    };
                    let plane = slice_plane(slice, ND)?;
                    let options = GridOptions { nodes, window, plane, motor_range, limits };
                    // The grid's rules are the Rust API's, said with the argument's name.
                    options.check().map_err(grid_err)?;
                    // Up to 2000 × 2000 nodes of continuation: without the GIL.
                    let leg = &self.leg;
                    let w = py.detach(|| leg.workspace(&start, &options)).map_err(analysis_err)?;
                    let n = w.nodes;
                    let x: Vec<f64> = (0..n).map(|i| w.node(i, 0)[0]).collect();
                    let y: Vec<f64> = (0..n).map(|i| w.node(0, i)[1]).collect();
                    let state: Vec<Vec<&str>> = (0..n).map(|iy| (0..n).map(|ix| w.states[iy * n + ix].name()).collect()).collect();
                    let grid = |f: &dyn Fn(&leg_models::analysis::PointMeasures<f64, NQ, NU, ND>) -> Option<f64>| {
                        let a = Array2::from_shape_fn((n, n), |(iy, ix)| match &w.measures[iy * n + ix] {
                            Some(Ok(m)) => f(m).unwrap_or(f64::NAN),
                            _ => f64::NAN,
                        });
                        PyArray2::from_owned_array(py, a)
                    };
                    let mut poses = Array3::from_elem((n, n, NQ), f64::NAN);
                    for iy in 0..n {
                        for ix in 0..n {
                            if w.states[iy * n + ix] == NodeState::Reached {
                                for j in 0..NQ {
                                    poses[[iy, ix, j]] = w.poses[iy * n + ix][j];
                                }
                            }
                        }
                    }
                    let d = PyDict::new(py);
                    d.set_item("x", x)?;
                    d.set_item("y", y)?;
                    d.set_item("state", state)?;
                    d.set_item("area", w.area)?;
                    if let Some((plane, offset)) = w.slice {
                        d.set_item("plane_axes", plane.axes.to_vec())?;
                        d.set_item("plane_offset", offset)?;
                    }
                    d.set_item("condition", grid(&|m| Some(m.condition)))?;
                    d.set_item("vertical_force", grid(&|m| m.vertical_force))?;
                    d.set_item("vertical_speed", grid(&|m| Some(m.vertical_speed)))?;
                    d.set_item("effective_mass", grid(&|m| Some(m.effective_mass)))?;
                    d.set_item("foot_rank", grid(&|m| Some(m.foot_rank)))?;
                    d.set_item("passive_rank", PyArray2::from_owned_array(py, Array2::from_shape_fn((n, n), |(iy, ix)| w.passive_rank[iy * n + ix])))?;
                    d.set_item("poses", PyArray3::from_owned_array(py, poses))?;
                    d.set_item("passive_curves", out_segments(py, &w.passive_curves))?;
                    d.set_item("foot_curves", out_segments(py, &w.foot_curves))?;
                    Ok(d)
                }
                /// A design's row of `cargo xtask analyze`'s table, the command's numbers to
                /// the bit: a dict of `analysis_columns` → float (NaN or infinite where a
                /// measure is not a number) and `not_computed` (column → why, for each of
                /// those, as `analysis.json` says it), at the assembled home pose.
                /// `torque_limit`, `speed_limit` (N m, rad/s; one for all motors or one
                /// each): by default each motor's 1 N m multiplied by its gear ratio and 100
                /// rad/s divided by it. `body_mass` (kg): the body ξ puts the hip on, by
                /// default ten times the leg's links' mass (a leg with body joints of its
                /// own uses them and ignores it). `nodes`: the workspace grid's per side (a
                /// spatial leg's in `slice`, "xz" by default), every motor within
                /// `motor_range` (one `(low, high)` for all, as `--motor-range`). Raises
                /// `AssemblyError` where the home pose does not assemble and
                /// `AnalysisError` where a limit is out of range.
                #[pyo3(signature = (torque_limit = None, speed_limit = None, body_mass = None, nodes = 200, motor_range = None, slice = None))]
                #[allow(clippy::too_many_arguments)]
                fn design_summary<'py>(&self, py: Python<'py>, torque_limit: Option<&Bound<'py, PyAny>>, speed_limit: Option<&Bound<'py, PyAny>>, body_mass: Option<f64>, nodes: usize, motor_range: Option<(f64, f64)>, slice: Option<&str>) -> PyResult<Bound<'py, PyDict>> {
                    use leg_models::analysis::summary;
                    let params = self.leg.params();
                    let mut limits = summary::default_limits::<Model, NQ, NC, NU>(params);
                    if let Some(t) = torque_limit {
                        limits.torque = per_motor("torque_limit", t)?;
                    }
                    if let Some(w) = speed_limit {
                        limits.speed = per_motor("speed_limit", w)?;
                    }
                    if let Some((kind, unit, k, v)) = summary::limit_out_of_range(&limits) {
                        return Err(AnalysisError::new_err(format!(
                            "the {kind} limit of motor {} ({}) is {v:.3e} {unit}: beyond (0, {:e}]; give `{kind}_limit` or a gear ratio in range",
                            k + 1,
                            Model::JOINT_NAMES[Model::ACTUATED[k]],
                            summary::MAX_LIMIT
                        )));
                    }
                    if let Some(mass) = body_mass {
                        if !(mass.is_finite() && mass > 0.0) {
                            return Err(PyValueError::new_err(format!("`body_mass` must be positive and finite, got {mass}")));
                        }
                    }
                    let options = GridOptions { nodes, window: None, plane: slice_plane(slice, ND)?, motor_range: motor_range.map(|r| [r; NU]), limits };
                    options.check().map_err(grid_err)?;
                    let stance = self.leg.assembled_home().map_err(assembly_err)?;
                    let frame = self.leg.analysis_frame();
                    let coupling = leg_models::analysis::BodyCoupling::new::<Model, f64, NQ, NC, NU>(params);
                    let body = summary::default_body(&frame, coupling.as_ref(), body_mass);
                    let (row, reasons) = py.detach(|| {
                        let s = summary::summary::<Model, NQ, NC, NU, ND, NP>(params, &stance, &frame, &body, coupling.as_ref(), &options);
                        (s.row(&frame), s.reasons(&frame))
                    });
                    let d = PyDict::new(py);
                    for (key, value) in summary::COLUMNS.iter().zip(row) {
                        d.set_item(*key, value)?;
                    }
                    let why = PyDict::new(py);
                    for (key, reason) in summary::COLUMNS.iter().zip(reasons) {
                        if let Some(reason) = reason {
                            why.set_item(*key, reason)?;
                        }
                    }
                    d.set_item("not_computed", why)?;
                    Ok(d)
                }
                $($extra)*
            }

            fn class_name() -> &'static str {
                let path = stringify!($ty);
                path.rsplit("::").next().unwrap_or(path).trim()
            }

            pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
                let class = m.py().get_type::<PyLeg>();
                // One Rust type per leg, each named for its leg (pickle finds a class by
                // `module.__qualname__`: under one shared name `Leg` none pickled).
                class.setattr("__name__", class_name())?;
                class.setattr("__qualname__", class_name())?;
                m.add(class_name(), &class)?;
                m.getattr("models")?.set_item(Model::NAME, class)?;
                Ok(())
            }
        }
    };
}

/// A planar leg: every method, its contacts and the hybrid simulator.
macro_rules! leg_class {
    ($module:ident, $ty:ty, $nq:expr, $nc:expr, $nu:expr, $nk:expr) => {
        leg_module!($module, $ty, $nq, $nc, $nu, $nk, 2, $nc, {
            /// The contact points' names.
            #[classattr]
            fn contact_names() -> Vec<&'static str> {
                <Model as ContactModel<NQ, NC, NU, NK>>::CONTACT_NAMES.to_vec()
            }
            /// The contact points stacked (x₀, y₀, x₁, y₁, …).
            fn contact_positions<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
            ) -> PyResult<Bound<'py, PyArray1<f64>>> {
                Ok(out_vector(
                    py,
                    &Model::contact_positions(&pose("q", q)?, self.leg.params()),
                ))
            }
            /// `J_c(q)`.
            fn contact_jacobian<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
            ) -> PyResult<Bound<'py, PyArray2<f64>>> {
                Ok(out_matrix(
                    py,
                    &Model::contact_jacobian(&pose("q", q)?, self.leg.params()),
                ))
            }
            /// `J̇_c q̇`.
            fn contact_bias<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
                qd: &Bound<'py, PyAny>,
            ) -> PyResult<Bound<'py, PyArray1<f64>>> {
                Ok(out_vector(
                    py,
                    &Model::contact_bias(&pose("q", q)?, &vector("qd", qd)?, self.leg.params()),
                ))
            }
            /// `(q̈, closure forces, contact forces)` with contacts held at `anchors`
            /// (`held[k]`: contact k sticks; others in flight), spec ground and friction.
            fn forward_dynamics_with_contacts<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
                qd: &Bound<'py, PyAny>,
                u: &Bound<'py, PyAny>,
                held: Vec<bool>,
                anchors: &Bound<'py, PyAny>,
            ) -> PyResult<(
                Bound<'py, PyArray1<f64>>,
                Bound<'py, PyArray1<f64>>,
                Bound<'py, PyArray1<f64>>,
            )> {
                held_contact_dynamics::<Model, NQ, NC, NU, NK, 2>(
                    py,
                    self.leg.params(),
                    self.leg.baumgarte(),
                    q,
                    qd,
                    u,
                    &held,
                    anchors,
                )
            }
            /// Simulates the leg on the ground (contacts, impacts, events) for `steps`
            /// RK4 steps of `dt` from `(q, qd)` with every contact in flight. Torques as
            /// in `simulate`. Returns a dict of arrays (t, q, qd, u, contact_forces,
            /// energy) and `events`, a list of dicts (t, kind, contact, impulse,
            /// energy_lost).
            #[pyo3(signature = (q, qd, steps, dt, torque = None))]
            fn simulate_hybrid<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
                qd: &Bound<'py, PyAny>,
                steps: &Bound<'py, PyAny>,
                dt: f64,
                torque: Option<&Bound<'py, PyAny>>,
            ) -> PyResult<Bound<'py, PyDict>> {
                simulate_on_ground(py, &self.leg.hybrid_simulator(dt), q, qd, steps, dt, torque)
            }
        });
    };
}

/// A spatial leg: the methods of every leg, its foot and foot-space control in three
/// coordinates, and its contacts in 3-D (three rows each: the ground's two tangents, then
/// its normal) with their dynamics and the hybrid simulator.
macro_rules! spatial_leg_class {
    ($module:ident, $ty:ty, $nq:expr, $nc:expr, $nu:expr, $np:expr, $nk:expr) => {
        leg_module!($module, $ty, $nq, $nc, $nu, $nk, 3, $np, {
            /// The contact points' names (three rows each).
            #[classattr]
            fn contact_names() -> Vec<&'static str> {
                <Model as ContactModel<NQ, NC, NU, NK, 3>>::CONTACT_NAMES.to_vec()
            }
            /// The contact points stacked (x₀, y₀, z₀, x₁, …).
            fn contact_positions<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
            ) -> PyResult<Bound<'py, PyArray1<f64>>> {
                Ok(out_vector(
                    py,
                    &<Model as ContactModel<NQ, NC, NU, NK, 3>>::contact_positions(
                        &pose("q", q)?,
                        self.leg.params(),
                    ),
                ))
            }
            /// `J_c(q)`, three rows per contact (base frame).
            fn contact_jacobian<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
            ) -> PyResult<Bound<'py, PyArray2<f64>>> {
                Ok(out_matrix(
                    py,
                    &<Model as ContactModel<NQ, NC, NU, NK, 3>>::contact_jacobian(
                        &pose("q", q)?,
                        self.leg.params(),
                    ),
                ))
            }
            /// `J̇_c q̇` (base frame).
            fn contact_bias<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
                qd: &Bound<'py, PyAny>,
            ) -> PyResult<Bound<'py, PyArray1<f64>>> {
                Ok(out_vector(
                    py,
                    &<Model as ContactModel<NQ, NC, NU, NK, 3>>::contact_bias(
                        &pose("q", q)?,
                        &vector("qd", qd)?,
                        self.leg.params(),
                    ),
                ))
            }
            /// `(q̈, closure forces, contact forces)` with contacts held at `anchors`
            /// (`held[k]`: contact k sticks at its ground coordinates `anchors[3k..3k+3]`;
            /// others in flight), spec ground and friction; contact forces in the ground's
            /// frame (t₁, t₂, n).
            fn forward_dynamics_with_contacts<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
                qd: &Bound<'py, PyAny>,
                u: &Bound<'py, PyAny>,
                held: Vec<bool>,
                anchors: &Bound<'py, PyAny>,
            ) -> PyResult<(
                Bound<'py, PyArray1<f64>>,
                Bound<'py, PyArray1<f64>>,
                Bound<'py, PyArray1<f64>>,
            )> {
                held_contact_dynamics::<Model, NQ, NC, NU, NK, 3>(
                    py,
                    self.leg.params(),
                    self.leg.baumgarte(),
                    q,
                    qd,
                    u,
                    &held,
                    anchors,
                )
            }
            /// Simulates the leg on the ground in 3-D (the exact friction cone, slip in any
            /// direction, impacts, events) for `steps` RK4 steps of `dt` from `(q, qd)`.
            /// Torques as in `simulate`. Returns a dict of arrays (t, q, qd, u,
            /// contact_forces: three per contact in the ground's frame, energy,
            /// closure_residual) and `events`, a list of dicts (t, kind, contact, impulse
            /// `[|Λ_t|, Λ_n]`, energy_lost).
            #[pyo3(signature = (q, qd, steps, dt, torque = None))]
            fn simulate_hybrid<'py>(
                &self,
                py: Python<'py>,
                q: &Bound<'py, PyAny>,
                qd: &Bound<'py, PyAny>,
                steps: &Bound<'py, PyAny>,
                dt: f64,
                torque: Option<&Bound<'py, PyAny>>,
            ) -> PyResult<Bound<'py, PyDict>> {
                simulate_on_ground(
                    py,
                    &self.leg.hybrid_simulator::<3>(dt),
                    q,
                    qd,
                    steps,
                    dt,
                    torque,
                )
            }
        });
    };
}

generated::for_each_model!(leg_class);
generated::for_each_spatial_model!(spatial_leg_class);

/// The generated leg models: one class per spec (`legmodels.Minitaur`, …), and
/// `legmodels.models`, a dict spec name → class. The native part of the package
/// (`legmodels._legmodels`): `python/legmodels/__init__.py` re-exports it beside the
/// package's Python modules (`legmodels.sweep`).
#[pymodule]
#[pyo3(name = "_legmodels")]
fn legmodels(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("models", PyDict::new(py))?;
    m.add(
        "analysis_columns",
        leg_models::analysis::summary::COLUMNS.to_vec(),
    )?;
    m.add("LegError", py.get_type::<LegError>())?;
    m.add("AssemblyError", py.get_type::<AssemblyError>())?;
    m.add("DynamicsError", py.get_type::<DynamicsError>())?;
    m.add("ControlError", py.get_type::<ControlError>())?;
    m.add("LinearizationError", py.get_type::<LinearizationError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    m.add("ParameterError", py.get_type::<ParameterError>())?;
    m.add("AnalysisError", py.get_type::<AnalysisError>())?;
    let module = m;
    // Defined here so that `module` in its body is this function's.
    macro_rules! register {
        ($name:ident, $($sizes:tt)*) => {
            $name::register(module)?;
        };
    }
    generated::for_each_model!(register);
    generated::for_each_spatial_model!(register);
    Ok(())
}
