//! `cargo xtask test`: every check CI runs, in the order that fails fastest.

use std::path::Path;
use std::process::Command;

use xtask::cli::{cargo, target_dir};
use xtask::gen::{self, GenOptions};

/// Snapshots insta wrote but nobody reviewed.
fn pending_snapshots(root: &Path) -> Vec<String> {
    fn walk(dir: &Path, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            let name = e.file_name().to_string_lossy().into_owned();
            if p.is_dir() && name != "target" && !name.starts_with('.') {
                walk(&p, out);
            } else if name.ends_with(".snap.new") || name.ends_with(".pending-snap") {
                out.push(p.display().to_string());
            }
        }
    }
    let mut out = Vec::new();
    walk(root, &mut out);
    out.sort();
    out
}

/// Every model exported to MJCF and loaded in MuJoCo (from the generation step's Python
/// environment): mass matrix and bias forces against ours, and the closure in a MuJoCo run.
fn mujoco_cross_check(root: &Path) -> Result<(), String> {
    eprintln!("==> MuJoCo cross-check (xtask/mujoco_check.py)");
    cargo(
        root,
        &[
            "build",
            "--quiet",
            "-p",
            "xtask",
            "--features",
            "models",
            "--bin",
            "legs",
        ],
        &[],
    )?;
    let target = target_dir(root);
    let legs = target.join("debug").join("legs");
    let py = gen::python(root)?;
    let dir = target.join("mujoco");
    for name in xtask::cli::model_names(root)? {
        let spec = gen::load_spec(
            root,
            &root.join(gen::SPECS_DIR).join(format!("{name}.toml")),
        )?;
        let model = xtask::model::build(&spec).map_err(|e| e.to_string())?;
        let file = dir.join(format!("{name}.xml"));
        xtask::cli::write_atomic(&file, &xtask::export::mjcf(&model))?;
        let status = Command::new(&py)
            .arg(root.join("xtask").join("mujoco_check.py"))
            .arg(&legs)
            .arg(&name)
            .arg(&file)
            .current_dir(root)
            .status()
            .map_err(|e| format!("cannot run the MuJoCo check: {e}"))?;
        if !status.success() {
            return Err(format!("MuJoCo disagrees with `{name}` (see above)"));
        }
    }
    Ok(())
}

pub fn run(root: &Path) -> Result<(), String> {
    cargo(root, &["fmt", "--all", "--check"], &[])
        .map_err(|e| format!("{e}: run `cargo fmt --all`"))?;
    eprintln!("==> cargo xtask gen --check");
    let report = gen::run(
        root,
        &GenOptions {
            check: true,
            names: Vec::new(),
        },
    )?;
    eprintln!("{report}");
    // Snapshots must match as committed: insta neither writes nor accepts here.
    cargo(
        root,
        &["test", "--workspace", "--all-features"],
        &[("INSTA_UPDATE", "no"), ("CI", "true")],
    )?;
    let pending = pending_snapshots(root);
    if !pending.is_empty() {
        return Err(format!(
            "unreviewed snapshots: {}\nrun `cargo insta review`",
            pending.join(", ")
        ));
    }
    mujoco_cross_check(root)?;
    eprintln!("==> instruction budgets ({})", xtask::bench::BUDGETS);
    eprintln!("{}", xtask::bench::check_budgets(root, false)?);
    cargo(
        root,
        &[
            "build",
            "-p",
            "leg-models",
            "-p",
            "generated",
            "--no-default-features",
        ],
        &[],
    )
    .map_err(|e| format!("{e}: the runtime and the generated models must build without std"))?;
    cargo(
        root,
        &[
            "clippy",
            "--workspace",
            "--all-targets",
            "--all-features",
            "--",
            "-D",
            "warnings",
        ],
        &[],
    )?;
    eprintln!("all checks passed");
    Ok(())
}
