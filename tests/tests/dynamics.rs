//! The runtime on every generated model: the structured KKT solve against its own
//! residual and a dense LU of the whole system; energy and closure conservation of a
//! passive leg; loop assembly, consistent velocities and the foot inverse; singular
//! configurations and early stops as typed errors.

use leg_models::assembly::{assemble, consistent_velocity, foot_inverse, AssemblyError, Tolerance};
use leg_models::dynamics::{actuation, forward_dynamics, DynamicsError};
use leg_models::nalgebra::{DMatrix, DVector, SVector};
use leg_models::simulate::Simulator;
use leg_models::simulate::{State, StepError, StepOptions};
use leg_models::{LegDynamics, LegModel, Parameters};
use leg_tests::{
    not_applicable, passive_release_state, random_assembled_state, rcond_of_rows, Rng,
};

const STATES: usize = 100;

pub fn check_kkt<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>() {
    let p = L::Params::<f64>::default();
    let mut rng = Rng::new(11);
    for _ in 0..STATES {
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 3.0);
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-2.0, 2.0));
        let acc = forward_dynamics::<L, f64, NQ, NC, NU>(&p, &s.q, &s.qd, &u, None).unwrap();
        let m = L::mass_matrix(&s.q, &p);
        let j = L::constraint_jacobian(&s.q, &p);
        let tau = actuation::<L, f64, NQ, NC, NU>(&u)
            - L::bias_forces(&s.q, &s.qd, &p)
            - L::damping_forces(&s.qd, &p);
        let jdqd = L::constraint_bias(&s.q, &s.qd, &p);
        // Residual of both block rows, relative to the size of their terms.
        let (mq, jf) = (m * acc.qdd, j.transpose() * acc.forces);
        let r1 = (mq - jf - tau).amax() / (mq.amax() + jf.amax() + tau.amax());
        assert!(r1 < 1e-10, "{}: dynamics row residual {r1:e}", L::NAME);
        if NC > 0 {
            // Relative to |J| |q̈|: J q̈ itself can be tiny by cancellation.
            let jq = j * acc.qdd;
            let r2 = (jq + jdqd).amax() / (j.amax() * acc.qdd.amax() + jdqd.amax());
            assert!(r2 < 1e-10, "{}: closure row residual {r2:e}", L::NAME);
        }
        // The same system, dense, by LU, on independent closure rows chosen here by rank
        // (a redundant row is implied by the others; its force is zero by convention).
        let mut rows: Vec<usize> = Vec::new();
        for r in 0..NC {
            let mut trial = rows.clone();
            trial.push(r);
            let sub = DMatrix::from_fn(trial.len(), NQ, |i, c| j[(trial[i], c)]);
            let sv = sub.svd(false, false).singular_values;
            if sv.min() > 1e-8 * sv.max() {
                rows = trial;
            }
        }
        assert_eq!(rows.len(), NC - L::REDUNDANT_ROWS, "{}: rank of J", L::NAME);
        let n = NQ + rows.len();
        let mut a = DMatrix::<f64>::zeros(n, n);
        let mut b = DVector::<f64>::zeros(n);
        a.view_mut((0, 0), (NQ, NQ)).copy_from(&m);
        for (k, &r) in rows.iter().enumerate() {
            for c in 0..NQ {
                a[(c, NQ + k)] = -j[(r, c)];
                a[(NQ + k, c)] = j[(r, c)];
            }
            b[NQ + k] = -jdqd[r];
        }
        b.rows_mut(0, NQ).copy_from(&tau);
        let x = a.lu().solve(&b).expect("regular KKT system");
        let scale = 1.0 + x.amax();
        for i in 0..NQ {
            assert!(
                (x[i] - acc.qdd[i]).abs() < 1e-9 * scale,
                "{}: q̈ vs dense LU",
                L::NAME
            );
        }
        // The forces themselves are not unique when rows repeat; Jᵀ F is.
        let mut f_dense = SVector::<f64, NC>::zeros();
        for (k, &r) in rows.iter().enumerate() {
            f_dense[r] = x[NQ + k];
        }
        let (generalized, generalized_dense) =
            (j.transpose() * acc.forces, j.transpose() * f_dense);
        assert!(
            (generalized - generalized_dense).amax() < 1e-9 * (1.0 + generalized_dense.amax()),
            "{}: Jᵀ F vs dense LU",
            L::NAME
        );
        if rows.len() == NC {
            assert!(
                (f_dense - acc.forces).amax() < 1e-9 * scale,
                "{}: F vs dense LU",
                L::NAME
            );
        }
        // f32 gives the same accelerations to its precision.
        let a32 = forward_dynamics::<L, f32, NQ, NC, NU>(
            &L::Params::<f32>::default(),
            &s.q.cast(),
            &s.qd.cast(),
            &u.cast(),
            None,
        );
        if let Ok(a32) = a32 {
            let d = (a32.qdd.cast::<f64>() - acc.qdd).amax();
            assert!(
                d < 2e-2 * (1.0 + acc.qdd.amax()),
                "{}: f32 q̈ differs by {d:e}",
                L::NAME
            );
        }
    }
}

