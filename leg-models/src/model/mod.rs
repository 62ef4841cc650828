//! The generator ↔ runtime contract and the arithmetic under it.
//!
//! - `contract`: [`LegModel`](crate::LegModel), the trait every generated geometry
//!   implements, its parameters and terms, and the scalar traits
//!   [`Real`](crate::Real)/[`Arithmetic`](crate::Arithmetic) the generated code is generic over;
//! - `trig`: the `sin_cos` the generated code calls, the same on every target;
//! - [`simd`]: several states in SIMD lanes, an `Arithmetic` of their own;
//! - [`linalg`]: fixed-size factorizations (Cholesky, pivoted L D Lᵀ, LU);
//! - `shown`: [`Shown`](crate::Shown) and [`ShownNumber`](crate::ShownNumber), user text and
//!   numbers as errors echo them.
//!
//! The ground floor: imports nothing from the rest of the crate.

pub(crate) mod contract;
pub mod linalg;
pub(crate) mod shown;
pub mod simd;
mod trig;
