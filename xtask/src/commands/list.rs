//! `cargo xtask list`: every spec with its dimension (2: planar, 3: spatial), sizes,
//! mobility, actuation and contacts, from the spec
//! and the committed IR. A spec that does not validate, or has no generated code yet, is
//! listed with what `gen` says of it; long messages stand under the table, which stays
//! narrow.

use std::path::Path;

use crate::cli::{self, text_table};
use crate::gen::{self, model};

/// Prints [`table`].
pub fn run(root: &Path) -> Result<(), cli::Error> {
    print!("{}", table(root)?);
    Ok(())
}

/// The table of specs, then the messages of the specs that need them.
pub fn table(root: &Path) -> Result<String, cli::Error> {
    let mut rows = vec![[
        "model".to_string(),
        "dim".into(),
        "NQ".into(),
        "NC".into(),
        "NU".into(),
        "mobility".into(),
        "actuation".into(),
        "actuated joints".into(),
        "contacts".into(),
    ]];
    let mut notes = Vec::new();
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
                let mut row: [String; 9] = Default::default();
                row[0] = name.to_string();
                row[6] = "does not validate (below)".into();
                rows.push(row);
                notes.push(format!("{name}: {e}"));
                continue;
            }
        };
        let actuated: Vec<&str> = m
            .actuated
            .iter()
            .map(|&a| m.links[a].name.as_str())
            .collect();
        // Mobility and redundant rows come from the derivation: the committed IR, or for a
        // spec not generated yet (just written by `new`) the derivation run in memory, so
        // that a spec `gen` would refuse shows its own error rather than advice to run it.
        let (redundant, mobility, actuation) =
            match gen::committed_ir(root, &m.name).map_err(cli::Error::Failed)? {
                Some(ir) => (
                    match ir.model.redundant_rows.len() {
                        0 => String::new(),
                        n => format!(" ({n} redundant)"),
                    },
                    ir.model.mobility.to_string(),
                    gen::actuation_note(ir.model.mobility, m.actuated.len()).to_string(),
                ),
                None => {
                    match gen::dry_run(root, &spec) {
                        Ok(line) => notes.push(format!(
                            "{}: not generated yet; `cargo xtask gen {}` will say: {line}",
                            m.name, m.name
                        )),
                        Err(e) => notes.push(format!(
                            "{}: `cargo xtask gen {}` fails: {e}",
                            m.name, m.name
                        )),
                    }
                    (String::new(), "–".into(), "not generated (below)".into())
                }
            };
        let contacts: Vec<&str> = m.contacts.iter().map(|c| c.name.as_str()).collect();
        rows.push([
            m.name.clone(),
            m.dimension.to_string(),
            m.links.len().to_string(),
            format!("{}{redundant}", m.closure_rows()),
            m.actuated.len().to_string(),
            mobility,
            actuation,
            actuated.join(", "),
            if contacts.is_empty() {
                "–".to_string()
            } else {
                contacts.join(", ")
            },
        ]);
    }
    let mut out = text_table(&rows, |c| (1..=5).contains(&c));
    if !notes.is_empty() {
        out.push('\n');
        for n in notes {
            out.push_str(&n);
            out.push('\n');
        }
    }
    Ok(out)
}
