//! Tracking error, peak torque and saturation count of every controller on every leg:
//! 3 s at dt = 1 ms (RK4 with projection), torques updated once per step (1 kHz) and
//! clipped at assumed motor limits. Errors are measured after the first second.
//!
//! The LQR row: discrete LQR on the constraint manifold (`leg_models::control::lqr`), linearized
//! once at home, tracking the same reference with a quasi-static feedforward.
//!
//! `cargo run --release -p leg-tests --example control_report`

use leg_models::assembly::{assemble_along, consistent_velocity, foot_inverse, Tolerance};
use leg_models::control::linearize::ManifoldChart;
use leg_models::control::lqr::ManifoldLqr;
use leg_models::control::reference::{Reference, Sinusoid, StepCycle};
use leg_models::control::{
    foot_inertias, joint_inertias, FootFeedbackLinearization, FootPdGravity, Gains,
    JointFeedbackLinearization, PdGravity, Saturated,
};
use leg_models::dynamics::structure::Structure;
use leg_models::nalgebra::{SMatrix, SVector};
use leg_models::simulate::{Sample, Simulator};
use leg_models::simulate::{State, StepOptions, TorqueSource};
use leg_models::{ContactModel, LegModel, Parameters};
use leg_tests::passive_release_state;

/// Assumed joint-side torque limits (N m): not in the specs; plausible for each leg.
fn limit(model: &str) -> f64 {
    match model {
        "minitaur" | "five_bar_offset" => 5.0,
        "atrias" => 600.0,
        "digit" => 120.0,
        _ => 30.0,
    }
}

struct Row {
    max: f64,
    rms: f64,
    peak: f64,
    saturations: usize,
    note: String,
}

