//! What the command-line tools share: errors with their exit codes, flag parsing,
//! model names, and writing files so that a failure leaves no partial output.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// A command that failed: bad input (exit code 2) or a failure while working (exit 1).
#[derive(Debug)]
pub enum Error {
    Usage(String),
    Failed(String),
}

impl Error {
    pub fn usage(msg: impl Into<String>) -> Error {
        Error::Usage(msg.into())
    }

    /// Prints the one-line error and gives the exit code.
    pub fn report(&self) -> ExitCode {
        match self {
            Error::Usage(m) => {
                eprintln!("error: {m}");
                ExitCode::from(2)
            }
            Error::Failed(m) => {
                eprintln!("error: {m}");
                ExitCode::FAILURE
            }
        }
    }
}

/// The models there are specs for.
pub fn model_names(root: &Path) -> Result<Vec<String>, String> {
    Ok(crate::gen::spec_paths(root)?
        .iter()
        .filter_map(|p| p.file_stem().and_then(|s| s.to_str()).map(String::from))
        .collect())
}

pub fn check_model(name: &str, known: &[String]) -> Result<(), Error> {
    if known.iter().any(|k| k == name) {
        Ok(())
    } else {
        Err(Error::usage(format!(
            "unknown model `{name}` (expected one of: {})",
            known.join(", ")
        )))
    }
}

/// Parsed arguments: `--flag value` options, boolean `--switch`es, and positionals.
pub struct Flags {
    values: Vec<(String, String)>,
    switches: Vec<String>,
    pub positionals: Vec<String>,
}

impl Flags {
    /// Refuses flags not in `with_value` or `switches`, a missing value, and a repeated
    /// flag.
    pub fn parse(args: &[String], with_value: &[&str], switches: &[&str]) -> Result<Flags, Error> {
        let mut f = Flags {
            values: Vec::new(),
            switches: Vec::new(),
            positionals: Vec::new(),
        };
        let mut it = args.iter();
        while let Some(a) = it.next() {
            if with_value.contains(&a.as_str()) {
                let v = it
                    .next()
                    .filter(|v| !v.starts_with("--"))
                    .ok_or_else(|| Error::usage(format!("`{a}` needs a value")))?;
                if f.values.iter().any(|(k, _)| k == a) {
                    return Err(Error::usage(format!("`{a}` given twice")));
                }
                f.values.push((a.clone(), v.clone()));
            } else if switches.contains(&a.as_str()) {
                f.switches.push(a.clone());
            } else if a.starts_with('-') && a.parse::<f64>().is_err() {
                let mut known: Vec<&str> = with_value.iter().chain(switches).copied().collect();
                known.sort_unstable();
                return Err(Error::usage(format!(
                    "unknown flag `{a}` (expected one of: {})",
                    known.join(", ")
                )));
            } else {
                f.positionals.push(a.clone());
            }
        }
        Ok(f)
    }

    pub fn take(&mut self, flag: &str) -> Option<String> {
        let i = self.values.iter().position(|(k, _)| k == flag)?;
        Some(self.values.remove(i).1)
    }

    pub fn switch(&self, flag: &str) -> bool {
        self.switches.iter().any(|s| s == flag)
    }

    /// The one positional argument, described as `what` in errors.
    pub fn single_positional(&mut self, what: &str) -> Result<String, Error> {
        match self.positionals.len() {
            1 => Ok(self.positionals.remove(0)),
            0 => Err(Error::usage(format!("expected {what}"))),
            _ => Err(Error::usage(format!(
                "expected {what} only, got: {}",
                self.positionals.join(" ")
            ))),
        }
    }

    /// A number: `flag` must parse as a finite float, `ok` says what else it must be.
    pub fn number(
        &mut self,
        flag: &str,
        default: f64,
        ok: (&str, fn(f64) -> bool),
    ) -> Result<f64, Error> {
        match self.take(flag) {
            None => Ok(default),
            Some(v) => match v.parse::<f64>() {
                Ok(x) if x.is_finite() && (ok.1)(x) => Ok(x),
                _ => Err(Error::usage(format!("`{flag} {v}`: expected {}", ok.0))),
            },
        }
    }
}

/// A comma-separated list of exactly `n` numbers (`--q 0.1,-1.2,…`).
pub fn numbers(flag: &str, text: &str, n: usize, what: &str) -> Result<Vec<f64>, Error> {
    let parts: Vec<&str> = text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect();
    let values: Result<Vec<f64>, _> = parts.iter().map(|p| p.parse::<f64>()).collect();
    match values {
        Ok(v) if v.len() == n && v.iter().all(|x| x.is_finite()) => Ok(v),
        Ok(v) if v.iter().all(|x| x.is_finite()) => Err(Error::usage(format!(
            "`{flag}` has {} values, expected {n} ({what})",
            v.len()
        ))),
        _ => Err(Error::usage(format!(
            "`{flag} {text}`: expected {n} comma-separated numbers ({what})"
        ))),
    }
}

/// Writes through a temporary file and a rename: a reader never sees half a file, and a
/// failure leaves nothing behind.
pub fn write_atomic(path: &Path, text: &str) -> Result<(), String> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let tmp = dir.join(format!(
        ".{}.tmp",
        path.file_name().and_then(|n| n.to_str()).unwrap_or("out")
    ));
    std::fs::write(&tmp, text).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        format!("{}: {e}", path.display())
    })?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        format!("{}: {e}", path.display())
    })
}

/// Cargo's target directory.
pub fn target_dir(root: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root.join("target"), PathBuf::from)
}

/// Runs `cargo ARGS` in the workspace (the same cargo that runs xtask), with extra
/// environment variables, saying what it runs.
pub fn cargo(root: &Path, args: &[&str], env: &[(&str, &str)]) -> Result<(), String> {
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
