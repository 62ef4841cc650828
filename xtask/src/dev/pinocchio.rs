//! Pinocchio's pipeline for the same legs, timed in C++ (`cargo xtask bench --pinocchio`).
//!
//! Installs `pin` (its C++ headers and libraries) and Eigen's headers from PyPI into the
//! generation step's virtual environment, compiles `xtask/pinocchio_bench.cpp` with g++
//! at -O3, and runs it on each leg (built with Pinocchio's API from the spec). Before
//! timing, Pinocchio's `M`, `N` and `q̈` must agree with the generated model's (from
//! `legs eval --json`), so that both compute the same thing. `xtask/pinocchio_derivatives.cpp`
//! times `constraintDynamics` + `computeConstraintDynamicsDerivatives` the same way, its
//! derivatives checked against `legs eval --derivatives` first (it works around a bug of
//! Pinocchio 4.1's loop-closure derivatives: see its header).

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

use crate::gen;
use crate::gen::model::{Model, Param};

const REQUIREMENTS: &str = "xtask/requirements-pinocchio.txt";
const SOURCE: &str = "xtask/pinocchio_bench.cpp";
const SX_SOURCE: &str = "xtask/pinocchio_casadi.cpp";
const DERIVATIVES_SOURCE: &str = "xtask/pinocchio_derivatives.cpp";
const SPATIAL_SOURCE: &str = "xtask/pinocchio_spatial_bench.cpp";
const LEG_HEADER: &str = "xtask/pinocchio_leg.hpp";

fn value(params: &[Param], name: &str) -> f64 {
    params
        .iter()
        .find(|p| p.name == name)
        .map_or(f64::NAN, |p| p.default)
}

/// The leg file `pinocchio_bench` reads (see its header), at the spec's home pose.
fn leg_file(m: &Model, qd: &[f64]) -> String {
    let v = |n: &String| value(&m.params, n);
    let mut out = format!("gravity {:?} {:?}\n", v(&m.gravity[0]), v(&m.gravity[1]));
    for l in &m.links {
        let armature = l
            .rotor
            .as_ref()
            .map_or(0.0, |r| v(&r[0]) * v(&r[1]) * v(&r[1]));
        let _ = writeln!(
            out,
            "link {} {} {:?} {:?} {:?} {:?} {:?} {:?} {:?} {:?}",
            l.name,
            l.parent.map_or(-1, |p| p as i64),
            v(&l.origin[0]),
            v(&l.origin[1]),
            v(&l.mass),
            v(&l.com[0]),
            v(&l.com[1]),
            l.inertia.planar().map_or(f64::NAN, |i| value(&m.params, i)),
            armature,
            v(&l.damping)
        );
    }
    for c in &m.closures {
        let _ = writeln!(
            out,
            "closure {} {} {:?} {:?} {} {:?} {:?}",
            c.name,
            c.a.link.map_or(-1, |l| l as i64),
            v(&c.a.point[0]),
            v(&c.a.point[1]),
            c.b.link.map_or(-1, |l| l as i64),
            v(&c.b.point[0]),
            v(&c.b.point[1])
        );
    }
    let state: Vec<String> = m.home.iter().chain(qd).map(|x| format!("{x:?}")).collect();
    let _ = writeln!(out, "state {}", state.join(" "));
    out
}

