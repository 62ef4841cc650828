//! `cargo xtask`: the project's command line.
//!
//! Commands that need the generated models (`sim`, `eval`) run the `legs` binary of
//! this package, built with the `models` feature: the generator itself never links the
//! code it generates, so it can always regenerate it.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use xtask::gen::{self, GenOptions};
use xtask::{cli, export, model, spec};

mod test;

const USAGE: &str = "\
usage: cargo xtask <command> [options]

commands:
  gen [--check] [NAME…]      derive the models (CasADi) and write generated/; with --check,
                             regenerate in memory and fail if the committed files differ
  sim [MODEL] [options]      simulate a leg under a controller and write a report
                             (cargo xtask sim --help)
  eval MODEL --q … [options] print every term at a state (cargo xtask eval --help)
  export MODEL --format mjcf|urdf [--out FILE]
                             the leg for MuJoCo (closures as <connect>) or URDF (spanning
                             tree, closure frames NAME_a / NAME_b)
  bench [--pinocchio]        criterion benchmarks beside CasADi's C (and Pinocchio), one table
  bench --instructions       instructions per call of the hot paths (callgrind) vs budgets
  bench --update-budgets     rewrite tests/instruction-budgets.json with today's counts
  list                       the geometries, their sizes and actuated joints
  new NAME                   write leg-models/specs/NAME.toml, a commented spec to start from
  test                       every check CI runs: formatting, `gen --check`, the workspace
                             tests (snapshots must be reviewed), the MuJoCo cross-check,
                             the no_std build, clippy
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let root = gen::workspace_root();
    let result = match args.first().map(String::as_str) {
        Some("gen") => run_gen(&root, &args[1..]),
        Some("test") => match args.get(1) {
            Some(extra) => Err(cli::Error::usage(format!(
                "`test` takes no arguments, got `{extra}`"
            ))),
            None => test::run(&root).map_err(cli::Error::Failed),
        },
        Some("list") => match args.get(1) {
            Some(extra) => Err(cli::Error::usage(format!(
                "`list` takes no arguments, got `{extra}`"
            ))),
            None => list(&root),
        },
        Some("new") => new(&root, &args[1..]),
        Some("export") => run_export(&root, &args[1..]),
        Some("bench") => run_bench(&root, &args[1..]),
        Some(cmd @ ("sim" | "eval")) => return delegate(&root, cmd, &args[1..]),
        Some("-h" | "--help" | "help") => {
            print!("{USAGE}");
            Ok(())
        }
        Some(other) => Err(cli::Error::usage(format!("unknown command `{other}`"))),
        None => Err(cli::Error::usage(
            "no command given (try `cargo xtask --help`)",
        )),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => e.report(),
    }
}

fn run_gen(root: &Path, args: &[String]) -> Result<(), cli::Error> {
    let mut opts = GenOptions {
        check: false,
        names: Vec::new(),
    };
    for a in args {
        match a.as_str() {
            "--check" => opts.check = true,
            "-h" | "--help" => {
                print!("{USAGE}");
                return Ok(());
            }
            flag if flag.starts_with('-') => {
                return Err(cli::Error::usage(format!(
                    "unknown flag `{flag}` for `gen` (expected --check)"
                )))
            }
            name => opts.names.push(name.to_string()),
        }
    }
    let known = cli::model_names(root).map_err(cli::Error::Failed)?;
    for n in &opts.names {
        cli::check_model(n, &known)?;
    }
    println!("{}", gen::run(root, &opts).map_err(cli::Error::Failed)?);
    Ok(())
}

fn run_bench(root: &Path, args: &[String]) -> Result<(), cli::Error> {
    let flags = cli::Flags::parse(
        args,
        &[],
        &["--pinocchio", "--instructions", "--update-budgets"],
    )?;
    if let Some(extra) = flags.positionals.first() {
        return Err(cli::Error::usage(format!(
            "`bench` takes no model, got `{extra}`"
        )));
    }
    if flags.switch("--instructions") || flags.switch("--update-budgets") {
        let report = xtask::bench::check_budgets(root, flags.switch("--update-budgets"))
            .map_err(cli::Error::Failed)?;
        println!("{report}");
        if flags.switch("--instructions") {
            let table = xtask::bench::compare_instructions(root).map_err(cli::Error::Failed)?;
            println!("\n{table}");
        }
        return Ok(());
    }
    xtask::bench::run(root, flags.switch("--pinocchio")).map_err(cli::Error::Failed)
}

