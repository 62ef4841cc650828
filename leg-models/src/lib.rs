//! Runtime for closed-chain leg models.
//!
//! This crate holds the contract between the generator and the runtime: the
//! [`LegModel`] trait that every generated geometry implements (see the `generated`
//! crate), and the scalar trait [`Real`] the generated code is generic over. The
//! geometry specs the generator reads live in `leg-models/specs/`.
//!
//! Conventions (see `shared/DESIGN.md` §3): `q` are relative joint angles, one per link,
//! in the order the links appear in the spec; a closure contributes two rows to the
//! closure residual `φ(q)` (point a minus point b, in the base frame); `M q̈ + N = Jᵀ F + B u`.
#![cfg_attr(not(feature = "std"), no_std)]

mod model;

pub use model::{DynamicsTerms, LegModel, Parameters, Real};
pub use nalgebra;
