//! `sim`'s command line turned into checked settings: which controller, which reference,
//! how long, with which step and limits (the simulation itself is in `sim/mod.rs`).

use std::path::PathBuf;

use leg_models::dynamics::structure::{NotApplicable, Structure};
use leg_models::ShownNumber;
use xtask::cli::args::{ControllerArg, FeetArg, SimArgs, TrajectoryArg};
use xtask::cli::Error;

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Controller {
    FootFl,
    FootPd,
    JointFl,
    JointPd,
    Passive,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Trajectory {
    Step,
    Sine,
    Spin,
    MinJerk,
    Hold,
}

/// The most rows `trajectory.csv` holds (a few hundred megabytes of text at most).
pub(crate) const MAX_CSV_ROWS: u64 = 1_000_000;

/// Whether sample `k` of `n` goes into trajectory.csv: every `every`-th, and the last.
pub(crate) fn written(k: usize, n: usize, every: usize) -> bool {
    k.is_multiple_of(every) || k + 1 == n
}

pub struct Settings {
    pub(crate) controller: Option<Controller>,
    pub(crate) trajectory: Option<Trajectory>,
    /// The spin trajectory's motor speed, or a leg on the ground's forward speed.
    pub(crate) speed: Option<f64>,
    pub(crate) duration: f64,
    pub(crate) dt: f64,
    pub(crate) kp: Option<f64>,
    pub(crate) torque_limit: Option<f64>,
    pub(crate) out: Option<PathBuf>,
    /// Write every `every`-th sample to trajectory.csv.
    pub(crate) every: usize,
    /// Commanded apex height (legs with contacts).
    pub(crate) apex: Option<f64>,
    /// Serve the hopping controller's torques on stdin/stdout (the MuJoCo closed loop).
    pub(crate) serve: bool,
    /// A floating robot's push on its body (N, world), `None` for the default.
    pub(crate) push: Option<[f64; 3]>,
    /// When the push starts and how long it lasts (s).
    pub(crate) push_at: f64,
    pub(crate) push_for: f64,
    /// Whether `--push-at` or `--push-for` was given (they mean nothing on a leg).
    pub(crate) push_timed: bool,
    /// A floating robot's feet free to lift, slip and land (`--feet free`).
    pub(crate) free_feet: bool,
    /// Whether `--feet` was given (it means nothing on a leg).
    pub(crate) feet_given: bool,
}

impl Settings {
    /// The folder the files go to: `--out`, or `target/sim/NAME`.
    pub(crate) fn out_dir(&self, name: &str) -> PathBuf {
        self.out.clone().unwrap_or_else(|| {
            xtask::gen::workspace_root()
                .join("target")
                .join("sim")
                .join(name)
        })
    }

    /// The spin trajectory's motor speed (1 turn/s unless `--speed` says).
    pub(crate) fn spin_speed(&self) -> f64 {
        self.speed.unwrap_or(std::f64::consts::TAU)
    }

    /// Whether the run is passive (no torque): `--controller passive`.
    pub(crate) fn passive(&self) -> bool {
        self.controller == Some(Controller::Passive)
    }

    /// Whether `--kp` was given (the swing controllers' gain).
    pub(crate) fn kp_given(&self) -> bool {
        self.kp.is_some()
    }

    /// A controller or trajectory named for the swing leg, which a leg on the ground does
    /// not run.
    pub(crate) fn swing_only(&self) -> Option<&'static str> {
        match (self.controller, self.trajectory) {
            (Some(c), _) if c != Controller::Passive => Some(c.name()),
            (_, Some(t)) => Some(t.name()),
            _ => None,
        }
    }
}

impl Controller {
    pub(crate) fn name(self) -> &'static str {
        match self {
            Controller::FootFl => "foot-fl",
            Controller::FootPd => "foot-pd",
            Controller::JointFl => "joint-fl",
            Controller::JointPd => "joint-pd",
            Controller::Passive => "passive",
        }
    }

    pub(crate) fn in_foot_space(self) -> bool {
        matches!(self, Controller::FootFl | Controller::FootPd)
    }

    /// Whether the controller applies to a leg of this structure, and why not.
    pub(crate) fn applies(self, s: &Structure) -> Result<(), NotApplicable> {
        match self {
            Controller::FootFl | Controller::FootPd => s.foot_space(),
            Controller::JointFl | Controller::JointPd => s.joint_space(),
            Controller::Passive => Ok(()),
        }
    }
}

impl Trajectory {
    pub(crate) fn name(self) -> &'static str {
        match self {
            Trajectory::Step => "step",
            Trajectory::Sine => "sine",
            Trajectory::Spin => "spin",
            Trajectory::MinJerk => "min-jerk",
            Trajectory::Hold => "hold",
        }
    }
}