fn run_command(cmd: &mut Command, shown: &str) -> Result<String, String> {
    let out = cmd
        .output()
        .map_err(|e| format!("cannot run {shown}: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "{shown} failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Pinocchio's figures for one leg (median ns per call).
#[derive(Clone, Copy, Debug, Default)]
pub struct Figures {
    /// Pinocchio's C++ pipeline (forward dynamics), where the C++ program has an instance.
    pub pipeline: Option<f64>,
    /// Pinocchio on casadi::SX emitted as C: the fused terms and forward dynamics.
    pub sx_terms: Option<f64>,
    pub sx_forward_dynamics: Option<f64>,
    /// Pinocchio's C++ `constraintDynamics` + `computeConstraintDynamicsDerivatives`.
    pub derivatives: Option<f64>,
}

/// The planar legs' figures and the spatial legs', by model.
pub type AllFigures = (BTreeMap<String, Figures>, BTreeMap<String, SpatialFigures>);

/// Pinocchio's C++ `constraintDynamics` on a spatial leg's URDF (median ns per call).
#[derive(Clone, Copy, Debug, Default)]
pub struct SpatialFigures {
    /// Converged proximal iterations (the exact solution, equal to ours).
    pub converged: f64,
    /// The iterations it took.
    pub iterations: u64,
    /// One proximal iteration, Pinocchio's fastest setting.
    pub one_iteration: f64,
    /// That solution's largest q̈ difference from ours, relative to our largest q̈.
    pub one_iteration_error: f64,
}

/// Whether `out` is older than any of `sources` (or missing).
fn stale(out: &Path, sources: &[PathBuf]) -> bool {
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    match modified(out) {
        None => true,
        Some(o) => sources.iter().any(|s| modified(s).is_none_or(|m| m > o)),
    }
}

/// Compiles one of the C++ programs with Pinocchio (and CasADi when `casadi` is given),
/// unless it is newer than its sources.
fn compile(
    root: &Path,
    source: &str,
    bin: &Path,
    prefix: &Path,
    casadi: Option<&Path>,
) -> Result<(), String> {
    let sources = [root.join(source), root.join(LEG_HEADER)];
    if !stale(bin, &sources) {
        return Ok(());
    }
    eprintln!("==> g++ {source} (Pinocchio's templates: a few minutes)");
    let inc = prefix.join("include");
    let lib = prefix.join("lib");
    let mut cmd = Command::new("g++");
    // The symbolic generator's own speed does not matter: -O1 builds faster.
    cmd.args([
        if casadi.is_some() { "-O1" } else { "-O3" },
        "-DNDEBUG",
        "-std=c++17",
    ])
    // The definitions Pinocchio's CMake configuration exports to its users.
    .args([
        "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
        "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
        "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
        "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
        "-DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION",
    ])
    .arg(format!("-I{}", inc.join("eigen3").display()))
    .arg(format!("-I{}", inc.display()));
    if let Some(c) = casadi {
        cmd.arg(format!("-I{}", c.join("include").display()));
    }
    if source == SPATIAL_SOURCE {
        // urdfdom's headers, from cmeel-urdfdom-headers (requirements-pinocchio.txt).
        cmd.arg(format!("-I{}", inc.join("urdfdom_headers").display()))
            .arg(format!("-I{}", inc.join("urdfdom").display()));
    }
    cmd.arg(&sources[0])
        .arg("-o")
        .arg(bin)
        .arg(format!("-L{}", lib.display()))
        .arg("-lpinocchio_default")
        .arg(format!("-Wl,-rpath,{}", lib.display()));
    if source == SPATIAL_SOURCE {
        // Pinocchio's URDF parser and urdfdom, from the same wheels.
        cmd.args(["-lpinocchio_parsers", "-lurdfdom_model"]);
    }
    if let Some(c) = casadi {
        cmd.arg(format!("-L{}", c.display()))
            .arg("-lcasadi")
            .arg(format!("-Wl,-rpath,{}", c.display()));
    }
    run_command(&mut cmd, "g++ (Debian: apt-get install g++)").map(|_| ())
}

/// Pinocchio's figures for every model: its C++ pipeline where the C++ program has a
/// fixed-size instance, and its algorithms on casadi::SX emitted as C for every leg
/// without redundant closure rows.
pub fn run(root: &Path) -> Result<AllFigures, String> {
    let py = gen::python(root)?;
    eprintln!("==> installing {REQUIREMENTS} into {}/", gen::VENV_DIR);
    run_command(
        Command::new(&py)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
                "-r",
                REQUIREMENTS,
            ])
            .current_dir(root),
        &format!("pip install -r {REQUIREMENTS}"),
    )?;
    let paths = run_command(
        Command::new(&py).args(["-c", "import sysconfig, os, casadi; print(os.path.join(sysconfig.get_paths()['purelib'], 'cmeel.prefix')); print(os.path.dirname(casadi.__file__))"]),
        "python",
    )?;
    let mut lines = paths.lines();
    let prefix = PathBuf::from(lines.next().unwrap_or_default().trim());
    let casadi_dir = PathBuf::from(lines.next().unwrap_or_default().trim());
    let target = crate::cli::target_dir(root);
    let dir = target.join("pinocchio");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let bin = dir.join("pinocchio_bench");
    compile(root, SOURCE, &bin, &prefix, None)?;
    let sx_bin = dir.join("pinocchio_casadi");
    compile(root, SX_SOURCE, &sx_bin, &prefix, Some(&casadi_dir))?;
    let derivatives_bin = dir.join("pinocchio_derivatives");
    compile(root, DERIVATIVES_SOURCE, &derivatives_bin, &prefix, None)?;
    let spatial_bin = dir.join("pinocchio_spatial_bench");
    compile(root, SPATIAL_SOURCE, &spatial_bin, &prefix, None)?;
    let target_legs = crate::cli::build_legs(root)?;
    let spatial = spatial_figures(root, &dir, &spatial_bin, &target_legs)?;
    let mut out = BTreeMap::new();
    for name in crate::gen::planar_model_names(root)? {
        let spec = gen::load_spec(
            root,
            &root.join(gen::SPECS_DIR).join(format!("{name}.toml")),
        )?;
        let m = crate::gen::model::build(&spec).map_err(|e| e.to_string())?;
        // The leg file holds revolute joints without springs: a leg with a prismatic
        // joint or a spring is not timed against Pinocchio (yet), rather than against a
        // different model.
        if m.links.iter().any(|l| l.axis.is_some()) || !m.springs.is_empty() {
            eprintln!("{name}: not timed against Pinocchio: the leg file has no prismatic joints or springs yet");
            continue;
        }
        let qd: Vec<f64> = (0..m.links.len()).map(|i| 0.1 * (i as f64 + 1.0)).collect();
        let file = dir.join(format!("{name}.leg"));
        crate::cli::write_atomic(&file, &leg_file(&m, &qd))?;
        let join = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:?}"))
                .collect::<Vec<_>>()
                .join(",")
        };
        let ours: Value = serde_json::from_str(&run_command(
            Command::new(&target_legs).args([
                "eval",
                &name,
                "--q",
                &join(&m.home),
                "--qd",
                &join(&qd),
                "--derivatives",
                "--json",
            ]),
            "legs eval",
        )?)
        .map_err(|e| e.to_string())?;
        let mut figures = Figures::default();
        match run_command(Command::new(&bin).arg(&file), "pinocchio_bench") {
            Ok(text) => {
                let pin: Value = serde_json::from_str(&text)
                    .map_err(|e| format!("pinocchio_bench printed {text}: {e}"))?;
                agree(&name, "Pinocchio's pipeline", &pin, &ours)?;
                figures.pipeline = pin["median_ns"].as_f64();
            }
            Err(e) if e.contains("no fixed-size instance") => {}
            Err(e) => return Err(e),
        }
        // Pinocchio's constrained-dynamics derivatives (proximal, so a planar closure's
        // zero z rows are no obstacle), at the same state with no torque, checked against
        // ours before they are timed.
        let actuated = m
            .actuated
            .iter()
            .map(|a| a.to_string())
            .collect::<Vec<_>>()
            .join(",");
        let zero_u = vec!["0"; m.actuated.len()].join(",");
        // Not on a leg closed redundantly: off its manifold (the home pose is assembled to
        // the spec's accuracy only) its rows are independent, and Pinocchio's proximal
        // solve and ours answer different systems.
        let redundant = !m.closures.is_empty() && has_redundant_rows(root, &name)?;
        match run_command(
            Command::new(&derivatives_bin)
                .arg(&file)
                .arg(&actuated)
                .arg(&zero_u),
            "pinocchio_derivatives",
        ) {
            _ if redundant => {
                eprintln!("{name}: no Pinocchio derivatives: its closure rows are redundant")
            }
            Ok(text) => {
                let pin: Value = serde_json::from_str(&text)
                    .map_err(|e| format!("pinocchio_derivatives printed {text}: {e}"))?;
                agree_on(
                    &name,
                    "Pinocchio's constrained-dynamics derivatives",
                    &pin,
                    &ours,
                    &["qdd", "dqdd_dq", "dqdd_dqd", "dqdd_du"],
                )?;
                figures.derivatives = pin["median_ns"].as_f64();
            }
            Err(e) => eprintln!("{name}: no Pinocchio derivatives: {e}"),
        }
        if m.closures.is_empty() || !has_redundant_rows(root, &name)? {
            let c = dir.join(format!("{name}_pinocchio_sx.c"));
            run_command(Command::new(&sx_bin).arg(&file).arg(&c), "pinocchio_casadi")?;
            let exe = dir.join(format!("{name}_pinocchio_sx"));
            run_command(
                Command::new("gcc")
                    .args(["-O3"])
                    .arg(&c)
                    .arg("-o")
                    .arg(&exe)
                    .arg("-lm"),
                "gcc",
            )?;
            let text = run_command(&mut Command::new(&exe), "Pinocchio-on-CasADi C")?;
            let sx: Value = serde_json::from_str(&text)
                .map_err(|e| format!("{} printed {text}: {e}", exe.display()))?;
            agree(&name, "Pinocchio on casadi::SX", &sx, &ours)?;
            figures.sx_terms = sx["terms_median_ns"].as_f64();
            figures.sx_forward_dynamics = sx["fd_median_ns"].as_f64();
        }
        eprintln!(
            "{name:<16} Pinocchio pipeline {}, Pinocchio-on-CasADi C terms {} / forward dynamics {}, derivatives {} (M, N, q̈ and the derivatives agree with ours)",
            show(figures.pipeline),
            show(figures.sx_terms),
            show(figures.sx_forward_dynamics),
            show(figures.derivatives)
        );
        out.insert(name, figures);
    }
    Ok((out, spatial))
}

