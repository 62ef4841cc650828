//! Control in the motor coordinates (DESIGN.md §3): every controller is a
//! [`TorqueSource`] (or a [`crate::simulate::hybrid::HybridTorqueSource`]), so the
//! simulators run it directly.
//!
//! - `reduction`: the dynamics in the motor angles `Ã θ̈ = b̃ + u` (Schur complement and
//!   null-space forms) and its derivatives, re-exported here;
//! - `feedback`: joint- and foot-space feedback linearization, PD with gravity
//!   compensation, torque saturation, re-exported here;
//! - [`reference`](mod@reference): reference trajectories (set points, ramps, minimum jerk, sinusoids,
//!   step cycles);
//! - [`linearize`]: the exact linearization of one integrator step, in joint coordinates
//!   and on the constraint manifold (for MPC);
//! - [`lqr`]: a discrete LQR on the constraint manifold;
//! - [`hop`]: a hopping controller for legs with a floating body (Raibert).
//!
//! The trait and its error live in [`crate::simulate`] (the simulators' port) and are
//! re-exported here. May import: [`crate::simulate`], [`crate::assembly`],
//! [`crate::dynamics`], the contract ([`LegModel`](crate::LegModel), [`Real`](crate::Real), [`linalg`](crate::linalg), [`simd`](crate::simd)).

pub(crate) mod feedback;
pub mod hop;
pub mod linearize;
pub mod lqr;
pub(crate) mod reduction;
pub mod reference;

pub use crate::simulate::{ControlError, State, TorqueSource, MAX_GAIN};
pub use feedback::{
    check_torque_limits, foot_inertias, joint_inertias, FootFeedbackLinearization, FootPdGravity,
    Gains, JointFeedbackLinearization, PdGravity, Saturated,
};
pub use reduction::{
    actuated_reduction, actuated_reduction_null_space, null_space, reduction_derivatives,
    ActuatedDynamics, NullSpace, ReductionDerivatives,
};
