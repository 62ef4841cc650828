//! `legs`: the commands of `cargo xtask` that run the generated models (`sim`, `eval`).
//! `cargo xtask sim …` and `cargo xtask eval …` build and run it.

use std::process::ExitCode;

use xtask::args::{self, Command, EvalArgs, Parsed, SimArgs, Xtask};
use xtask::cli::Error;

mod eval;
mod hop_sim;
mod report;
mod sim;

/// The generated models' names.
fn models() -> Vec<&'static str> {
    let mut names = Vec::new();
    macro_rules! name {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            names.push(stringify!($module));
        };
    }
    generated::for_each_model!(name);
    names
}

fn unknown(name: &str) -> Error {
    let spec = xtask::gen::workspace_root()
        .join(xtask::gen::SPECS_DIR)
        .join(format!("{name}.toml"));
    if xtask::spec::check_name(name).is_ok() && spec.exists() {
        return Error::usage(format!(
            "`{name}` has a spec but no generated code yet: run `cargo xtask gen {name}`"
        ));
    }
    Error::usage(format!(
        "unknown model `{}` (expected one of: {})",
        xtask::spec::shown(name),
        models().join(", ")
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
    Err(unknown(&args.model))
}

fn simulate(args: SimArgs) -> Result<(), Error> {
    let name = args.model.clone().unwrap_or_else(|| "minitaur".to_string());
    let settings = sim::Settings::from_args(&args)?;
    macro_rules! dispatch {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            if name == stringify!($module) {
                // A leg with contacts runs on the ground.
                if $nk > 0 {
                    return hop_sim::run::<$ty, $nq, $nc, $nu, $nk>(&settings);
                }
                return sim::run::<$ty, $nq, $nc, $nu>(&settings);
            }
        };
    }
    generated::for_each_model!(dispatch);
    Err(unknown(&name))
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
        Ok(Parsed::Run(_)) => Err(Error::usage(
            "`legs` runs `sim` and `eval` only; the other commands are `cargo xtask`'s",
        )),
        Ok(Parsed::Printed) => Ok(()),
        Err(e) => Err(e),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => e.report(),
    }
}
