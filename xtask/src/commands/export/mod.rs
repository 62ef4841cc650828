//! `cargo xtask export`: a leg for MuJoCo (MJCF) and URDF tools, from its spec.
//! `planar.rs` writes a planar leg's MJCF and URDF, `spatial.rs` a spatial leg's,
//! `common.rs` what they share (the names the exporters add, exact numbers, closures and
//! coupling springs in MJCF, URDF's added frames and transmissions).

mod common;
pub mod planar;
pub mod spatial;

use std::path::Path;

pub use common::added;
pub use planar::{mjcf, urdf};

use crate::cli::{self, args::ExportArgs, args::ExportFormat};
use crate::gen::{self, model};

/// The validated model of a built-in spec, by name.
fn load_model(root: &Path, name: &str) -> Result<model::Model, cli::Error> {
    let known = gen::model_names(root).map_err(cli::Error::Failed)?;
    gen::check_model(name, &known)?;
    let path = root.join(gen::SPECS_DIR).join(format!("{name}.toml"));
    // A spec that does not load is bad input, as in `gen`.
    let spec = gen::load_spec(root, &path).map_err(cli::Error::Usage)?;
    model::build(&spec).map_err(|e| cli::Error::Usage(e.to_string()))
}

/// `cargo xtask export`: writes `--out FILE` whole (or prints to standard output).
pub fn run(root: &Path, a: ExportArgs) -> Result<(), cli::Error> {
    let m = load_model(root, &a.model)?;
    let text = match a.format {
        ExportFormat::Mjcf if m.dimension == 3 => spatial::mjcf(&m),
        ExportFormat::Mjcf => mjcf(&m),
        ExportFormat::Urdf if m.dimension == 3 => spatial::urdf(&m),
        ExportFormat::Urdf => urdf(&m),
    };
    match a.out {
        Some(out) => {
            cli::write_atomic(&out, &text).map_err(cli::Error::Failed)?;
            eprintln!("wrote {}", out.display());
        }
        None => print!("{text}"),
    }
    Ok(())
}
