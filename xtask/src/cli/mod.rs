//! What every command of `cargo xtask` shares: the command line's grammar ([`args`], one
//! clap definition for both binaries), errors with their exit codes, lists of numbers,
//! text tables, files written whole or not at all, running cargo, and progress bars.
//!
//! The ground floor of xtask: imports nothing from the rest of the crate.

pub mod args;
mod common;
pub mod progress;

pub use common::{
    build_legs, cargo, check_target, check_targets, numbers, shown, target_dir, text_table,
    write_all, write_atomic, Error,
};
