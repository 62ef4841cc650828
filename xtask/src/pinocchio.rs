//! Pinocchio's pipeline for the same legs, timed in C++ (`cargo xtask bench --pinocchio`).
//!
//! Installs `pin` (its C++ headers and libraries) and Eigen's headers from PyPI into the
//! generation step's virtual environment, compiles `xtask/pinocchio_bench.cpp` with g++
//! at -O3, and runs it on each leg (built with Pinocchio's API from the spec). Before
//! timing, Pinocchio's `M`, `N` and `q̈` must agree with the generated model's (from
//! `legs eval --json`), so that both compute the same thing.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

use crate::gen;
use crate::model::{Model, Param};

const REQUIREMENTS: &str = "xtask/requirements-pinocchio.txt";
const SOURCE: &str = "xtask/pinocchio_bench.cpp";

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
            v(&l.inertia),
            armature,
            v(&l.damping)
        );
    }
    for c in &m.closures {
        let _ = writeln!(
            out,
            "closure {} {} {:?} {:?} {} {:?} {:?}",
            c.name,
            c.a.link,
            v(&c.a.point[0]),
            v(&c.a.point[1]),
            c.b.link,
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

/// The median time (ns) of Pinocchio's pipeline for every model with a fixed-size
/// instance in the C++ program.
pub fn run(root: &Path) -> Result<BTreeMap<String, f64>, String> {
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
    let prefix = run_command(
        Command::new(&py).args(["-c", "import sysconfig, os; print(os.path.join(sysconfig.get_paths()['purelib'], 'cmeel.prefix'))"]),
        "python",
    )?;
    let prefix = PathBuf::from(prefix.trim());
    let target = crate::cli::target_dir(root);
    let dir = target.join("pinocchio");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let bin = dir.join("pinocchio_bench");
    eprintln!("==> g++ -O3 {SOURCE}");
    let inc = prefix.join("include");
    let lib = prefix.join("lib");
    // The definitions Pinocchio's CMake configuration exports to its users.
    run_command(
        Command::new("g++")
            .args(["-O3", "-DNDEBUG", "-std=c++17"])
            .args([
                "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
                "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
                "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
                "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
                "-DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION",
            ])
            .arg(format!("-I{}", inc.join("eigen3").display()))
            .arg(format!("-I{}", inc.display()))
            .arg(root.join(SOURCE))
            .arg("-o")
            .arg(&bin)
            .arg(format!("-L{}", lib.display()))
            .arg("-lpinocchio_default")
            .arg(format!("-Wl,-rpath,{}", lib.display())),
        "g++ (Debian: apt-get install g++)",
    )?;
    let target_legs = target.join("debug").join("legs");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    run_command(
        Command::new(cargo)
            .args([
                "build",
                "--quiet",
                "-p",
                "xtask",
                "--features",
                "models",
                "--bin",
                "legs",
            ])
            .current_dir(root),
        "cargo build --bin legs",
    )?;
    let mut out = BTreeMap::new();
    for name in crate::cli::model_names(root)? {
        let spec = gen::load_spec(
            root,
            &root.join(gen::SPECS_DIR).join(format!("{name}.toml")),
        )?;
        let m = crate::model::build(&spec).map_err(|e| e.to_string())?;
        let qd: Vec<f64> = (0..m.links.len()).map(|i| 0.1 * (i as f64 + 1.0)).collect();
        let file = dir.join(format!("{name}.leg"));
        crate::cli::write_atomic(&file, &leg_file(&m, &qd))?;
        let pin_out = match run_command(Command::new(&bin).arg(&file), "pinocchio_bench") {
            Ok(text) => text,
            Err(e) if e.contains("no fixed-size instance") => continue,
            Err(e) => return Err(e),
        };
        let pin: Value = serde_json::from_str(&pin_out)
            .map_err(|e| format!("pinocchio_bench printed {pin_out}: {e}"))?;
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
                "--json",
            ]),
            "legs eval",
        )?)
        .map_err(|e| e.to_string())?;
        for key in ["M", "N", "qdd"] {
            let flat = |v: &Value| -> Vec<f64> {
                match v {
                    Value::Array(a) => a
                        .iter()
                        .flat_map(|x| match x {
                            Value::Array(r) => {
                                r.iter().filter_map(Value::as_f64).collect::<Vec<_>>()
                            }
                            x => x.as_f64().into_iter().collect(),
                        })
                        .collect(),
                    _ => Vec::new(),
                }
            };
            let (a, b) = (flat(&pin[key]), flat(&ours[key]));
            let scale = b.iter().fold(0.0f64, |s, x| s.max(x.abs())).max(1e-300);
            let diff = a
                .iter()
                .zip(&b)
                .fold(0.0f64, |s, (x, y)| s.max((x - y).abs()));
            if a.len() != b.len() || diff > 1e-9 * scale {
                return Err(format!("{name}: Pinocchio's {key} differs from ours ({diff:e}); not timing different things"));
            }
        }
        let ns = pin["median_ns"].as_f64().ok_or("no median_ns")?;
        eprintln!("{name:<16} Pinocchio pipeline {ns:.0} ns (M, N, q̈ agree with ours)");
        out.insert(name, ns);
    }
    Ok(out)
}
