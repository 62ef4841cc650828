//! `cargo xtask`: the project's command line, in three rooms over a shared floor.
//!
//! | room | what lives there |
//! |---|---|
//! | [`gen`] | the build tool: spec → CasADi derivation → IR → Rust, `gen --check` |
//! | [`commands`] and `src/bin/legs/` | the user's commands: `list`, `new`, `export`; `sim`, `eval`, `analyze` and their reports (the `legs` binary, which links the generated models) |
//! | [`dev`] | the developer's commands: `bench`, `test` |
//! | [`cli`] | what all of them share: arguments, errors, files, progress |
//!
//! Imports run `dev` → `commands` → `gen` → `cli`. A library so that the workspace tests
//! can check the committed code without Python.

pub mod cli;
pub mod commands;
pub mod dev;
pub mod gen;
