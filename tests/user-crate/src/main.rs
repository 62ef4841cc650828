//! A user's program for their own leg: the generated module plus `leg-models`, nothing
//! else. `cargo xtask test` runs it; it exits non-zero if a check fails.

// A binary uses part of the generated module; the rest is there for other programs.
#[allow(dead_code)]
mod parallelogram_knee;

use leg_models::control::{Gains, Saturated};
use leg_models::simulate::{State, StepOptions};
use leg_models::nalgebra::{Vector2, Vector4};
use leg_models::control::reference::Sinusoid;
use parallelogram_knee::Leg;

fn main() {
    let leg = Leg::default();
    let home = leg.assembled_home().expect("the spec's home assembles");
    println!(
        "parallelogram_knee: foot at home {:?} m, closure residual {:.1e} m",
        leg.foot_position(&home).as_slice(),
        leg.closure_residual(&home).amax()
    );

    // A parallelogram knee: the coupler stays parallel to the thigh, so the shank's
    // absolute angle is the crank's minus π whatever the motors do (geometry, not code).
    let q = leg
        .assemble(&Vector2::new(-1.3, 2.8), &home)
        .expect("reachable");
    let shank = q[0] + q[1];
    let crank = q[2];
    let parallel = (shank - (crank - std::f64::consts::PI)).rem_euclid(std::f64::consts::TAU);
    assert!(
        parallel.min(std::f64::consts::TAU - parallel) < 1e-9,
        "not a parallelogram: {parallel}"
    );

    // Free swing from rest without damping: energy is kept (RK4, 0.1 ms steps).
    let sim = leg.simulator(StepOptions::rk4(1e-4));
    let mut off = leg.torque_source(|_t, _s| Vector2::zeros());
    let swing = sim
        .run(
            State {
                q,
                qd: Vector4::zeros(),
            },
            5000,
            &mut off,
        )
        .expect("a free swing runs");
    let drift = swing
        .iter()
        .map(|s| (s.energy - swing[0].energy).abs())
        .fold(0.0, f64::max);
    println!("free swing 0.5 s: energy drift {drift:.1e} J");
    assert!(drift < 1e-9, "energy drift {drift}");

    // Foot-space tracking of a 2 cm circle under 20 N·m limits, and the exact derivatives.
    let centre = leg.foot_position(&home);
    let circle = Sinusoid {
        offset: centre,
        amplitude: Vector2::new(0.02, 0.02),
        frequency: Vector2::new(1.0, 1.0),
        phase: Vector2::new(std::f64::consts::FRAC_PI_2, 0.0),
    };
    let start = leg
        .foot_inverse(&(centre + Vector2::new(0.02, 0.0)), &home)
        .expect("the circle's start is reachable");
    let tracker = leg
        .foot_feedback_linearization(Gains::critically_damped(400.0), circle)
        .expect("two motors that determine the leg place the foot");
    let mut controller = Saturated::new(tracker, Vector2::from_element(20.0)).unwrap();
    let run = leg
        .simulator(StepOptions::rk4(1e-3))
        .run(
            State {
                q: start,
                qd: Vector4::zeros(),
            },
            2000,
            &mut controller,
        )
        .expect("tracking runs");
    let last = run.last().unwrap();
    let want = centre
        + Vector2::new(
            0.02 * (std::f64::consts::TAU * last.t + std::f64::consts::FRAC_PI_2).sin(),
            0.02 * (std::f64::consts::TAU * last.t).sin(),
        );
    let error = (leg.foot_position(&last.state.q) - want).norm();
    println!(
        "foot circle after 2 s: {error:.1e} m off, saturations {:?}",
        controller.saturations
    );
    assert!(error < 1e-4, "foot {error} m off the circle");

    let d = leg
        .forward_dynamics_derivatives(&last.state.q, &last.state.qd, &last.u)
        .expect("regular state");
    let h = 1e-6;
    let plus = leg
        .forward_dynamics(
            &last.state.q,
            &last.state.qd,
            &(last.u + Vector2::new(h, 0.0)),
        )
        .unwrap();
    let minus = leg
        .forward_dynamics(
            &last.state.q,
            &last.state.qd,
            &(last.u - Vector2::new(h, 0.0)),
        )
        .unwrap();
    let fd = (plus.qdd - minus.qdd) / (2.0 * h);
    let err = (fd - d.qdd_u.column(0)).amax() / d.qdd_u.amax();
    println!("∂q̈/∂u against a central difference: {err:.1e} (relative)");
    assert!(err < 1e-6);
    println!("user crate: all checks passed");
}
