//! [`Leg`]: one leg with its parameters and settings, the runtime's entry point.
//!
//! Every operation of the runtime is a method here, so the leg's sizes (`NQ` joints,
//! `NC` closure rows, `NU` motors, `NK` contact rows, and the chart's `M`, `NX`) come
//! from its type and are never written at a call. Each generated module names its leg
//! (`generated::minitaur::Leg`, an alias of `Leg<Minitaur, f64, 4, 2, 2, 0>`), so a
//! change of leg is a change of one `use`:
//!
//! ```
//! use generated::minitaur::Leg;
//! use leg_models::nalgebra::Vector2;
//!
//! let leg = Leg::default(); // the spec's parameters
//! let q = leg.assemble(&Vector2::new(-0.8, -2.3), &leg.home()).unwrap();
//! let qd = leg.consistent_velocity(&q, &Vector2::new(1.0, -1.0)).unwrap();
//! let acc = leg.forward_dynamics(&q, &qd, &Vector2::new(0.1, -0.1)).unwrap();
//! assert!(acc.qdd.iter().all(|x| x.is_finite()));
//! ```
//!
//! The free functions of the other modules ([`crate::dynamics::forward_dynamics`], …)
//! remain: the methods call them, and generic code over many legs can use either.

use core::fmt;

use crate::model::shown::{Shown, ShownNumber};

use nalgebra::{SMatrix, SVector};

use crate::analysis;
use crate::assembly::{self, AssemblyError, Tolerance};
use crate::control::linearize::{
    self, ChartTangent, ManifoldChart, ManifoldLinearization, StepJacobian,
};
use crate::control::lqr::ManifoldLqr;
use crate::control::reference::Reference;
use crate::control::{
    self, ActuatedDynamics, ControlError, FootFeedbackLinearization, FootPdGravity, Gains,
    JointFeedbackLinearization, PdGravity, ReductionDerivatives,
};
use crate::dynamics::batch::{self, BatchAcceleration, BatchError};
use crate::dynamics::contact::{self, ContactSolution, Ground, Impact, ImpactError, Modes};
use crate::dynamics::derivatives::{self, ContactDynamicsDerivatives, ForwardDynamicsDerivatives};
use crate::dynamics::structure::Structure;
use crate::dynamics::{self, Acceleration, Baumgarte, DynamicsError};
use crate::model::contract::{
    ContactModel, DynamicsTerms, LegDynamics, LegModel, Parameters, Real,
};
use crate::model::simd::F64x4;
use crate::simulate::hybrid::{HybridSimulator, HybridState};
use crate::simulate::source::LinearizationError;
use crate::simulate::{self, State, StepError, StepOptions, StepReport, TorqueSource};

/// The size of a leg's constraint manifold chart: `M` coordinates (its mobility,
/// [`LegDynamics::MOBILITY`]) and `NX = 2 M` states (coordinates and rates). Generated models
/// implement it, which lets [`Leg::chart`] and [`Leg::manifold_lqr`] infer both sizes;
/// stable Rust cannot compute `2 · MOBILITY` in a signature.
pub trait ChartSize<const M: usize, const NX: usize> {}

/// A parameter the leg refused, by name.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParameterError<'a> {
    /// The leg has no parameter of this name.
    Unknown {
        /// The name asked for.
        name: &'a str,
        /// The leg's name ([`LegDynamics::NAME`]).
        leg: &'static str,
        /// The leg's parameter names, for the message's suggestion.
        known: &'static [&'static str],
    },
    /// The value is NaN or infinite (every later evaluation would be).
    NotFinite {
        /// The parameter.
        name: &'a str,
        /// The value refused.
        value: f64,
    },
    /// A mass, an inertia or a damping (a name ending in `_mass`, `_inertia` or
    /// `_damping`) below zero: the mass matrix would not be positive definite, or the
    /// damping would feed energy in.
    Negative {
        /// The parameter.
        name: &'a str,
        /// The value refused.
        value: f64,
    },
    /// A gear ratio (a name ending in `_gear_ratio`) zero or negative, as a spec refuses.
    NotPositive {
        /// The parameter.
        name: &'a str,
        /// The value refused.
        value: f64,
    },
    /// Beyond [`MAX_PARAMETER`] in magnitude, as a spec refuses (the terms' products
    /// overflow: a mass of 1e308 was reported as "the mass matrix is not positive definite").
    TooLarge {
        /// The parameter.
        name: &'a str,
        /// The value refused.
        value: f64,
    },
}

/// The largest magnitude a parameter may have, in its unit: a spec's bound
/// (`xtask::gen::spec::MAX_MAGNITUDE`), the same at run time.
pub const MAX_PARAMETER: f64 = 1e6;

/// The largest magnitude a joint coordinate (rad, or m on a slider) may have where a pose
/// is read: beyond it an angle has lost its precision (an f64 step of 1e9 rad is 1e-7
/// rad), and a continuation towards it has no step a solve can take.
pub const MAX_COORDINATE: f64 = 1e9;