/// Every spatial leg's URDF in `pinocchio_spatial_bench` at its assembled home pose with
/// rates and torques, its q̈ checked against ours (`legs eval`) before it is timed.
fn spatial_figures(
    root: &Path,
    dir: &Path,
    bin: &Path,
    legs: &Path,
) -> Result<BTreeMap<String, SpatialFigures>, String> {
    // Numbers written exactly: comma-separated for `legs`, space-separated for the file.
    let joined = |v: &[f64], sep: &str| {
        v.iter()
            .map(|x| format!("{x:?}"))
            .collect::<Vec<_>>()
            .join(sep)
    };
    let join = |v: &[f64]| joined(v, ",");
    let floats = |v: &Value| -> Vec<f64> {
        v.as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect())
            .unwrap_or_default()
    };
    let mut out = BTreeMap::new();
    for name in crate::gen::spatial_model_names(root)? {
        let spec = gen::load_spec(
            root,
            &root.join(gen::SPECS_DIR).join(format!("{name}.toml")),
        )?;
        let m = crate::gen::model::build(&spec).map_err(|e| e.to_string())?;
        if m.closures.iter().any(|c| c.revolute.is_some()) {
            eprintln!("{name}: not timed against Pinocchio: its constraintDynamics has no 5-D (revolute) loop constraint (pinocchio#2729)");
            continue;
        }
        if m.closures.iter().any(|c| c.distance.is_some()) {
            eprintln!("{name}: not timed against Pinocchio: its constraintDynamics has no rod (distance) constraint");
            continue;
        }
        let urdf = dir.join(format!("{name}.urdf"));
        crate::cli::write_atomic(&urdf, &crate::commands::export::spatial::urdf(&m))?;
        let n = m.links.len();
        let qd: Vec<f64> = (0..n).map(|i| 0.3 + 0.1 * i as f64).collect();
        let u: Vec<f64> = (0..m.actuated.len())
            .map(|k| 0.05 * (k as f64 + 1.0))
            .collect();
        let ours: Value = serde_json::from_str(&run_command(
            Command::new(legs).args([
                "eval",
                &name,
                "--q",
                &join(&m.home),
                "--qd",
                &join(&qd),
                "--u",
                &join(&u),
                "--project",
                "--json",
            ]),
            "legs eval",
        )?)
        .map_err(|e| e.to_string())?;
        let (q, qd, qdd) = (
            floats(&ours["q"]),
            floats(&ours["qd"]),
            floats(&ours["qdd"]),
        );
        // τ = B u − D q̇ − ∂V_spring/∂q: Pinocchio's constraintDynamics has no damping or
        // springs.
        let v = |p: &String| value(&m.params, p);
        let mut tau: Vec<f64> = (0..n).map(|i| -v(&m.links[i].damping) * qd[i]).collect();
        for (k, &a) in m.actuated.iter().enumerate() {
            tau[a] += u[k];
        }
        for sp in &m.springs {
            let stretch = q[sp.a] - sp.b.map_or(0.0, |b| q[b]) - v(&sp.rest);
            let force = v(&sp.stiffness) * stretch;
            tau[sp.a] -= force;
            if let Some(b) = sp.b {
                tau[b] += force;
            }
        }
        let mut file = format!(
            "gravity {}\n",
            m.gravity
                .iter()
                .map(|g| format!("{:?}", v(g)))
                .collect::<Vec<_>>()
                .join(" ")
        );
        for l in &m.links {
            let _ = writeln!(file, "joint {}", l.name);
            if let Some(r) = &l.rotor {
                let _ = writeln!(
                    file,
                    "armature {} {:?}",
                    l.name,
                    v(&r[0]) * v(&r[1]) * v(&r[1])
                );
            }
        }
        for c in &m.closures {
            let _ = writeln!(file, "closure {}", c.name);
        }
        let line = |v: &[f64]| joined(v, " ");
        let _ = writeln!(file, "q {}\nv {}\ntau {}", line(&q), line(&qd), line(&tau));
        let state = dir.join(format!("{name}.state"));
        crate::cli::write_atomic(&state, &file)?;
        let text = run_command(
            Command::new(bin).arg(&urdf).arg(&state),
            "pinocchio_spatial_bench",
        )?;
        let pin: Value = serde_json::from_str(&text)
            .map_err(|e| format!("pinocchio_spatial_bench printed {text}: {e}"))?;
        let scale = qdd.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let off = |theirs: &[f64]| {
            theirs
                .iter()
                .zip(&qdd)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f64, f64::max)
                / scale
        };
        let converged = off(&floats(&pin["qdd"]));
        if converged.is_nan() || converged >= 1e-9 {
            eprintln!(
                "{name}: not timed: Pinocchio's constraintDynamics q̈ differs from ours by {converged:e} (relative); not timing different work"
            );
            continue;
        }
        let figures = SpatialFigures {
            converged: pin["median_ns"].as_f64().unwrap_or(f64::NAN),
            iterations: pin["iterations"].as_u64().unwrap_or(0),
            one_iteration: pin["one_iteration_ns"].as_f64().unwrap_or(f64::NAN),
            one_iteration_error: off(&floats(&pin["one_iteration_qdd"])),
        };
        eprintln!(
            "{name:<16} Pinocchio constraintDynamics {:.0} ns ({} iterations, q̈ equal to ours to {converged:.1e}); one iteration {:.0} ns (q̈ off by {:.1e})",
            figures.converged, figures.iterations, figures.one_iteration, figures.one_iteration_error
        );
        out.insert(name, figures);
    }
    Ok(out)
}

