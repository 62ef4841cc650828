//! The build tool proper: the generation pipeline from a geometry spec to committed Rust.
//!
//! - [`spec`]: the TOML spec, parsed with every error located (file, line, column, field);
//! - [`model`]: the validated leg the derivation reads (links, joints, closures, foot);
//! - `pipeline`: `cargo xtask gen` and `gen --check`: the CasADi derivation
//!   (`xtask/derive.py`, in the project's `.venv/`), the IR it prints, and the files
//!   written only when every model succeeded; re-exported here;
//! - [`ir_file`]: the committed IR (`generated/ir/*.json`) and what it records of the leg;
//! - [`rust_module`]: IR → one generated Rust module (through `codegen`).
//!
//! May import: [`crate::cli`].

pub mod ir_file;
pub mod model;
pub(crate) mod pipeline;
pub mod rust_module;
pub mod spec;

pub use pipeline::{
    actuation_note, check_model, committed_ir, committed_irs, dry_run, load_spec, model_names,
    planar_model_names, python, run, rust_files, spatial_model_names, spec_paths, stale_files,
    standalone, workspace_root, GenOptions, CASADI_C_DIR, IR_DIR, REQUIREMENTS, SPECS_DIR, SRC_DIR,
    VENV_DIR,
};