impl Settings {
    pub fn from_args(a: &SimArgs) -> Result<Settings, Error> {
        let controller = a.controller.map(|c| match c {
            ControllerArg::FootFl => Controller::FootFl,
            ControllerArg::FootPd => Controller::FootPd,
            ControllerArg::JointFl => Controller::JointFl,
            ControllerArg::JointPd => Controller::JointPd,
            ControllerArg::Passive => Controller::Passive,
        });
        let trajectory = a.trajectory.map(|t| match t {
            TrajectoryArg::Step => Trajectory::Step,
            TrajectoryArg::Sine => Trajectory::Sine,
            TrajectoryArg::Spin => Trajectory::Spin,
            TrajectoryArg::MinJerk => Trajectory::MinJerk,
            TrajectoryArg::Hold => Trajectory::Hold,
        });
        let free_feet = a.feet == Some(FeetArg::Free);
        // Free feet step at the velocity level, first order: half a millisecond by
        // default, where Cassie under the balance QP is stable (at 1 ms it diverges).
        let dt = a.dt.unwrap_or(if free_feet { 5e-4 } else { 1e-3 });
        // Not one step: nothing would be simulated, and the report would show nothing.
        if a.duration < dt {
            return Err(Error::usage(format!(
                "`--duration {} s` is shorter than one step (`--dt {} s`): nothing would be simulated",
                ShownNumber(a.duration),
                ShownNumber(dt)
            )));
        }
        if a.duration / dt > 5e6 {
            return Err(Error::usage(format!(
                "{} s at dt = {} s is more than 5 million steps",
                ShownNumber(a.duration),
                ShownNumber(dt)
            )));
        }
        // trajectory.csv is bounded as the record is: a run of 5 million steps would write
        // about a gigabyte of text; such a run names the --every that fits.
        let steps = (a.duration / dt).round() as u64;
        let every = a.every.max(1);
        let rows = steps / every + 2;
        if rows > MAX_CSV_ROWS {
            return Err(Error::usage(format!(
                "{} s at dt = {} s with --every {every} writes {rows} rows to trajectory.csv, more than the file's limit of {MAX_CSV_ROWS}: pass --every {} or more",
                ShownNumber(a.duration),
                ShownNumber(dt),
                steps.div_ceil(MAX_CSV_ROWS - 2)
            )));
        }
        let settings = Settings {
            controller,
            trajectory,
            speed: a.speed,
            duration: a.duration,
            dt,
            kp: a.kp,
            torque_limit: a.torque_limit,
            out: a.out.clone(),
            every: every as usize,
            apex: a.apex,
            serve: a.serve,
            push: match &a.push {
                None => None,
                Some(text) => {
                    let f = xtask::cli::numbers("--push", text, 3, "a force FX,FY,FZ in N")?;
                    if f.iter().any(|x| x.abs() > 1e6) {
                        return Err(Error::usage(format!(
                            "--push {text}: a force of at most 1e6 N along each axis"
                        )));
                    }
                    Some([f[0], f[1], f[2]])
                }
            },
            push_at: a.push_at.unwrap_or(0.5),
            push_for: a.push_for.unwrap_or(0.1),
            push_timed: a.push_at.is_some() || a.push_for.is_some(),
            free_feet,
            feet_given: a.feet.is_some(),
        };
        if let (Some(c), Some(t)) = (controller, trajectory) {
            settings.check_pair(c, t)?;
        }

        Ok(settings)
    }

    pub(crate) fn check_pair(&self, c: Controller, t: Trajectory) -> Result<(), Error> {
        let fits = match t {
            Trajectory::Hold => true,
            Trajectory::Step => c.in_foot_space(),
            _ => !c.in_foot_space() && c != Controller::Passive,
        };
        if fits || c == Controller::Passive && t == Trajectory::Hold {
            Ok(())
        } else {
            Err(Error::usage(format!(
                "trajectory `{}` does not suit controller `{}` (foot controllers: step, hold; joint controllers: sine, spin, min-jerk, hold)",
                t.name(),
                c.name()
            )))
        }
    }

    /// The controller and trajectory for a leg of this structure, and why they were
    /// chosen. A controller asked for that does not apply is bad input.
    pub(crate) fn resolve(
        &self,
        model: &str,
        s: &Structure,
    ) -> Result<(Controller, Trajectory, String), Error> {
        let (controller, why) = match self.controller {
            Some(c) => {
                c.applies(s).map_err(|e| {
                    Error::usage(format!(
                        "controller `{}` does not apply to {model}: {e}",
                        c.name()
                    ))
                })?;
                (c, "asked for".to_string())
            }
            None => match (s.foot_space(), s.joint_space()) {
                (Ok(()), _) => (
                    Controller::FootFl,
                    "default: the motors can place the foot".to_string(),
                ),
                (Err(foot), Ok(())) => (
                    Controller::JointFl,
                    format!("default: joint-space tracking of the motors, because {foot}"),
                ),
                (Err(_), Err(joint)) => (
                    Controller::Passive,
                    format!("default: no controller applies ({joint})"),
                ),
            },
        };
        let trajectory = match self.trajectory {
            Some(t) => {
                self.check_pair(controller, t)?;
                t
            }
            None if controller.in_foot_space() => Trajectory::Step,
            None if controller == Controller::Passive => Trajectory::Hold,
            // One motor turning a crank: spin it.
            None if s.motors == 1 => Trajectory::Spin,
            None => Trajectory::Sine,
        };
        // Settings that mean nothing here are refused, not ignored (the new user's trial).
        if self.apex.is_some() {
            return Err(Error::usage(format!(
                "--apex is the hopping controller's apex height; {model} has no contacts (it is simulated in the air)"
            )));
        }
        // (A zero speed is refused as such where the spin is built.)
        if self.speed.is_some_and(|v| v != 0.0) && trajectory != Trajectory::Spin {
            return Err(Error::usage(format!(
                "--speed sets the spin trajectory's motor speed; the `{}` trajectory has none (add --trajectory spin, or leave out --speed)",
                trajectory.name()
            )));
        }
        if self.kp.is_some() && controller == Controller::Passive {
            return Err(Error::usage(
                "--kp sets a controller's stiffness; with --controller passive there is none (leave out one or the other)",
            ));
        }
        Ok((controller, trajectory, why))
    }
}