/// The rule a pose's coordinates obey where they are read (the command line's `--q` and
/// `--guess`, the Python bindings' poses): finite and at most [`MAX_COORDINATE`] in
/// magnitude. Gives the first coordinate that is not.
pub fn check_pose(q: &[f64]) -> Result<(), (usize, f64)> {
    match q
        .iter()
        .position(|x| !(x.is_finite() && x.abs() <= MAX_COORDINATE))
    {
        Some(k) => Err((k, q[k])),
        None => Ok(()),
    }
}

/// Whether parameter `name` is a mass, an inertia or a damping (its name ends in `_mass`,
/// `_inertia` or `_damping`, as every spec's are): a negative value would make `M`
/// indefinite, or the damping feed energy in.
fn must_be_nonnegative(name: &str) -> bool {
    name.ends_with("_mass") || name.ends_with("_inertia") || name.ends_with("_damping")
}

/// The rules a parameter's value obeys, the spec's: finite, at most [`MAX_PARAMETER`] in
/// magnitude, masses, inertias and dampings not negative, gear ratios positive. The one
/// check [`Leg::set_parameter`], the command line and the Python bindings share.
pub fn check_parameter(name: &str, value: f64) -> Result<(), ParameterError<'_>> {
    if !value.is_finite() {
        Err(ParameterError::NotFinite { name, value })
    } else if value.abs() > MAX_PARAMETER {
        Err(ParameterError::TooLarge { name, value })
    } else if name.ends_with("_gear_ratio") && value <= 0.0 {
        Err(ParameterError::NotPositive { name, value })
    } else if value < 0.0 && must_be_nonnegative(name) {
        Err(ParameterError::Negative { name, value })
    } else {
        Ok(())
    }
}

impl ParameterError<'_> {
    /// The known name closest to an unknown one (edit distance at most a third of its
    /// length), if any.
    pub fn suggestion(&self) -> Option<&'static str> {
        let ParameterError::Unknown { name, known, .. } = *self else {
            return None;
        };
        known
            .iter()
            .filter_map(|k| edit_distance(name, k).map(|d| (d, *k)))
            .filter(|(d, _)| 3 * d <= name.len().max(3))
            .min_by_key(|(d, _)| *d)
            .map(|(_, k)| k)
    }
}

/// Levenshtein distance of two names of at most 64 bytes (`None` beyond: no allocation).
fn edit_distance(a: &str, b: &str) -> Option<usize> {
    const MAX: usize = 64;
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() > MAX || b.len() > MAX {
        return None;
    }
    let mut prev = [0usize; MAX + 1];
    let mut row = [0usize; MAX + 1];
    for (j, p) in prev.iter_mut().enumerate().take(b.len() + 1) {
        *p = j;
    }
    for i in 1..=a.len() {
        row[0] = i;
        for j in 1..=b.len() {
            let substitution = prev[j - 1] + usize::from(a[i - 1] != b[j - 1]);
            row[j] = substitution.min(prev[j] + 1).min(row[j - 1] + 1);
        }
        prev = row;
    }
    Some(prev[b.len()])
}