fn show(ns: Option<f64>) -> String {
    ns.map_or("–".into(), |x| format!("{x:.0} ns"))
}

/// Whether the committed IR records closure rows that repeat the others (the KKT matrix
/// the peers' LU and symbolic solve would factor is then singular).
fn has_redundant_rows(root: &Path, name: &str) -> Result<bool, String> {
    Ok(gen::committed_ir(root, name)?.is_some_and(|ir| !ir.model.redundant_rows.is_empty()))
}

/// `peer`'s M, N and q̈ (rows in the spec's order; M as rows or flat, column-major or
/// symmetric) agree with ours, so that both compute the same thing.
fn agree(name: &str, what: &str, peer: &Value, ours: &Value) -> Result<(), String> {
    agree_on(name, what, peer, ours, &["M", "N", "qdd"])
}

/// `peer`'s `keys` agree with ours to 1e-9 of their largest entry.
fn agree_on(
    name: &str,
    what: &str,
    peer: &Value,
    ours: &Value,
    keys: &[&str],
) -> Result<(), String> {
    let flat = |v: &Value| -> Vec<f64> {
        match v {
            Value::Array(a) => a
                .iter()
                .flat_map(|x| match x {
                    Value::Array(r) => r.iter().filter_map(Value::as_f64).collect::<Vec<_>>(),
                    x => x.as_f64().into_iter().collect(),
                })
                .collect(),
            _ => Vec::new(),
        }
    };
    for &key in keys {
        let (a, b) = (flat(&peer[key]), flat(&ours[key]));
        let scale = b.iter().fold(0.0f64, |s, x| s.max(x.abs())).max(1e-300);
        let diff = a
            .iter()
            .zip(&b)
            .fold(0.0f64, |s, (x, y)| s.max((x - y).abs()));
        if a.len() != b.len() || diff > 1e-9 * scale {
            return Err(format!(
                "{name}: {what}'s {key} differs from ours ({diff:e}); not timing different things"
            ));
        }
    }
    Ok(())
}
