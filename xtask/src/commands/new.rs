//! `cargo xtask new NAME`: a spec to start from (a five-bar), written to
//! `leg-models/specs/NAME.toml`.

use std::path::{Path, PathBuf};

use crate::cli;
use crate::gen::{self, spec};

const NEW_SPEC: &str = include_str!("new_spec.toml");

pub fn run(root: &Path, name: &str) -> Result<(), cli::Error> {
    spec::check_name(name).map_err(|m| cli::Error::usage(format!("model name: {m}")))?;
    let path: PathBuf = root.join(gen::SPECS_DIR).join(format!("{name}.toml"));
    if path.exists() {
        return Err(cli::Error::usage(format!(
            "{} exists already: choose another name, or edit that spec",
            path.display()
        )));
    }
    let text = NEW_SPEC.replace("NAME", name);
    cli::write_atomic(&path, &text).map_err(cli::Error::Failed)?;
    println!(
        "wrote {}: a five-bar (two motors at the hip, two branches of two links, one closure at\n  the toe, the foot at the closure, home pose knee-out). Edit the links (lengths, masses,\n  centres of mass, inertias, which joints have an actuator), the closures, the foot and\n  `home` (a pose near assembled: it picks the assembly mode), then `cargo xtask gen {name}`;\n  it prints the leg's mobility and motors and checks that the home pose assembles.",
        path.strip_prefix(root).unwrap_or(&path).display()
    );
    Ok(())
}