impl fmt::Display for ParameterError<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            ParameterError::Unknown { name, leg, known } => {
                write!(f, "leg `{leg}` has no parameter `{}`", Shown(name))?;
                match self.suggestion() {
                    Some(s) => write!(f, "; did you mean `{s}`?"),
                    None => write!(
                        f,
                        " ({} parameters, the model's `Params::NAMES`)",
                        known.len()
                    ),
                }
            }
            ParameterError::NotFinite { name, value } => {
                write!(
                    f,
                    "parameter `{}` must be finite, got {}",
                    Shown(name),
                    ShownNumber(value)
                )
            }
            ParameterError::Negative { name, value } => write!(
                f,
                "parameter `{}` is a mass, an inertia or a damping and cannot be negative, got {}",
                Shown(name),
                ShownNumber(value)
            ),
            ParameterError::NotPositive { name, value } => write!(
                f,
                "parameter `{}` is a gear ratio and must be positive, got {}",
                Shown(name),
                ShownNumber(value)
            ),
            ParameterError::TooLarge { name, value } => write!(
                f,
                "parameter `{}` must be at most {MAX_PARAMETER:e} in magnitude (a spec's bound), got {}",
                Shown(name),
                ShownNumber(value)
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ParameterError<'_> {}

/// One leg of model `L` in scalar `T`: its parameters, the tolerance of its assembly
/// solvers and the Baumgarte terms of its forward dynamics (none by default). Cheap to
/// copy; every method is allocation-free except those returning a recording simulator's
/// run.
///
/// Write it through the generated alias (`generated::minitaur::Leg`, `LegF32` for `f32`);
/// the sizes here are the model's. Every leg has the methods of the first block; a planar
/// leg's [`ContactModel`] adds its foot in the plane and contacts; the design measures
/// take planar and spatial legs.
pub struct Leg<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize = 0>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    params: L::Params<T>,
    tolerance: Tolerance<T>,
    baumgarte: Option<Baumgarte<T>>,
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize> Clone
    for Leg<L, T, NQ, NC, NU, NK>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    fn clone(&self) -> Self {
        *self
    }
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize> Copy
    for Leg<L, T, NQ, NC, NU, NK>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize> fmt::Debug
    for Leg<L, T, NQ, NC, NU, NK>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Leg")
            .field("model", &L::NAME)
            .field("params", &self.params)
            .field("tolerance", &self.tolerance)
            .field("baumgarte", &self.baumgarte)
            .finish()
    }
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize> Default
    for Leg<L, T, NQ, NC, NU, NK>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    /// The spec's parameters.
    fn default() -> Self {
        Self::new(L::Params::<T>::default())
    }
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    Leg<L, T, NQ, NC, NU, NK>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    // ---- construction and settings ----

    /// The leg with these parameters, the default [`Tolerance`] and no Baumgarte terms.
    pub fn new(params: L::Params<T>) -> Self {
        Leg {
            params,
            tolerance: Tolerance::default(),
            baumgarte: None,
        }
    }

    /// The same leg with the assembly solvers stopping at `tolerance`.
    pub fn with_tolerance(mut self, tolerance: Tolerance<T>) -> Self {
        self.tolerance = tolerance;
        self
    }

    /// The same leg with Baumgarte terms in its forward dynamics and their derivatives
    /// (`J q̈ = −J̇ q̇ − 2α J q̇ − β² φ`).
    pub fn with_baumgarte(mut self, alpha: T, beta: T) -> Self {
        self.baumgarte = Some(Baumgarte { alpha, beta });
        self
    }

    /// The same leg with one parameter changed by name (see [`Leg::set_parameter`]).
    pub fn with_parameter(mut self, name: &str, value: T) -> Result<Self, ParameterError<'_>> {
        self.set_parameter(name, value)?;
        Ok(self)
    }

    /// The parameters.
    pub fn params(&self) -> &L::Params<T> {
        &self.params
    }

    /// The parameters, to change (`leg.params_mut().update(|v| v.gravity_y = -1.62)`).
    pub fn params_mut(&mut self) -> &mut L::Params<T> {
        &mut self.params
    }

    /// The index of the parameter named `name` (a field of the spec's `ParamValues`) in
    /// [`Parameters::NAMES`], for [`Parameters::get`] and [`Parameters::set`].
    pub fn parameter_index<'a>(&self, name: &'a str) -> Result<usize, ParameterError<'a>> {
        L::Params::<T>::NAMES
            .iter()
            .position(|n| *n == name)
            .ok_or(ParameterError::Unknown {
                name,
                leg: L::NAME,
                known: L::Params::<T>::NAMES,
            })
    }

    /// The parameter named `name`.
    pub fn parameter<'a>(&self, name: &'a str) -> Result<T, ParameterError<'a>> {
        let i = self.parameter_index(name)?;
        self.params.get(i).ok_or(ParameterError::Unknown {
            name,
            leg: L::NAME,
            known: L::Params::<T>::NAMES,
        })
    }

    /// Sets the parameter named `name` (and prepares the parameter-only quantities once);
    /// an unknown name or a non-finite value changes nothing.
    pub fn set_parameter<'a>(&mut self, name: &'a str, value: T) -> Result<(), ParameterError<'a>> {
        let i = self.parameter_index(name)?;
        let shown = nalgebra::try_convert::<T, f64>(value).unwrap_or(f64::NAN);
        if !value.is_finite() {
            return Err(ParameterError::NotFinite { name, value: shown });
        }
        check_parameter(name, shown)?;
        self.params.set(i, value);
        Ok(())
    }

    /// The assembly solvers' tolerance.
    pub fn tolerance(&self) -> &Tolerance<T> {
        &self.tolerance
    }

    /// The Baumgarte terms of the forward dynamics, if any.
    pub fn baumgarte(&self) -> Option<Baumgarte<T>> {
        self.baumgarte
    }

    /// What the leg is (motors, mobility, closures): which methods apply to it.
    pub fn structure(&self) -> Structure {
        Structure::of::<L, NQ, NC, NU>()
    }

    /// The spec's home pose (rad, m for prismatic joints), as written: the default guess
    /// of assembly. [`Leg::assembled_home`] puts it on the closures.
    pub fn home(&self) -> SVector<T, NQ> {
        SVector::from_fn(|i, _| T::lit(L::HOME[i]))
    }

    /// The home pose projected onto the closures (nearest assembled pose).
    pub fn assembled_home(&self) -> Result<SVector<T, NQ>, AssemblyError> {
        let mut q = self.home();
        self.project_position(&mut q)?;
        Ok(q)
    }

    /// The motor angles of joint angles `q` (`q` at [`LegDynamics::ACTUATED`]).
    pub fn motor_angles(&self, q: &SVector<T, NQ>) -> SVector<T, NU> {
        SVector::from_fn(|k, _| q[L::ACTUATED[k]])
    }

    // ---- generated terms ----

    /// `M`, `N`, `J` and `J̇ q̇` together ([`LegDynamics::dynamics_terms`]).
    pub fn dynamics_terms(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
    ) -> DynamicsTerms<T, NQ, NC> {
        L::dynamics_terms(q, qd, &self.params)
    }

    /// `M(q)` with reflected rotor inertia.
    pub fn mass_matrix(&self, q: &SVector<T, NQ>) -> SMatrix<T, NQ, NQ> {
        L::mass_matrix(q, &self.params)
    }

    /// `N(q, q̇) = C q̇ + G`.
    pub fn bias_forces(&self, q: &SVector<T, NQ>, qd: &SVector<T, NQ>) -> SVector<T, NQ> {
        L::bias_forces(q, qd, &self.params)
    }

    /// The closure residual `φ(q)` (zero on an assembled leg).
    pub fn closure_residual(&self, q: &SVector<T, NQ>) -> SVector<T, NC> {
        L::closure_residual(q, &self.params)
    }

    /// `J(q) = ∂φ/∂q`.
    pub fn constraint_jacobian(&self, q: &SVector<T, NQ>) -> SMatrix<T, NC, NQ> {
        L::constraint_jacobian(q, &self.params)
    }

    /// Kinetic plus potential energy, spring energy included ([`simulate::energy`]).
    pub fn energy(&self, state: &State<T, NQ>) -> T {
        simulate::energy::<L, T, NQ, NC, NU>(&self.params, state)
    }

    /// The leg's size at `q` (m), the scale of its residual tolerance.
    pub fn leg_size(&self, q: &SVector<T, NQ>) -> T {
        assembly::leg_size::<L, T, NQ, NC, NU>(&self.params, q)
    }

    // ---- assembly ----

    /// The closed pose with motor angles `theta`, Newton from `guess` (which picks the
    /// assembly mode; [`Leg::home`] picks the spec's).
    pub fn assemble(
        &self,
        theta: &SVector<T, NU>,
        guess: &SVector<T, NQ>,
    ) -> Result<SVector<T, NQ>, AssemblyError> {
        assembly::assemble::<L, T, NQ, NC, NU>(&self.params, theta, guess, &self.tolerance)
    }

    /// The closed pose at motor angles `theta` reached by continuation from the assembled
    /// pose `from` in steps of at most `max_step` rad: it keeps `from`'s branch.
    pub fn assemble_along(
        &self,
        from: &SVector<T, NQ>,
        theta: &SVector<T, NU>,
        max_step: T,
    ) -> Result<SVector<T, NQ>, AssemblyError> {
        assembly::assemble_along::<L, T, NQ, NC, NU>(
            &self.params,
            from,
            theta,
            max_step,
            &self.tolerance,
        )
    }

    /// The joint rates of motor rates `theta_dot` at the assembled pose `q`.
    pub fn consistent_velocity(
        &self,
        q: &SVector<T, NQ>,
        theta_dot: &SVector<T, NU>,
    ) -> Result<SVector<T, NQ>, AssemblyError> {
        assembly::consistent_velocity::<L, T, NQ, NC, NU>(&self.params, q, theta_dot)
    }

    /// Moves `q` to the nearest pose on the closures.
    pub fn project_position(&self, q: &mut SVector<T, NQ>) -> Result<(), AssemblyError> {
        assembly::project_position::<L, T, NQ, NC, NU>(&self.params, q, &self.tolerance)
    }

    /// Removes from `qd` its component off the closures' tangent at `q`.
    pub fn project_velocity(
        &self,
        q: &SVector<T, NQ>,
        qd: &mut SVector<T, NQ>,
    ) -> Result<(), AssemblyError> {
        assembly::project_velocity::<L, T, NQ, NC, NU>(&self.params, q, qd)
    }

    // ---- dynamics ----

    /// `q̈` and the closure forces `F` under motor torques `u` (the KKT solve,
    /// [`dynamics::forward_dynamics`]), with the leg's Baumgarte terms.
    pub fn forward_dynamics(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        u: &SVector<T, NU>,
    ) -> Result<Acceleration<T, NQ, NC>, DynamicsError> {
        dynamics::forward_dynamics::<L, T, NQ, NC, NU>(&self.params, q, qd, u, self.baumgarte)
            .map_err(|e| e.explained(q, qd, u))
    }

    /// [`Leg::forward_dynamics`] from terms already evaluated at `(q, q̇)`.
    pub fn forward_dynamics_from_terms(
        &self,
        terms: &DynamicsTerms<T, NQ, NC>,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        u: &SVector<T, NU>,
    ) -> Result<Acceleration<T, NQ, NC>, DynamicsError> {
        dynamics::forward_dynamics_from_terms::<L, T, NQ, NC, NU>(
            &self.params,
            terms,
            q,
            qd,
            u,
            self.baumgarte,
        )
    }

    /// The forward dynamics and its exact derivatives by `q`, `q̇` and `u`
    /// ([`derivatives::forward_dynamics_derivatives`]).
    pub fn forward_dynamics_derivatives(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        u: &SVector<T, NU>,
    ) -> Result<ForwardDynamicsDerivatives<T, NQ, NC, NU>, DynamicsError> {
        derivatives::forward_dynamics_derivatives::<L, T, NQ, NC, NU>(
            &self.params,
            q,
            qd,
            u,
            self.baumgarte,
        )
    }

    /// The generalized force of motor torques `u` (`B u`).
    pub fn actuation(&self, u: &SVector<T, NU>) -> SVector<T, NQ> {
        dynamics::actuation::<L, T, NQ, NC, NU>(u)
    }

    /// The dynamics reduced to the motor angles, `Ã θ̈ = b̃ + u` (Schur complement of the
    /// KKT system, [`control::actuated_reduction`]).
    pub fn actuated_reduction(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
    ) -> Result<ActuatedDynamics<T, NU>, ControlError> {
        let terms = self.dynamics_terms(q, qd);
        control::actuated_reduction::<L, T, NQ, NC, NU>(&self.params, &terms, qd)
    }

    /// The same reduction in its null-space form `Ã = Gᵀ M G`.
    pub fn actuated_reduction_null_space(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
    ) -> Result<ActuatedDynamics<T, NU>, ControlError> {
        let terms = self.dynamics_terms(q, qd);
        control::actuated_reduction_null_space::<L, T, NQ, NC, NU>(&self.params, &terms, qd)
    }

    /// The torque `u = Ã v − b̃` giving motor accelerations `v`, and its derivatives by
    /// `q` and `q̇` ([`control::reduction_derivatives`]).
    pub fn reduction_derivatives(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        v: &SVector<T, NU>,
    ) -> Result<ReductionDerivatives<T, NQ, NU>, ControlError> {
        control::reduction_derivatives::<L, T, NQ, NC, NU>(&self.params, q, qd, v)
    }

    /// The inertia each motor feels at `q` (the diagonal of `Ã`).
    pub fn joint_inertias(&self, q: &SVector<T, NQ>) -> Result<SVector<T, NU>, ControlError> {
        control::joint_inertias::<L, T, NQ, NC, NU>(&self.params, q)
    }

    // ---- contact ----

    // ---- time stepping and simulation ----

    /// One step of `opts` from `state` at time `t` under `source`'s torques.
    pub fn step(
        &self,
        state: &mut State<T, NQ>,
        t: T,
        source: &mut impl TorqueSource<T, NQ, NU>,
        opts: &StepOptions<T>,
    ) -> Result<StepReport<T, NQ, NC, NU>, StepError> {
        simulate::step::<L, T, NQ, NC, NU>(&self.params, state, t, source, opts)
    }

    /// A recording simulator of this leg in the air (closures only), stepping by `opts`.
    #[cfg(feature = "std")]
    pub fn simulator(&self, opts: StepOptions<T>) -> crate::simulate::Simulator<L, T, NQ, NC, NU> {
        crate::simulate::Simulator::new(self.params, opts)
    }

    /// `torques` as a torque source of this leg: the closure's argument types come from
    /// the leg, so it needs no annotation (`leg.torque_source(|_t, s| -0.5 * leg.motor_angles(&s.qd))`).
    pub fn torque_source<F>(&self, torques: F) -> F
    where
        F: FnMut(T, &State<T, NQ>) -> SVector<T, NU>,
    {
        torques
    }

    // ---- controllers ----

    /// Feedback linearization tracking `reference` in the motor angles.
    pub fn joint_feedback_linearization<R: Reference<T, NU>>(
        &self,
        gains: Gains<T, NU>,
        reference: R,
    ) -> Result<JointFeedbackLinearization<L, T, R, NQ, NC, NU>, ControlError> {
        JointFeedbackLinearization::new(self.params, gains, reference)
    }

    /// PD on the motor angles with gravity compensation (the baseline).
    pub fn pd_gravity<R: Reference<T, NU>>(
        &self,
        gains: Gains<T, NU>,
        reference: R,
    ) -> Result<PdGravity<L, T, R, NQ, NC, NU>, ControlError> {
        PdGravity::new(self.params, gains, reference)
    }

    // ---- linearization and LQR ----

    /// One step of `opts` and its Jacobian `(∂x⁺/∂x, ∂x⁺/∂u)` in joint coordinates,
    /// torques held ([`linearize::linearize_step`]).
    pub fn linearize_step(
        &self,
        state: &State<T, NQ>,
        u: &SVector<T, NU>,
        opts: &StepOptions<T>,
    ) -> Result<(State<T, NQ>, StepJacobian<T, NQ, NU>), LinearizationError> {
        linearize::linearize_step::<L, T, NQ, NC, NU>(&self.params, state, u, opts)
    }

    /// Coordinates of the constraint manifold at the assembled pose `q` (the motors
    /// where they determine the leg, [`ManifoldChart`]).
    pub fn chart<const M: usize, const NX: usize>(
        &self,
        q: &SVector<T, NQ>,
    ) -> Result<ManifoldChart<T, NQ, M>, LinearizationError>
    where
        L: ChartSize<M, NX>,
    {
        ManifoldChart::new::<L, NC, NU>(&self.params, q)
    }

    /// The state on the closures with chart coordinates `theta` and rates `theta_dot`.
    pub fn lift<const M: usize>(
        &self,
        chart: &ManifoldChart<T, NQ, M>,
        theta: &SVector<T, M>,
        theta_dot: &SVector<T, M>,
    ) -> Result<State<T, NQ>, LinearizationError> {
        chart.lift::<L, NC, NU>(&self.params, theta, theta_dot, &self.tolerance)
    }

    /// The chart's tangent at `(q, q̇)` ([`ChartTangent`]).
    pub fn chart_tangent<const M: usize>(
        &self,
        chart: &ManifoldChart<T, NQ, M>,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
    ) -> Result<ChartTangent<T, NQ, M>, LinearizationError> {
        chart.tangent::<L, NC, NU>(&self.params, q, qd)
    }

    /// One step of `opts` linearized in the chart's coordinates: the `(A, B)` an MPC or
    /// an LQR needs.
    pub fn linearize_on_chart<const M: usize, const NX: usize>(
        &self,
        chart: &ManifoldChart<T, NQ, M>,
        state: &State<T, NQ>,
        u: &SVector<T, NU>,
        opts: &StepOptions<T>,
    ) -> Result<ManifoldLinearization<T, NQ, NX, NU>, LinearizationError>
    where
        L: ChartSize<M, NX>,
    {
        chart.linearize_step::<L, NC, NU, NX>(&self.params, state, u, opts)
    }

    /// The torques holding the leg at rest at `q`.
    pub fn holding_torque<const M: usize>(
        &self,
        chart: &ManifoldChart<T, NQ, M>,
        q: &SVector<T, NQ>,
    ) -> Result<SVector<T, NU>, LinearizationError> {
        chart.holding_torque::<L, NC, NU>(&self.params, q)
    }

    /// A discrete LQR on the manifold about the rest pose `pose`, tracking `reference` in
    /// the chart's coordinates, torques clipped to `±torque_limit` ([`ManifoldLqr`]).
    #[allow(clippy::too_many_arguments)]
    pub fn manifold_lqr<R: Reference<T, M>, const M: usize, const NX: usize>(
        &self,
        pose: &SVector<T, NQ>,
        opts: &StepOptions<T>,
        state_weights: &SMatrix<T, NX, NX>,
        torque_weights: &SMatrix<T, NU, NU>,
        reference: R,
        torque_limit: SVector<T, NU>,
    ) -> Result<ManifoldLqr<L, T, R, NQ, NC, NU, M, NX>, ControlError>
    where
        L: ChartSize<M, NX>,
    {
        ManifoldLqr::at_pose(
            self.params,
            pose,
            opts,
            state_weights,
            torque_weights,
            reference,
            torque_limit,
        )
    }
}

