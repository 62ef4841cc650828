//! `cargo xtask sim`: simulate a leg under a controller; write `trajectory.csv`,
//! `summary.json` and a self-contained `report.html`.

use std::fmt::Write as _;

use leg_models::control::ControlError;
use leg_models::nalgebra::SVector;
use leg_models::simulate::{Sample, Simulator};
use leg_models::simulate::{State, StepOptions, TorqueSource};
use leg_models::LegModel;
use serde_json::json;
use xtask::cli::progress::Progress;
use xtask::cli::{check_targets, write_all, Error};

use crate::report::{self, quantity as report_quantity, Report, Series};

mod drive;
pub mod ground;
pub mod hop;
pub mod robot;
mod settings;

use drive::Drive;
use settings::written;
pub use settings::Settings;

/// A torque source that moves a progress bar: the simulator asks for torques once per
/// step (torques are held over the step), at the step's start time.
pub(crate) struct WithProgress<S> {
    pub(crate) inner: S,
    pub(crate) progress: Progress,
    pub(crate) dt: f64,
}

impl<S: TorqueSource<f64, NQ, NU>, const NQ: usize, const NU: usize> TorqueSource<f64, NQ, NU>
    for WithProgress<S>
{
    fn torque(&mut self, t: f64, s: &State<f64, NQ>) -> Result<SVector<f64, NU>, ControlError> {
        self.progress.set((t / self.dt).round() as u64);
        self.inner.torque(t, s)
    }
}

/// On the ground, the same source reads the state and not the contact modes (a swing-leg
/// controller does not know the ground).
impl<S, const NQ: usize, const NK: usize, const NU: usize, const ND: usize>
    leg_models::simulate::hybrid::HybridTorqueSource<f64, NQ, NK, NU, ND> for WithProgress<S>
where
    S: TorqueSource<f64, NQ, NU>,
{
    fn torque(
        &mut self,
        t: f64,
        s: &leg_models::simulate::hybrid::HybridState<f64, NQ, NK, ND>,
    ) -> Result<SVector<f64, NU>, ControlError> {
        TorqueSource::torque(self, t, &s.state)
    }
}

/// A torque server's loop (`--serve`): each line on stdin is `width` numbers, handed to
/// `torques`; each answer on stdout is its torques, or `error: …` (for a line of another
/// width or not numbers too), flushed at once, so that another simulator can close its
/// loop through it line by line.
pub(crate) fn serve_lines<const NU: usize>(
    width: usize,
    mut torques: impl FnMut(&[f64]) -> Result<SVector<f64, NU>, String>,
) -> Result<(), Error> {
    use std::io::{BufRead, Write};
    let stdin = std::io::stdin();
    let mut stdout = std::io::stdout().lock();
    for line in stdin.lock().lines() {
        let line = line.map_err(|e| Error::Failed(format!("stdin: {e}")))?;
        let values: Result<Vec<f64>, _> = line.split_whitespace().map(str::parse).collect();
        let answer = match values {
            Ok(v) if v.len() == width => match torques(&v) {
                Ok(u) => u
                    .iter()
                    .map(|x| format!("{x:e}"))
                    .collect::<Vec<_>>()
                    .join(" "),
                Err(e) => format!("error: {e}"),
            },
            Ok(v) => format!("error: {} numbers, expected {width}", v.len()),
            Err(e) => format!("error: {e}"),
        };
        writeln!(stdout, "{answer}")
            .and_then(|_| stdout.flush())
            .map_err(|e| Error::Failed(format!("stdout: {e}")))?;
    }
    Ok(())
}

/// trajectory.csv's first columns: the time, the joints' positions and rates, and the
/// motors' torques.
pub(crate) fn state_columns<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>() -> String {
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
    csv
}

/// The closure forces' columns. A point closure's force has one row per coordinate of its
/// point, a rod's one (its tension along the rod, scaled as φ's row), a revolute closure's
/// its point's and two moments across its axis (`M_k_u`, `M_k_w`: about link b's `û`,
/// `ŵ`, scaled as φ's rows).
pub(crate) fn closure_force_columns<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    csv: &mut String,
) {
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
}

/// The motors' names: their joints', in `u`'s order.
pub(crate) fn motor_names<
    L: leg_models::LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() -> Vec<&'static str> {
    L::ACTUATED.iter().map(|&a| L::JOINT_NAMES[a]).collect()
}