fn run<L, C, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    initial: State<f64, NQ>,
    controller: C,
    error: impl Fn(&Sample<f64, NQ, NC, NU>) -> f64,
) -> Row
where
    L: LegModel<NQ, NC, NU>,
    C: TorqueSource<f64, NQ, NU>,
{
    let mut limited = Saturated::new(controller, SVector::from_element(limit(L::NAME))).unwrap();
    let sim = Simulator::<L, f64, NQ, NC, NU>::new(*p, StepOptions::rk4(1e-3));
    let (samples, note) = match sim.run(initial, 3000, &mut limited) {
        Ok(s) => (s, String::new()),
        Err(stop) => {
            let note = format!("stopped at {:.3} s: {}", stop.t, stop.cause);
            (stop.samples, note)
        }
    };
    let errs: Vec<f64> = samples.iter().filter(|s| s.t >= 1.0).map(&error).collect();
    let n = errs.len().max(1) as f64;
    Row {
        max: errs.iter().copied().fold(0.0, f64::max),
        rms: (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        peak: samples.iter().map(|s| s.u.amax()).fold(0.0, f64::max),
        saturations: limited.saturations.iter().sum(),
        note,
    }
}

fn report<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const M: usize,
    const NX: usize,
>() {
    let p = L::Params::<f64>::default();
    let home = passive_release_state::<L, NQ, NC, NU>(&p).q;
    let theta_home = SVector::<f64, NU>::from_fn(|k, _| home[L::ACTUATED[k]]);
    let joint_ref = Sinusoid {
        offset: theta_home,
        amplitude: SVector::from_element(0.1),
        frequency: SVector::from_element(1.0),
        phase: SVector::from_fn(|k, _| k as f64),
    };
    let cycle = StepCycle {
        center: L::foot_position(&home, &p),
        half_stride: 0.03,
        half_height: 0.015,
        period: 0.5,
    };
    let joint_err = |s: &Sample<f64, NQ, NC, NU>| {
        let r = joint_ref.sample(s.t);
        (0..NU)
            .map(|k| (r.position[k] - s.state.q[L::ACTUATED[k]]).abs())
            .fold(0.0, f64::max)
    };
    let foot_err = |s: &Sample<f64, NQ, NC, NU>| {
        (L::foot_position(&s.state.q, &p) - cycle.sample(s.t).position).norm()
    };
    let mut heavy = p;
    for (i, name) in <L::Params<f64> as Parameters<f64>>::NAMES
        .iter()
        .enumerate()
    {
        if name.ends_with("_mass") || name.ends_with("_inertia") {
            let v = heavy.get(i).unwrap();
            heavy.set(i, v * 1.2);
        }
    }

    let structure = Structure::of::<L, NQ, NC, NU>();
    let mut rows: Vec<(&str, Result<Row, String>)> = Vec::new();
    match structure.joint_space() {
        Ok(()) => {
            // Baseline gains with the same bandwidth (ω = 10 rad/s), scaled by diag(Ã).
            let joint_inertia = joint_inertias::<L, f64, NQ, NC, NU>(&p, &home).unwrap();
            let joint_pd = Gains {
                kp: joint_inertia * 100.0,
                kd: joint_inertia * 20.0,
            };
            let r0 = joint_ref.sample(0.0);
            let q_joint = assemble_along::<L, f64, NQ, NC, NU>(
                &p,
                &home,
                &r0.position,
                0.05,
                &Tolerance::default(),
            )
            .unwrap();
            let joint_start = State {
                q: q_joint,
                qd: consistent_velocity::<L, f64, NQ, NC, NU>(&p, &q_joint, &r0.velocity).unwrap(),
            };
            let fl = |params| {
                JointFeedbackLinearization::<L, f64, _, NQ, NC, NU>::new(
                    params,
                    Gains::critically_damped(100.0),
                    joint_ref,
                )
                .unwrap()
            };
            let pd = PdGravity::<L, f64, _, NQ, NC, NU>::new(p, joint_pd, joint_ref).unwrap();
            rows.push((
                "joint FL, sinusoid (rad)",
                Ok(run::<L, _, NQ, NC, NU>(&p, joint_start, fl(p), joint_err)),
            ));
            rows.push((
                "joint PD+g, sinusoid (rad)",
                Ok(run::<L, _, NQ, NC, NU>(&p, joint_start, pd, joint_err)),
            ));
            rows.push((
                "joint FL, masses +20 % (rad)",
                Ok(run::<L, _, NQ, NC, NU>(
                    &p,
                    joint_start,
                    fl(heavy),
                    joint_err,
                )),
            ));
        }
        Err(why) => rows.push(("joint control", Err(why.to_string()))),
    }
    match structure.foot_space() {
        Ok(()) => {
            // Foot PD scaled by the foot-space inertia Λ = (J_y Ã⁻¹ J_yᵀ)⁻¹ (ω = 20 rad/s).
            let foot_inertia = foot_inertias::<L, f64, NQ, NC, NU, 2, NC>(&p, &home).unwrap();
            let foot_pd = Gains {
                kp: foot_inertia * 400.0,
                kd: foot_inertia * 40.0,
            };
            let q_foot = foot_inverse::<L, f64, NQ, NC, NU, 2, NC>(
                &p,
                &cycle.sample(0.0).position,
                &home,
                &Tolerance::default(),
            )
            .unwrap();
            let foot_start = State {
                q: q_foot,
                qd: SVector::zeros(),
            };
            let fl = |params| {
                FootFeedbackLinearization::<L, f64, _, NQ, NC, NU>::new(
                    params,
                    Gains::critically_damped(400.0),
                    cycle,
                )
                .unwrap()
            };
            let pd = FootPdGravity::<L, f64, _, NQ, NC, NU>::new(p, foot_pd, cycle).unwrap();
            rows.push((
                "foot FL, step cycle (m)",
                Ok(run::<L, _, NQ, NC, NU>(&p, foot_start, fl(p), foot_err)),
            ));
            rows.push((
                "foot PD+g, step cycle (m)",
                Ok(run::<L, _, NQ, NC, NU>(&p, foot_start, pd, foot_err)),
            ));
            rows.push((
                "foot FL, masses +20 % (m)",
                Ok(run::<L, _, NQ, NC, NU>(&p, foot_start, fl(heavy), foot_err)),
            ));
        }
        Err(why) => rows.push(("foot control", Err(why.to_string()))),
    }
    // Discrete LQR on the constraint manifold, linearized once at home under the holding
    // torques (step 1 ms, as simulated), tracking the joint reference in the chart's
    // coordinates (the motor angles wherever the motors determine the leg).
    let chart = ManifoldChart::<f64, NQ, M>::new::<L, NC, NU>(&p, &home);
    let lqr_row = chart.map_err(|e| e.to_string()).and_then(|chart| {
        if chart
            .coordinates
            .iter()
            .zip(&L::ACTUATED)
            .any(|(a, b)| a != b)
            || M != NU
        {
            return Err(format!(
                "this row tracks the motors' reference, and the leg's coordinates on its constraint manifold (joints {:?}) are not its motors' (joints {:?})",
                chart.coordinates,
                L::ACTUATED
            ));
        }
        let reference = Sinusoid {
            offset: SVector::<f64, M>::from_fn(|k, _| joint_ref.offset[k]),
            amplitude: SVector::from_element(0.1),
            frequency: SVector::from_element(1.0),
            phase: SVector::from_fn(|k, _| k as f64),
        };
        let weights = SMatrix::<f64, NX, NX>::from_fn(|i, j| match (i == j, i < M) {
            (true, true) => 1e4,
            (true, false) => 1.0,
            _ => 0.0,
        });
        let r = SMatrix::<f64, NU, NU>::identity() * 1e-2;
        let lqr = ManifoldLqr::<L, f64, _, NQ, NC, NU, M, NX>::at_pose(
            p,
            &home,
            &StepOptions::rk4(1e-3),
            &weights,
            &r,
            reference,
            SVector::from_element(f64::INFINITY),
        )
        .map_err(|e| e.to_string())?;
        let r0 = joint_ref.sample(0.0);
        let q0 = assemble_along::<L, f64, NQ, NC, NU>(
            &p,
            &home,
            &r0.position,
            0.05,
            &Tolerance::default(),
        )
        .map_err(|e| e.to_string())?;
        let start = State {
            q: q0,
            qd: consistent_velocity::<L, f64, NQ, NC, NU>(&p, &q0, &r0.velocity)
                .map_err(|e| e.to_string())?,
        };
        Ok(run::<L, _, NQ, NC, NU>(&p, start, lqr, joint_err))
    });
    rows.push(("LQR at home, sinusoid (rad)", lqr_row));
    for (name, r) in rows {
        let r = match r {
            Ok(r) => r,
            Err(why) => {
                println!(
                    "| {} | {name} | – | – | – | – | not applicable: {why} |",
                    L::NAME
                );
                continue;
            }
        };
        println!(
            "| {} | {} | {:.2e} | {:.2e} | {:.3} | {} | {} |",
            L::NAME,
            name,
            r.max,
            r.rms,
            r.peak,
            r.saturations,
            if r.note.is_empty() { "" } else { &r.note }
        );
    }
}

/// The linearization of stance: the legs with contacts at home, every contact held where
/// it is, no torque; the eigenvalues of `ẋ = A x` with `A = [0 I; ∂q̈/∂q ∂q̈/∂q̇]` from the
/// derivatives of the contact dynamics. A positive real part is a falling mode (the body
/// over its foot: an inverted pendulum), its inverse the time it takes to grow e-fold.
fn stance<
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>() {
    use leg_models::dynamics::contact::{spec_friction, ContactMode, Ground, Modes};
    use leg_models::dynamics::derivatives::contact_dynamics_derivatives;
    if NK == 0 {
        return;
    }
    let p = L::Params::<f64>::default();
    let home = passive_release_state::<L, NQ, NC, NU>(&p);
    let (ground, mu) = (
        Ground::of::<L, NQ, NC, NU, NK>(),
        spec_friction::<L, f64, NQ, NC, NU, NK, 2>(),
    );
    let mut modes = Modes::<NK>::flight();
    for k in 0..NK / 2 {
        modes.set(k, ContactMode::Stick);
    }
    let anchors = ground.coordinates(&L::contact_positions(&home.q, &p));
    match contact_dynamics_derivatives::<L, f64, NQ, NC, NU, NK, 2>(
        &p,
        &home.q,
        &home.qd,
        &SVector::zeros(),
        &modes,
        &anchors,
        &ground,
        &mu,
        None,
        None,
    ) {
        Ok(d) => {
            let a = leg_models::nalgebra::DMatrix::from_fn(2 * NQ, 2 * NQ, |i, j| {
                match (i < NQ, j < NQ) {
                    (true, true) => 0.0,
                    (true, false) => f64::from(u8::from(j - NQ == i)),
                    (false, true) => d.qdd_q[(i - NQ, j)],
                    (false, false) => d.qdd_qd[(i - NQ, j - NQ)],
                }
            });
            let eig = a.complex_eigenvalues();
            let fastest = eig.iter().map(|z| z.re).fold(f64::NEG_INFINITY, f64::max);
            println!(
                "| {} | {} | {:.3} | {} |",
                L::NAME,
                L::CONTACT_NAMES.join(", "),
                fastest,
                if fastest > 1e-3 {
                    format!("falls: e-fold in {:.3} s", 1.0 / fastest)
                } else {
                    "no growing mode".into()
                }
            );
        }
        Err(e) => println!(
            "| {} | {} | – | {e} |",
            L::NAME,
            L::CONTACT_NAMES.join(", ")
        ),
    }
}

fn main() {
    println!(
        "| leg | controller | max error | RMS error | peak torque (N m) | saturations | note |"
    );
    println!("|---|---|---|---|---|---|---|");
    macro_rules! each {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {{
            const M: usize = <$ty as leg_models::LegDynamics<$nq, $nc, $nu>>::MOBILITY;
            report::<$ty, $nq, $nc, $nu, M, { 2 * M }>();
        }};
    }
    generated::for_each_model!(each);
    println!();
    println!("| leg | contacts held at home | largest real eigenvalue of the stance linearization (1/s) | |");
    println!("|---|---|---|---|");
    macro_rules! each_stance {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            stance::<$ty, $nq, $nc, $nu, $nk>();
        };
    }
    generated::for_each_model!(each_stance);
}
