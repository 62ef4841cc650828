//! `cargo xtask`: the project's command line.

use std::process::ExitCode;

use xtask::gen::{self, GenOptions};

mod test;

const USAGE: &str = "\
usage: cargo xtask <command>

commands:
  gen [--check] [NAME…]   derive the models (CasADi) and write generated/; with --check,
                          regenerate in memory and fail if the committed files differ
  test                    every check CI runs: formatting, `gen --check`, the workspace
                          tests (snapshots must be reviewed), the no_std build, clippy
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage_error = |msg: String| {
        eprintln!("error: {msg}\n\n{USAGE}");
        ExitCode::from(2)
    };
    match args.first().map(String::as_str) {
        Some("gen") => {
            let mut opts = GenOptions {
                check: false,
                names: Vec::new(),
            };
            for a in &args[1..] {
                match a.as_str() {
                    "--check" => opts.check = true,
                    "-h" | "--help" => {
                        print!("{USAGE}");
                        return ExitCode::SUCCESS;
                    }
                    flag if flag.starts_with('-') => {
                        return usage_error(format!("unknown flag `{flag}` for `gen`"))
                    }
                    name => opts.names.push(name.to_string()),
                }
            }
            match gen::run(&gen::workspace_root(), &opts) {
                Ok(report) => {
                    println!("{report}");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Some("test") => {
            if let Some(extra) = args.get(1) {
                return usage_error(format!("`test` takes no arguments, got `{extra}`"));
            }
            match test::run(&gen::workspace_root()) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Some("-h" | "--help" | "help") => {
            print!("{USAGE}");
            ExitCode::SUCCESS
        }
        Some(other) => usage_error(format!("unknown command `{other}`")),
        None => usage_error("no command given".into()),
    }
}
