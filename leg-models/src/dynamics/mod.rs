//! The constrained dynamics of a leg at one state (DESIGN.md §3, §3.1, §3.2).
//!
//! - `forward`: the KKT solve `[M Jᵀ; J 0] (q̈, −F) = (−N − D q̇ + B u, −J̇ q̇ − Baumgarte)`,
//!   structured (Cholesky of `M`, then the small `J M⁻¹ Jᵀ` system), re-exported here;
//! - [`structure`]: what a leg's closures and motors leave free (redundant rows,
//!   mobility, the kind of actuation);
//! - [`contact`]: contact rows on the ground, the dynamics with contacts and the impact map;
//! - [`derivatives`]: exact derivatives of the forward and contact dynamics;
//! - [`batch`]: forward dynamics of four states at once in SIMD lanes;
//! - `lcp` (feature `std`): the linear complementarity problem, solved exactly by Lemke's pivoting.
//!
//! May import: the contract ([`LegModel`](crate::LegModel), [`Real`](crate::Real), [`linalg`](crate::linalg), [`simd`](crate::simd)) only.

pub mod batch;
pub mod contact;
pub mod derivatives;
pub(crate) mod forward;
#[cfg(feature = "std")]
pub mod lcp;
pub mod structure;

pub use forward::{
    actuation, forward_dynamics, forward_dynamics_from_terms, rcond_floor, solve_kkt, Acceleration,
    Baumgarte, DynamicsError, KktFactorization,
};
