//! Time stepping of the constrained dynamics, with drift control: Baumgarte
//! stabilization inside the dynamics and/or projection of `q` onto `φ = 0` and of `q̇`
//! onto `J q̇ = 0` after each step. Motor torques are held over a step.

use core::fmt;

use nalgebra::SVector;

use crate::assembly::{project_position, project_velocity, AssemblyError, Tolerance};
use crate::dynamics::{forward_dynamics, Acceleration, Baumgarte, DynamicsError};
use crate::model::{LegModel, Real};

/// Joint positions and velocities.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State<T: Real, const NQ: usize> {
    pub q: SVector<T, NQ>,
    pub qd: SVector<T, NQ>,
}

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
    pub method: Method,
    pub dt: T,
    /// Baumgarte terms in the constraint row of the dynamics (`None`: plain `J q̈ = −J̇ q̇`).
    pub baumgarte: Option<Baumgarte<T>>,
    /// Project `q` and `q̇` back onto the constraints after each step.
    pub project: bool,
    /// For the position projection.
    pub tolerance: Tolerance<T>,
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
        }
    }
}

/// Why a step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StepError {
    Dynamics(DynamicsError),
    Projection(AssemblyError),
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StepError::Dynamics(e) => write!(f, "dynamics: {e}"),
            StepError::Projection(e) => write!(f, "projection onto the constraints: {e}"),
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

impl From<AssemblyError> for StepError {
    fn from(e: AssemblyError) -> Self {
        StepError::Projection(e)
    }
}

/// Advances `state` by one step under torques `u`; returns the accelerations and closure
/// forces at the start of the step.
pub fn step<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &mut State<T, NQ>,
    u: &SVector<T, NU>,
    opts: &StepOptions<T>,
) -> Result<Acceleration<T, NQ, NC>, StepError>
where
    L: LegModel<NQ, NC, NU>,
    T: Real,
{
    let f = |q: &SVector<T, NQ>, qd: &SVector<T, NQ>| {
        forward_dynamics::<L, T, NQ, NC, NU>(params, q, qd, u, opts.baumgarte)
    };
    let dt = opts.dt;
    let (q, qd) = (state.q, state.qd);
    let first = f(&q, &qd)?;
    match opts.method {
        Method::SemiImplicitEuler => {
            state.qd = qd + first.qdd * dt;
            state.q = q + state.qd * dt;
        }
        Method::Rk4 => {
            let half = dt * T::lit(0.5);
            let (k1q, k1v) = (qd, first.qdd);
            let (k2q, k2v) = (
                qd + k1v * half,
                f(&(q + k1q * half), &(qd + k1v * half))?.qdd,
            );
            let (k3q, k3v) = (
                qd + k2v * half,
                f(&(q + k2q * half), &(qd + k2v * half))?.qdd,
            );
            let (k4q, k4v) = (qd + k3v * dt, f(&(q + k3q * dt), &(qd + k3v * dt))?.qdd);
            let sixth = dt / T::lit(6.0);
            state.q = q + (k1q + (k2q + k3q) * T::lit(2.0) + k4q) * sixth;
            state.qd = qd + (k1v + (k2v + k3v) * T::lit(2.0) + k4v) * sixth;
        }
    }
    if opts.project && NC > 0 {
        project_position::<L, T, NQ, NC, NU>(params, &mut state.q, &opts.tolerance)?;
        project_velocity::<L, T, NQ, NC, NU>(params, &state.q, &mut state.qd)?;
    }
    Ok(first)
}

/// Total mechanical energy `T + V`.
pub fn energy<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &State<T, NQ>,
) -> T
where
    L: LegModel<NQ, NC, NU>,
    T: Real,
{
    L::kinetic_energy(&state.q, &state.qd, params) + L::potential_energy(&state.q, params)
}
