//! `cargo xtask test`: every check CI runs. Each check runs even when an earlier one
//! failed, and every failure is listed at the end.

use std::path::Path;
use std::process::Command;

use crate::cli::{cargo, target_dir};
use crate::gen::{self, GenOptions};

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

/// Every model exported and loaded by independent tools, from the generation step's
/// Python environment: the MJCF in MuJoCo (mass matrix and bias forces against ours, and
/// the closure in a MuJoCo run), the URDF in Pinocchio (its parser, mass matrix, bias
/// forces, foot and closure frames against ours). Returns the models that disagree.
fn cross_checks(root: &Path) -> Result<Vec<String>, String> {
    eprintln!(
        "==> MuJoCo (xtask/mujoco_check.py, mujoco_push.py) and Pinocchio (xtask/urdf_check.py) cross-checks"
    );
    let legs = crate::cli::build_legs(root)?;
    let target = target_dir(root);
    let py = gen::python(root)?;
    let dir = target.join("exports");
    // The planar exports in MuJoCo and Pinocchio; a spatial
    // leg's MJCF in MuJoCo (mass matrix, bias forces, the connect rows and the foot, a
    // ball joint mapped to MuJoCo's quaternion and angular velocity) and its URDF in
    // Pinocchio (a ball joint as three revolute joints, so q maps one to one), and an
    // imported leg on the file it came from too (joints by name).
    // (script, model, its files, tool). An imported leg whose source is here also runs
    // loop_gaps.py: 1 s passive and tracking, its loop gaps beside MuJoCo's on the source
    // and Pinocchio's on the URDF.
    let mut jobs: Vec<(&str, String, Vec<std::path::PathBuf>, &str)> = Vec::new();
    let planar = crate::gen::planar_model_names(root)?;
    for name in planar.iter().chain(&crate::gen::spatial_model_names(root)?) {
        let spec = gen::load_spec(
            root,
            &root.join(gen::SPECS_DIR).join(format!("{name}.toml")),
        )?;
        let model = crate::gen::model::build(&spec).map_err(|e| e.to_string())?;
        let mjcf = dir.join(format!("{name}.xml"));
        if planar.contains(name) {
            crate::cli::write_atomic(&mjcf, &crate::commands::export::mjcf(&model))?;
            let urdf = dir.join(format!("{name}.urdf"));
            crate::cli::write_atomic(&urdf, &crate::commands::export::urdf(&model))?;
            jobs.push(("mujoco_check.py", name.clone(), vec![mjcf], "MuJoCo"));
            jobs.push(("urdf_check.py", name.clone(), vec![urdf], "Pinocchio"));
        } else {
            crate::cli::write_atomic(&mjcf, &crate::commands::export::spatial::mjcf(&model))?;
            jobs.push((
                "mujoco_spatial_check.py",
                name.clone(),
                vec![mjcf.clone()],
                "MuJoCo",
            ));
            let urdf = dir.join(format!("{name}.urdf"));
            crate::cli::write_atomic(&urdf, &crate::commands::export::spatial::urdf(&model))?;
            let mut files = vec![urdf.clone()];
            if model
                .links
                .iter()
                .any(|l| l.spec_kind == crate::gen::spec::JointKind::Free)
            {
                // The body as the root link too, for Pinocchio's own free joint.
                let floating = dir.join(format!("{name}.floating.urdf"));
                let text = crate::commands::export::spatial::urdf_floating(&model);
                crate::cli::write_atomic(&floating, &text)?;
                files.push(floating);
                // Standing under the balance QP and pushed, ours beside MuJoCo on the
                // export (the same controller closing both loops).
                let runs = target.join("mujoco-push").join(name);
                jobs.push((
                    "mujoco_push.py",
                    name.clone(),
                    vec![mjcf, runs],
                    "the MuJoCo push run",
                ));
            }
            jobs.push(("urdf_check.py", name.clone(), files, "Pinocchio"));
            if let Some(a) = crate::commands::import::header_args(root, &spec.text) {
                // A source in the repository that is missing fails its check below.
                if a.file.exists() || !crate::commands::import::outside_repository(root, &a.file) {
                    let file = a.file.clone();
                    jobs.push((
                        "mujoco_spatial_check.py",
                        name.clone(),
                        vec![file],
                        "MuJoCo",
                    ));
                    if model
                        .links
                        .iter()
                        .any(|l| l.spec_kind == crate::gen::spec::JointKind::Free)
                    {
                        // The loop-gap run holds the base and runs `legs sim`, which a
                        // floating robot does not take yet.
                        eprintln!("note: `{name}` floats: its loop-gap run beside MuJoCo's comes with `sim` for robots");
                        continue;
                    }
                    let runs = target.join("loop-gaps").join(name);
                    let files = vec![a.file, urdf, runs];
                    jobs.push(("loop_gaps.py", name.clone(), files, "the loop-gap run"));
                } else {
                    // Menagerie's `cassie.xml` is not ours to commit; it is checked where
                    // it lies beside the clone (docs/testing.md says how to get it).
                    eprintln!(
                        "note: `{name}` not checked against its source: {} is not here",
                        a.file.display()
                    );
                }
            }
        }
    }
    let mut failed = Vec::new();
    for (script, name, files, tool) in jobs {
        let status = Command::new(&py)
            .arg(root.join("xtask").join(script))
            .arg(&legs)
            .arg(&name)
            .args(&files)
            .current_dir(root)
            .status()
            .map_err(|e| format!("cannot run {script}: {e}"))?;
        if !status.success() {
            failed.push(format!(
                "{tool} disagrees with `{name}` on {} (see above)",
                files[0].display()
            ));
        }
    }
    Ok(failed)
}

