//! The developer's commands: `bench` (criterion, instruction counts and their budgets,
//! the Pinocchio peer, MuJoCo's simulated second) and `test` (every check CI runs), with the relative-link check of
//! the documentation.
//!
//! May import: [`crate::gen`], [`crate::commands`], [`crate::cli`].

pub mod bench;
pub mod links;
pub mod mujoco_step;
pub mod pinocchio;
pub mod test;
