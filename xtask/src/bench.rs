//! `cargo xtask bench`: criterion benchmarks of every model beside CasADi's own C code
//! (and Pinocchio when asked), printed as one table of medians and ratios; and the
//! instruction counts (callgrind) of the hot paths, checked against committed budgets.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use serde_json::Value;

use crate::cli::target_dir;
use crate::progress::Progress;

/// The committed instruction budgets: per model, per hot path, instructions per call.
pub const BUDGETS: &str = "tests/instruction-budgets.json";
/// Counted instructions may exceed the budget by this fraction before the check fails
/// (they are repeatable, but differ slightly between compiler versions).
pub const TOLERANCE: f64 = 0.02;
const PATHS: [&str; 2] = ["fused", "forward_dynamics"];
const CALLS: u64 = 10_000;

fn cargo(root: &Path, args: &[&str]) -> Result<(), String> {
    crate::cli::cargo(root, args, &[])
}

/// Instructions of `calls` calls of `path` of `model`, whole program.
fn collected(bin: &Path, model: &str, path: &str, calls: u64) -> Result<u64, String> {
    let out = Command::new("valgrind")
        .args(["--tool=callgrind", "--callgrind-out-file=/dev/null"])
        .arg(bin)
        .args([model, path, &calls.to_string()])
        .output()
        .map_err(|e| {
            format!("cannot run valgrind ({e}); install it (Debian: apt-get install valgrind)")
        })?;
    let text = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        return Err(format!("callgrind of {model} {path} failed:\n{text}"));
    }
    text.lines()
        .find_map(|l| l.split("Collected : ").nth(1))
        .and_then(|n| n.trim().parse().ok())
        .ok_or_else(|| format!("no instruction count in callgrind's output:\n{text}"))
}

/// Instructions per call of every hot path of every model: the difference between
/// `CALLS` calls and none, so start-up does not count.
pub fn instruction_counts(root: &Path) -> Result<BTreeMap<String, BTreeMap<String, u64>>, String> {
    cargo(
        root,
        &[
            "build",
            "--quiet",
            "--release",
            "-p",
            "leg-tests",
            "--example",
            "count_calls",
        ],
    )?;
    let bin = target_dir(root)
        .join("release")
        .join("examples")
        .join("count_calls");
    let mut out = BTreeMap::new();
    let models = crate::cli::model_names(root)?;
    let mut progress = Progress::new(
        (models.len() * PATHS.len()) as u64,
        "counting instructions (callgrind)",
    );
    for model in models {
        let mut per = BTreeMap::new();
        for path in PATHS {
            let base = collected(&bin, &model, path, 0)?;
            let full = collected(&bin, &model, path, CALLS)?;
            per.insert(path.to_string(), full.saturating_sub(base) / CALLS);
            progress.set((out.len() * PATHS.len() + per.len()) as u64);
        }
        out.insert(model, per);
    }
    Ok(out)
}

/// Instructions per call of ours and of CasADi's C, side by side (not budgeted: the
/// peer's count only puts ours in perspective).
pub fn compare_instructions(root: &Path) -> Result<String, String> {
    cargo(
        root,
        &[
            "build",
            "--quiet",
            "--release",
            "-p",
            "leg-tests",
            "--features",
            "peers",
            "--example",
            "count_calls",
        ],
    )?;
    let bin = target_dir(root)
        .join("release")
        .join("examples")
        .join("count_calls");
    let per_call = |model: &str, path: &str| -> Result<u64, String> {
        Ok(
            collected(&bin, model, path, CALLS)?.saturating_sub(collected(&bin, model, path, 0)?)
                / CALLS,
        )
    };
    let models = crate::cli::model_names(root)?;
    let mut progress = Progress::new(models.len() as u64, "counting CasADi's C (callgrind)");
    let mut lines = vec![
        "| model | fused ours | fused CasADi C | ratio | FD ours | FD CasADi C | ratio |"
            .to_string(),
        "|---|---|---|---|---|---|---|".to_string(),
    ];
    for (k, m) in models.iter().enumerate() {
        progress.set(k as u64);
        let (fo, fc) = (per_call(m, "fused")?, per_call(m, "casadi_fused")?);
        let (do_, dc) = (
            per_call(m, "forward_dynamics")?,
            per_call(m, "casadi_forward_dynamics")?,
        );
        lines.push(format!(
            "| {m} | {fo} | {fc} | {:.2} | {do_} | {dc} | {:.2} |",
            fo as f64 / fc as f64,
            do_ as f64 / dc as f64
        ));
    }
    Ok(lines.join("\n"))
}