/// The leg's contacts on its ground, planar or spatial. Each method takes the contacts'
/// dimension `ND` (two rows per contact in the plane, three in space) from the leg's
/// [`ContactModel`], so `leg.hybrid_simulator(dt)` needs no annotation on a generated leg.
impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    Leg<L, T, NQ, NC, NU, NK>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    /// The contact points in the base frame, stacked `(x₀, y₀, x₁, y₁, …)` (with `z` in 3-D).
    pub fn contact_positions<const ND: usize>(&self, q: &SVector<T, NQ>) -> SVector<T, NK>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        <L as ContactModel<NQ, NC, NU, NK, ND>>::contact_positions(q, &self.params)
    }

    /// The spec's ground.
    pub fn ground<const ND: usize>(&self) -> Ground<T, ND>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        Ground::of::<L, NQ, NC, NU, NK>()
    }

    /// The spec's friction coefficient per contact row.
    pub fn friction<const ND: usize>(&self) -> SVector<T, NK>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        contact::spec_friction::<L, T, NQ, NC, NU, NK, ND>()
    }

    /// The forward dynamics with the contacts in `modes` held (sticking at `anchors`) or
    /// sliding, on the spec's ground with its friction
    /// ([`contact::forward_dynamics_with_contacts`]). A spatial contact sliding from rest
    /// needs its direction: [`contact::ContactSystem::with_slip`].
    pub fn forward_dynamics_with_contacts<const ND: usize>(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        u: &SVector<T, NU>,
        modes: &Modes<NK, ND>,
        anchors: &SVector<T, NK>,
    ) -> Result<ContactSolution<T, NQ, NC, NK>, DynamicsError>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        contact::forward_dynamics_with_contacts::<L, T, NQ, NC, NU, NK, ND>(
            &self.params,
            q,
            qd,
            u,
            modes,
            anchors,
            &self.ground(),
            &self.friction(),
            self.baumgarte,
        )
    }

    /// [`Leg::forward_dynamics_with_contacts`] and its derivatives
    /// ([`derivatives::contact_dynamics_derivatives`]; a spatial slide's friction turns
    /// with its slip velocity). A spatial contact sliding from rest has no direction here
    /// (`DynamicsError::SlipFromRest`): give it one with the free function's `rest`.
    pub fn contact_dynamics_derivatives<const ND: usize>(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        u: &SVector<T, NU>,
        modes: &Modes<NK, ND>,
        anchors: &SVector<T, NK>,
    ) -> Result<ContactDynamicsDerivatives<T, NQ, NC, NU, NK>, DynamicsError>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        derivatives::contact_dynamics_derivatives::<L, T, NQ, NC, NU, NK, ND>(
            &self.params,
            q,
            qd,
            u,
            modes,
            anchors,
            &self.ground(),
            &self.friction(),
            self.baumgarte,
            None,
        )
    }

    /// The plastic impact of the contacts `modes` marks as landing
    /// ([`contact::impact_map`]); `modes` gets the contacts' modes after it.
    pub fn impact_map<const ND: usize>(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        modes: &mut Modes<NK, ND>,
    ) -> Result<Impact<T, NQ, NC, NK>, ImpactError>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        contact::impact_map::<L, T, NQ, NC, NU, NK, ND>(
            &self.params,
            q,
            qd,
            modes,
            &self.ground(),
            &self.friction(),
        )
    }

    /// A simulator of this leg on the ground (contacts, impacts, events), RK4 steps of
    /// `dt` on the spec's ground; its `options` hold the rest.
    pub fn hybrid_simulator<const ND: usize>(
        &self,
        dt: T,
    ) -> HybridSimulator<L, T, NQ, NC, NU, NK, ND>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        let mut sim = HybridSimulator::new(self.params, dt);
        sim.options.baumgarte = self.baumgarte;
        sim.options.tolerance = self.tolerance;
        sim
    }

    /// `torques` as a torque source of this leg on the ground ([`Leg::torque_source`]
    /// for a [`HybridSimulator`]).
    pub fn hybrid_torque_source<F, const ND: usize>(&self, torques: F) -> F
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
        F: FnMut(T, &HybridState<T, NQ, NK, ND>) -> SVector<T, NU>,
    {
        torques
    }
}