/// 5 s at dt = 1 ms, RK4 with projection, no damping, no torque, from the spec's home
/// pose at rest: energy conserved to 1e-5 of `|E0|`, converging with the step, and the
/// closure to 1e-12 m.
pub fn check_passive_release<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    if NC == 0 {
        return;
    }
    // Energy is conserved without damping: a damped leg is released with it set to zero.
    let mut p = L::Params::<f64>::default();
    for (i, name) in <L::Params<f64> as Parameters<f64>>::NAMES
        .iter()
        .enumerate()
    {
        if name.ends_with("_damping") {
            assert!(p.set(i, 0.0));
        }
    }
    for i in 0..NQ {
        assert_eq!(
            L::damping_forces(&SVector::from_fn(|r, _| if r == i { 1.0 } else { 0.0 }), &p).amax(),
            0.0
        );
    }
    // 5 s at dt = 1 ms and at dt = 0.5 ms: the energy error is the integrator's, so it is
    // small and falls with the step (RK4: by 16; at least 4 is asked for), on any leg.
    let release = |dt: f64| {
        let sim = Simulator::<L, f64, NQ, NC, NU>::new(p, StepOptions::rk4(dt));
        let mut zero = |_: f64, _: &State<f64, NQ>| SVector::<f64, NU>::zeros();
        let steps = (5.0 / dt).round() as usize;
        let samples = sim
            .run(passive_release_state::<L, NQ, NC, NU>(&p), steps, &mut zero)
            .unwrap();
        assert_eq!(samples.len(), steps + 1);
        // Up to the first near-singular configuration (a parallelogram folding flat):
        // passing through one is a jump of the mechanism, not integration error.
        let regular = samples
            .iter()
            .position(|s| {
                NC > 0
                    && rcond_of_rows::<L, NQ, NC, NU>(&L::constraint_jacobian(&s.state.q, &p))
                        < 1e-10
            })
            .map_or(5.0, |k| samples[k].t);
        (samples, regular)
    };
    let drift_until = |samples: &[leg_models::simulate::Sample<f64, NQ, NC, NU>], until: f64| {
        let e0 = samples[0].energy;
        samples
            .iter()
            .filter(|s| s.t < until - 0.01)
            .map(|s| (s.energy - e0).abs())
            .fold(0.0, f64::max)
            / e0.abs()
    };
    let (samples, regular) = release(1e-3);
    let (fine_samples, fine_regular) = release(5e-4);
    let until = regular.min(fine_regular);
    if until < 5.0 {
        not_applicable(
            L::NAME,
            &format!("energy conservation after {until:.3} s of the passive release"),
            &"the leg folds through a singular configuration there",
        );
    }
    assert!(
        until > 0.5,
        "{}: singular within {until} s of the release",
        L::NAME
    );
    let drift = drift_until(&samples, until);
    let finer = drift_until(&fine_samples, until);
    let residual = samples
        .iter()
        .map(|s| s.closure_residual)
        .fold(0.0, f64::max);
    let moved = samples
        .iter()
        .map(|s| (s.state.q - samples[0].state.q).amax())
        .fold(0.0, f64::max);
    assert!(
        moved > 0.1,
        "{}: the leg barely moved ({moved} rad)",
        L::NAME
    );
    assert!(drift < 1e-5, "{}: relative energy drift {drift:e}", L::NAME);
    assert!(
        finer < drift / 4.0 + 1e-9,
        "{}: relative energy drift {drift:e} at 1 ms, {finer:e} at 0.5 ms",
        L::NAME
    );
    assert!(
        residual < 1e-12,
        "{}: closure residual {residual:e} m",
        L::NAME
    );
}