fn load_model(root: &Path, name: &str) -> Result<model::Model, cli::Error> {
    let known = cli::model_names(root).map_err(cli::Error::Failed)?;
    cli::check_model(name, &known)?;
    let path = root.join(gen::SPECS_DIR).join(format!("{name}.toml"));
    let spec = gen::load_spec(root, &path).map_err(cli::Error::Failed)?;
    model::build(&spec).map_err(|e| cli::Error::Failed(e.to_string()))
}

fn run_export(root: &Path, args: &[String]) -> Result<(), cli::Error> {
    let mut flags = cli::Flags::parse(args, &["--format", "--out"], &[])?;
    let name = flags.single_positional("a model name")?;
    let format = flags
        .take("--format")
        .ok_or_else(|| cli::Error::usage("`--format mjcf|urdf` is required"))?;
    let m = load_model(root, &name)?;
    let text = match format.as_str() {
        "mjcf" => export::mjcf(&m),
        "urdf" => export::urdf(&m),
        other => {
            return Err(cli::Error::usage(format!(
                "unknown format `{other}` (expected mjcf or urdf)"
            )))
        }
    };
    match flags.take("--out") {
        Some(out) => {
            cli::write_atomic(Path::new(&out), &text).map_err(cli::Error::Failed)?;
            eprintln!("wrote {out}");
        }
        None => print!("{text}"),
    }
    Ok(())
}

fn list(root: &Path) -> Result<(), cli::Error> {
    // Mobility and redundant rows come from the derivation (the committed IR).
    let irs = gen::committed_irs(root).map_err(cli::Error::Failed)?;
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
    for (path, ir) in gen::spec_paths(root)
        .map_err(cli::Error::Failed)?
        .iter()
        .zip(&irs)
    {
        let spec = gen::load_spec(root, path).map_err(cli::Error::Failed)?;
        let m = model::build(&spec).map_err(|e| cli::Error::Failed(e.to_string()))?;
        let actuated: Vec<&str> = m
            .actuated
            .iter()
            .map(|&a| m.links[a].name.as_str())
            .collect();
        let redundant = match ir.model.redundant_rows.len() {
            0 => String::new(),
            n => format!(" ({n} redundant)"),
        };
        rows.push([
            m.name.clone(),
            m.links.len().to_string(),
            format!("{}{redundant}", 2 * m.closures.len()),
            m.actuated.len().to_string(),
            ir.model.mobility.to_string(),
            gen::actuation_note(ir.model.mobility, m.actuated.len()).to_string(),
            actuated.join(", "),
            spec.path.display().to_string(),
        ]);
    }
    let widths: Vec<usize> = (0..8)
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    for r in &rows {
        let cells: Vec<String> = r
            .iter()
            .zip(&widths)
            .enumerate()
            .map(|(c, (cell, &w))| {
                if (1..=4).contains(&c) {
                    format!("{cell:>w$}")
                } else {
                    format!("{cell:<w$}")
                }
            })
            .collect();
        println!("{}", cells.join("  ").trim_end());
    }
    Ok(())
}

const NEW_SPEC: &str = include_str!("new_spec.toml");

fn new(root: &Path, args: &[String]) -> Result<(), cli::Error> {
    let [name] = args else {
        return Err(cli::Error::usage(
            "`new` takes one name, e.g. `cargo xtask new my_leg`",
        ));
    };
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

/// Runs `legs` (this package's binary with the generated models) with the same arguments.
fn delegate(root: &Path, cmd: &str, args: &[String]) -> ExitCode {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .args([
            "run",
            "--quiet",
            "--package",
            "xtask",
            "--features",
            "models",
            "--bin",
            "legs",
            "--",
        ])
        .arg(cmd)
        .args(args)
        .current_dir(root)
        .status();
    match status {
        Ok(s) => ExitCode::from(s.code().unwrap_or(1).clamp(0, 255) as u8),
        Err(e) => cli::Error::Failed(format!("cannot run cargo: {e}")).report(),
    }
}
