//! The port between the simulators and the controllers: the [`State`] a simulator
//! passes, the [`TorqueSource`] it asks for torques, when it asks ([`ControlUpdate`]),
//! and [`ControlError`], every reason a controller gives for not acting, with the errors
//! it carries from a linearization ([`LinearizationError`]) or a Riccati solve
//! ([`LqrError`]). Kept below both sides so that neither imports the other's upper floor.

use core::fmt;

use nalgebra::SVector;

use crate::assembly::AssemblyError;
use crate::dynamics::forward::DynamicsError;
use crate::dynamics::structure::NotApplicable;
use crate::model::contract::Real;
use crate::model::shown::ShownNumber;

/// Joint positions and velocities.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State<T: Real, const NQ: usize> {
    /// The joint coordinates `q` (rad, or m on a prismatic joint).
    pub q: SVector<T, NQ>,
    /// The joint rates `q̇` (rad/s, or m/s).
    pub qd: SVector<T, NQ>,
}

/// Motor torques as a function of time and state: a controller, or any closure
/// `FnMut(t, &State) -> u`. A controller that cannot act (a singular configuration, an
/// unreachable reference) says why.
pub trait TorqueSource<T: Real, const NQ: usize, const NU: usize> {
    /// The motor torques `u` at time `t` (s) and `state`, or why there are none.
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> Result<SVector<T, NU>, ControlError>;
}

impl<T: Real, const NQ: usize, const NU: usize, F> TorqueSource<T, NQ, NU> for F
where
    F: FnMut(T, &State<T, NQ>) -> SVector<T, NU>,
{
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> Result<SVector<T, NU>, ControlError> {
        Ok(self(t, state))
    }
}

/// When the torque source is asked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControlUpdate {
    /// Once per step, held over the step (a digital controller at the step rate).
    PerStep,
    /// At every stage of the integrator (the continuous-time control law).
    PerStage,
}

/// Why a controller cannot act at a state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ControlError {
    /// `A22` is singular: the passive joints lose rank (e.g. a five-bar's lower links
    /// collinear), so the motors do not determine the leg's motion.
    SingularPassive,
    /// The foot Jacobian in actuated coordinates `J_f G` loses rank: the foot cannot be
    /// moved in some direction.
    SingularTask,
    /// The leg's dynamics cannot be solved at the state (the mass matrix is not positive
    /// definite, or a closure or contact system is singular).
    Dynamics(DynamicsError),
    /// A state, reference or parameter is NaN or infinite.
    NonFinite,
    /// The method does not apply to this leg (too few motors for the foot, an
    /// under- or over-actuated leg): reported when the controller is built.
    NotApplicable(NotApplicable),
    /// A torque limit is negative or NaN (a limit is zero or more; infinite for none):
    /// refused when the limited source is built, never clipping to garbage.
    TorqueLimit {
        /// The motor (from 0, in the order of the leg's motors).
        motor: usize,
        /// The limit given (N m, or N on a prismatic motor).
        value: f64,
    },
    /// A feedback gain is negative, not finite or beyond [`MAX_GAIN`]: refused when the
    /// controller is built.
    Gain {
        /// `kp` or `kd`.
        name: &'static str,
        /// The coordinate (from 0: a motor, or a foot coordinate).
        coordinate: usize,
        /// The gain given.
        value: f64,
    },
    /// The caller stopped the run (a Ctrl-C seen by the Python bindings): the record so
    /// far is kept, as for any other stop.
    Interrupted,
    /// A linearization-based controller (LQR) could not linearize the leg.
    Linearization(crate::simulate::source::LinearizationError),
    /// The Riccati equation of an LQR has no solution.
    Lqr(crate::simulate::source::LqrError),
}

/// The largest feedback gain a controller takes: `k_p` = 1e9 1/s² is an error dynamics of
/// 3·10⁴ rad/s, past any integrator's stable step; larger gains only overflow the torques.
pub const MAX_GAIN: f64 = 1e9;

