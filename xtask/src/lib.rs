//! The generator behind `cargo xtask`: geometry specs, the CasADi derivation driver, the
//! committed IR files and the Rust modules made from them. A library so that the
//! workspace tests can check the committed code without Python.

pub mod args;
pub mod bench;
pub mod cli;
pub mod export;
pub mod gen;
pub mod ir_file;
pub mod model;
pub mod pinocchio;
pub mod progress;
pub mod rust_module;
pub mod spec;
