//! A simulated second of each standing, pushed floating robot, ours beside MuJoCo's
//! `mj_step` at the same time step (`cargo xtask bench --mujoco`).
//!
//! `legs sim ROBOT --dt 0.0005 --duration 1` records a run (the balance QP closing the
//! loop, the default push on the body); criterion replays its torques and pushes through
//! `robot::pushed_stance_step_by` (`ROBOT/second-ours`, RK4, and `second-ours-euler`),
//! and `xtask/mujoco_step_bench.py` replays the same ones through `mujoco.rollout` on the
//! exported MJCF, RK4 and MuJoCo's default Euler. The controller is timed in neither.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

/// MuJoCo Menagerie's Cassie's time step, the issue's.
pub const DT: &str = "0.0005";
const SCRIPT: &str = "xtask/mujoco_step_bench.py";

/// Where the recorded runs, the exports and MuJoCo's figures go.
pub fn dir(root: &Path) -> PathBuf {
    crate::cli::target_dir(root).join("step-bench")
}

/// Records `sim`'s run of each robot in `robots` (under [`dir`]`/ROBOT/`) and exports its
/// MJCF beside it; the robots `sim` runs for the whole second (a robot with fewer than
/// three contact points, or one whose foot slips under the push, is left out and said).
pub fn record(root: &Path, legs: &Path, robots: &[String]) -> Result<Vec<String>, String> {
    let out = dir(root);
    let mut kept = Vec::new();
    for name in robots {
        let run = out.join(name);
        // An old run of a robot that no longer runs must not be replayed.
        let _ = std::fs::remove_dir_all(&run);
        let status = Command::new(legs)
            .args(["sim", name, "--dt", DT, "--duration", "1", "--out"])
            .arg(&run)
            .current_dir(root)
            .output()
            .map_err(|e| format!("cannot run `legs sim {name}`: {e}"))?;
        if !status.status.success() {
            let _ = std::fs::remove_dir_all(&run);
            eprintln!(
                "note: `{name}` not timed over a simulated second: {}",
                String::from_utf8_lossy(&status.stderr).trim()
            );
            continue;
        }
        let spec = crate::gen::load_spec(
            root,
            &root
                .join(crate::gen::SPECS_DIR)
                .join(format!("{name}.toml")),
        )?;
        let model = crate::gen::model::build(&spec).map_err(|e| e.to_string())?;
        crate::cli::write_atomic(
            &out.join(format!("{name}.xml")),
            &crate::commands::export::spatial::mjcf(&model),
        )?;
        kept.push(name.clone());
    }
    Ok(kept)
}

/// MuJoCo's figures of each recorded robot (the JSON `mujoco_step_bench.py` writes).
pub fn run(root: &Path, legs: &Path, robots: &[String]) -> Result<BTreeMap<String, Value>, String> {
    let py = crate::gen::python(root)?;
    let out = dir(root);
    let mut figures = BTreeMap::new();
    for name in robots {
        let json = out.join(format!("{name}.mujoco.json"));
        let status = Command::new(&py)
            .arg(root.join(SCRIPT))
            .arg(legs)
            .arg(name)
            .arg(out.join(format!("{name}.xml")))
            .arg(out.join(name).join("trajectory.csv"))
            .arg(&json)
            .current_dir(root)
            .status()
            .map_err(|e| format!("cannot run {SCRIPT}: {e}"))?;
        if !status.success() {
            return Err(format!("{SCRIPT} failed on `{name}` ({status})"));
        }
        let text =
            std::fs::read_to_string(&json).map_err(|e| format!("{}: {e}", json.display()))?;
        figures.insert(
            name.clone(),
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", json.display()))?,
        );
    }
    Ok(figures)
}
