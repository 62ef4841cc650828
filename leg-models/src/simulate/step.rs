//! Time stepping of the constrained dynamics, with drift control: Baumgarte
//! stabilization inside the dynamics and/or projection of `q` onto `φ = 0` and of `q̇`
//! onto `J q̇ = 0` after each step. Motor torques are held over a step.

use core::fmt;

use nalgebra::SVector;

use crate::assembly::{project_position, project_velocity, AssemblyError, Tolerance};
use crate::dynamics::forward::{forward_dynamics, Acceleration, Baumgarte, DynamicsError};
use crate::model::contract::{LegDynamics, Real};
use crate::simulate::source::ControlError;
use crate::simulate::source::ControlUpdate;
use crate::simulate::source::{State, TorqueSource};

/// The integrator of a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Semi-implicit (symplectic) Euler: `q̇ += dt q̈(q, q̇)`, then `q += dt q̇`.
    SemiImplicitEuler,
    /// The classical fourth-order Runge–Kutta method.
    Rk4,
}

/// How to take a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOptions<T> {
    /// The integrator.
    pub method: Method,
    /// The step (s).
    pub dt: T,
    /// Baumgarte terms in the constraint row of the dynamics (`None`: plain `J q̈ = −J̇ q̇`).
    pub baumgarte: Option<Baumgarte<T>>,
    /// Project `q` and `q̇` back onto the constraints after each step.
    pub project: bool,
    /// For the position projection.
    pub tolerance: Tolerance<T>,
    /// When the torque source is asked.
    pub control: ControlUpdate,
}

impl<T: Real> StepOptions<T> {
    /// RK4 with projection, no Baumgarte terms: the accurate default.
    pub fn rk4(dt: T) -> Self {
        StepOptions {
            method: Method::Rk4,
            dt,
            baumgarte: None,
            project: true,
            tolerance: Tolerance::default(),
            control: ControlUpdate::PerStep,
        }
    }
}

/// Why a step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StepError {
    /// The constrained dynamics cannot be solved at a stage (the mass matrix is not
    /// positive definite, the closures are singular, or a value is not finite).
    Dynamics(DynamicsError),
    /// Projecting the state onto the closures after the step failed.
    Projection(AssemblyError),
    /// The torque source could not act.
    Control(ControlError),
    /// The record a run would keep is larger than its budget: refused before the first
    /// step and before anything is allocated.
    RecordTooLarge(RecordTooLarge),
}

/// A record of `samples` samples would take `bytes` bytes, more than `budget`
/// ([`MAX_RECORD_BYTES`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecordTooLarge {
    /// The samples asked for (steps + 1), saturated at `usize::MAX`.
    pub samples: usize,
    /// Their size (bytes), saturated at `usize::MAX`.
    pub bytes: usize,
    /// The budget (bytes).
    pub budget: usize,
}

/// The most memory a recording run keeps (bytes): 512 MiB, millions of samples of any
/// leg, well below the machine a simulation runs on.
pub const MAX_RECORD_BYTES: usize = 512 << 20;

/// Checks a record of `steps + 1` samples of `sample_bytes` each against
/// [`MAX_RECORD_BYTES`]: the one bound every recording run shares.
pub fn check_record(steps: usize, sample_bytes: usize) -> Result<(), RecordTooLarge> {
    let samples = steps.saturating_add(1);
    let bytes = samples.saturating_mul(sample_bytes);
    if bytes > MAX_RECORD_BYTES {
        Err(RecordTooLarge {
            samples,
            bytes,
            budget: MAX_RECORD_BYTES,
        })
    } else {
        Ok(())
    }
}

impl fmt::Display for RecordTooLarge {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "a record of {} samples would take {} MiB, more than the budget of {} MiB: run fewer steps, or several runs",
            self.samples,
            self.bytes >> 20,
            self.budget >> 20
        )
    }
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StepError::Dynamics(e) => write!(f, "dynamics: {e}"),
            StepError::Projection(e) => write!(f, "projection onto the constraints: {e}"),
            StepError::Control(e) => write!(f, "control: {e}"),
            StepError::RecordTooLarge(e) => write!(f, "{e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for StepError {}

impl From<DynamicsError> for StepError {
    fn from(e: DynamicsError) -> Self {
        StepError::Dynamics(e)
    }
}

impl From<ControlError> for StepError {
    fn from(e: ControlError) -> Self {
        StepError::Control(e)
    }
}

impl From<AssemblyError> for StepError {
    fn from(e: AssemblyError) -> Self {
        StepError::Projection(e)
    }
}

/// What a step did: the torques applied at its start and the accelerations and closure
/// forces there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport<T: Real, const NQ: usize, const NC: usize, const NU: usize> {
    /// The torques at the step's start.
    pub u: SVector<T, NU>,
    /// `q̈` and the closure forces `F` at the step's start.
    pub acceleration: Acceleration<T, NQ, NC>,
}