/// Compares the counts with the committed budgets; `update` rewrites the budgets file.
pub fn check_budgets(root: &Path, update: bool) -> Result<String, String> {
    let counts = instruction_counts(root)?;
    let path = root.join(BUDGETS);
    if update {
        let text = serde_json::to_string_pretty(&counts).expect("counts serialize") + "\n";
        crate::cli::write_atomic(&path, &text)?;
        return Ok(format!("wrote {BUDGETS}"));
    }
    let budgets: BTreeMap<String, BTreeMap<String, u64>> = serde_json::from_str(
        &std::fs::read_to_string(&path).map_err(|e| format!("{BUDGETS}: {e}"))?,
    )
    .map_err(|e| format!("{BUDGETS}: {e}"))?;
    let mut lines = Vec::new();
    let mut over = Vec::new();
    for (model, per) in &counts {
        for (p, &n) in per {
            let Some(&b) = budgets.get(model).and_then(|m| m.get(p)) else {
                over.push(format!(
                    "{model} {p}: no budget (run `cargo xtask bench --update-budgets`)"
                ));
                continue;
            };
            let limit = (b as f64 * (1.0 + TOLERANCE)).floor() as u64;
            lines.push(format!(
                "{model:<16} {p:<17} {n:>6} instructions (budget {b})"
            ));
            if n > limit {
                over.push(format!(
                    "{model} {p}: {n} instructions, over the budget {b} (+{:.0} %)",
                    TOLERANCE * 100.0
                ));
            }
        }
    }
    if over.is_empty() {
        Ok(lines.join("\n"))
    } else {
        Err(format!(
            "instruction budgets exceeded:\n  {}\nif the increase is intended, run `cargo xtask bench --update-budgets` and commit {BUDGETS}",
            over.join("\n  ")
        ))
    }
}

/// The median time of a criterion benchmark, in ns.
fn median(root: &Path, group: &str, id: &str) -> Option<f64> {
    let file = target_dir(root)
        .join("criterion")
        .join(group)
        .join(id)
        .join("new")
        .join("estimates.json");
    let v: Value = serde_json::from_str(&std::fs::read_to_string(file).ok()?).ok()?;
    v["median"]["point_estimate"].as_f64()
}

fn ns(v: Option<f64>) -> String {
    v.map_or("–".into(), |x| {
        if x >= 1000.0 {
            format!("{:.2} µs", x / 1000.0)
        } else {
            format!("{x:.0} ns")
        }
    })
}

fn ratio(a: Option<f64>, b: Option<f64>) -> String {
    match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => format!("{:.2}", a / b),
        _ => "–".into(),
    }
}

/// Runs the criterion benchmarks (and Pinocchio's pipeline when `pinocchio`), then
/// prints the table.
pub fn run(root: &Path, pinocchio: bool) -> Result<(), String> {
    cargo(
        root,
        &[
            "bench",
            "-p",
            "leg-tests",
            "--features",
            "peers",
            "--bench",
            "dynamics",
        ],
    )?;
    let pin = if pinocchio {
        crate::pinocchio::run(root)?
    } else {
        BTreeMap::new()
    };
    let models = crate::cli::model_names(root)?;
    println!();
    println!("| model | fused ours | fused CasADi C | ratio | FD ours | FD CasADi C | ratio | FD Pinocchio | ratio | control step | control / FD | fused f32/f64 | FD f32/f64 | sim step |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for m in &models {
        let g = |id: &str| median(root, m, id);
        let (fo, fc, dd, dc, c) = (
            g("fused-ours"),
            g("fused-casadi"),
            g("fd-ours"),
            g("fd-casadi"),
            g("control-ours"),
        );
        let p = pin.get(m).copied();
        println!(
            "| {m} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            ns(fo),
            ns(fc),
            ratio(fo, fc),
            ns(dd),
            ns(dc),
            ratio(dd, dc),
            ns(p),
            ratio(dd, p),
            ns(c),
            ratio(c, dd),
            ratio(g("fused-ours-f32"), fo),
            ratio(g("fd-ours-f32"), dd),
            ns(g("step-ours")),
        );
    }
    println!("\nmedians of criterion (target/criterion/); ratios are ours / peer, measured in this one run");
    Ok(())
}
