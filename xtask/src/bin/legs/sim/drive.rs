//! How `sim` drives a leg under the swing-leg controllers, in the air or on the ground
//! where the hopping controller does not apply: the controller `--controller` names (or the
//! one the leg's structure allows), its reference, the start on that reference, and the
//! tracking error the outputs report.

use leg_models::assembly::{
    assemble_along, consistent_velocity, foot_inverse, project_position, Tolerance,
};
use leg_models::control::reference::{MinimumJerk, Ramp, Reference, Setpoint, Sinusoid, StepCycle};
use leg_models::control::{
    foot_inertias, joint_inertias, ControlError, FootFeedbackLinearization, FootPdGravity, Gains,
    JointFeedbackLinearization, PdGravity, Saturated,
};
use leg_models::dynamics::structure::Structure;
use leg_models::nalgebra::SVector;
use leg_models::simulate::{State, TorqueSource};
use leg_models::LegModel;
use serde_json::{json, Value};
use xtask::cli::Error;

use super::max;
use super::settings::{Controller, Settings, Trajectory};
use crate::report::{self, Series};

/// The foot references `sim` offers, in the foot's `ND` coordinates.
#[derive(Clone, Copy)]
pub(crate) enum FootRef<const ND: usize> {
    /// The step cycle's ellipse, drawn in the plane of `forward` (its stride) and `up`
    /// (its height): the base's x and y on a planar leg, where the ellipse is the cycle's
    /// own; on a spatial leg, `up` against gravity and `forward` the base's x made square
    /// to it.
    Cycle {
        cycle: StepCycle<f64>,
        origin: SVector<f64, ND>,
        forward: SVector<f64, ND>,
        up: SVector<f64, ND>,
    },
    Hold(SVector<f64, ND>),
}

impl<const ND: usize> Reference<f64, ND> for FootRef<ND> {
    fn sample(&self, t: f64) -> Setpoint<f64, ND> {
        match self {
            FootRef::Cycle {
                cycle,
                origin,
                forward,
                up,
            } => {
                let s = cycle.sample(t);
                let at = |v: SVector<f64, 2>| forward * v[0] + up * v[1];
                Setpoint {
                    position: origin + at(s.position),
                    velocity: at(s.velocity),
                    acceleration: at(s.acceleration),
                }
            }
            FootRef::Hold(p) => Setpoint {
                position: *p,
                velocity: SVector::zeros(),
                acceleration: SVector::zeros(),
            },
        }
    }
}

/// The joint references `sim` offers.
#[derive(Clone, Copy)]
pub(crate) enum JointRef<const NU: usize> {
    Sine(Sinusoid<f64, NU>),
    Spin(Ramp<f64, NU>),
    MinJerk(MinimumJerk<f64, NU>),
}

impl<const NU: usize> Reference<f64, NU> for JointRef<NU> {
    fn sample(&self, t: f64) -> Setpoint<f64, NU> {
        match self {
            JointRef::Sine(s) => s.sample(t),
            JointRef::Spin(r) => r.sample(t),
            JointRef::MinJerk(m) => m.sample(t),
        }
    }
}

/// One of the controllers, as a torque source.
pub(crate) enum AnyController<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
> {
    FootFl(FootFeedbackLinearization<L, f64, FootRef<ND>, NQ, NC, NU, ND, NP>),
    FootPd(FootPdGravity<L, f64, FootRef<ND>, NQ, NC, NU, ND, NP>),
    JointFl(JointFeedbackLinearization<L, f64, JointRef<NU>, NQ, NC, NU>),
    JointPd(PdGravity<L, f64, JointRef<NU>, NQ, NC, NU>),
    Passive,
}

