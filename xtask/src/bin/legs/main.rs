//! `legs`: the user's commands of `cargo xtask` that run the generated models; `cargo
//! xtask sim|eval|analyze …` build and run it. One room per command:
//!
//! - `sim/`: `settings.rs` (the command line, checked), `mod.rs` (the simulation and its
//!   outputs), `hop.rs` (legs on the ground, under the hopping controller), `ground.rs`
//!   (spatial legs on their ground), `robot.rs` (a floating robot standing under the
//!   balance QP, pushed);
//! - `eval.rs`: every term at one state, as text or JSON;
//! - `analyze/`: `mod.rs` (the measures over the workspace), `design.rs` (what both
//!   outputs read), `report.rs` (its `report.html`);
//! - `report.rs`: `sim`'s `report.html` (the animation, the summary, the plots).
//!
//! May import: the `xtask` library's `cli` and `gen`, `leg-models`, `generated`.

use std::process::ExitCode;

use xtask::cli::args::{self, AnalyzeArgs, Command, EvalArgs, Parsed, SimArgs, Xtask};
use xtask::cli::Error;

mod analyze;
mod eval;
mod report;
mod sim;

/// The generated models' names, planar then spatial.
fn models() -> Vec<&'static str> {
    let mut names = Vec::new();
    macro_rules! planar {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            names.push(stringify!($module));
        };
    }
    generated::for_each_model!(planar);
    macro_rules! name {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            names.push(stringify!($module));
        };
    }
    generated::for_each_spatial_model!(name);
    generated::for_each_floating_model!(name);
    names
}

/// Floating robots' names: `eval` takes them (the terms in the body's chart); the
/// commands built for a leg on a fixed base say so.
fn floating_models() -> Vec<&'static str> {
    let mut names = Vec::new();
    macro_rules! name {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            names.push(stringify!($module));
        };
    }
    generated::for_each_floating_model!(name);
    names
}

/// The refusal of a command that does not take a floating robot yet.
fn not_for_floating(command: &str, name: &str) -> Result<(), Error> {
    if floating_models().contains(&name) {
        return Err(Error::usage(format!(
            "`{name}` is a floating robot (its body is on a free joint): `legs {command}` takes legs on a fixed base; `legs eval {name}` gives its terms in the body's chart, and leg_models::robot steps it"
        )));
    }
    Ok(())
}

/// Why `name` is not one of the models `known` takes.
fn unknown(name: &str, known: &[&str]) -> Error {
    let spec = xtask::gen::workspace_root()
        .join(xtask::gen::SPECS_DIR)
        .join(format!("{name}.toml"));
    if xtask::gen::spec::check_name(name).is_ok() && spec.exists() {
        return Error::usage(format!(
            "`{name}` has a spec but no generated code yet: run `cargo xtask gen {name}`"
        ));
    }
    Error::usage(format!(
        "unknown model `{}` (expected one of: {})",
        xtask::gen::spec::shown(name),
        known.join(", ")
    ))
}

fn eval(args: EvalArgs) -> Result<(), Error> {
    macro_rules! dispatch {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            if args.model == stringify!($module) {
                return eval::run::<$ty, $nq, $nc, $nu, $nk>(&args);
            }
        };
    }
    generated::for_each_model!(dispatch);
    macro_rules! spatial {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            if args.model == stringify!($module) {
                return eval::run_spatial::<$ty, $nq, $nc, $nu, $np, $nk>(&args);
            }
        };
    }
    generated::for_each_spatial_model!(spatial);
    generated::for_each_floating_model!(spatial);
    Err(unknown(&args.model, &models()))
}

