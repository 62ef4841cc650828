//! Discrete LQR on the constraint manifold, on every leg that can be held at rest at its
//! home pose: the Riccati solution against the plain Riccati iteration and its own
//! residual, and the closed loop of the nonlinear simulation against the prediction of
//! the linearization (the error follows `(A − B K)ᵏ e₀`, decaying at its spectral radius).
//! Legs with no holding torque at home (passive joints away from equilibrium) say so.

use leg_models::assembly::Tolerance;
use leg_models::control::linearize::{LinearizationError, ManifoldChart};
use leg_models::control::lqr::ManifoldLqr;
use leg_models::control::reference::{Hold, Reference, Sinusoid};
use leg_models::nalgebra::{DMatrix, SMatrix, SVector};
use leg_models::simulate::{step, State, StepOptions};
use leg_models::LegModel;
use leg_tests::{not_applicable, passive_release_state, Rng};

fn weights<const NX: usize, const NU: usize>() -> (SMatrix<f64, NX, NX>, SMatrix<f64, NU, NU>) {
    let q = SMatrix::<f64, NX, NX>::from_fn(|i, j| match (i == j, i < NX / 2) {
        (true, true) => 100.0,
        (true, false) => 1.0,
        _ => 0.0,
    });
    (q, SMatrix::<f64, NU, NU>::identity() * 0.1)
}

fn spectral_radius<const N: usize>(a: &SMatrix<f64, N, N>) -> f64 {
    let d = DMatrix::from_fn(N, N, |i, j| a[(i, j)]);
    d.complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max)
}

fn hold_and_decay<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const M: usize,
    const NX: usize,
>() {
    let p = L::Params::<f64>::default();
    let pose = passive_release_state::<L, NQ, NC, NU>(&p).q;
    let mut opts = StepOptions::rk4(2e-3);
    // Linearized and simulated without the projection, whose linearization is only first
    // order (see leg_models::control::linearize); the drift of 300 RK4 steps is far below the errors
    // compared here.
    opts.project = false;
    let chart = ManifoldChart::<f64, NQ, M>::new::<L, NC, NU>(&p, &pose).expect("regular home");
    let (q, r) = weights::<NX, NU>();
    let target = chart.coordinates_of(&State {
        q: pose,
        qd: SVector::zeros(),
    });
    let controller = ManifoldLqr::<L, f64, _, NQ, NC, NU, M, NX>::at_pose(
        p,
        &pose,
        &opts,
        &q,
        &r,
        Hold(target.0),
        SVector::from_element(f64::INFINITY),
    );
    let mut controller = match controller {
        Ok(c) => c,
        Err(leg_models::control::ControlError::Linearization(
            e @ LinearizationError::NotAnEquilibrium { .. },
        )) => {
            assert!(
                M > NU,
                "{}: a leg with a motor per degree of freedom can be held: {e}",
                L::NAME
            );
            not_applicable(L::NAME, "LQR hold at home", &e);
            return;
        }
        Err(e) => panic!("{}: {e}", L::NAME),
    };
    // The Riccati solution: its residual, and the plain iteration from P = Q.
    let u_hold = chart.holding_torque::<L, NC, NU>(&p, &pose).unwrap();
    let rest = State {
        q: pose,
        qd: SVector::zeros(),
    };
    let lin = chart
        .linearize_step::<L, NC, NU, NX>(&p, &rest, &u_hold, &opts)
        .unwrap();
    let lqr = controller.lqr;
    let scale = lqr.cost.amax();
    assert!(
        lqr.riccati_residual(&lin.a, &lin.b, &q) <= 1e-9 * scale,
        "{}: Riccati residual {:.2e} of |P| {scale:.2e}",
        L::NAME,
        lqr.riccati_residual(&lin.a, &lin.b, &q)
    );
    if NX <= 6 {
        let mut pk = q;
        for _ in 0..200_000 {
            let bt_p = lin.b.transpose() * pk;
            let k = (r + bt_p * lin.b).try_inverse().unwrap() * bt_p * lin.a;
            let next = q + lin.a.transpose() * pk * (lin.a - lin.b * k);
            let done = (next - pk).amax() <= 1e-13 * next.amax();
            pk = next;
            if done {
                break;
            }
        }
        assert!(
            (pk - lqr.cost).amax() <= 1e-7 * scale,
            "{}: doubling and plain Riccati iteration differ by {:.2e}",
            L::NAME,
            (pk - lqr.cost).amax()
        );
    }
    let rho = spectral_radius(&lqr.closed_loop);
    assert!(rho < 1.0, "{}: closed loop not stable (ρ = {rho})", L::NAME);
    // The closed loop from a small offset of the coordinates, simulated with the full
    // nonlinear model, against the linear prediction.
    let mut rng = Rng::new(21);
    let delta = 1e-4;
    let theta0 = target.0 + SVector::<f64, M>::from_fn(|_, _| rng.range(-delta, delta));
    let mut state = chart
        .lift::<L, NC, NU>(&p, &theta0, &SVector::zeros(), &Tolerance::default())
        .expect("lifts");
    let error_of = |s: &State<f64, NQ>| {
        let (th, rate) = chart.coordinates_of(s);
        SVector::<f64, NX>::from_fn(|k, _| {
            if k < M {
                th[k] - target.0[k]
            } else {
                rate[k - M]
            }
        })
    };
    let e0 = error_of(&state);
    let mut predicted = e0;
    let steps = 300;
    let mut worst = 0.0f64;
    for k in 0..steps {
        step::<L, f64, NQ, NC, NU>(&p, &mut state, k as f64 * opts.dt, &mut controller, &opts)
            .expect("steps");
        predicted = lqr.closed_loop * predicted;
        worst = worst.max((error_of(&state) - predicted).norm());
    }
    let e = error_of(&state);
    assert!(
        worst <= 1e-2 * e0.norm(),
        "{}: nonlinear closed loop leaves the linear prediction by {worst:.2e} (|e₀| {:.2e})",
        L::NAME,
        e0.norm()
    );
    // The decay over the run matches the prediction's.
    let (measured, expected) = (e.norm() / e0.norm(), predicted.norm() / e0.norm());
    assert!(
        (measured - expected).abs() <= 1e-2 * expected.max(1e-3),
        "{}: decay {measured:.4e}, predicted {expected:.4e}",
        L::NAME
    );
    eprintln!(
        "{}: LQR ρ(A − BK) = {rho:.5} per {} s step; |e| after {steps} steps {measured:.3e} of |e₀| (predicted {expected:.3e}); {} doubling rounds",
        L::NAME,
        opts.dt,
        lqr.iterations
    );
}

