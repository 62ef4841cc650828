//! `cargo xtask list`: every spec with its sizes, mobility and actuation, from the spec
//! and the committed IR; a spec that does not validate is listed with its error.

use std::path::Path;

use crate::cli::{self, text_table};
use crate::gen::{self, model};

/// Prints the table of specs.
pub fn run(root: &Path) -> Result<(), cli::Error> {
    // Mobility and redundant rows come from the derivation (the committed IR); a spec not
    // generated yet (just written by `new`) is listed with what to run.
    let mut rows = vec![[
        "model".to_string(),
        "NQ".into(),
        "NC".into(),
        "NU".into(),
        "mobility".into(),
        "actuation".into(),
        "actuated joints".into(),
        "spec".into(),
    ]];
    for path in gen::spec_paths(root).map_err(cli::Error::Failed)? {
        // A spec that does not validate is listed with its error, not in the way of the rest.
        let built = gen::load_spec(root, &path).and_then(|spec| {
            model::build(&spec)
                .map(|m| (spec, m))
                .map_err(|e| e.to_string())
        });
        let (spec, m) = match built {
            Ok(x) => x,
            Err(e) => {
                let name = path
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .unwrap_or_default();
                let mut row: [String; 8] = Default::default();
                row[0] = name.to_string();
                row[5] = format!("does not validate: {e}");
                row[7] = path
                    .strip_prefix(root)
                    .unwrap_or(&path)
                    .display()
                    .to_string();
                rows.push(row);
                continue;
            }
        };
        let actuated: Vec<&str> = m
            .actuated
            .iter()
            .map(|&a| m.links[a].name.as_str())
            .collect();
        let ir = gen::committed_ir(root, &m.name).map_err(cli::Error::Failed)?;
        let (redundant, mobility, actuation) = match &ir {
            Some(ir) => (
                match ir.model.redundant_rows.len() {
                    0 => String::new(),
                    n => format!(" ({n} redundant)"),
                },
                ir.model.mobility.to_string(),
                gen::actuation_note(ir.model.mobility, m.actuated.len()).to_string(),
            ),
            None => (
                String::new(),
                "–".into(),
                format!("not generated yet: run `cargo xtask gen {}`", m.name),
            ),
        };
        rows.push([
            m.name.clone(),
            m.links.len().to_string(),
            format!("{}{redundant}", 2 * m.closures.len()),
            m.actuated.len().to_string(),
            mobility,
            actuation,
            actuated.join(", "),
            spec.path.display().to_string(),
        ]);
    }
    print!("{}", text_table(&rows, |c| (1..=4).contains(&c)));
    Ok(())
}