/// What needs the leg's planar foot: a [`ContactModel`] (every planar leg,
/// with or without contacts; a spatial leg has the methods above).
impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    Leg<L, T, NQ, NC, NU, NK>
where
    L: ContactModel<NQ, NC, NU, NK> + LegModel<NQ, NC, NU>,
    T: Real,
{
    /// The foot point in the base frame.
    pub fn foot_position(&self, q: &SVector<T, NQ>) -> SVector<T, 2> {
        L::foot_position(q, &self.params)
    }

    /// `J_f(q) = ∂(foot)/∂q`.
    pub fn foot_jacobian(&self, q: &SVector<T, NQ>) -> SMatrix<T, 2, NQ> {
        L::foot_jacobian(q, &self.params)
    }

    /// The closed pose putting the foot at `foot` (base frame), from `guess`.
    pub fn foot_inverse(
        &self,
        foot: &SVector<T, 2>,
        guess: &SVector<T, NQ>,
    ) -> Result<SVector<T, NQ>, AssemblyError> {
        assembly::foot_inverse::<L, T, NQ, NC, NU, 2, NC>(
            &self.params,
            foot,
            guess,
            &self.tolerance,
        )
    }

    /// The foot's apparent mass along x and y at `q`.
    pub fn foot_inertias(&self, q: &SVector<T, NQ>) -> Result<SVector<T, 2>, ControlError> {
        control::foot_inertias::<L, T, NQ, NC, NU, 2, NC>(&self.params, q)
    }

    /// Feedback linearization tracking `reference` with the foot (two motors that
    /// determine the leg).
    pub fn foot_feedback_linearization<R: Reference<T, 2>>(
        &self,
        gains: Gains<T, 2>,
        reference: R,
    ) -> Result<FootFeedbackLinearization<L, T, R, NQ, NC, NU>, ControlError> {
        FootFeedbackLinearization::new(self.params, gains, reference)
    }

    /// PD on the foot with gravity compensation (the baseline).
    pub fn foot_pd_gravity<R: Reference<T, 2>>(
        &self,
        gains: Gains<T, 2>,
        reference: R,
    ) -> Result<FootPdGravity<L, T, R, NQ, NC, NU>, ControlError> {
        FootPdGravity::new(self.params, gains, reference)
    }
}

