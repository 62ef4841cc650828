//! `cargo xtask sim`: simulate a leg under a controller; write `trajectory.csv`,
//! `summary.json` and a self-contained `report.html`.

use std::fmt::Write as _;

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
use leg_models::simulate::{Sample, Simulator};
use leg_models::simulate::{State, StepOptions, TorqueSource};
use leg_models::LegModel;
use serde_json::json;
use xtask::cli::progress::Progress;
use xtask::cli::{check_targets, write_all, Error};

use crate::report::{self, quantity as report_quantity, Report, Series};

pub mod hop;
mod settings;

pub use settings::Settings;
use settings::{written, Controller, Trajectory};

/// The foot references `sim` offers, in the foot's `ND` coordinates.
#[derive(Clone, Copy)]
enum FootRef<const ND: usize> {
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
enum JointRef<const NU: usize> {
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
enum AnyController<
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

/// A torque source that moves a progress bar: the simulator asks for torques once per
/// step (torques are held over the step), at the step's start time.
struct WithProgress<S> {
    inner: S,
    progress: Progress,
    dt: f64,
}

impl<S: TorqueSource<f64, NQ, NU>, const NQ: usize, const NU: usize> TorqueSource<f64, NQ, NU>
    for WithProgress<S>
{
    fn torque(&mut self, t: f64, s: &State<f64, NQ>) -> Result<SVector<f64, NU>, ControlError> {
        self.progress.set((t / self.dt).round() as u64);
        self.inner.torque(t, s)
    }
}

pub(crate) fn max(xs: impl Iterator<Item = f64>) -> f64 {
    xs.fold(0.0, f64::max)
}

/// A point of the drawing, by what the generated functions call it.
pub(crate) enum Member {
    Joint(usize),
    Tip(usize),
    /// A column of `closure_points`.
    Closure(usize),
    Foot,
}

/// The leg drawn at one instant: each link as the rigid body of its points (`members`,
/// from [`body_points`]), its joints and tips, the closure points and the foot.
pub(crate) fn frame_at<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    p: &L::Params<f64>,
    members: &[Vec<Member>],
    t: f64,
    q: &SVector<f64, NQ>,
    reference: Option<Vec<f64>>,
) -> report::Frame {
    let joints = L::joint_positions(q, p);
    let tips = L::link_tips(q, p);
    let closures = L::closure_points(q, p);
    let f = L::foot_position(q, p);
    let at = |m: &Member| -> Vec<f64> {
        match *m {
            Member::Joint(i) => joints.column(i).iter().copied().collect(),
            Member::Tip(i) => tips.column(i).iter().copied().collect(),
            Member::Closure(c) => closures.column(c).iter().copied().collect(),
            Member::Foot => f.iter().copied().collect(),
        }
    };
    report::Frame {
        t,
        bodies: members.iter().map(|b| b.iter().map(at).collect()).collect(),
        links: (0..NQ)
            .map(|i| {
                joints
                    .column(i)
                    .iter()
                    .chain(tips.column(i).iter())
                    .copied()
                    .collect()
            })
            .collect(),
        closures: (0..NP)
            .map(|i| closures.column(i).iter().copied().collect())
            .collect(),
        foot: f.iter().copied().collect(),
        reference,
    }
}

/// The points of each link, from the leg's spec (joint and tip only if it cannot be read).
pub(crate) fn body_points(name: &str, nq: usize) -> Vec<Vec<Member>> {
    let mut bodies: Vec<Vec<Member>> = (0..nq)
        .map(|i| vec![Member::Joint(i), Member::Tip(i)])
        .collect();
    let root = xtask::gen::workspace_root();
    let path = root
        .join(xtask::gen::SPECS_DIR)
        .join(format!("{name}.toml"));
    let Ok(model) = xtask::gen::load_spec(&root, &path)
        .and_then(|s| xtask::gen::model::build(&s).map_err(|e| e.to_string()))
    else {
        return bodies;
    };
    if model.links.len() != nq {
        return bodies;
    }
    for (i, l) in model.links.iter().enumerate() {
        if let Some(parent) = l.parent {
            bodies[parent].push(Member::Joint(i));
        }
    }
    // A point fixed to the base belongs to no link's drawing.
    for (k, c) in model.closures.iter().enumerate() {
        for (side, p) in [(0, &c.a), (1, &c.b)] {
            if let Some(l) = p.link {
                bodies[l].push(Member::Closure(2 * k + side));
            }
        }
    }
    if let Some(l) = model.foot.link {
        bodies[l].push(Member::Foot);
    }
    bodies
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

pub fn run<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    s: &Settings,
) -> Result<(), Error> {
    let p = <L as leg_models::LegDynamics<NQ, NC, NU>>::Params::<f64>::default();
    let tol = Tolerance::default();
    let fail =
        |what: &str, e: &dyn std::fmt::Display| Error::Failed(format!("{}: {what}: {e}", L::NAME));
    // A target in the way is found before the simulation runs, not after.
    check_targets(
        &s.out_dir(L::NAME),
        &["trajectory.csv", "summary.json", "report.html"],
    )
    .map_err(Error::Failed)?;
    let mut home = SVector::<f64, NQ>::from_column_slice(&L::HOME);
    project_position::<L, f64, NQ, NC, NU>(&p, &mut home, &tol)
        .map_err(|e| fail("the home pose does not assemble", &e))?;
    let structure = Structure::of::<L, NQ, NC, NU>();
    let (controller_kind, trajectory, choice) = s.resolve(L::NAME, &structure)?;
    let theta_home = SVector::<f64, NU>::from_fn(|k, _| home[L::ACTUATED[k]]);
    let foot_home = L::foot_position(&home, &p);
    let kp = s.kp.unwrap_or(if controller_kind.in_foot_space() {
        400.0
    } else {
        100.0
    });
    let kd = 2.0 * kp.sqrt();

    let foot_ref = match trajectory {
        Trajectory::Step => {
            let (origin, forward, up) = step_plane::<L, NQ, NC, NU, ND, NP>(&p, &foot_home);
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
            "--speed 0: on a leg in the air ({}) the speed is the spin trajectory's motor speed, which is not zero",
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
            &p,
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
        let q = assemble_along::<L, f64, NQ, NC, NU>(&p, &home, &r0.position, 0.05, &tol)
            .map_err(|e| fail("the joint reference's start", &e))?;
        let qd = consistent_velocity::<L, f64, NQ, NC, NU>(&p, &q, &r0.velocity)
            .map_err(|e| fail("the joint reference's start", &e))?;
        State { q, qd }
    };

    let not_applicable = |e: ControlError| fail("the controller", &e);
    let (controller, gains_text): (AnyController<L, NQ, NC, NU, ND, NP>, String) =
        match controller_kind {
            Controller::FootFl => (
                AnyController::FootFl(
                    FootFeedbackLinearization::new(p, Gains::new(kp, kd), foot_ref)
                        .map_err(not_applicable)?,
                ),
                format!(
                    "k_p = {} 1/s², k_d = {} 1/s",
                    report::significant(kp, 4),
                    report::significant(kd, 4)
                ),
            ),
            Controller::FootPd => {
                let foot_inertia = foot_inertias::<L, f64, NQ, NC, NU, ND, NP>(&p, &home)
                    .map_err(|e| fail("the foot's inertia at home", &e))?;
                let g = Gains {
                    kp: foot_inertia * kp,
                    kd: foot_inertia * kd,
                };
                (
                    AnyController::FootPd(
                        FootPdGravity::new(p, g, foot_ref).map_err(not_applicable)?,
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
                    JointFeedbackLinearization::new(p, Gains::new(kp, kd), joint_ref)
                        .map_err(not_applicable)?,
                ),
                format!(
                    "k_p = {} 1/s², k_d = {} 1/s",
                    report::significant(kp, 4),
                    report::significant(kd, 4)
                ),
            ),
            Controller::JointPd => {
                let joint_inertia = joint_inertias::<L, f64, NQ, NC, NU>(&p, &home)
                    .map_err(|e| fail("the motors' inertia at home", &e))?;
                let g = Gains {
                    kp: joint_inertia * kp,
                    kd: joint_inertia * kd,
                };
                (
                    AnyController::JointPd(
                        PdGravity::new(p, g, joint_ref).map_err(not_applicable)?,
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
    let steps = (s.duration / s.dt).round() as usize;
    // Refused before the run, as bad input, not after it with empty files.
    leg_models::simulate::check_record(steps, std::mem::size_of::<Sample<f64, NQ, NC, NU>>())
        .map_err(|e| Error::usage(format!("`--duration` over `--dt`: {e}")))?;
    let sim = Simulator::<L, f64, NQ, NC, NU>::new(p, StepOptions::rk4(s.dt));
    let mut source = WithProgress {
        inner: source,
        progress: Progress::new(steps as u64, &format!("simulating {}", L::NAME)),
        dt: s.dt,
    };
    let (samples, stopped) = match sim.run(initial, steps, &mut source) {
        Ok(samples) => (samples, None),
        Err(stop) => {
            let why = (stop.t, stop.cause.to_string());
            (stop.samples, Some(why))
        }
    };
    // The bar goes before anything is printed.
    let WithProgress {
        inner: source,
        progress,
        ..
    } = source;
    drop(progress);

    // What each sample is measured against.
    let foot_task = controller_kind.in_foot_space();
    let foot_of = |x: &Sample<f64, NQ, NC, NU>| L::foot_position(&x.state.q, &p);
    let error_of = |x: &Sample<f64, NQ, NC, NU>| -> f64 {
        if foot_task {
            (foot_of(x) - foot_ref.sample(x.t).position).norm()
        } else {
            let r = joint_ref.sample(x.t).position;
            max((0..NU).map(|k| (r[k] - x.state.q[L::ACTUATED[k]]).abs()))
        }
    };
    let tracked = controller_kind != Controller::Passive;
    let errors: Vec<f64> = samples.iter().map(error_of).collect();
    let settle = 1.0f64.min(s.duration / 2.0);
    let steady: Vec<f64> = samples
        .iter()
        .zip(&errors)
        .filter(|(x, _)| x.t >= settle)
        .map(|(_, e)| *e)
        .collect();
    let rms = |v: &[f64]| (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let e0 = samples.first().map_or(0.0, |x| x.energy);
    let energy_drift = max(samples.iter().map(|x| (x.energy - e0).abs())) / e0.abs().max(1e-300);

    let out = s.out_dir(L::NAME);

    // trajectory.csv
    let mut csv = String::from("t");
    for j in L::JOINT_NAMES {
        let _ = write!(csv, ",q_{j}");
    }
    for j in L::JOINT_NAMES {
        let _ = write!(csv, ",qd_{j}");
    }
    for &a in &L::ACTUATED {
        let _ = write!(csv, ",u_{}", L::JOINT_NAMES[a]);
    }
    // A point closure's force has one row per coordinate of its point, a rod's one (its
    // tension along the rod, scaled as φ's row), a revolute closure's its point's and two
    // moments across its axis (`M_k_u`, `M_k_w`: about link b's `û`, `ŵ`, scaled as φ's
    // rows).
    const AXES: [&str; 3] = ["x", "y", "z"];
    for k in 0..NP / 2 {
        if L::DISTANCE_CLOSURES.contains(&k) {
            let _ = write!(csv, ",F_{k}");
        } else {
            for a in &AXES[..ND] {
                let _ = write!(csv, ",F_{k}_{a}");
            }
            if L::REVOLUTE_CLOSURES.contains(&k) {
                let _ = write!(csv, ",M_{k}_u,M_{k}_w");
            }
        }
    }
    csv.push_str(",closure_residual,energy");
    for a in &AXES[..ND] {
        let _ = write!(csv, ",foot_{a}");
    }
    if foot_task {
        for a in &AXES[..ND] {
            let _ = write!(csv, ",ref_{a}");
        }
    } else if tracked {
        for &a in &L::ACTUATED {
            let _ = write!(csv, ",ref_{}", L::JOINT_NAMES[a]);
        }
    }
    if tracked {
        csv.push_str(",error");
    }
    csv.push('\n');
    let n = samples.len();
    for (k, (x, e)) in samples.iter().zip(&errors).enumerate() {
        if !written(k, n, s.every) {
            continue;
        }
        let mut row = format!("{}", x.t);
        for v in x
            .state
            .q
            .iter()
            .chain(x.state.qd.iter())
            .chain(x.u.iter())
            .chain(x.forces.iter())
        {
            let _ = write!(row, ",{v}");
        }
        let _ = write!(row, ",{},{}", x.closure_residual, x.energy);
        for v in foot_of(x).iter() {
            let _ = write!(row, ",{v}");
        }
        if foot_task {
            for v in foot_ref.sample(x.t).position.iter() {
                let _ = write!(row, ",{v}");
            }
        } else if tracked {
            for v in joint_ref.sample(x.t).position.iter() {
                let _ = write!(row, ",{v}");
            }
        }
        if tracked {
            let _ = write!(row, ",{e}");
        }
        csv.push_str(&row);
        csv.push('\n');
    }

    let unit = if foot_task { "m" } else { "rad" };
    let summary = json!({
        "model": L::NAME,
        "controller": controller_kind.name(),
        "controller_choice": choice,
        "structure": {
            "joints": NQ,
            "closure_rows": NC,
            "redundant_rows": structure.redundant_rows,
            "mobility": structure.mobility,
            "motors": NU,
        },
        "trajectory": if tracked { json!(trajectory.name()) } else { json!(null) },
        "settings": {
            "duration_s": s.duration,
            "dt_s": s.dt,
            "integrator": "RK4 with projection onto the closure",
            "torque_update": "once per step (zero-order hold)",
            "gains": gains_text,
            "torque_limit_nm": s.torque_limit,
            "spin_speed_rad_s": if trajectory == Trajectory::Spin { json!(s.spin_speed()) } else { json!(null) },
        },
        "samples": samples.len(),
        "tracking_error": if tracked { json!({
            "unit": unit,
            "max": max(errors.iter().copied()),
            "rms": rms(&errors),
            "steady_state_from_s": settle,
            "steady_state_max": max(steady.iter().copied()),
            "steady_state_rms": rms(&steady),
        }) } else { json!(null) },
        "peak_torque_nm": max(samples.iter().map(|x| x.u.amax())),
        "saturations": source.saturations.iter().sum::<usize>(),
        "saturations_per_motor": source.saturations.to_vec(),
        "max_closure_residual_m": max(samples.iter().map(|x| x.closure_residual)),
        "energy_drift_relative": if tracked { json!(null) } else { json!(energy_drift) },
        "stopped": stopped.as_ref().map(|(t, why)| json!({"t": t, "cause": why})),
    });

    // report.html
    let frame_every = ((0.02 / s.dt).round() as usize).max(1);
    // Each link as the rigid body it is: every point that belongs to it (its joint and tip,
    // its children's joints, its closure points, the foot), from the spec's structure.
    let members = body_points(L::NAME, NQ);
    let frames: Vec<report::Frame> = samples
        .iter()
        .step_by(frame_every)
        .map(|x| {
            let reference =
                foot_task.then(|| foot_ref.sample(x.t).position.iter().copied().collect());
            frame_at::<L, NQ, NC, NU, ND, NP>(&p, &members, x.t, &x.state.q, reference)
        })
        .collect();
    let t: Vec<f64> = samples.iter().map(|x| x.t).collect();
    let mut plots = Vec::new();
    if tracked {
        let what = if foot_task {
            "the distance from the foot to its reference"
        } else {
            "the largest motor angle's distance from its reference"
        };
        plots.push(
            Series::new("Tracking error", &t, vec![("error".into(), errors.clone())])
                .axis("tracking error", unit)
                .caption(&format!(
                    "{}, {what}; steady state counted from t = {settle} s.",
                    if foot_task {
                        "|p_foot − p_ref|"
                    } else {
                        "max |θ − θ_ref|"
                    }
                )),
        );
    }
    plots.push(
        Series::new(
            "Motor torques",
            &t,
            L::ACTUATED
                .iter()
                .enumerate()
                .map(|(k, &a)| {
                    (
                        L::JOINT_NAMES[a].to_string(),
                        samples.iter().map(|x| x.u[k]).collect(),
                    )
                })
                .collect(),
        )
        .axis("torque", "N m")
        .caption("Each motor's torque at its joint (after the gearbox), held over each step."),
    );
    plots.push(
        Series::log(
            "Closure residual",
            &t,
            vec![(
                "|φ|".into(),
                samples.iter().map(|x| x.closure_residual).collect(),
            )],
        )
        .axis("max |φ|", "m")
        .caption("The largest gap of the closure constraints φ(q) = 0 after each step's projection: rounding error, not physics."),
    );
    // The motors' work: the torques are held over each step, so W = Σ u · Δθ is exact.
    let mut work = Vec::with_capacity(samples.len());
    let mut w = 0.0;
    for (i, x) in samples.iter().enumerate() {
        if i > 0 {
            let prev = &samples[i - 1];
            for (k, &a) in L::ACTUATED.iter().enumerate() {
                w += prev.u[k] * (x.state.q[a] - prev.state.q[a]);
            }
        }
        work.push(w);
    }
    let balance: Vec<f64> = samples
        .iter()
        .zip(&work)
        .map(|(x, w)| x.energy - w)
        .collect();
    let spread = |v: &[f64]| {
        v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - v.iter().copied().fold(f64::INFINITY, f64::min)
    };
    let damped = L::damping_forces(&SVector::from_element(1.0), &p)
        .iter()
        .any(|d| *d != 0.0);
    plots.push(
        Series::new(
            "Energy",
            &t,
            vec![
                ("T + V".into(), samples.iter().map(|x| x.energy).collect()),
                ("T + V − W (the motors' work subtracted)".into(), balance.clone()),
            ],
        )
        .axis("energy", "J")
        .caption(&format!(
            "The leg's kinetic plus potential energy T + V (blue) {}: W = Σ ∫ u θ̇ dt. With that work subtracted (red) the energy {}: it moves by {} over the run, against {} for T + V.",
            if tracked {
                "rises and falls because the motors do work on it"
            } else {
                "changes with no motor work (the motors are off, W = 0)"
            },
            if damped { "only falls, by what the joints' damping dissipates" } else { "is conserved up to the integrator's error" },
            report_quantity(spread(&balance), "J"),
            report_quantity(spread(&samples.iter().map(|x| x.energy).collect::<Vec<_>>()), "J"),
        )),
    );
    let html = report::html(&Report {
        title: format!(
            "{} — {}{}",
            L::NAME,
            controller_kind.name(),
            if tracked {
                format!(", {}", trajectory.name())
            } else {
                String::new()
            }
        ),
        summary: &summary,
        plots: &plots,
        frames: &frames,
        ground: None,
        rods: L::DISTANCE_CLOSURES,
    })
    .map_err(Error::Failed)?;

    let written = [
        ("trajectory.csv".into(), csv),
        ("summary.json".into(), format!("{:#}\n", summary)),
        ("report.html".into(), html),
    ];
    write_all(&out, &written).map_err(Error::Failed)?;
    println!(
        "{} with {} ({choice}; {} s at dt = {} s): wrote {}/{{trajectory.csv, summary.json, report.html}}",
        L::NAME,
        controller_kind.name(),
        s.duration,
        s.dt,
        out.display()
    );
    if tracked {
        println!(
            "  tracking error: max {:.3e} {unit}, steady-state max {:.3e} {unit}",
            max(errors.iter().copied()),
            max(steady.iter().copied())
        );
    }
    println!(
        "  peak torque {:.4} N m, {} saturations, max closure residual {:.1e} m",
        max(samples.iter().map(|x| x.u.amax())),
        source.saturations.iter().sum::<usize>(),
        max(samples.iter().map(|x| x.closure_residual))
    );
    if !tracked {
        // Damped joints dissipate energy: the change is physics, not integration error.
        // Asked of the model (D q̇ at unit rates), not of parameter names.
        let damped = L::damping_forces(&SVector::from_element(1.0), &p)
            .iter()
            .any(|d| *d != 0.0);
        println!(
            "  energy drift max |E(t) − E(0)| / |E(0)| = {energy_drift:.1e}{}",
            if damped {
                " (the leg's joints are damped: its energy falls by design)"
            } else {
                ""
            }
        );
    }
    match stopped {
        None => Ok(()),
        Some((t, why)) => Err(Error::Failed(format!(
            "the simulation stopped at t = {t} s: {why} (the output holds everything until then)"
        ))),
    }
}