pub fn check_assembly<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let p = L::Params::<f64>::default();
    let mut rng = Rng::new(12);
    let tol = Tolerance::default();
    for _ in 0..STATES {
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 0.0);
        let theta = SVector::<f64, NU>::from_fn(|k, _| s.q[L::ACTUATED[k]]);
        let guess = s.q + SVector::<f64, NQ>::from_fn(|_, _| rng.range(-0.05, 0.05));
        let q = assemble::<L, f64, NQ, NC, NU>(&p, &theta, &guess, &tol).unwrap();
        if NC > 0 {
            assert!(
                L::closure_residual(&q, &p).amax() < 1e-12,
                "{}: assembled φ",
                L::NAME
            );
        }
        for (k, &a) in L::ACTUATED.iter().enumerate() {
            assert_eq!(
                q[a],
                theta[k],
                "{}: actuated joints stay where asked",
                L::NAME
            );
        }
        // Consistent velocities: J q̇ = 0 with the motors' rates.
        let theta_dot = SVector::<f64, NU>::from_fn(|_, _| rng.range(-2.0, 2.0));
        match consistent_velocity::<L, f64, NQ, NC, NU>(&p, &q, &theta_dot) {
            Ok(qd) => {
                if NC > 0 {
                    let jqd = L::constraint_jacobian(&q, &p) * qd;
                    assert!(
                        jqd.amax() < 1e-10 * (1.0 + qd.amax()),
                        "{}: J q̇ = {jqd}",
                        L::NAME
                    );
                }
                for (k, &a) in L::ACTUATED.iter().enumerate() {
                    assert_eq!(qd[a], theta_dot[k]);
                }
            }
            Err(AssemblyError::Singular) => {}
            Err(e) => panic!("{}: {e}", L::NAME),
        }
        // Foot → assembled configuration → foot.
        let foot = L::foot_position(&s.q, &p);
        let q2 = foot_inverse::<L, f64, NQ, NC, NU, 2, NC>(&p, &foot, &guess, &tol).unwrap();
        assert!(
            (L::foot_position(&q2, &p) - foot).amax() < 1e-12,
            "{}: foot round trip",
            L::NAME
        );
        if NC > 0 {
            assert!(L::closure_residual(&q2, &p).amax() < 1e-12);
        }
    }
    // Out of reach and non-finite requests are typed errors.
    let home = SVector::<f64, NQ>::from_column_slice(&L::HOME);
    let far = SVector::<f64, 2>::new(10.0, -10.0);
    assert!(matches!(
        foot_inverse::<L, f64, NQ, NC, NU, 2, NC>(&p, &far, &home, &tol),
        Err(AssemblyError::Unreachable { residual }) if residual > 1.0
    ));
    let nan = SVector::<f64, NU>::from_element(f64::NAN);
    assert_eq!(
        assemble::<L, f64, NQ, NC, NU>(&p, &nan, &home, &tol),
        Err(AssemblyError::NonFinite)
    );
    assert_eq!(
        forward_dynamics::<L, f64, NQ, NC, NU>(&p, &home, &home, &nan, None),
        Err(DynamicsError::NonFinite)
    );
    // Issue 29: a NaN pose was reported as "the mass matrix is not positive definite", and
    // finite rates whose terms overflow as a non-finite input. Each is said as what it is
    // (explained off the hot path; the `Leg` methods do it).
    let zero = SVector::<f64, NQ>::zeros();
    let none = SVector::<f64, NU>::zeros();
    let nan_q = SVector::<f64, NQ>::from_element(f64::NAN);
    assert_eq!(
        forward_dynamics::<L, f64, NQ, NC, NU>(&p, &nan_q, &zero, &none, None)
            .map_err(|e| e.explained(&nan_q, &zero, &none)),
        Err(DynamicsError::NonFinite),
        "{}: a NaN pose",
        L::NAME
    );
    let fast = SVector::<f64, NQ>::from_element(1e200);
    assert_eq!(
        forward_dynamics::<L, f64, NQ, NC, NU>(&p, &home, &fast, &none, None)
            .map_err(|e| e.explained(&home, &fast, &none)),
        Err(DynamicsError::Overflow),
        "{}: rates of 1e200",
        L::NAME
    );
}

