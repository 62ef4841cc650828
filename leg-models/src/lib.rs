//! Runtime for closed-chain leg models.
//!
//! This crate holds the contract between the generator and the runtime — the
//! [`LegModel`] trait that every generated geometry implements (see the `generated`
//! crate) and the scalar trait [`Real`] the generated code is generic over — and the
//! algorithms that use the generated terms, in floors that import only downward:
//!
//! | floor | what lives there |
//! |---|---|
//! | [`Leg`] | the facade: every operation as a method of one leg with its parameters |
//! | [`analysis`] | design measures: singularities, force and speed polygons, foot inertia, workspace |
//! | [`control`] | controllers in the motor coordinates, references, linearization, LQR, hopping |
//! | [`robot`] | whole robots: a body on a free joint, its pose (a unit quaternion) and the chart centred on it, steps, energy, momentum |
//! | [`simulate`] | integrators with drift control, the hybrid simulator, the recorder; the controllers' port |
//! | [`assembly`] | closing the loops: assembly, projection, continuation along a branch |
//! | [`dynamics`] | the KKT forward dynamics, structure, contact and impacts, derivatives, batches |
//! | contract | [`LegDynamics`] and [`LegModel`], [`Real`], trigonometry, [`simd`] lanes, fixed-size [`linalg`] |
//!
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
pub mod control;
pub mod dynamics;
pub mod leg;
mod model;
pub mod robot;
pub mod simulate;

pub use leg::{
    check_parameter, check_pose, ChartSize, Leg, ParameterError, MAX_COORDINATE, MAX_PARAMETER,
};
pub use model::contract::{
    Arithmetic, ConstraintDerivatives, ContactModel, DynamicsDerivatives, DynamicsTerms, JointKind,
    LegDynamics, LegModel, Parameters, Real, Spring,
};
pub use model::shown::{Shown, ShownNumber};
pub use model::{linalg, simd};
pub use nalgebra;