fn simulate(args: SimArgs) -> Result<(), Error> {
    let name = args.model.clone().unwrap_or_else(|| "minitaur".to_string());
    let settings = sim::Settings::from_args(&args)?;
    macro_rules! floating {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            if name == stringify!($module) {
                return sim::robot::run::<$ty, $nq, $nc, $nu, $np, $nk>(&settings);
            }
        };
    }
    generated::for_each_floating_model!(floating);
    // A push is a floating robot's; on a leg it would be silently ignored.
    if settings.push.is_some() || settings.push_timed {
        return Err(Error::usage(format!(
            "--push, --push-at and --push-for push a floating robot's body; `{name}` is a leg on a fixed base (floating robots: {})",
            floating_models().join(", ")
        )));
    }
    if settings.feet_given {
        return Err(Error::usage(format!(
            "--feet says how a floating robot's feet meet the ground; `{name}` is a leg on a fixed base (floating robots: {})",
            floating_models().join(", ")
        )));
    }
    macro_rules! dispatch {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            if name == stringify!($module) {
                // A leg with contacts runs on the ground.
                if $nk > 0 {
                    return sim::hop::run::<$ty, $nq, $nc, $nu, $nk>(&settings);
                }
                return sim::run::<$ty, $nq, $nc, $nu, 2, $nc>(&settings);
            }
        };
    }
    generated::for_each_model!(dispatch);
    macro_rules! spatial {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            if name == stringify!($module) {
                // A leg with contacts runs on its ground.
                if $nk > 0 {
                    return sim::ground::run::<$ty, $nq, $nc, $nu, 3, $np, $nk>(&settings, None);
                }
                return sim::run::<$ty, $nq, $nc, $nu, 3, $np>(&settings);
            }
        };
    }
    generated::for_each_spatial_model!(spatial);
    Err(unknown(&name, &models()))
}

fn analyze(args: AnalyzeArgs, raw: &[String]) -> Result<(), Error> {
    let root = xtask::gen::workspace_root();
    let settings = analyze::Settings::from_args(&args, &root)?;
    // Every model is checked before anything is computed.
    let known = models();
    let mut planar = Vec::new();
    macro_rules! planar {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            planar.push(stringify!($module));
        };
    }
    generated::for_each_model!(planar);
    for m in &args.models {
        if !known.contains(&m.as_str()) {
            return Err(unknown(m, &known));
        }
        not_for_floating("analyze", m)?;
        if planar.contains(&m.as_str()) {
            settings.spatial_only(m)?;
        }
    }
    let total = args.models.len() as u64 * settings_designs(&args);
    let progress = std::sync::Mutex::new((
        xtask::cli::progress::Progress::ticking(total, "analysing designs"),
        0u64,
    ));
    let started = std::time::Instant::now();
    let mut designs = Vec::new();
    for name in &args.models {
        macro_rules! dispatch {
            ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
                if name == stringify!($module) {
                    designs.extend(analyze::run::<$ty, $nq, $nc, $nu, 2, $nc>(
                        &settings,
                        &progress,
                        analyze::planar_grid::<$ty, $nq, $nc, $nu>,
                    )?);
                }
            };
        }
        generated::for_each_model!(dispatch);
        macro_rules! spatial {
            ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
                if name == stringify!($module) {
                    designs.extend(analyze::run::<$ty, $nq, $nc, $nu, 3, $np>(
                        &settings,
                        &progress,
                        analyze::spatial_grid::<$ty, $nq, $nc, $nu, $np>,
                    )?);
                }
            };
        }
        generated::for_each_spatial_model!(spatial);
    }
    drop(progress);
    let command = format!("cargo xtask {}", raw.join(" "));
    analyze::write(&settings, &designs, &command)?;
    print!("{}", analyze::table(&designs));
    for d in &designs {
        if let Some(e) = d.json["error"].as_str() {
            println!("{}: {e}", d.label);
        }
        if let Some(why) = d.json["not_computed"].as_object() {
            let mut seen = Vec::new();
            for (key, reason) in why {
                let reason = reason.as_str().unwrap_or_default();
                if !seen.contains(&reason) {
                    seen.push(reason);
                    println!("{}: {key}: {reason}", d.label);
                }
            }
        }
    }
    println!(
        "{} design{} in {:.2} s; wrote analysis.json, the grids' CSVs and report.html to {}",
        designs.len(),
        if designs.len() == 1 { "" } else { "s" },
        started.elapsed().as_secs_f64(),
        settings.out.display()
    );
    Ok(())
}

/// Designs per model: the sweep's count, or one.
fn settings_designs(args: &AnalyzeArgs) -> u64 {
    args.sweep
        .as_deref()
        .and_then(|s| s.rsplit(':').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(1)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args::parse::<Xtask>(&args) {
        Ok(Parsed::Run(Xtask {
            command: Command::Eval(a),
        })) => eval(a),
        Ok(Parsed::Run(Xtask {
            command: Command::Sim(a),
        })) => simulate(a),
        Ok(Parsed::Run(Xtask {
            command: Command::Analyze(a),
        })) => analyze(a, &args),
        Ok(Parsed::Run(_)) => Err(Error::usage(
            "`legs` runs `sim`, `eval` and `analyze` only; the other commands are `cargo xtask`'s",
        )),
        Ok(Parsed::Printed) => Ok(()),
        Err(e) => Err(e),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => e.report(),
    }
}
