//! Energy drift and closure drift of every closed-chain leg released under gravity
//! (no damping, no torque): 5 s at dt = 1 ms, RK4, with and without stabilization.
//!
//! `cargo run --release -p leg-tests --example drift`

use leg_models::dynamics::Baumgarte;
use leg_models::nalgebra::SVector;
use leg_models::simulate::Simulator;
use leg_models::simulate::{Method, State, StepOptions};
use leg_models::LegModel;
use leg_tests::passive_release_state;

fn report<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>() {
    if NC == 0 {
        return;
    }
    let p = L::Params::<f64>::default();
    let initial: State<f64, NQ> = passive_release_state::<L, NQ, NC, NU>(&p);
    let variants = [
        ("RK4 + projection", StepOptions::rk4(1e-3)),
        (
            "RK4, no stabilization",
            StepOptions {
                project: false,
                ..StepOptions::rk4(1e-3)
            },
        ),
        (
            "RK4 + Baumgarte (α = β = 20)",
            StepOptions {
                project: false,
                baumgarte: Some(Baumgarte {
                    alpha: 20.0,
                    beta: 20.0,
                }),
                ..StepOptions::rk4(1e-3)
            },
        ),
        (
            "semi-implicit Euler + projection",
            StepOptions {
                method: Method::SemiImplicitEuler,
                ..StepOptions::rk4(1e-3)
            },
        ),
        (
            "semi-implicit Euler, no stabilization",
            StepOptions {
                method: Method::SemiImplicitEuler,
                project: false,
                ..StepOptions::rk4(1e-3)
            },
        ),
    ];
    for (name, opts) in variants {
        let sim = Simulator::<L, f64, NQ, NC, NU>::new(p, opts);
        let mut zero = |_: f64, _: &State<f64, NQ>| SVector::<f64, NU>::zeros();
        let (samples, note) = match sim.run(initial, 5000, &mut zero) {
            Ok(s) => (s, String::new()),
            Err(stop) => {
                let note = format!(" (stopped at t = {:.3} s: {})", stop.t, stop.cause);
                (stop.samples, note)
            }
        };
        let e0 = samples[0].energy;
        let kmax = samples
            .iter()
            .map(|s| L::kinetic_energy(&s.state.q, &s.state.qd, &p))
            .fold(0.0f64, f64::max);
        let drift = samples
            .iter()
            .map(|s| (s.energy - e0).abs())
            .fold(0.0f64, f64::max);
        let residual = samples
            .iter()
            .map(|s| s.closure_residual)
            .fold(0.0f64, f64::max);
        println!(
            "{:<16} {:<40} energy drift {:.2e} J (relative to E0 {:.2e}, to max kinetic {:.2e}), max |φ| {:.2e} m{}",
            L::NAME, name, drift, drift / e0.abs(), drift / kmax, residual, note
        );
    }
}

fn main() {
    macro_rules! each {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            report::<$ty, $nq, $nc, $nu>();
        };
    }
    generated::for_each_model!(each);
}
