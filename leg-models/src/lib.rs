//! Runtime for closed-chain leg models.
//!
//! This crate holds the contract between the generator and the runtime — the
//! [`LegModel`] trait that every generated geometry implements (see the `generated`
//! crate) and the scalar trait [`Real`] the generated code is generic over — and the
//! algorithms that use the generated terms: constrained forward dynamics
//! ([`dynamics`]), loop assembly ([`assembly`]), time stepping with drift control
//! ([`integrate`]), control in the actuated coordinates ([`control`]) with reference
//! trajectories ([`mod@reference`]), the exact derivatives of the dynamics
//! ([`derivatives`]) and the linearization of a step in joint coordinates and on the
//! constraint manifold ([`linearize`]) for MPC, a discrete LQR on that manifold
//! ([`lqr`]) and, with the `std` feature, a recording [`simulate::Simulator`].
//! Everything but the simulator's record is fixed-size and allocation-free, and the
//! crate is `no_std` without the default `std` feature. The geometry specs the generator
//! reads live in `leg-models/specs/`.
//!
//! Conventions (see `shared/DESIGN.md` §3): `q` are relative joint angles, one per link,
//! in the order the links appear in the spec; a closure contributes two rows to the
//! closure residual `φ(q)` (point a minus point b, in the base frame);
//! `M q̈ + N + D q̇ = Jᵀ F + B u`.
#![cfg_attr(not(feature = "std"), no_std)]
#![warn(missing_docs)]

pub mod analysis;
pub mod assembly;
pub mod batch;
pub mod contact;
pub mod control;
pub mod derivatives;
pub mod dynamics;
pub mod hop;
pub mod hybrid;
pub mod integrate;
pub mod leg;
pub mod linalg;
pub mod linearize;
pub mod lqr;
mod model;
pub mod reference;
pub mod simd;
#[cfg(feature = "std")]
pub mod simulate;
pub mod structure;
mod trig;

pub use leg::{must_be_nonnegative, ChartSize, Leg, ParameterError};
pub use model::{
    Arithmetic, ConstraintDerivatives, ContactModel, DynamicsDerivatives, DynamicsTerms, JointKind,
    LegModel, Parameters, Real, Spring,
};
pub use nalgebra;