impl<
        L: LegModel<NQ, NC, NU, ND, NP>,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const ND: usize,
        const NP: usize,
    > TorqueSource<f64, NQ, NU> for AnyController<L, NQ, NC, NU, ND, NP>
{
    fn torque(&mut self, t: f64, s: &State<f64, NQ>) -> Result<SVector<f64, NU>, ControlError> {
        match self {
            AnyController::FootFl(c) => c.torque(t, s),
            AnyController::FootPd(c) => c.torque(t, s),
            AnyController::JointFl(c) => c.torque(t, s),
            AnyController::JointPd(c) => c.torque(t, s),
            AnyController::Passive => Ok(SVector::zeros()),
        }
    }
}

/// The step cycle's plane through the foot's home: `(origin, forward, up)`. A planar
/// leg's is the base's own x and y, the ellipse the cycle's (`origin` zero). A spatial
/// leg's `up` is against its gravity parameter, `forward` the base's x made square to it
/// (its y where x is vertical), and the ellipse is centred on the foot's home.
fn step_plane<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    p: &L::Params<f64>,
    foot_home: &SVector<f64, ND>,
) -> (SVector<f64, ND>, SVector<f64, ND>, SVector<f64, ND>) {
    let axis = |i: usize| SVector::<f64, ND>::from_fn(|r, _| if r == i { 1.0 } else { 0.0 });
    if ND == 2 {
        return (SVector::zeros(), axis(0), axis(1));
    }
    use leg_models::Parameters;
    let names = <L::Params<f64> as Parameters<f64>>::NAMES;
    let g = SVector::<f64, ND>::from_fn(|r, _| {
        names
            .iter()
            .position(|n| *n == ["gravity_x", "gravity_y", "gravity_z"][r])
            .and_then(|i| p.get(i))
            .unwrap_or(0.0)
    });
    // Without gravity, the base's z is up.
    let up = if g.norm() > 0.0 {
        -g / g.norm()
    } else {
        axis(2)
    };
    let square = |v: SVector<f64, ND>| v - up * up.dot(&v);
    let forward = [square(axis(0)), square(axis(1))]
        .into_iter()
        .find(|v| v.norm() > 1e-6)
        .map(|v| v / v.norm())
        .unwrap_or(axis(0));
    (*foot_home, forward, up)
}

/// The controller within `--torque-limit`, as a torque source.
pub(crate) type Source<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
> = Saturated<AnyController<L, NQ, NC, NU, ND, NP>, f64, NU>;

/// How a leg is driven by one of the swing-leg controllers: what it tracks, from where.
pub(crate) struct Drive<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
> {
    pub(crate) kind: Controller,
    pub(crate) trajectory: Trajectory,
    /// Why this controller (asked for, or the default and the reason).
    pub(crate) choice: String,
    /// The gains, as the summary shows them.
    pub(crate) gains: String,
    pub(crate) structure: Structure,
    /// On the reference, at rest for foot tasks, at the reference's rates for joint tasks.
    pub(crate) initial: State<f64, NQ>,
    foot_ref: FootRef<ND>,
    joint_ref: JointRef<NU>,
    /// The steady state's tracking error is counted from here (s).
    pub(crate) settle: f64,
    leg: std::marker::PhantomData<L>,
}

