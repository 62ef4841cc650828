//! `cargo xtask bench`: criterion benchmarks of every model beside CasADi's own C code
//! (and Pinocchio when asked), printed as one table of medians and ratios; and the
//! instruction counts (callgrind) of the hot paths, checked against committed budgets.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use serde_json::Value;

use crate::cli::progress::Progress;
use crate::cli::target_dir;

/// The committed instruction budgets: per model, per hot path, instructions per call.
pub const BUDGETS: &str = "tests/instruction-budgets.json";
/// Counted instructions may exceed the budget by this fraction before the check fails
/// (they are repeatable, but differ slightly between compiler versions).
pub const TOLERANCE: f64 = 0.02;
const PATHS: [&str; 3] = ["fused", "forward_dynamics", "derivatives"];
/// The paths only some models have (count_calls refuses them elsewhere): on a leg with
/// contacts, forward dynamics with every contact held and with every contact sliding; on
/// a floating robot, as a user calls it (`leg_models::robot`: the chart centred on the
/// body, gravity rotated into it), forward dynamics, the stance with every contact
/// held, one semi-implicit Euler step of that stance at 0.5 ms (its projection
/// included: `bench --mujoco`'s step), and one step at 0.5 ms with every foot free
/// (`time_stepping`: the contact modes' complementarity solve included).
const APPLICABLE_PATHS: [&str; 6] = [
    "contact_stance",
    "contact_slide",
    "robot_forward_dynamics",
    "robot_stance",
    "robot_stance_step",
    "robot_free_step",
];
/// The paths CasADi's C has in both forms (its derivatives are compared apart).
const COMPARED: [&str; 2] = ["fused", "forward_dynamics"];
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