/// The design measures at one pose, planar or spatial: each method takes the foot's
/// dimension `ND` (and the closure points `NP`) from the leg's [`LegModel`], so
/// `leg.design_measures(&q, &limits)` needs no annotation on a generated leg.
impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    Leg<L, T, NQ, NC, NU, NK>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    /// The frame the design measures use: the leg's body joints held
    /// ([`analysis::LegFrame`]).
    pub fn analysis_frame(&self) -> analysis::LegFrame<NQ> {
        analysis::LegFrame::of::<L, NC, NU>()
    }

    /// Every design measure at the assembled pose `q` ([`analysis::point_measures`]).
    pub fn design_measures<const ND: usize, const NP: usize>(
        &self,
        q: &SVector<T, NQ>,
        limits: &analysis::MotorLimits<T, NU>,
    ) -> Result<analysis::PointMeasures<T, NQ, NU, ND>, analysis::AnalysisError>
    where
        L: LegModel<NQ, NC, NU, ND, NP>,
    {
        analysis::point_measures::<L, T, NQ, NC, NU, ND, NP>(
            &self.params,
            q,
            &self.analysis_frame(),
            limits,
        )
    }

    /// The foot's inverse operational-space inertia `Λ⁻¹` (`ND × ND`) at `q`, the motors
    /// free or locked ([`analysis::foot_inverse_inertia`]).
    pub fn foot_inverse_inertia<const ND: usize, const NP: usize>(
        &self,
        q: &SVector<T, NQ>,
        motors_locked: bool,
    ) -> Result<SMatrix<T, ND, ND>, analysis::AnalysisError>
    where
        L: LegModel<NQ, NC, NU, ND, NP>,
    {
        analysis::foot_inverse_inertia::<L, T, NQ, NC, NU, ND, NP>(
            &self.params,
            q,
            &self.analysis_frame(),
            motors_locked,
        )
    }

    /// The impact mitigation factor at `q` with the hip on `body` (a leg with body joints
    /// of its own uses them) ([`analysis::impact_mitigation`]).
    pub fn impact_mitigation<const ND: usize, const NP: usize>(
        &self,
        q: &SVector<T, NQ>,
        body: &analysis::Body<T>,
    ) -> Result<T, analysis::AnalysisError>
    where
        L: LegModel<NQ, NC, NU, ND, NP>,
    {
        let coupling = analysis::BodyCoupling::new::<L, T, NQ, NC, NU>(&self.params);
        analysis::impact_mitigation::<L, T, NQ, NC, NU, ND, NP>(
            &self.params,
            q,
            &self.analysis_frame(),
            body,
            coupling.as_ref(),
        )
    }
}