impl<
        L: LegModel<NQ, NC, NU, ND, NP>,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const ND: usize,
        const NP: usize,
    > Drive<L, NQ, NC, NU, ND, NP>
{
    /// The drive `s` asks for on leg `L` with parameters `p` and its controller within
    /// `--torque-limit`, or why there is none.
    pub(crate) fn new(
        s: &Settings,
        p: &L::Params<f64>,
    ) -> Result<(Self, Source<L, NQ, NC, NU, ND, NP>), Error> {
        drive::<L, NQ, NC, NU, ND, NP>(s, p)
    }

    /// Whether the controller tracks the foot (else the motors' angles, or nothing).
    pub(crate) fn foot_task(&self) -> bool {
        self.kind.in_foot_space()
    }

    /// Whether there is a reference at all (not `passive`).
    pub(crate) fn tracked(&self) -> bool {
        self.kind != Controller::Passive
    }

    /// The tracking error's unit.
    pub(crate) fn unit(&self) -> &'static str {
        if self.foot_task() {
            "m"
        } else {
            "rad"
        }
    }

    /// The tracking error at time `t` in pose `q`: the foot's distance from its reference,
    /// or the largest motor angle's distance from its own.
    pub(crate) fn error(&self, p: &L::Params<f64>, t: f64, q: &SVector<f64, NQ>) -> f64 {
        if self.foot_task() {
            (L::foot_position(q, p) - self.foot_ref.sample(t).position).norm()
        } else {
            let r = self.joint_ref.sample(t).position;
            max((0..NU).map(|k| (r[k] - q[L::ACTUATED[k]]).abs()))
        }
    }

    /// The foot's reference at `t`, which the report draws (foot tasks only).
    pub(crate) fn drawn_reference(&self, t: f64) -> Option<Vec<f64>> {
        self.foot_task()
            .then(|| self.foot_ref.sample(t).position.iter().copied().collect())
    }

    /// trajectory.csv's last columns: the foot, the reference and the error.
    pub(crate) fn csv_header(&self, csv: &mut String) {
        const AXES: [&str; 3] = ["x", "y", "z"];
        for a in &AXES[..ND] {
            csv.push_str(&format!(",foot_{a}"));
        }
        if self.foot_task() {
            for a in &AXES[..ND] {
                csv.push_str(&format!(",ref_{a}"));
            }
        } else if self.tracked() {
            for &a in &L::ACTUATED {
                csv.push_str(&format!(",ref_{}", L::JOINT_NAMES[a]));
            }
        }
        if self.tracked() {
            csv.push_str(",error");
        }
    }

    /// Those columns' values at `t` in pose `q`.
    pub(crate) fn csv_row(
        &self,
        p: &L::Params<f64>,
        t: f64,
        q: &SVector<f64, NQ>,
        row: &mut String,
    ) {
        let values = L::foot_position(q, p).iter().copied().collect::<Vec<_>>();
        let reference: Vec<f64> = if self.foot_task() {
            self.foot_ref.sample(t).position.iter().copied().collect()
        } else if self.tracked() {
            self.joint_ref.sample(t).position.iter().copied().collect()
        } else {
            Vec::new()
        };
        for v in values.iter().chain(&reference) {
            row.push_str(&format!(",{v}"));
        }
        if self.tracked() {
            row.push_str(&format!(",{}", self.error(p, t, q)));
        }
    }

    /// The summary's `tracking_error` (`null` without a reference), from the errors at
    /// the times `t`.
    pub(crate) fn tracking_summary(&self, t: &[f64], errors: &[f64]) -> Value {
        if !self.tracked() {
            return json!(null);
        }
        let steady = self.steady(t, errors);
        json!({
            "unit": self.unit(),
            "max": max(errors.iter().copied()),
            "rms": rms(errors),
            "steady_state_from_s": self.settle,
            "steady_state_max": max(steady.iter().copied()),
            "steady_state_rms": rms(&steady),
        })
    }

    /// The errors from the settling time on.
    pub(crate) fn steady(&self, t: &[f64], errors: &[f64]) -> Vec<f64> {
        t.iter()
            .zip(errors)
            .filter(|(t, _)| **t >= self.settle)
            .map(|(_, e)| *e)
            .collect()
    }

    /// The report's tracking-error plot (`None` without a reference).
    pub(crate) fn tracking_plot(&self, t: &[f64], errors: &[f64]) -> Option<Series> {
        if !self.tracked() {
            return None;
        }
        let what = if self.foot_task() {
            "the distance from the foot to its reference"
        } else {
            "the largest motor angle's distance from its reference"
        };
        Some(
            Series::new("Tracking error", t, vec![("error".into(), errors.to_vec())])
                .axis("tracking error", self.unit())
                .caption(&format!(
                    "{}, {what}; steady state counted from t = {} s.",
                    if self.foot_task() {
                        "|p_foot − p_ref|"
                    } else {
                        "max |θ − θ_ref|"
                    },
                    self.settle
                )),
        )
    }

    /// The summary's `structure`.
    pub(crate) fn structure_summary(&self) -> Value {
        json!({
            "joints": NQ,
            "closure_rows": NC,
            "redundant_rows": self.structure.redundant_rows,
            "mobility": self.structure.mobility,
            "motors": NU,
        })
    }

    /// The spin trajectory's motor speed (`null` for other references).
    pub(crate) fn spin_speed(&self, s: &Settings) -> Value {
        if self.trajectory == Trajectory::Spin {
            json!(s.spin_speed())
        } else {
            json!(null)
        }
    }

    /// The title's words for the controller and its reference.
    pub(crate) fn title(&self) -> String {
        if self.tracked() {
            format!("{}, {}", self.kind.name(), self.trajectory.name())
        } else {
            self.kind.name().to_string()
        }
    }
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn drive<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    s: &Settings,
    p: &L::Params<f64>,
) -> Result<(Drive<L, NQ, NC, NU, ND, NP>, Source<L, NQ, NC, NU, ND, NP>), Error> {
    let tol = Tolerance::default();
    let fail =
        |what: &str, e: &dyn std::fmt::Display| Error::Failed(format!("{}: {what}: {e}", L::NAME));
    let mut home = SVector::<f64, NQ>::from_column_slice(&L::HOME);
    project_position::<L, f64, NQ, NC, NU>(p, &mut home, &tol)
        .map_err(|e| fail("the home pose does not assemble", &e))?;
    let structure = Structure::of::<L, NQ, NC, NU>();
    let (controller_kind, trajectory, choice) = s.resolve(L::NAME, &structure)?;
    let theta_home = SVector::<f64, NU>::from_fn(|k, _| home[L::ACTUATED[k]]);
    let foot_home = L::foot_position(&home, p);
    let kp = s.kp.unwrap_or(if controller_kind.in_foot_space() {
        400.0
    } else {
        100.0
    });
    let kd = 2.0 * kp.sqrt();

    let foot_ref = match trajectory {
        Trajectory::Step => {
            let (origin, forward, up) = step_plane::<L, NQ, NC, NU, ND, NP>(p, &foot_home);
            let center = if ND == 2 {
                SVector::<f64, 2>::new(foot_home[0], foot_home[1])
            } else {
                SVector::zeros()
            };
            FootRef::Cycle {
                cycle: StepCycle {
                    center,
                    half_stride: 0.03,
                    half_height: 0.015,
                    period: 0.5,
                },
                origin,
                forward,
                up,
            }
        }
        _ => FootRef::Hold(foot_home),
    };
    if s.speed == Some(0.0) {
        return Err(Error::usage(format!(
            "--speed 0: under the swing-leg controllers ({}) the speed is the spin trajectory's motor speed, which is not zero",
            L::NAME
        )));
    }
    let joint_ref = match trajectory {
        Trajectory::Spin => JointRef::Spin(Ramp {
            start: theta_home,
            rate: SVector::from_element(s.spin_speed()),
        }),
        Trajectory::MinJerk => JointRef::MinJerk(MinimumJerk {
            start: theta_home,
            goal: theta_home.add_scalar(0.2),
            t0: 0.5,
            duration: 1.0,
        }),
        Trajectory::Sine => JointRef::Sine(Sinusoid {
            offset: theta_home,
            amplitude: SVector::from_element(0.1),
            frequency: SVector::from_element(1.0),
            phase: SVector::from_fn(|k, _| k as f64),
        }),
        _ => JointRef::Sine(Sinusoid {
            offset: theta_home,
            amplitude: SVector::zeros(),
            frequency: SVector::zeros(),
            phase: SVector::zeros(),
        }),
    };

    // Start on the reference, at rest for foot tasks, at the reference's rates for joint tasks.
    let initial = if controller_kind.in_foot_space() {
        let q = foot_inverse::<L, f64, NQ, NC, NU, ND, NP>(
            p,
            &foot_ref.sample(0.0).position,
            &home,
            &tol,
        )
        .map_err(|e| fail("the foot reference's start", &e))?;
        State {
            q,
            qd: SVector::zeros(),
        }
    } else if controller_kind == Controller::Passive {
        State {
            q: home,
            qd: SVector::zeros(),
        }
    } else {
        let r0 = joint_ref.sample(0.0);
        // Along the home pose's branch, so that the start is in its assembly mode.
        let q = assemble_along::<L, f64, NQ, NC, NU>(p, &home, &r0.position, 0.05, &tol)
            .map_err(|e| fail("the joint reference's start", &e))?;
        let qd = consistent_velocity::<L, f64, NQ, NC, NU>(p, &q, &r0.velocity)
            .map_err(|e| fail("the joint reference's start", &e))?;
        State { q, qd }
    };

    let not_applicable = |e: ControlError| fail("the controller", &e);
    let (controller, gains_text): (AnyController<L, NQ, NC, NU, ND, NP>, String) =
        match controller_kind {
            Controller::FootFl => (
                AnyController::FootFl(
                    FootFeedbackLinearization::new(*p, Gains::new(kp, kd), foot_ref)
                        .map_err(not_applicable)?,
                ),
                format!(
                    "k_p = {} 1/s², k_d = {} 1/s",
                    report::significant(kp, 4),
                    report::significant(kd, 4)
                ),
            ),
            Controller::FootPd => {
                let foot_inertia = foot_inertias::<L, f64, NQ, NC, NU, ND, NP>(p, &home)
                    .map_err(|e| fail("the foot's inertia at home", &e))?;
                let g = Gains {
                    kp: foot_inertia * kp,
                    kd: foot_inertia * kd,
                };
                (
                    AnyController::FootPd(
                        FootPdGravity::new(*p, g, foot_ref).map_err(not_applicable)?,
                    ),
                    format!(
                        "K = {:?} N/m, D = {:?} N s/m (Λ × {kp}, Λ × {kd:.3})",
                        g.kp.as_slice(),
                        g.kd.as_slice()
                    ),
                )
            }
            Controller::JointFl => (
                AnyController::JointFl(
                    JointFeedbackLinearization::new(*p, Gains::new(kp, kd), joint_ref)
                        .map_err(not_applicable)?,
                ),
                format!(
                    "k_p = {} 1/s², k_d = {} 1/s",
                    report::significant(kp, 4),
                    report::significant(kd, 4)
                ),
            ),
            Controller::JointPd => {
                let joint_inertia = joint_inertias::<L, f64, NQ, NC, NU>(p, &home)
                    .map_err(|e| fail("the motors' inertia at home", &e))?;
                let g = Gains {
                    kp: joint_inertia * kp,
                    kd: joint_inertia * kd,
                };
                (
                    AnyController::JointPd(
                        PdGravity::new(*p, g, joint_ref).map_err(not_applicable)?,
                    ),
                    format!(
                        "k_p = {:?} N m/rad, k_d = {:?} N m s/rad",
                        g.kp.as_slice(),
                        g.kd.as_slice()
                    ),
                )
            }
            Controller::Passive => (AnyController::Passive, "none".to_string()),
        };
    let limit = s.torque_limit.unwrap_or(f64::INFINITY);
    let source = Saturated::new(controller, SVector::from_element(limit))
        .map_err(|e| Error::usage(format!("`--torque-limit`: {e}")))?;
    let drive = Drive {
        kind: controller_kind,
        trajectory,
        choice,
        gains: gains_text,
        structure,
        initial,
        foot_ref,
        joint_ref,
        settle: 1.0f64.min(s.duration / 2.0),
        leg: std::marker::PhantomData,
    };
    Ok((drive, source))
}