/// Whether `model` has `path`: count_calls runs it with no calls, or says it has none
/// (exit code 2: the path does not apply, or its solve fails at the counted state); any
/// other failure (a panic) is an error, not a path left out.
fn applies(bin: &Path, model: &str, path: &str) -> Result<bool, String> {
    let out = Command::new(bin)
        .args([model, path, "0"])
        .output()
        .map_err(|e| format!("{}: {e}", bin.display()))?;
    match out.status.code() {
        Some(0) => Ok(true),
        Some(2) => Ok(false),
        _ => Err(format!(
            "count_calls {model} {path} failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        )),
    }
}

/// Instructions of `CALLS` calls of `path` of `model`, less those of none (so start-up
/// does not count).
fn gross(bin: &Path, model: &str, path: &str) -> Result<u64, String> {
    Ok(collected(bin, model, path, CALLS)?.saturating_sub(collected(bin, model, path, 0)?))
}

/// The measured loop with no contender in it (`empty`), over `CALLS` calls.
struct Harness(u64);

impl Harness {
    fn of(bin: &Path, model: &str) -> Result<Harness, String> {
        gross(bin, model, "empty").map(Harness)
    }

    fn per_call(&self) -> u64 {
        self.0 / CALLS
    }

    /// Instructions of one call of `path`, net of the harness's loop.
    fn net(&self, bin: &Path, model: &str, path: &str) -> Result<u64, String> {
        Ok(gross(bin, model, path)?.saturating_sub(self.0) / CALLS)
    }
}

fn count_calls(root: &Path, peers: bool) -> Result<std::path::PathBuf, String> {
    let mut args = vec!["build", "--quiet", "--release", "-p", "leg-tests"];
    if peers {
        args.extend(["--features", "peers"]);
    }
    args.extend(["--example", "count_calls"]);
    cargo(root, &args)?;
    Ok(target_dir(root)
        .join("release")
        .join("examples")
        .join("count_calls"))
}

/// Instructions per call of every hot path of every model, net of the harness's loop.
pub fn instruction_counts(root: &Path) -> Result<BTreeMap<String, BTreeMap<String, u64>>, String> {
    let bin = count_calls(root, false)?;
    let mut out = BTreeMap::new();
    let mut models = crate::gen::planar_model_names(root)?;
    models.extend(crate::gen::spatial_model_names(root)?);
    // A leg with contacts adds its contact paths, a floating robot its own.
    let mut paths: Vec<(String, Vec<&str>)> = Vec::new();
    for model in models {
        let mut own = PATHS.to_vec();
        for path in APPLICABLE_PATHS {
            if applies(&bin, &model, path)? {
                own.push(path);
            }
        }
        paths.push((model, own));
    }
    let total = paths.iter().map(|(_, p)| p.len()).sum::<usize>();
    let mut progress = Progress::new(total as u64, "counting instructions (callgrind)");
    let mut done = 0;
    for (model, own) in paths {
        let harness = Harness::of(&bin, &model)?;
        let mut per = BTreeMap::new();
        for path in own {
            per.insert(path.to_string(), harness.net(&bin, &model, path)?);
            done += 1;
            progress.set(done as u64);
        }
        out.insert(model, per);
    }
    Ok(out)
}

/// Instructions per call of ours and of CasADi's C of the same terms in the closed form
/// and in the Lagrange form, side by side, net of the harness's loop, which is shown (not
/// budgeted: the peers' counts only put ours in perspective).
pub fn compare_instructions(root: &Path) -> Result<String, String> {
    let bin = count_calls(root, true)?;
    let models = crate::gen::planar_model_names(root)?;
    let mut progress = Progress::new(models.len() as u64, "counting CasADi's C (callgrind)");
    let mut lines = vec![
        "| model | harness | fused ours | CasADi C, closed form | ratio | CasADi C, Lagrange | ratio | FD ours | CasADi C, closed form | ratio | CasADi C, Lagrange | ratio | fused batch per state | × scalar | FD batch per state | × scalar |"
            .to_string(),
        format!("|{}", "---|".repeat(16)),
    ];
    let ratio = |a: u64, b: u64| format!("{:.2}", a as f64 / b.max(1) as f64);
    for (k, m) in models.iter().enumerate() {
        progress.set(k as u64);
        let harness = Harness::of(&bin, m)?;
        let mut cells = vec![m.clone(), harness.per_call().to_string()];
        let mut scalar = Vec::new();
        for path in COMPARED {
            let ours = harness.net(&bin, m, path)?;
            let closed = harness.net(&bin, m, &format!("casadi_closed_{path}"))?;
            let lagrange = harness.net(&bin, m, &format!("casadi_{path}"))?;
            cells.extend([
                ours.to_string(),
                closed.to_string(),
                ratio(ours, closed),
                lagrange.to_string(),
                ratio(ours, lagrange),
            ]);
            scalar.push(ours);
        }
        // Four states per call; a leg without a batched path shows a dash.
        for (path, ours) in COMPARED.iter().zip(scalar) {
            match harness.net(&bin, m, &format!("batch_{path}")) {
                Ok(four) => {
                    let per = four as f64 / 4.0;
                    cells.extend([format!("{per:.0}"), format!("{:.2}", ours as f64 / per)]);
                }
                Err(_) => cells.extend(["–".to_string(), "–".to_string()]),
            }
        }
        lines.push(format!("| {} |", cells.join(" | ")));
    }
    lines.push(String::new());
    lines.push(format!(
        "instructions per call (callgrind, {CALLS} calls less none, less the harness's empty loop, shown as `harness`); every contender's inputs are prepared once and its outputs preallocated; ratios are ours / peer; batch: four states per call on F64x4 lanes, per state, and the scalar path's count over it"
    ));
    // The derivatives of forward dynamics: q̈, F and ∂/∂(q, q̇, u) of both.
    lines.push(String::new());
    lines.push("| model | derivatives ours | finite differences of ours | ratio | CasADi C `jacobian`, closed form | ratio |".into());
    lines.push(format!("|{}", "---|".repeat(6)));
    for m in &models {
        let harness = Harness::of(&bin, m)?;
        let ours = harness.net(&bin, m, "derivatives")?;
        let fd = harness.net(&bin, m, "finite_differences")?;
        let casadi = harness.net(&bin, m, "casadi_closed_derivatives")?;
        lines.push(format!(
            "| {m} | {ours} | {fd} | {} | {casadi} | {} |",
            ratio(ours, fd),
            ratio(ours, casadi)
        ));
    }
    lines.push(String::new());
    lines.push("derivatives of forward dynamics per call: q̈ and F with ∂/∂q, ∂/∂q̇, ∂/∂u of both; finite differences: forward differences of our forward dynamics (2 NQ + NU + 1 calls) into preallocated matrices; CasADi: `jacobian` of its forward-dynamics function of the same closed-form terms, compiled at -O3".into());
    // Spatial legs: CasADi's C has their fused terms only (derive.py says why), so our
    // forward dynamics, terms and solve, is shown beside its terms alone.
    lines.push(String::new());
    lines.push("| spatial model | harness | fused ours | CasADi C, closed form | ratio | CasADi C, Lagrange | ratio | FD ours | FD ours / CasADi C Lagrange fused | derivatives ours | finite differences of ours | ratio |".into());
    lines.push(format!("|{}", "---|".repeat(12)));
    for m in crate::gen::spatial_model_names(root)? {
        let harness = Harness::of(&bin, &m)?;
        let fused = harness.net(&bin, &m, "fused")?;
        let closed = harness.net(&bin, &m, "casadi_closed_fused")?;
        let lagrange = harness.net(&bin, &m, "casadi_fused")?;
        let fd = harness.net(&bin, &m, "forward_dynamics")?;
        let derivatives = harness.net(&bin, &m, "derivatives")?;
        let differences = harness.net(&bin, &m, "finite_differences")?;
        lines.push(format!(
            "| {m} | {} | {fused} | {closed} | {} | {lagrange} | {} | {fd} | {} | {derivatives} | {differences} | {} |",
            harness.per_call(),
            ratio(fused, closed),
            ratio(fused, lagrange),
            ratio(fd, lagrange),
            ratio(derivatives, differences)
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
    // A budget whose path no longer runs is a regression too, not a row that drops out.
    for (model, per) in &budgets {
        for p in per.keys() {
            if counts.get(model).is_none_or(|m| !m.contains_key(p)) {
                over.push(format!(
                    "{model} {p}: budgeted but not measured (the leg is gone, or the path no longer solves at the counted state)"
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
        if x >= 1e6 {
            format!("{:.1} ms", x / 1e6)
        } else if x >= 1000.0 {
            format!("{:.2} µs", x / 1000.0)
        } else if x >= 10.0 {
            format!("{x:.0} ns")
        } else {
            format!("{x:.1} ns")
        }
    })
}

fn ratio(a: Option<f64>, b: Option<f64>) -> String {
    match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => format!("{:.2}", a / b),
        _ => "–".into(),
    }
}

/// A batched call's time per state (four states per call).
fn per_state(v: Option<f64>) -> Option<f64> {
    v.map(|x| x / 4.0)
}

/// Runs the criterion benchmarks (and Pinocchio's pipeline when `pinocchio`, MuJoCo's
/// simulated second of the floating robots when `mujoco`) of `only` (every model when
/// empty), then prints the tables.
pub fn run(root: &Path, pinocchio: bool, mujoco: bool, only: &[String]) -> Result<(), String> {
    let planar = crate::gen::planar_model_names(root)?;
    let spatial = crate::gen::spatial_model_names(root)?;
    for m in only {
        if !planar.contains(m) && !spatial.contains(m) {
            return Err(format!(
                "bench: no model `{}` (the models: {})",
                crate::cli::shown(m),
                planar
                    .iter()
                    .chain(&spatial)
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
    }
    let chosen = |m: &String| only.is_empty() || only.contains(m);
    // Criterion's groups are the models' names.
    let filter = format!("^({})/", only.join("|"));
    let mut args = vec![
        "bench",
        "-p",
        "leg-tests",
        "--features",
        "peers",
        "--bench",
        "dynamics",
    ];
    if !only.is_empty() {
        args.extend(["--", filter.as_str()]);
    }
    let floating = |m: &String| {
        crate::gen::committed_ir(root, m)
            .map(|ir| ir.is_some_and(|ir| ir.model.free_joint.is_some()))
    };
    let mut robots = Vec::new();
    for m in spatial.iter().filter(|m| chosen(m)) {
        if floating(m)? {
            robots.push(m.clone());
        }
    }
    // The runs criterion and MuJoCo replay, recorded before criterion starts.
    let (replay, legs) = if mujoco {
        let legs = crate::cli::build_legs(root)?;
        (
            crate::dev::mujoco_step::record(root, &legs, &robots)?,
            Some(legs),
        )
    } else {
        (Vec::new(), None)
    };
    let replay_dir = crate::dev::mujoco_step::dir(root);
    let mut env = Vec::new();
    if mujoco {
        // An empty variable would run the bench without the replay: refused instead.
        let dir = replay_dir.to_str().ok_or_else(|| {
            format!(
                "{}: the replay folder's path is not UTF-8, which the bench's environment variable cannot carry",
                replay_dir.display()
            )
        })?;
        env.push(("LEG_BENCH_REPLAY", dir));
    }
    crate::cli::cargo(root, &args, &env)?;
    let mujoco_figures = match &legs {
        Some(legs) => crate::dev::mujoco_step::run(root, legs, &replay)?,
        None => BTreeMap::new(),
    };
    let (pin, pin_spatial) = if pinocchio {
        crate::dev::pinocchio::run(root, &chosen)?
    } else {
        (BTreeMap::new(), BTreeMap::new())
    };
    let models: Vec<String> = planar.into_iter().filter(chosen).collect();
    // A table with no rows (no model of its kind chosen) is not printed.
    let header = |text: &str, columns: usize, rows: usize| {
        if rows > 0 {
            println!("\n{text}\n|{}", "---|".repeat(columns));
        }
    };
    header("| model | harness | fused ours | CasADi C closed | ratio | CasADi C Lagrange | ratio | Pinocchio-on-CasADi C | ratio | FD ours | CasADi C closed | ratio | CasADi C Lagrange | ratio | Pinocchio-on-CasADi C | ratio | Pinocchio C++ | ratio | control step | control / FD | fused f32/f64 | FD f32/f64 | sim step | fused batch per state | × scalar | FD batch per state | × scalar |", 27, models.len());
    for m in &models {
        let g = |id: &str| median(root, m, id);
        let (fo, fcc, fcl, dd, dcc, dcl, c) = (
            g("fused-ours"),
            g("fused-casadi-closed"),
            g("fused-casadi"),
            g("fd-ours"),
            g("fd-casadi-closed"),
            g("fd-casadi"),
            g("control-ours"),
        );
        let p = pin.get(m).copied().unwrap_or_default();
        let cells = [
            ns(g("empty")),
            ns(fo),
            ns(fcc),
            ratio(fo, fcc),
            ns(fcl),
            ratio(fo, fcl),
            ns(p.sx_terms),
            ratio(fo, p.sx_terms),
            ns(dd),
            ns(dcc),
            ratio(dd, dcc),
            ns(dcl),
            ratio(dd, dcl),
            ns(p.sx_forward_dynamics),
            ratio(dd, p.sx_forward_dynamics),
            ns(p.pipeline),
            ratio(dd, p.pipeline),
            ns(c),
            ratio(c, dd),
            ratio(g("fused-ours-f32"), fo),
            ratio(g("fd-ours-f32"), dd),
            ns(g("step-ours")),
            ns(per_state(g("fused-batch"))),
            ratio(fo, per_state(g("fused-batch"))),
            ns(per_state(g("fd-batch"))),
            ratio(dd, per_state(g("fd-batch"))),
        ];
        println!("| {m} | {} |", cells.join(" | "));
    }
    header("| model | derivatives ours | finite differences of ours | ratio | CasADi C `jacobian` closed | ratio | Pinocchio C++ constraint dynamics derivatives | ratio |", 8, models.len());
    for m in &models {
        let g = |id: &str| median(root, m, id);
        let (ours, fd, cas) = (
            g("deriv-ours"),
            g("deriv-finite-differences"),
            g("deriv-casadi-closed"),
        );
        let p = pin.get(m).copied().unwrap_or_default();
        println!(
            "| {m} | {} | {} | {} | {} | {} | {} | {} |",
            ns(ours),
            ns(fd),
            ratio(ours, fd),
            ns(cas),
            ratio(ours, cas),
            ns(p.derivatives),
            ratio(ours, p.derivatives)
        );
    }
    let legs: Vec<String> = spatial
        .into_iter()
        .filter(|m| chosen(m) && !robots.contains(m))
        .collect();
    header("| spatial model | harness | fused ours | CasADi C Lagrange | ratio | CasADi C closed | ratio | FD ours | Pinocchio C++ constraintDynamics (converged) | ratio | its iterations | Pinocchio, one iteration | ratio | its q̈ off by | sim step | Pinocchio aba (no closures) | ratio |", 17, legs.len());
    for m in legs {
        let g = |id: &str| median(root, &m, id);
        let (fo, fd) = (g("fused-ours"), g("fd-ours"));
        let p = pin_spatial.get(&m);
        let cells = [
            ns(g("empty")),
            ns(fo),
            ns(g("fused-casadi")),
            ratio(fo, g("fused-casadi")),
            ns(g("fused-casadi-closed")),
            ratio(fo, g("fused-casadi-closed")),
            ns(fd),
            ns(p.map(|p| p.converged)),
            ratio(fd, p.map(|p| p.converged)),
            p.map_or("–".into(), |p| p.iterations.to_string()),
            ns(p.map(|p| p.one_iteration)),
            ratio(fd, p.map(|p| p.one_iteration)),
            p.map_or("–".into(), |p| format!("{:.1e}", p.one_iteration_error)),
            ns(g("step-ours")),
            ns(p.and_then(|p| p.aba)),
            ratio(fd, p.and_then(|p| p.aba)),
        ];
        println!("| {m} | {} |", cells.join(" | "));
    }
    // Floating robots: ours through leg_models::robot (the chart centred on the body, v̇
    // from its q̈), Pinocchio with its free flyer; on the ground every contact held.
    header("| floating robot | harness | fused ours | FD ours (forward_dynamics_at, v̇) | Pinocchio C++ constraintDynamics, free flyer (to its stopping test or its cap of 100) | ratio | its iterations | Pinocchio at the fewest iterations that give that q̈ (an oracle's choice) | ratio | those iterations | Pinocchio, one iteration | ratio | its q̈ off by | stance ours (stance_dynamics, every contact held) | Pinocchio, every contact held (to its stopping test or cap) | ratio | its iterations | Pinocchio held, fewest iterations (an oracle's choice) | ratio | those iterations | Pinocchio aba (no closures) | ratio |", 22, robots.len());
    for m in &robots {
        let g = |id: &str| median(root, m, id);
        let (fd, st) = (g("fd-ours"), g("stance-ours"));
        let p = pin_spatial.get(m);
        let (stance, stance_fewest) = (p.and_then(|p| p.stance), p.and_then(|p| p.stance_fewest));
        let fewest = p.and_then(|p| p.fewest);
        let count = |n: Option<u64>| n.map_or("–".into(), |n| n.to_string());
        let cells = [
            ns(g("empty")),
            ns(g("fused-ours")),
            ns(fd),
            ns(p.map(|p| p.converged)),
            ratio(fd, p.map(|p| p.converged)),
            count(p.map(|p| p.iterations)),
            ns(fewest),
            ratio(fd, fewest),
            count(
                p.filter(|p| p.fewest.is_some())
                    .map(|p| p.fewest_iterations),
            ),
            ns(p.map(|p| p.one_iteration)),
            ratio(fd, p.map(|p| p.one_iteration)),
            p.map_or("–".into(), |p| format!("{:.1e}", p.one_iteration_error)),
            ns(st),
            ns(stance),
            ratio(st, stance),
            count(
                p.filter(|p| p.stance.is_some())
                    .map(|p| p.stance_iterations),
            ),
            ns(stance_fewest),
            ratio(st, stance_fewest),
            count(
                p.filter(|p| p.stance_fewest.is_some())
                    .map(|p| p.stance_fewest_iterations),
            ),
            ns(p.and_then(|p| p.aba)),
            ratio(fd, p.and_then(|p| p.aba)),
        ];
        println!("| {m} | {} |", cells.join(" | "));
    }
    header("| floating robot, a simulated second standing and pushed (the same recorded torques and push, 0.5 ms steps) | ours RK4 | MuJoCo RK4 | ratio | ours semi-implicit Euler | MuJoCo Euler (its default) | ratio | ours feet free (every contact's mode solved each step) | ratio to MuJoCo Euler | one step ours RK4 / Euler / feet free | MuJoCo's largest loop gap (RK4 / Euler) | MuJoCo's body from ours, largest (RK4 / Euler) |", 12, mujoco_figures.len());
    for (m, f) in &mujoco_figures {
        let g = |id: &str| median(root, m, id);
        let theirs = |integrator: &str, key: &str| f[integrator][key].as_f64();
        let seconds = |integrator: &str| theirs(integrator, "median_s").map(|s| s * 1e9);
        let (rk4, euler, free) = (
            g("second-ours"),
            g("second-ours-euler"),
            g("second-ours-free"),
        );
        let cells = [
            ns(rk4),
            ns(seconds("rk4")),
            ratio(rk4, seconds("rk4")),
            ns(euler),
            ns(seconds("euler")),
            ratio(euler, seconds("euler")),
            ns(free),
            ratio(free, seconds("euler")),
            format!(
                "{} / {} / {}",
                ns(g("step-ours")),
                ns(g("step-ours-euler")),
                ns(g("step-ours-free"))
            ),
            format!(
                "{:.1e} / {:.1e} m",
                theirs("rk4", "largest_gap_m").unwrap_or(f64::NAN),
                theirs("euler", "largest_gap_m").unwrap_or(f64::NAN)
            ),
            format!(
                "{:.1} / {:.1} mm",
                1e3 * theirs("rk4", "body_from_ours_m").unwrap_or(f64::NAN),
                1e3 * theirs("euler", "body_from_ours_m").unwrap_or(f64::NAN)
            ),
        ];
        println!("| {m} | {} |", cells.join(" | "));
    }
    println!("\nmedians of criterion (target/criterion/); `harness` is the measured loop with no contender (included in every other figure); ratios are ours / peer, measured in this one run; batch: four states per call on F64x4 lanes, per state, and the scalar time over it (states per second over the scalar path's)");
    Ok(())
}