/// `project_position_near` (the Euler stance step's projection, chord steps with the
/// step's start's `J`): from a step's move along assembled rates, and from a long one
/// (which may take the fallback), the pose ends on the closures to the tolerance, and a
/// short move's projection is where `project_position`'s is to second order of the move
/// (both are minimal-norm corrections, with `J` from the start and at the pose).
pub fn check_projection_near<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    use leg_models::assembly::{leg_size, project_position, project_position_near};
    if NC == 0 {
        return;
    }
    let p = L::Params::<f64>::default();
    let tol = Tolerance::default();
    let mut rng = Rng::new(29);
    let (mut worst, mut apart) = (0.0f64, 0.0f64);
    for _ in 0..20 {
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 3.0);
        let j = L::constraint_jacobian(&s.q, &p);
        for dt in [1e-3, 0.1] {
            let moved = s.q + s.qd * dt;
            let mut near = moved;
            project_position_near::<L, f64, NQ, NC, NU>(&p, &mut near, &s.q, &j, &tol)
                .unwrap_or_else(|e| panic!("{}: {e} after a move of {dt} s", L::NAME));
            let size = leg_size::<L, f64, NQ, NC, NU>(&p, &near);
            let r = L::closure_residual(&near, &p).amax() / size;
            worst = worst.max(r);
            assert!(
                r <= 1.01 * tol.relative_residual,
                "{}: {r:e} of its size off the closures after a move of {dt} s",
                L::NAME
            );
            if dt == 1e-3 {
                let mut full = moved;
                project_position::<L, f64, NQ, NC, NU>(&p, &mut full, &tol).unwrap();
                let step = (moved - s.q).amax();
                apart = apart.max((near - full).amax() / (step * step).max(1e-300));
            }
        }
    }
    eprintln!(
        "{}: projected near a step's start: residual {worst:.1e} of the size; off project_position's by {apart:.1e} × the move²",
        L::NAME
    );
    assert!(
        apart < 100.0,
        "{}: the chord projection lands {apart:e} × the move² from project_position's",
        L::NAME
    );
}