macro_rules! lqr_checks {
    ($module:ident, $ty:ty, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        #[test]
        fn $module() {
            const M: usize = <$ty as leg_models::LegDynamics<$nq, $nc, $nu>>::MOBILITY;
            hold_and_decay::<$ty, $nq, $nc, $nu, M, { 2 * M }>();
        }
    };
}

generated::for_each_model!(lqr_checks);

/// Minitaur's motors track a slow sinusoid with the LQR of its home pose, under torque
/// limits: the error stays small and no torque exceeds its limit.
#[test]
fn minitaur_tracks_a_slow_reference_under_torque_limits() {
    use generated::Minitaur;
    let p = <Minitaur as leg_models::LegDynamics<4, 2, 2>>::Params::<f64>::default();
    let pose = passive_release_state::<Minitaur, 4, 2, 2>(&p).q;
    let chart = ManifoldChart::<f64, 4, 2>::new::<Minitaur, 2, 2>(&p, &pose).unwrap();
    let home = chart.coordinates_of(&State {
        q: pose,
        qd: SVector::zeros(),
    });
    let reference = Sinusoid {
        offset: home.0,
        amplitude: SVector::<f64, 2>::new(0.15, -0.15),
        frequency: SVector::<f64, 2>::new(0.5, 0.5),
        phase: SVector::zeros(),
    };
    let opts = StepOptions::rk4(1e-3);
    let (q, r) = weights::<4, 2>();
    let limit = 2.0;
    let mut controller = ManifoldLqr::<Minitaur, f64, _, 4, 2, 2, 2, 4>::at_pose(
        p,
        &pose,
        &opts,
        &q,
        &r,
        reference,
        SVector::from_element(limit),
    )
    .unwrap();
    let mut state = State {
        q: pose,
        qd: SVector::zeros(),
    };
    let mut worst = 0.0f64;
    for k in 0..3000 {
        let t = k as f64 * opts.dt;
        let report =
            step::<Minitaur, f64, 4, 2, 2>(&p, &mut state, t, &mut controller, &opts).unwrap();
        let _ = report; // (the limits are a clip in the controller: nothing to check here)
        if t >= 1.0 {
            let (theta, _) = chart.coordinates_of(&state);
            worst = worst.max((theta - reference.sample(t + opts.dt).position).amax());
        }
    }
    assert!(worst < 0.02, "tracking error {worst:.3e} rad");
    eprintln!("minitaur LQR tracking a 0.5 Hz, 0.15 rad sinusoid: worst error {worst:.2e} rad");
}
