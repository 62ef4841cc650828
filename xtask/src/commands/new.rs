//! `cargo xtask new NAME [--spatial]`: a spec to start from (a planar five-bar, or a
//! five-bar on a hip abduction motor in 3-D), written to `leg-models/specs/NAME.toml`.

use std::path::{Path, PathBuf};

use crate::cli;
use crate::gen::{self, spec};

const NEW_SPEC: &str = include_str!("new_spec.toml");
const NEW_SPATIAL_SPEC: &str = include_str!("new_spatial_spec.toml");

pub fn run(root: &Path, name: &str, spatial: bool) -> Result<(), cli::Error> {
    spec::check_name(name).map_err(|m| cli::Error::usage(format!("model name: {m}")))?;
    let path: PathBuf = root.join(gen::SPECS_DIR).join(format!("{name}.toml"));
    if path.exists() {
        return Err(cli::Error::usage(format!(
            "{} exists already: choose another name, or edit that spec",
            path.display()
        )));
    }
    let text = if spatial { NEW_SPATIAL_SPEC } else { NEW_SPEC }.replace("NAME", name);
    cli::write_atomic(&path, &text).map_err(cli::Error::Failed)?;
    let shown = path.strip_prefix(root).unwrap_or(&path).display();
    if spatial {
        println!(
            "wrote {shown}: a spatial five-bar on a hip abduction motor (three motors, one closure at\n  the toe, a toe contact on a floor 0.25 m below). Edit the links (axes, origins,\n  orientations, lengths, masses, inertias, actuators), the closures, the foot, the contacts and\n  `home`, then `cargo xtask gen {name}`; it prints the leg's mobility, motors and redundant\n  closure rows and checks that the home pose assembles."
        );
        return Ok(());
    }
    println!(
        "wrote {}: a five-bar (two motors at the hip, two branches of two links, one closure at\n  the toe, the foot at the closure, home pose knee-out). Edit the links (lengths, masses,\n  centres of mass, inertias, which joints have an actuator), the closures, the foot and\n  `home` (a pose near assembled: it picks the assembly mode), then `cargo xtask gen {name}`;\n  it prints the leg's mobility and motors and checks that the home pose assembles.",
        shown
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both templates, named, are specs the model builder takes, of their dimension (that
    /// their home poses assemble is checked by `gen`, run on both in the CLI tests).
    #[test]
    fn the_templates_build() {
        for (template, dimension) in [(NEW_SPEC, 2), (NEW_SPATIAL_SPEC, 3)] {
            let text = template.replace("NAME", "my_leg");
            let path = Path::new("my_leg.toml");
            let parsed = spec::Spec::parse(path, text).expect("the template parses");
            let model = gen::model::build(&parsed).expect("the template builds");
            assert_eq!(model.dimension, dimension);
        }
    }
}
