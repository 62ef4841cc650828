//! `legs`: the commands of `cargo xtask` that run the generated models (`sim`, `eval`).
//! `cargo xtask sim …` and `cargo xtask eval …` build and run it.

use std::process::ExitCode;

use xtask::cli::{Error, Flags};

mod eval;
mod report;
mod sim;

/// The generated models' names.
fn models() -> Vec<&'static str> {
    let mut names = Vec::new();
    macro_rules! name {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal) => {
            names.push(stringify!($module));
        };
    }
    generated::for_each_model!(name);
    names
}

fn unknown(name: &str) -> Error {
    Error::usage(format!(
        "unknown model `{name}` (expected one of: {})",
        models().join(", ")
    ))
}

fn eval(mut flags: Flags) -> Result<(), Error> {
    let name = flags
        .positionals
        .first()
        .cloned()
        .ok_or_else(|| Error::usage("expected a model name (see `cargo xtask eval --help`)"))?;
    flags.positionals.remove(0);
    macro_rules! dispatch {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal) => {
            if name == stringify!($module) {
                return eval::run::<$ty, $nq, $nc, $nu>(flags);
            }
        };
    }
    generated::for_each_model!(dispatch);
    Err(unknown(&name))
}

fn simulate(mut flags: Flags) -> Result<(), Error> {
    let name = match flags.positionals.len() {
        0 => "minitaur".to_string(),
        1 => flags.positionals.remove(0),
        _ => {
            return Err(Error::usage(format!(
                "expected at most one model, got: {}",
                flags.positionals.join(" ")
            )))
        }
    };
    let settings = sim::Settings::from_flags(&mut flags)?;
    macro_rules! dispatch {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal) => {
            if name == stringify!($module) {
                return sim::run::<$ty, $nq, $nc, $nu>(&settings);
            }
        };
    }
    generated::for_each_model!(dispatch);
    Err(unknown(&name))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("eval") if args[1..].iter().any(|a| a == "-h" || a == "--help") => {
            print!("{}", eval::HELP);
            Ok(())
        }
        Some("sim") if args[1..].iter().any(|a| a == "-h" || a == "--help") => {
            print!("{}", sim::HELP);
            Ok(())
        }
        Some("eval") => Flags::parse(
            &args[1..],
            &["--q", "--qd", "--u", "--guess"],
            &["--json", "--assemble"],
        )
        .and_then(eval),
        Some("sim") => Flags::parse(&args[1..], sim::VALUE_FLAGS, &[]).and_then(simulate),
        _ => Err(Error::usage(
            "usage: legs sim|eval … (run through `cargo xtask sim` or `cargo xtask eval`)",
        )),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => e.report(),
    }
}