/// The report's plot of the motors' torques over time, one line per motor.
pub(crate) fn torque_plot<const NU: usize>(
    t: &[f64],
    names: &[&str],
    torques: impl Iterator<Item = SVector<f64, NU>> + Clone,
) -> Series {
    Series::new(
        "Motor torques",
        t,
        names
            .iter()
            .enumerate()
            .map(|(k, name)| (name.to_string(), torques.clone().map(|u| u[k]).collect()))
            .collect(),
    )
    .axis("torque", "N m")
    .caption("Each motor's torque at its joint (after the gearbox), held over each step.")
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
    // A target in the way is found before the simulation runs, not after.
    check_targets(
        &s.out_dir(L::NAME),
        &["trajectory.csv", "summary.json", "report.html"],
    )
    .map_err(Error::Failed)?;
    let (drive, source) = Drive::<L, NQ, NC, NU, ND, NP>::new(s, &p)?;
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
    let (samples, stopped) = match sim.run(drive.initial, steps, &mut source) {
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

    let tracked = drive.tracked();
    let t: Vec<f64> = samples.iter().map(|x| x.t).collect();
    let errors: Vec<f64> = samples
        .iter()
        .map(|x| drive.error(&p, x.t, &x.state.q))
        .collect();
    let steady = drive.steady(&t, &errors);
    let e0 = samples.first().map_or(0.0, |x| x.energy);
    let energy_drift = max(samples.iter().map(|x| (x.energy - e0).abs())) / e0.abs().max(1e-300);

    let out = s.out_dir(L::NAME);

    // trajectory.csv
    let mut csv = state_columns::<L, NQ, NC, NU, ND, NP>();
    closure_force_columns::<L, NQ, NC, NU, ND, NP>(&mut csv);
    csv.push_str(",closure_residual,energy");
    drive.csv_header(&mut csv);
    csv.push('\n');
    let n = samples.len();
    for (k, x) in samples.iter().enumerate() {
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
        drive.csv_row(&p, x.t, &x.state.q, &mut row);
        csv.push_str(&row);
        csv.push('\n');
    }

    let summary = json!({
        "model": L::NAME,
        "controller": drive.kind.name(),
        "controller_choice": drive.choice,
        "structure": drive.structure_summary(),
        "trajectory": if tracked { json!(drive.trajectory.name()) } else { json!(null) },
        "settings": {
            "duration_s": s.duration,
            "dt_s": s.dt,
            "integrator": "RK4 with projection onto the closure",
            "torque_update": "once per step (zero-order hold)",
            "gains": drive.gains,
            "torque_limit_nm": s.torque_limit,
            "spin_speed_rad_s": drive.spin_speed(s),
        },
        "samples": samples.len(),
        "tracking_error": drive.tracking_summary(&t, &errors),
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
            frame_at::<L, NQ, NC, NU, ND, NP>(
                &p,
                &members,
                x.t,
                &x.state.q,
                drive.drawn_reference(x.t),
            )
        })
        .collect();
    let mut plots: Vec<Series> = drive.tracking_plot(&t, &errors).into_iter().collect();
    plots.push(crate::sim::torque_plot(
        &t,
        &crate::sim::motor_names::<L, NQ, NC, NU>(),
        samples.iter().map(|x| x.u),
    ));
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
        title: format!("{} — {}", L::NAME, drive.title()),
        summary: &summary,
        plots: &plots,
        frames: &frames,
        ground: None,
        rods: L::DISTANCE_CLOSURES,
        robot: false,
    })
    .map_err(Error::Failed)?;

    let written = [
        ("trajectory.csv".into(), csv),
        ("summary.json".into(), format!("{:#}\n", summary)),
        ("report.html".into(), html),
    ];
    write_all(&out, &written).map_err(Error::Failed)?;
    println!(
        "{} with {} ({}; {} s at dt = {} s): wrote {}/{{trajectory.csv, summary.json, report.html}}",
        L::NAME,
        drive.kind.name(),
        drive.choice,
        s.duration,
        s.dt,
        out.display()
    );
    if tracked {
        println!(
            "  tracking error: max {:.3e} {unit}, steady-state max {:.3e} {unit}",
            max(errors.iter().copied()),
            max(steady.iter().copied()),
            unit = drive.unit(),
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
