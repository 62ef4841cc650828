//! Errors with their exit codes, lists of numbers, text tables, writing files so that a
//! failure leaves no partial output, and running cargo.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// A command that failed: bad input (exit code 2) or a failure while working (exit 1).
#[derive(Debug)]
pub enum Error {
    Usage(String),
    Failed(String),
}

impl std::fmt::Display for Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Error::Usage(m) | Error::Failed(m) => f.write_str(m),
        }
    }
}

impl Error {
    pub fn usage(msg: impl Into<String>) -> Error {
        Error::Usage(msg.into())
    }

    /// Whether the input was at fault (exit code 2).
    pub fn is_usage(&self) -> bool {
        matches!(self, Error::Usage(_))
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

/// A comma-separated list of exactly `n` numbers (`--q 0.1,-1.2,…`).
pub fn numbers(flag: &str, text: &str, n: usize, what: &str) -> Result<Vec<f64>, Error> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let numbers = if n == 1 { "number" } else { "numbers" };
    let shown = shown(text);
    // An empty field (`-1.7,,-0.6`, a trailing comma) was dropped, and the values after
    // it taken for the wrong joints.
    if let Some(k) = parts.iter().position(|p| p.is_empty()) {
        return Err(Error::usage(format!(
            "`{flag} {shown}`: value {} is empty; expected {n} comma-separated {numbers} ({what})",
            k + 1
        )));
    }
    let values: Result<Vec<f64>, _> = parts.iter().map(|p| p.parse::<f64>()).collect();
    match values {
        Ok(v) if v.len() == n && v.iter().all(|x| x.is_finite()) => Ok(v),
        Ok(v) if v.iter().all(|x| x.is_finite()) => Err(Error::usage(format!(
            "`{flag}` has {} {}, expected {n} ({what})",
            v.len(),
            if v.len() == 1 { "value" } else { "values" }
        ))),
        Ok(_) => Err(Error::usage(format!(
            "`{flag} {shown}`: every value must be finite (not NaN or infinite); expected {n} comma-separated {numbers} ({what})"
        ))),
        Err(_) => Err(Error::usage(format!(
            "`{flag} {shown}`: expected {n} comma-separated {numbers} ({what})"
        ))),
    }
}

/// Rows of cells as aligned text columns, two spaces apart, one line a row; the columns
/// for which `right` holds are right-aligned (numbers).
pub fn text_table<R: AsRef<[String]>>(rows: &[R], right: impl Fn(usize) -> bool) -> String {
    let columns = rows.iter().map(|r| r.as_ref().len()).max().unwrap_or(0);
    let widths: Vec<usize> = (0..columns)
        .map(|c| {
            rows.iter()
                .map(|r| r.as_ref().get(c).map_or(0, |s| s.chars().count()))
                .max()
                .unwrap_or(0)
        })
        .collect();
    let mut out = String::new();
    for r in rows {
        let cells: Vec<String> = r
            .as_ref()
            .iter()
            .zip(&widths)
            .enumerate()
            .map(|(c, (cell, &w))| {
                if right(c) {
                    format!("{cell:>w$}")
                } else {
                    format!("{cell:<w$}")
                }
            })
            .collect();
        out.push_str(cells.join("  ").trim_end());
        out.push('\n');
    }
    out
}

/// Writes through a temporary file and a rename: a reader never sees half a file, and a
/// failure leaves nothing behind.
pub fn write_atomic(path: &Path, text: &str) -> Result<(), String> {
    check_target(path)?;
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

/// [`check_targets`] for one file path: its folder can be made and it is not a folder
/// (a path under a file was "File exists (os error 17)").
pub fn check_target(path: &Path) -> Result<(), String> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    match path.file_name().and_then(|n| n.to_str()) {
        Some(name) => check_targets(dir, &[name]),
        None => Err(format!("{}: not a file name", path.display())),
    }
}

/// Checks, before anything is computed or written, that each of `names` can be written in
/// the folder `out`: the folder is a folder (or can be made) and no target is a folder or
/// anything else that is not a plain file. Names the first path in the way.
pub fn check_targets(out: &Path, names: &[&str]) -> Result<(), String> {
    // The nearest existing ancestor must be a folder, or the folder cannot be made.
    let mut up = Some(out);
    while let Some(dir) = up.filter(|d| !d.as_os_str().is_empty()) {
        match std::fs::metadata(dir) {
            Ok(m) if m.is_dir() => break,
            Ok(_) => {
                return Err(format!(
                    "{}: exists and is not a folder (the output folder {} cannot be made there)",
                    dir.display(),
                    out.display()
                ))
            }
            Err(_) => up = dir.parent(),
        }
    }
    for name in names {
        let path = out.join(name);
        if let Ok(m) = std::fs::symlink_metadata(&path) {
            if !m.is_file() {
                return Err(format!(
                    "{}: exists and is not a file (nothing was written; move it or choose another --out)",
                    path.display()
                ));
            }
        }
    }
    Ok(())
}

/// Writes a set of files into the folder `out` whole or not at all: every target is checked
/// first, the files are written into a temporary folder inside `out`, and then moved into
/// place; if a move fails, the files already moved are put back, so a failure leaves the
/// folder as it was (a folder this call made is removed again).
pub fn write_all(out: &Path, files: &[(String, String)]) -> Result<(), String> {
    let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
    check_targets(out, &names)?;
    let made = !out.exists();
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let undo_made = || {
        if made {
            let _ = std::fs::remove_dir_all(out);
        }
    };
    let tmp = out.join(format!(".writing-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    if let Err(e) = std::fs::create_dir(&tmp) {
        undo_made();
        return Err(format!("{}: {e}", tmp.display()));
    }
    let result = (|| {
        for (name, text) in files {
            std::fs::write(tmp.join(name), text)
                .map_err(|e| format!("{}: {e}", out.join(name).display()))?;
        }
        // Move each new file in, keeping the old one aside until all have moved.
        let mut moved: Vec<(&str, bool)> = Vec::new();
        for name in &names {
            let target = out.join(name);
            let old = tmp.join(format!("{name}.old"));
            let had_old = target.exists();
            let step = (|| {
                if had_old {
                    std::fs::rename(&target, &old)?;
                }
                std::fs::rename(tmp.join(name), &target)
            })();
            if let Err(e) = step {
                moved.push((name, had_old));
                for (back, had) in moved.iter().rev() {
                    let target = out.join(back);
                    let old = tmp.join(format!("{back}.old"));
                    if *had {
                        let _ = std::fs::rename(&old, &target);
                    } else {
                        let _ = std::fs::remove_file(&target);
                    }
                }
                return Err(format!("{}: {e}", target.display()));
            }
            moved.push((name, had_old));
        }
        Ok(())
    })();
    let _ = std::fs::remove_dir_all(&tmp);
    if result.is_err() {
        undo_made();
    }
    result
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

/// Builds the `legs` binary (the commands that run the generated models) and gives its
/// path: the cross-checks, the Python tests and the Pinocchio peer run it.
pub fn build_legs(root: &Path) -> Result<PathBuf, String> {
    cargo(
        root,
        &[
            "build",
            "--quiet",
            "-p",
            "xtask",
            "--features",
            "models",
            "--bin",
            "legs",
        ],
        &[],
    )?;
    Ok(target_dir(root).join("debug").join("legs"))
}

/// Text from a spec or the command line as an error shows it: escaped, so that a newline or another control
/// character cannot break the one-line error, and at most 40 characters.
pub fn shown(text: &str) -> String {
    let escaped: String = text.escape_debug().collect();
    if escaped.chars().count() > 40 {
        format!("{}…", escaped.chars().take(40).collect::<String>())
    } else {
        escaped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_under_a_file_is_refused_by_name() {
        let dir = std::env::temp_dir().join(format!("check-target-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("a_file"), "").unwrap();
        // It was "File exists (os error 17)", after the derivation had run.
        let e = check_target(&dir.join("a_file").join("leg.rs")).unwrap_err();
        assert!(e.contains("a_file: exists and is not a folder"), "{e}");
        let e = check_target(&dir).unwrap_err();
        assert!(e.contains("exists and is not a file"), "{e}");
        assert!(check_target(&dir.join("new").join("leg.rs")).is_ok());
        assert!(!dir.join("new").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn an_empty_field_in_a_list_is_named() {
        let e = numbers("--q", "-1.7,,-0.6", 3, "joint values").unwrap_err();
        assert!(
            matches!(&e, Error::Usage(m) if m.contains("value 2 is empty")),
            "{e:?}"
        );
        let e = numbers("--q", "1,2,", 2, "joint values").unwrap_err();
        assert!(
            matches!(&e, Error::Usage(m) if m.contains("value 3 is empty")),
            "{e:?}"
        );
        assert_eq!(
            numbers("--q", " 1, 2 ", 2, "joint values").unwrap(),
            [1.0, 2.0]
        );
    }
}