impl fmt::Display for ControlError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ControlError::SingularPassive => {
                write!(
                    f,
                    "singular configuration: the passive joints lose rank (A22 singular)"
                )
            }
            ControlError::SingularTask => {
                write!(f, "the foot Jacobian in motor coordinates is singular")
            }
            ControlError::Dynamics(e) => write!(f, "{e}"),
            ControlError::NonFinite => write!(f, "non-finite state, reference or parameter"),
            ControlError::NotApplicable(why) => write!(f, "not applicable: {why}"),
            ControlError::TorqueLimit { motor, value } => write!(
                f,
                "the torque limit of motor {motor} is {}: a limit must be zero or more (infinite for none)",
                ShownNumber(*value)
            ),
            ControlError::Gain {
                name,
                coordinate,
                value,
            } => write!(
                f,
                "the gain {name} of coordinate {coordinate} is {}: a gain must be zero or more and at most {}",
                ShownNumber(*value),
                ShownNumber(MAX_GAIN)
            ),
            ControlError::Interrupted => write!(f, "interrupted by the caller"),
            ControlError::Linearization(e) => write!(f, "linearization: {e}"),
            ControlError::Lqr(e) => write!(f, "LQR: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ControlError {}

impl From<NotApplicable> for ControlError {
    fn from(e: NotApplicable) -> Self {
        ControlError::NotApplicable(e)
    }
}

impl From<AssemblyError> for ControlError {
    fn from(e: AssemblyError) -> Self {
        match e {
            AssemblyError::NonFinite => ControlError::NonFinite,
            _ => ControlError::SingularPassive,
        }
    }
}

/// Why a linearization cannot be made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LinearizationError {
    /// The dynamics cannot be solved at a stage.
    Dynamics(DynamicsError),
    /// Projecting onto the constraints, or lifting chart coordinates onto them, failed.
    Assembly(AssemblyError),
    /// The chart's size does not match the leg: it has `mobility` degrees of freedom
    /// here, so its manifold states are `2 · mobility`, not `states`.
    Dimension {
        /// The leg's degrees of freedom at the pose.
        mobility: usize,
        /// The number of manifold states asked for.
        states: usize,
    },
    /// No torque holds the leg at rest at this pose (an under-actuated leg away from its
    /// passive equilibrium): `residual` is the smallest acceleration left (rad/s², m/s²).
    NotAnEquilibrium {
        /// The acceleration left under the best torque, its largest entry (rad/s², m/s²).
        residual: f64,
    },
    /// The motors do not move the chart's coordinates at this pose (`∂θ̈/∂u` loses rank),
    /// so no torque is determined.
    MotorsDoNotMoveCoordinates,
}

impl fmt::Display for LinearizationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinearizationError::Dynamics(e) => write!(f, "dynamics: {e}"),
            LinearizationError::Assembly(e) => write!(f, "constraints: {e}"),
            LinearizationError::Dimension { mobility, states } => write!(
                f,
                "the leg has {mobility} degree(s) of freedom here, so its states on the constraint manifold are {} numbers, not {states}",
                2 * mobility
            ),
            LinearizationError::MotorsDoNotMoveCoordinates => write!(
                f,
                "the motors do not move the leg's coordinates at this pose: no torque holds it"
            ),
            LinearizationError::NotAnEquilibrium { residual } => write!(
                f,
                "no motor torque holds the leg at rest at this pose (acceleration {residual:.3e} remains): the passive joints are not at an equilibrium"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for LinearizationError {}

impl From<DynamicsError> for LinearizationError {
    fn from(e: DynamicsError) -> Self {
        LinearizationError::Dynamics(e)
    }
}

impl From<AssemblyError> for LinearizationError {
    fn from(e: AssemblyError) -> Self {
        LinearizationError::Assembly(e)
    }
}

/// Why the Riccati equation has no solution here.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LqrError {
    /// `R` (or `R + Bᵀ P B`) is not positive definite, or a doubling round is singular.
    NotPositiveDefinite,
    /// The iteration did not settle in `iterations` rounds: `(A, B)` is not stabilizable
    /// or `(A, Q)` not detectable.
    NotConverged {
        /// The doubling rounds taken.
        iterations: usize,
    },
    /// NaN or infinity in the data or the iterates.
    NonFinite,
}

impl fmt::Display for LqrError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LqrError::NotPositiveDefinite => {
                write!(f, "R + Bᵀ P B is not positive definite")
            }
            LqrError::NotConverged { iterations } => write!(
                f,
                "the Riccati iteration did not converge in {iterations} rounds: the linearization is not stabilizable"
            ),
            LqrError::NonFinite => write!(f, "non-finite Riccati data or iterate"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for LqrError {}
