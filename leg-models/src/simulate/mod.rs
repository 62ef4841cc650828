//! Running a leg in time.
//!
//! - `source`: the port between simulators and controllers: the [`State`] a simulator
//!   passes, the [`TorqueSource`] it asks for torques and [`ControlError`], every reason a
//!   controller gives for not acting. It sits here, below [`crate::control`], so that
//!   the simulators never import a controller and the controllers import only downward;
//! - `step`: integrators (RK4, semi-implicit Euler) with drift control (Baumgarte terms,
//!   projection onto the closures) and the energy, re-exported here;
//! - [`hybrid`]: the hybrid simulator: contact modes, touchdown and lift-off events,
//!   impacts;
//! - `record` (with `std`): the recording [`Simulator`].
//!
//! May import: [`crate::assembly`], [`crate::dynamics`], the contract ([`LegModel`](crate::LegModel), [`Real`](crate::Real), [`linalg`](crate::linalg), [`simd`](crate::simd)).

pub mod hybrid;
#[cfg(feature = "std")]
pub(crate) mod record;
pub(crate) mod source;
pub(crate) mod step;

#[cfg(feature = "std")]
pub use record::{Sample, Simulator, Stopped};
pub use source::{ControlError, ControlUpdate, State, TorqueSource, MAX_GAIN};
pub use step::{
    check_record, energy, step, Method, RecordTooLarge, StepError, StepOptions, StepReport,
    MAX_RECORD_BYTES,
};
