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
    /// The fewest proximal iterations that give the converged q̈ (where rows repeat each
    /// other the converged solve runs to its cap of 100 though q̈ is exact after two or
    /// three), and their time: an oracle's choice (found against the capped answer at this one
    /// state), Pinocchio's lower bound for the exact solution, not a setting a user knows.
    pub fewest: Option<f64>,
    pub fewest_iterations: u64,
    /// A floating robot with contact points: the closures and every contact point held
    /// (a stance), converged, its iterations, and at the fewest iterations.
    pub stance: Option<f64>,
    pub stance_iterations: u64,
    pub stance_fewest: Option<f64>,
    pub stance_fewest_iterations: u64,
    /// A model with nothing to hold (no closures): Pinocchio's `aba`, its faster call
    /// there, where its q̈ equals ours.
    pub aba: Option<f64>,
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
/// without redundant closure rows; of the models `chosen` says.
pub fn run(root: &Path, chosen: &dyn Fn(&String) -> bool) -> Result<AllFigures, String> {
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
    // Each program takes minutes to compile: only those the chosen models need.
    let planar: Vec<String> = crate::gen::planar_model_names(root)?
        .into_iter()
        .filter(chosen)
        .collect();
    let spatial: Vec<String> = crate::gen::spatial_model_names(root)?
        .into_iter()
        .filter(chosen)
        .collect();
    let bin = dir.join("pinocchio_bench");
    let sx_bin = dir.join("pinocchio_casadi");
    let derivatives_bin = dir.join("pinocchio_derivatives");
    if !planar.is_empty() {
        compile(root, SOURCE, &bin, &prefix, None)?;
        compile(root, SX_SOURCE, &sx_bin, &prefix, Some(&casadi_dir))?;
        compile(root, DERIVATIVES_SOURCE, &derivatives_bin, &prefix, None)?;
    }
    let target_legs = crate::cli::build_legs(root)?;
    let spatial = if spatial.is_empty() {
        BTreeMap::new()
    } else {
        let spatial_bin = dir.join("pinocchio_spatial_bench");
        compile(root, SPATIAL_SOURCE, &spatial_bin, &prefix, None)?;
        spatial_figures(root, &dir, &spatial_bin, &target_legs, &spatial)?
    };
    let mut out = BTreeMap::new();
    for name in planar {
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
/// rates and torques, its q̈ checked against ours (`legs eval`) before it is timed. A
/// floating robot's body is Pinocchio's free flyer (its URDF's root link the body), level
/// at the origin, the chart centred on it; with contact points, every one held too (its
/// rates put on them: a stance), checked and timed apart.
fn spatial_figures(
    root: &Path,
    dir: &Path,
    bin: &Path,
    legs: &Path,
    models: &[String],
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
    for name in models.iter().cloned() {
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
        // A floating robot's free joint: Pinocchio's own (one 6-dof joint), not the
        // chart's six 1-dof joints.
        let free = m
            .links
            .iter()
            .position(|l| l.spec_kind == crate::gen::spec::JointKind::Free);
        let stance = free.is_some() && !m.contacts.is_empty();
        let urdf = dir.join(format!("{name}.urdf"));
        let text = match free {
            Some(_) => crate::commands::export::spatial::urdf_floating(&m),
            None => crate::commands::export::spatial::urdf(&m),
        };
        crate::cli::write_atomic(&urdf, &text)?;
        let n = m.links.len();
        let qd: Vec<f64> = (0..n).map(|i| 0.3 + 0.1 * i as f64).collect();
        let u: Vec<f64> = (0..m.actuated.len())
            .map(|k| 0.05 * (k as f64 + 1.0))
            .collect();
        let eval = |q: &[f64], qd: &[f64], project: bool, stance: bool| -> Result<Value, String> {
            let mut cmd = Command::new(legs);
            cmd.args([
                "eval",
                &name,
                "--q",
                &join(q),
                "--qd",
                &join(qd),
                "--u",
                &join(&u),
                "--json",
            ]);
            if project {
                cmd.arg("--project");
            }
            if stance {
                cmd.arg("--stance");
            }
            serde_json::from_str(&run_command(&mut cmd, "legs eval")?).map_err(|e| e.to_string())
        };
        let mut ours = eval(&m.home, &qd, true, false)?;
        if let Some(f) = free {
            // The chart centred on the body: the free joint's six q zero (closing the
            // loops moves them a little, the body with the legs; the closures do not see
            // the chart, so they stay closed), ours again at that very state: with
            // contacts, the rates put on the held ones there too (two held points of one
            // rigid foot contradict each other where the foot turns about another line),
            // which leaves q as it is.
            let mut q = floats(&ours["q"]);
            q[f..f + 6].fill(0.0);
            ours = eval(&q, &floats(&ours["qd"]), stance, stance)?;
            let mut q = floats(&ours["q"]);
            if q[f..f + 6].iter().any(|&x| x != 0.0) {
                // The projection stepped after all: centred once more, not projected
                // (the rates then as they were; both sides are given this same state).
                q[f..f + 6].fill(0.0);
                ours = eval(&q, &floats(&ours["qd"]), false, stance)?;
            }
        }
        // Pinocchio's q̈ of a free flyer is v̇ (body frame): `legs eval` gives ours as
        // `vdot` beside the chart's q̈.
        let rates = |terms: &Value| match free {
            Some(_) => floats(&terms["vdot"]),
            None => floats(&terms["qdd"]),
        };
        let (q, qd, qdd) = (floats(&ours["q"]), floats(&ours["qd"]), rates(&ours));
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
        if let Some(f) = free {
            // Level at the origin: the world's gravity is the chart's, as `legs eval` has it.
            let _ = writeln!(file, "free {f} 0 0 0 1 0 0 0");
        }
        for (i, l) in m.links.iter().enumerate() {
            if free.is_some_and(|f| (f..f + 6).contains(&i)) {
                continue;
            }
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
        if stance {
            for c in &m.contacts {
                let _ = writeln!(file, "contact {}", c.name);
            }
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
        // NaN (never below a tolerance) where a side is missing or short.
        let off_from = |ours: &[f64], theirs: &[f64]| {
            if ours.is_empty() || theirs.len() != ours.len() {
                return f64::NAN;
            }
            let scale = ours.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            theirs
                .iter()
                .zip(ours)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f64, f64::max)
                / scale
        };
        let off = |theirs: &[f64]| off_from(&qdd, theirs);
        let converged = off(&floats(&pin["qdd"]));
        if converged.is_nan() || converged >= 1e-9 {
            eprintln!(
                "{name}: not timed: Pinocchio's constraintDynamics q̈ differs from ours by {converged:e} (relative); not timing different work"
            );
            continue;
        }
        let mut figures = SpatialFigures {
            converged: pin["median_ns"].as_f64().unwrap_or(f64::NAN),
            iterations: pin["iterations"].as_u64().unwrap_or(0),
            one_iteration: pin["one_iteration_ns"].as_f64().unwrap_or(f64::NAN),
            one_iteration_error: off(&floats(&pin["one_iteration_qdd"])),
            fewest: None,
            fewest_iterations: pin["fewest_iterations"].as_u64().unwrap_or(0),
            stance: None,
            stance_iterations: 0,
            stance_fewest: None,
            stance_fewest_iterations: 0,
            aba: None,
        };
        // The fewest iterations' q̈ equal to ours too, or that figure is not given.
        if off(&floats(&pin["fewest_qdd"])) < 1e-9 {
            figures.fewest = pin["fewest_ns"].as_f64();
        }
        if !pin["aba_qdd"].is_null() {
            let differs = off(&floats(&pin["aba_qdd"]));
            if differs < 1e-9 {
                figures.aba = pin["aba_ns"].as_f64();
                eprintln!(
                    "{name:<16} Pinocchio aba (nothing to hold) {}",
                    show(figures.aba)
                );
            } else {
                eprintln!(
                    "{name}: aba not timed: Pinocchio's aba q̈ differs from ours by {differs:e} (relative); not timing different work"
                );
            }
        }
        eprintln!(
            "{name:<16} Pinocchio constraintDynamics {:.0} ns ({} iterations, q̈ equal to ours to {converged:.1e}); at {} iterations {}; one iteration {:.0} ns (q̈ off by {:.1e})",
            figures.converged,
            figures.iterations,
            figures.fewest_iterations,
            show(figures.fewest),
            figures.one_iteration,
            figures.one_iteration_error
        );
        if stance {
            // Ours with every contact held (`legs eval --stance`), the same rule: timed
            // only where both compute the same thing.
            let held = rates(&ours["stance"]);
            let differs = off_from(&held, &floats(&pin["stance_qdd"]));
            if held.len() == n && differs < 1e-9 {
                figures.stance = pin["stance_median_ns"].as_f64();
                figures.stance_iterations = pin["stance_iterations"].as_u64().unwrap_or(0);
                figures.stance_fewest_iterations =
                    pin["stance_fewest_iterations"].as_u64().unwrap_or(0);
                if off_from(&held, &floats(&pin["stance_fewest_qdd"])) < 1e-9 {
                    figures.stance_fewest = pin["stance_fewest_ns"].as_f64();
                }
                eprintln!(
                    "{name:<16} Pinocchio constraintDynamics, every contact held: {:.0} ns ({} iterations, q̈ equal to ours to {differs:.1e}); at {} iterations {}",
                    figures.stance.unwrap_or(f64::NAN),
                    figures.stance_iterations,
                    figures.stance_fewest_iterations,
                    show(figures.stance_fewest)
                );
            } else {
                eprintln!(
                    "{name}: stance not timed: Pinocchio's q̈ with every contact held differs from ours by {differs:e} (relative){}",
                    ours["errors"]["stance"].as_str().map_or(String::new(), |e| format!("; ours: {e}"))
                );
            }
        }
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