/// Advances `state` from time `t` by one step, with torques from `source`.
pub fn step<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &mut State<T, NQ>,
    t: T,
    source: &mut impl TorqueSource<T, NQ, NU>,
    opts: &StepOptions<T>,
) -> Result<StepReport<T, NQ, NC, NU>, StepError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let dt = opts.dt;
    let (q, qd) = (state.q, state.qd);
    let u0 = source.torque(t, state)?;
    let mut f =
        |tau: T, q: SVector<T, NQ>, qd: SVector<T, NQ>| -> Result<SVector<T, NQ>, StepError> {
            let u = match opts.control {
                ControlUpdate::PerStep => u0,
                ControlUpdate::PerStage => source.torque(t + tau, &State { q, qd })?,
            };
            Ok(forward_dynamics::<L, T, NQ, NC, NU>(params, &q, &qd, &u, opts.baumgarte)?.qdd)
        };
    let first = forward_dynamics::<L, T, NQ, NC, NU>(params, &q, &qd, &u0, opts.baumgarte)?;
    *state = advance(opts.method, dt, &q, &qd, first.qdd, &mut f)?;
    project_onto_closures::<L, T, NQ, NC, NU>(params, state, opts)?;
    Ok(StepReport {
        u: u0,
        acceleration: first,
    })
}

/// The integrators' arithmetic, shared by [`step`] and its linearization
/// ([`crate::control::linearize::linearize_step`]): one step of `method` from `(q, q̇)`, `first`
/// the acceleration there and `accel(τ, q, q̇)` that of the later stages (`τ` their time
/// offset in the step).
pub(crate) fn advance<T: Real, const NQ: usize, E>(
    method: Method,
    dt: T,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    first: SVector<T, NQ>,
    mut accel: impl FnMut(T, SVector<T, NQ>, SVector<T, NQ>) -> Result<SVector<T, NQ>, E>,
) -> Result<State<T, NQ>, E> {
    let (q, qd) = (*q, *qd);
    Ok(match method {
        Method::SemiImplicitEuler => {
            let qd = qd + first * dt;
            State { q: q + qd * dt, qd }
        }
        Method::Rk4 => {
            let half = dt * T::lit(0.5);
            let (k1q, k1v) = (qd, first);
            let (k2q, k2v) = (
                qd + k1v * half,
                accel(half, q + k1q * half, qd + k1v * half)?,
            );
            let (k3q, k3v) = (
                qd + k2v * half,
                accel(half, q + k2q * half, qd + k2v * half)?,
            );
            let (k4q, k4v) = (qd + k3v * dt, accel(dt, q + k3q * dt, qd + k3v * dt)?);
            let sixth = dt / T::lit(6.0);
            State {
                q: q + (k1q + (k2q + k3q) * T::lit(2.0) + k4q) * sixth,
                qd: qd + (k1v + (k2v + k3v) * T::lit(2.0) + k4v) * sixth,
            }
        }
    })
}

/// The post-step projection of `opts` (positions onto `φ = 0`, then rates onto
/// `J q̇ = 0`), when it is on.
pub(crate) fn project_onto_closures<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &mut State<T, NQ>,
    opts: &StepOptions<T>,
) -> Result<(), AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if opts.project && NC > 0 {
        project_position::<L, T, NQ, NC, NU>(params, &mut state.q, &opts.tolerance)?;
        project_velocity::<L, T, NQ, NC, NU>(params, &state.q, &mut state.qd)?;
    }
    Ok(())
}

/// Total mechanical energy `T + V`.
pub fn energy<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &State<T, NQ>,
) -> T
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    L::kinetic_energy(&state.q, &state.qd, params) + L::potential_energy(&state.q, params)
}
