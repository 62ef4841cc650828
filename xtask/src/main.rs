//! `cargo xtask`: the project's command line.
//!
//! Commands that need the generated models (`sim`, `eval`) run the `legs` binary of
//! this package, built with the `models` feature: the generator itself never links the
//! code it generates, so it can always regenerate it.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use xtask::args::{self, Command, ExportFormat};
use xtask::gen::{self, GenOptions};
use xtask::{cli, export, model, spec};

mod test;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let root = gen::workspace_root();
    let parsed = match args::parse::<args::Xtask>(&args) {
        Ok(args::Parsed::Run(a)) => a,
        Ok(args::Parsed::Printed) => return ExitCode::SUCCESS,
        Err(e) => return e.report(),
    };
    let result = match parsed.command {
        Command::Gen(a) => run_gen(&root, a),
        Command::Test => test::run(&root).map_err(cli::Error::Failed),
        Command::List => list(&root),
        Command::New(a) => new(&root, &a.name),
        Command::Export(a) => run_export(&root, a),
        Command::Bench(a) => run_bench(&root, a),
        // Parsed here so that bad input is refused at once; `legs` parses them again.
        Command::Sim(_) | Command::Eval(_) | Command::Analyze(_) => return delegate(&root, &args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => e.report(),
    }
}

fn run_gen(root: &Path, a: args::GenArgs) -> Result<(), cli::Error> {
    if let (Some(spec), Some(out)) = (&a.spec, &a.out) {
        println!("{}", gen::standalone(root, spec, out, a.check)?);
        return Ok(());
    }
    let known = cli::model_names(root).map_err(cli::Error::Failed)?;
    for n in &a.names {
        cli::check_model(n, &known)?;
    }
    let opts = GenOptions {
        check: a.check,
        names: a.names,
    };
    println!("{}", gen::run(root, &opts)?);
    Ok(())
}

fn run_bench(root: &Path, a: args::BenchArgs) -> Result<(), cli::Error> {
    if a.instructions || a.update_budgets {
        let report =
            xtask::bench::check_budgets(root, a.update_budgets).map_err(cli::Error::Failed)?;
        println!("{report}");
        if a.instructions {
            let table = xtask::bench::compare_instructions(root).map_err(cli::Error::Failed)?;
            println!("\n{table}");
        }
        return Ok(());
    }
    xtask::bench::run(root, a.pinocchio).map_err(cli::Error::Failed)
}

fn load_model(root: &Path, name: &str) -> Result<model::Model, cli::Error> {
    let known = cli::model_names(root).map_err(cli::Error::Failed)?;
    cli::check_model(name, &known)?;
    let path = root.join(gen::SPECS_DIR).join(format!("{name}.toml"));
    // A spec that does not load is bad input, as in `gen`.
    let spec = gen::load_spec(root, &path).map_err(cli::Error::Usage)?;
    model::build(&spec).map_err(|e| cli::Error::Usage(e.to_string()))
}

fn run_export(root: &Path, a: args::ExportArgs) -> Result<(), cli::Error> {
    let m = load_model(root, &a.model)?;
    let text = match a.format {
        ExportFormat::Mjcf => export::mjcf(&m),
        ExportFormat::Urdf => export::urdf(&m),
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

fn list(root: &Path) -> Result<(), cli::Error> {
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
    print!("{}", cli::text_table(&rows, |c| (1..=4).contains(&c)));
    Ok(())
}

const NEW_SPEC: &str = include_str!("new_spec.toml");

fn new(root: &Path, name: &str) -> Result<(), cli::Error> {
    spec::check_name(name).map_err(|m| cli::Error::usage(format!("model name: {m}")))?;
    let path: PathBuf = root.join(gen::SPECS_DIR).join(format!("{name}.toml"));
    if path.exists() {
        return Err(cli::Error::usage(format!(
            "{} exists already",
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

/// Builds `legs` (this package's binary with the generated models) and runs it with the
/// same arguments. The build is quiet (cargo's progress would bury the command's output)
/// and the first one takes minutes, so a build that is still going after a second says so.
fn delegate(root: &Path, args: &[String]) -> ExitCode {
    const LEGS: [&str; 7] = [
        "--quiet",
        "--package",
        "xtask",
        "--features",
        "models",
        "--bin",
        "legs",
    ];
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let build = std::process::Command::new(&cargo)
        .arg("build")
        .args(LEGS)
        .current_dir(root)
        .spawn();
    let mut child = match build {
        Ok(c) => c,
        Err(e) => return cli::Error::Failed(format!("cannot run cargo: {e}")).report(),
    };
    let started = Instant::now();
    let mut said = false;
    let built = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) => {
                if !said && started.elapsed() >= Duration::from_secs(1) {
                    eprintln!(
                        "building the generated models for `{}` (a first build takes a few minutes)…",
                        args[0]
                    );
                    said = true;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(e) => return cli::Error::Failed(format!("cargo build: {e}")).report(),
        }
    };
    if !built.success() {
        return cli::Error::Failed(format!("building `legs` failed ({built})")).report();
    }
    if said {
        eprintln!("built in {:.0} s", started.elapsed().as_secs_f64());
    }
    // Cargo finds the binary it just built (wherever the target directory is) and does
    // not build again.
    match std::process::Command::new(cargo)
        .arg("run")
        .args(LEGS)
        .arg("--")
        .args(args)
        .current_dir(root)
        .status()
    {
        Ok(s) => ExitCode::from(s.code().unwrap_or(1).clamp(0, 255) as u8),
        Err(e) => cli::Error::Failed(format!("cannot run cargo: {e}")).report(),
    }
}