/// Builds and installs the Python package into the project's environment (the README's
/// `pip install ./python`, maturin from source), then runs its pytest suite against the
/// `legs` binary the cross-checks built.
fn python_package(root: &Path) -> Result<(), String> {
    eprintln!("==> Python package: pip install ./python, then pytest python/tests");
    let py = gen::python(root)?;
    let run = |args: &[&str], shown: &str| -> Result<(), String> {
        let status = Command::new(&py)
            .args(args)
            .env("LEGS_BINARY", target_dir(root).join("debug").join("legs"))
            .current_dir(root)
            .status()
            .map_err(|e| format!("cannot run `{shown}`: {e}"))?;
        if status.success() {
            Ok(())
        } else {
            Err(format!("`{shown}` failed ({status})"))
        }
    };
    run(
        &[
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "./python",
        ],
        ".venv/bin/python -m pip install ./python",
    )?;
    run(
        &["-m", "pytest", "-q", "python/tests"],
        ".venv/bin/python -m pytest python/tests",
    )
}

/// The user's crate of the README (tests/user-crate): its generated module is fresh and
/// its program, which checks its own leg, runs.
fn user_crate(root: &Path) -> Result<(), String> {
    eprintln!("==> a user's crate (tests/user-crate): gen --spec --check, then cargo run");
    gen::standalone(
        root,
        &root.join("tests/user-crate/specs/parallelogram_knee.toml"),
        &root.join("tests/user-crate/src/parallelogram_knee.rs"),
        true,
    )
    .map_err(|e| e.to_string())?;
    let target = target_dir(root).join("user-crate");
    cargo(
        root,
        &[
            "run",
            "--quiet",
            "--manifest-path",
            "tests/user-crate/Cargo.toml",
        ],
        &[(
            "CARGO_TARGET_DIR",
            target.to_str().unwrap_or("target/user-crate"),
        )],
    )
}

pub fn run(root: &Path) -> Result<(), String> {
    let mut failures: Vec<String> = Vec::new();
    let mut check = |what: &str, r: Result<(), String>| {
        if let Err(e) = r {
            eprintln!("FAILED: {what}: {e}");
            failures.push(format!("{what}: {e}"));
        }
    };
    check(
        "formatting",
        cargo(root, &["fmt", "--all", "--check"], &[])
            .map_err(|e| format!("{e}: run `cargo fmt --all`")),
    );
    eprintln!("==> cargo xtask gen --check");
    check(
        "gen --check",
        gen::run(
            root,
            &GenOptions {
                check: true,
                names: Vec::new(),
            },
        )
        .map(|report| eprintln!("{report}"))
        .map_err(|e| e.to_string()),
    );
    // Which checks did not apply to which leg, and why: written by the tests.
    let applicability = target_dir(root).join("not-applicable.txt");
    let _ = std::fs::remove_file(&applicability);
    // Snapshots must match as committed: insta neither writes nor accepts here.
    check(
        "workspace tests",
        cargo(
            root,
            &["test", "--workspace", "--all-features", "--no-fail-fast"],
            &[("INSTA_UPDATE", "no"), ("CI", "true")],
        ),
    );
    let pending = pending_snapshots(root);
    if !pending.is_empty() {
        check(
            "snapshots",
            Err(format!(
                "unreviewed snapshots: {}\nrun `cargo insta review`",
                pending.join(", ")
            )),
        );
    }
    match cross_checks(root) {
        Ok(failed) => failed
            .into_iter()
            .for_each(|f| check("cross-check", Err(f))),
        Err(e) => check("cross-checks", Err(e)),
    }
    check("Python package", python_package(root));
    check("user crate", user_crate(root));
    eprintln!("==> docs (cargo doc of the whole workspace, warnings denied; relative links)");
    check(
        "docs",
        cargo(
            root,
            &["doc", "--workspace", "--no-deps", "--all-features"],
            &[("RUSTDOCFLAGS", "-D warnings")],
        ),
    );
    check(
        "links",
        crate::dev::links::check_links(root)
            .map(|n| eprintln!("{n} relative links in README.md and docs/ resolve")),
    );
    eprintln!("==> instruction budgets ({})", crate::dev::bench::BUDGETS);
    check(
        "instruction budgets",
        crate::dev::bench::check_budgets(root, false).map(|r| eprintln!("{r}")),
    );
    check(
        "no_std build",
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
        .map_err(|e| format!("{e}: the runtime and the generated models must build without std")),
    );
    check(
        "clippy",
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
        ),
    );
    if let Ok(text) = std::fs::read_to_string(&applicability) {
        let mut lines: Vec<&str> = text.lines().collect();
        lines.sort_unstable();
        lines.dedup();
        eprintln!(
            "checks that do not apply to a leg (by its structure):\n  {}",
            lines.join("\n  ")
        );
    }
    if failures.is_empty() {
        eprintln!("all checks passed");
        Ok(())
    } else {
        Err(format!(
            "{} check(s) failed:\n  {}",
            failures.len(),
            failures.join("\n  ")
        ))
    }
}