impl<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    Leg<L, f64, NQ, NC, NU, NK>
where
    L: LegDynamics<NQ, NC, NU>,
{
    /// The parameters on four SIMD lanes, each lane this leg's (set a lane's value with
    /// [`Parameters::set`] for a sweep).
    pub fn lanes(&self) -> L::Params<F64x4> {
        batch::broadcast::<L, NQ, NC, NU>(&self.params)
    }

    /// The forward dynamics of four states (or four parameter sets, `params`) in one call
    /// on SIMD lanes ([`batch::forward_dynamics`]; no Baumgarte terms).
    pub fn forward_dynamics_lanes(
        &self,
        params: &L::Params<F64x4>,
        q: &SVector<F64x4, NQ>,
        qd: &SVector<F64x4, NQ>,
        u: &SVector<F64x4, NU>,
    ) -> Result<BatchAcceleration<NQ, NC>, BatchError> {
        batch::forward_dynamics::<L, NQ, NC, NU>(params, q, qd, u)
    }
}

impl<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    Leg<L, f64, NQ, NC, NU, NK>
where
    L: LegDynamics<NQ, NC, NU>,
{
    /// The workspace of the branch of `start` (an assembled pose) over a grid of foot
    /// positions, with every design measure at every node; a spatial leg's in a slice
    /// through its foot (`options.plane`) ([`analysis::workspace::workspace`]).
    #[cfg(feature = "std")]
    pub fn workspace<const ND: usize, const NP: usize>(
        &self,
        start: &SVector<f64, NQ>,
        options: &analysis::workspace::GridOptions<NU>,
    ) -> Result<analysis::workspace::Workspace<NQ, NU, ND>, analysis::AnalysisError>
    where
        L: LegModel<NQ, NC, NU, ND, NP>,
    {
        analysis::workspace::workspace::<L, NQ, NC, NU, ND, NP>(
            &self.params,
            start,
            &self.analysis_frame(),
            options,
        )
    }
}
