//! The user's commands that need no generated model: `list` (the specs, their sizes and
//! what applies), `new` (a spec to start from), `export` (MJCF and URDF; a spatial leg's
//! MJCF in `export::spatial`) and `import` (a spatial spec from an MJCF file). The
//! commands that run a generated model (`sim`, `eval`, `analyze`) are the `legs` binary,
//! in `src/bin/legs/`.
//!
//! May import: [`crate::gen`], [`crate::cli`].

pub mod export;
pub mod import;
pub mod list;
pub mod new;
