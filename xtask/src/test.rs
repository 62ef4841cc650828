//! `cargo xtask test`: every check CI runs, in the order that fails fastest.

use std::path::Path;
use std::process::Command;

use xtask::gen::{self, GenOptions};

fn cargo(root: &Path, args: &[&str], env: &[(&str, &str)]) -> Result<(), String> {
    let shown = format!("cargo {}", args.join(" "));
    eprintln!("==> {shown}");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .args(args)
        .envs(env.iter().copied())
        .current_dir(root)
        .status()
        .map_err(|e| format!("cannot run `{shown}`: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{shown}` failed ({status})"))
    }
}

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
        &["test", "--workspace"],
        &[("INSTA_UPDATE", "no"), ("CI", "true")],
    )?;
    let pending = pending_snapshots(root);
    if !pending.is_empty() {
        return Err(format!(
            "unreviewed snapshots: {}\nrun `cargo insta review`",
            pending.join(", ")
        ));
    }
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
            "--",
            "-D",
            "warnings",
        ],
        &[],
    )?;
    eprintln!("all checks passed");
    Ok(())
}