macro_rules! runtime {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        mod $module {
            type Model = $ty;
            #[test]
            fn kkt_solution_has_small_residual_and_matches_dense_lu() {
                super::check_kkt::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn passive_release_conserves_energy_and_closure() {
                super::check_passive_release::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn assembly_velocities_and_foot_inverse() {
                super::check_assembly::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn projection_near_a_step_start_closes_the_loops() {
                super::check_projection_near::<Model, $nq, $nc, $nu>();
            }
        }
    };
}

generated::for_each_model!(runtime);

mod minitaur_singularities {
    use super::*;
    use generated::Minitaur;
    use std::f64::consts::FRAC_PI_2;

    fn params() -> generated::minitaur::Params<f64> {
        Default::default()
    }

    /// Both branches straight down along one line: `J` loses rank, the KKT system is
    /// singular.
    #[test]
    fn full_extension_is_a_singular_configuration() {
        let q = SVector::<f64, 4>::new(-FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0);
        assert!(Minitaur::closure_residual(&q, &params()).amax() < 1e-15);
        let r = forward_dynamics::<Minitaur, f64, 4, 2, 2>(
            &params(),
            &q,
            &SVector::zeros(),
            &SVector::zeros(),
            None,
        );
        assert!(
            matches!(r, Err(DynamicsError::SingularConstraints { .. })),
            "{r:?}"
        );
    }

    /// Knees together, so the lower links are collinear: the passive joints lose rank
    /// and the motors no longer determine their rates (the dynamics stay regular).
    #[test]
    fn collinear_lower_links_are_singular_for_the_passive_joints() {
        let q = SVector::<f64, 4>::new(-1.2, 0.7, -1.2, 0.7);
        assert!(Minitaur::closure_residual(&q, &params()).amax() < 1e-15);
        let r = consistent_velocity::<Minitaur, f64, 4, 2, 2>(
            &params(),
            &q,
            &SVector::<f64, 2>::new(1.0, -1.0),
        );
        assert_eq!(r, Err(AssemblyError::Singular));
        assert!(forward_dynamics::<Minitaur, f64, 4, 2, 2>(
            &params(),
            &q,
            &SVector::zeros(),
            &SVector::zeros(),
            None
        )
        .is_ok());
    }

    /// Without stabilization the closure drifts until the dynamics fail; the simulator
    /// stops with the cause and keeps every sample it had.
    #[test]
    fn a_failing_simulation_keeps_what_it_recorded() {
        let p = params();
        let opts = StepOptions {
            project: false,
            ..StepOptions::rk4(1e-3)
        };
        let sim = Simulator::<Minitaur, f64, 4, 2, 2>::new(p, opts);
        let mut zero = |_: f64, _: &State<f64, 4>| SVector::<f64, 2>::zeros();
        let stop = sim
            .run(
                passive_release_state::<Minitaur, 4, 2, 2>(&p),
                5000,
                &mut zero,
            )
            .expect_err("an unstabilized passive Minitaur drifts apart within 5 s");
        assert!(stop.t > 0.1 && stop.t < 5.0, "{}", stop);
        assert_eq!(stop.samples.len() as f64, (stop.t / 1e-3).round());
        assert!(stop
            .samples
            .iter()
            .all(|s| s.state.q.iter().all(|x| x.is_finite())));
        assert!(
            stop.samples.last().unwrap().closure_residual > 1e-6,
            "it drifted before failing"
        );
        let shown = stop.to_string();
        assert!(shown.contains("stopped at t ="), "{shown}");
    }

    /// Lower links shortened at run time (no regeneration) to 5 cm: knees 20 cm apart
    /// cannot meet, and assembly says so.
    #[test]
    fn unreachable_motor_angles_are_a_typed_error() {
        let mut p = params();
        p.update(|v| {
            v.lower_a_length_x = 0.05;
            v.lower_b_length_x = 0.05;
        });
        let guess = SVector::<f64, 4>::from_column_slice(&Minitaur::HOME);
        let theta = SVector::<f64, 2>::new(0.0, std::f64::consts::PI);
        let r = assemble::<Minitaur, f64, 4, 2, 2>(&p, &theta, &guess, &Tolerance::default());
        match r {
            Err(AssemblyError::Unreachable { residual }) => assert!(residual > 0.01, "{residual}"),
            other => panic!("expected Unreachable, got {other:?}"),
        }
        // The same angles with the spec's links assemble.
        assert!(assemble::<Minitaur, f64, 4, 2, 2>(
            &params(),
            &theta,
            &guess,
            &Tolerance::default()
        )
        .is_ok());
    }

    /// A simulation started at a singular configuration stops at once with the typed
    /// cause and an empty record.
    #[test]
    fn a_simulation_stops_at_a_singularity() {
        let q = SVector::<f64, 4>::new(-FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0);
        let sim = Simulator::<Minitaur, f64, 4, 2, 2>::new(params(), StepOptions::rk4(1e-3));
        let mut zero = |_: f64, _: &State<f64, 4>| SVector::<f64, 2>::zeros();
        let stop = sim
            .run(
                State {
                    q,
                    qd: SVector::zeros(),
                },
                10,
                &mut zero,
            )
            .unwrap_err();
        assert!(
            matches!(
                stop.cause,
                StepError::Dynamics(DynamicsError::SingularConstraints { .. })
            ),
            "{stop}"
        );
        assert_eq!((stop.t, stop.samples.len()), (0.0, 0));
    }
}
