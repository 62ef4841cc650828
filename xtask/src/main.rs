//! `cargo xtask`: the project's command line.
//!
//! Commands that need the generated models (`sim`, `eval`) run the `legs` binary of
//! this package, built with the `models` feature: the generator itself never links the
//! code it generates, so it can always regenerate it.

use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use xtask::cli::args::{self, Command};
use xtask::gen::{self, GenOptions};
use xtask::{cli, commands, dev};

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
        Command::Test => dev::test::run(&root).map_err(cli::Error::Failed),
        Command::List => commands::list::run(&root),
        Command::New(a) => commands::new::run(&root, &a.name, a.spatial),
        Command::Import(a) => commands::import::run(&root, a),
        Command::Export(a) => commands::export::run(&root, a),
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
    let known = gen::model_names(root).map_err(cli::Error::Failed)?;
    for n in &a.names {
        gen::check_model(n, &known)?;
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
            xtask::dev::bench::check_budgets(root, a.update_budgets).map_err(cli::Error::Failed)?;
        println!("{report}");
        if a.instructions {
            let table =
                xtask::dev::bench::compare_instructions(root).map_err(cli::Error::Failed)?;
            println!("\n{table}");
        }
        return Ok(());
    }
    xtask::dev::bench::run(root, a.pinocchio, a.mujoco, &a.models).map_err(cli::Error::Failed)
}

/// Builds `legs` (this package's binary with the generated models) and runs it with the
/// same arguments. The build shows cargo's progress (the first one compiles every generated
/// model, minutes on a fresh clone), and says why it is building before it starts.
fn delegate(root: &Path, args: &[String]) -> ExitCode {
    const LEGS: [&str; 6] = [
        "--package",
        "xtask",
        "--features",
        "models",
        "--bin",
        "legs",
    ];
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // Said before cargo starts when the build will take a while: no binary yet, or
    // generated code newer than it (a leg added or regenerated recompiles every model).
    let binary = cli::target_dir(root).join("debug").join("legs");
    let built_at = std::fs::metadata(&binary).and_then(|m| m.modified()).ok();
    let generated_at = std::fs::read_dir(root.join(gen::SRC_DIR))
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok()?.metadata().ok()?.modified().ok())
        .max();
    if built_at.is_none() || generated_at > built_at {
        eprintln!(
            "building `legs`, the commands that run the generated models (`{}`): it compiles every generated model, 3 minutes or so on 2 cores…",
            args[0]
        );
    }
    let started = Instant::now();
    let built = match std::process::Command::new(&cargo)
        .arg("build")
        .args(LEGS)
        .current_dir(root)
        .status()
    {
        Ok(s) => s,
        Err(e) => return cli::Error::Failed(format!("cannot run cargo: {e}")).report(),
    };
    if !built.success() {
        return cli::Error::Failed(format!("building `legs` failed ({built})")).report();
    }
    if started.elapsed() >= Duration::from_secs(5) {
        eprintln!("built in {:.0} s", started.elapsed().as_secs_f64());
    }
    // Cargo finds the binary it just built (wherever the target directory is) and does
    // not build again.
    match std::process::Command::new(cargo)
        .args(["run", "--quiet"])
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
