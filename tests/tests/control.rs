//! Control in the actuated coordinates, for every generated model: the two reductions
//! agree and reproduce the KKT forward dynamics; the feedback-linearized loop follows
//! the analytic error dynamics; the foot follows a step cycle; a 20 % mass error keeps
//! the loop stable; singular configurations are typed errors.

use leg_models::assembly::{assemble, consistent_velocity, foot_inverse, Tolerance};
use leg_models::control::reference::{Reference, Setpoint, Sinusoid, StepCycle};
use leg_models::control::{
    actuated_reduction, actuated_reduction_null_space, ControlError, FootFeedbackLinearization,
    FootPdGravity, Gains, JointFeedbackLinearization, PdGravity,
};
use leg_models::dynamics::forward_dynamics;
use leg_models::dynamics::structure::{NotApplicable, Structure};
use leg_models::nalgebra::{DMatrix, SVector};
use leg_models::simulate::Simulator;
use leg_models::simulate::{ControlUpdate, State, StepOptions, TorqueSource};
use leg_models::{LegDynamics, LegModel, Parameters};
use leg_tests::{not_applicable, passive_release_state, random_assembled_state, Rng};

pub fn check_reductions<
    L: LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let p = L::Params::<f64>::default();
    let structure = Structure::of::<L, NQ, NC, NU>();
    if let Err(why) = structure.joint_space() {
        // Typed, not NaN: the reduction says why.
        let s = passive_release_state::<L, NQ, NC, NU>(&p);
        let terms = L::dynamics_terms(&s.q, &s.qd, &p);
        assert_eq!(
            actuated_reduction::<L, f64, NQ, NC, NU>(&p, &terms, &s.qd),
            Err(ControlError::NotApplicable(why))
        );
        return not_applicable(L::NAME, "the actuated reduction", &why);
    }
    let full = structure.motors_determine_the_leg();
    if let Err(why) = full {
        not_applicable(L::NAME, "the null-space reduction (Schur form only)", &why);
    }
    let mut rng = Rng::new(21);
    for _ in 0..100 {
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 3.0);
        let terms = L::dynamics_terms(&s.q, &s.qd, &p);
        let schur = actuated_reduction::<L, f64, NQ, NC, NU>(&p, &terms, &s.qd).unwrap();
        let scale = 1.0 + schur.a_tilde.amax();
        // Both forms square the passive joints' conditioning: rounding grows as 1/rcond.
        let tol = 1e-12 / leg_tests::passive_rcond::<L, NQ, NC, NU>(&p, &s.q);
        if full.is_ok() {
            let ns =
                actuated_reduction_null_space::<L, f64, NQ, NC, NU>(&p, &terms, &s.qd).unwrap();
            assert!(
                (schur.a_tilde - ns.a_tilde).amax() < tol * scale,
                "{}: Ã differs by {:e} (scale {scale:e}): {} vs {}",
                L::NAME,
                (schur.a_tilde - ns.a_tilde).amax(),
                schur.a_tilde,
                ns.a_tilde
            );
            let bscale = 1.0 + schur.b_tilde.amax();
            assert!(
                (schur.b_tilde - ns.b_tilde).amax() < tol * bscale,
                "{}: b̃ differs",
                L::NAME
            );
        }
        assert!(
            (schur.a_tilde - schur.a_tilde.transpose()).amax() < 1e-10 * scale,
            "Ã symmetric"
        );
        // Ã θ̈ = b̃ + u reproduces the motor accelerations of the full KKT solve.
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-3.0, 3.0));
        let acc = forward_dynamics::<L, f64, NQ, NC, NU>(&p, &s.q, &s.qd, &u, None).unwrap();
        let theta_dd = SVector::<f64, NU>::from_fn(|k, _| acc.qdd[L::ACTUATED[k]]);
        let lhs = schur.a_tilde * theta_dd;
        let rhs = schur.b_tilde + u;
        assert!(
            (lhs - rhs).amax() < 1e-9 * (1.0 + rhs.amax() + lhs.amax()),
            "{}: Ã θ̈ = {lhs} but b̃ + u = {rhs}",
            L::NAME
        );
    }
}

/// A step cycle in the foot's `ND` coordinates: the ellipse `center + a cos ωt e₀ +
/// b sin ωt e_last` (stride along the base's x, height along its last axis: y in the plane,
/// z in space), once per 0.5 s. On a planar leg it is [`StepCycle`]'s ellipse.
#[derive(Clone, Copy)]
struct Ellipse<const ND: usize> {
    center: SVector<f64, ND>,
    half_stride: f64,
    half_height: f64,
}

impl<const ND: usize> Ellipse<ND> {
    fn step_cycle(center: SVector<f64, ND>, half_stride: f64, half_height: f64) -> Self {
        Ellipse {
            center,
            half_stride,
            half_height,
        }
    }
}

impl<const ND: usize> Reference<f64, ND> for Ellipse<ND> {
    fn sample(&self, t: f64) -> Setpoint<f64, ND> {
        let plane = StepCycle {
            center: SVector::<f64, 2>::zeros(),
            half_stride: self.half_stride,
            half_height: self.half_height,
            period: 0.5,
        }
        .sample(t);
        let embed = |v: SVector<f64, 2>| {
            let mut w = SVector::<f64, ND>::zeros();
            w[0] = v[0];
            w[ND - 1] = v[1];
            w
        };
        Setpoint {
            position: self.center + embed(plane.position),
            velocity: embed(plane.velocity),
            acceleration: embed(plane.acceleration),
        }
    }
}

/// The assembled state whose motors are at `theta` with rates `theta_dot`, on the home
/// pose's branch.
fn state_at<L: LegDynamics<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    theta: &SVector<f64, NU>,
    theta_dot: &SVector<f64, NU>,
) -> State<f64, NQ> {
    let home = passive_release_state::<L, NQ, NC, NU>(p).q;
    let q = assemble::<L, f64, NQ, NC, NU>(p, theta, &home, &Tolerance::default()).unwrap();
    let qd = consistent_velocity::<L, f64, NQ, NC, NU>(p, &q, theta_dot).unwrap();
    State { q, qd }
}

fn home_theta<L: LegDynamics<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
) -> SVector<f64, NU> {
    let home = passive_release_state::<L, NQ, NC, NU>(p).q;
    SVector::from_fn(|k, _| home[L::ACTUATED[k]])
}

/// From an initial error, `θ_ref − θ` follows the solution of `ë + k_d ė + k_p e = 0`.
pub fn check_error_dynamics<
    L: LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let p = L::Params::<f64>::default();
    if let Err(why) = Structure::of::<L, NQ, NC, NU>().joint_space() {
        return not_applicable(L::NAME, "joint feedback linearization", &why);
    }
    let reference = Sinusoid {
        offset: home_theta::<L, NQ, NC, NU>(&p),
        amplitude: SVector::from_element(0.1),
        frequency: SVector::from_element(0.5),
        phase: SVector::from_fn(|k, _| k as f64),
    };
    let (kp, e0) = (100.0f64, 0.02);
    for kd in [2.0 * kp.sqrt(), 6.0] {
        let r0 = reference.sample(0.0);
        let initial = state_at::<L, NQ, NC, NU>(&p, &r0.position.add_scalar(-e0), &r0.velocity);
        let controller = JointFeedbackLinearization::<L, f64, _, NQ, NC, NU>::new(
            p,
            Gains::new(kp, kd),
            reference,
        )
        .unwrap();
        let opts = StepOptions {
            control: ControlUpdate::PerStage,
            ..StepOptions::rk4(1e-3)
        };
        let sim = Simulator::<L, f64, NQ, NC, NU>::new(p, opts);
        let samples = sim.run(initial, 2000, &mut { controller }).unwrap();
        // e(t) with e(0) = e0, ė(0) = 0.
        let analytic = |t: f64| {
            let w = kp.sqrt();
            let zeta = kd / (2.0 * w);
            if (zeta - 1.0).abs() < 1e-12 {
                e0 * (1.0 + w * t) * (-w * t).exp()
            } else {
                let wd = w * (1.0 - zeta * zeta).sqrt();
                e0 * (-zeta * w * t).exp() * ((wd * t).cos() + zeta * w / wd * (wd * t).sin())
            }
        };
        let mut worst = 0.0f64;
        for s in &samples {
            let r = reference.sample(s.t);
            for k in 0..NU {
                let e = r.position[k] - s.state.q[L::ACTUATED[k]];
                worst = worst.max((e - analytic(s.t)).abs());
            }
        }
        assert!(
            worst < 1e-6,
            "{} (k_d = {kd}): error dynamics off by {worst:e} rad",
            L::NAME
        );
    }
}

/// Scales every mass and inertia in `p` by `factor`.
fn scale_masses<P: Parameters<f64>>(p: &mut P, factor: f64) {
    for (i, name) in P::NAMES.iter().enumerate() {
        if name.ends_with("_mass") || name.ends_with("_inertia") {
            let v = p.get(i).unwrap();
            assert!(p.set(i, v * factor));
        }
    }
}

/// The foot's largest distance from the step cycle in each second after the first,
/// (1 s, 2 s] and (2 s, 3 s], under foot-space feedback linearization (k_p = 400).
fn foot_tracking<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    controller_params: L::Params<f64>,
) -> (f64, f64) {
    let p = L::Params::<f64>::default();
    let home = passive_release_state::<L, NQ, NC, NU>(&p).q;
    let cycle = Ellipse::step_cycle(L::foot_position(&home, &p), 0.03, 0.015);
    let r0 = cycle.sample(0.0);
    let q0 =
        foot_inverse::<L, f64, NQ, NC, NU, ND, NP>(&p, &r0.position, &home, &Tolerance::default())
            .unwrap();
    let initial = State {
        q: q0,
        qd: SVector::zeros(),
    };
    let mut controller = FootFeedbackLinearization::<L, f64, _, NQ, NC, NU, ND, NP>::new(
        controller_params,
        Gains::critically_damped(400.0),
        cycle,
    )
    .unwrap();
    let sim = Simulator::<L, f64, NQ, NC, NU>::new(p, StepOptions::rk4(1e-3));
    let samples = sim.run(initial, 3000, &mut controller).unwrap();
    let worst = |from: f64, to: f64| {
        samples
            .iter()
            .filter(|s| s.t > from && s.t <= to)
            .map(|s| (L::foot_position(&s.state.q, &p) - cycle.sample(s.t).position).norm())
            .fold(0.0, f64::max)
    };
    (worst(1.0, 2.0), worst(2.0, 3.0))
}

pub fn check_foot_tracking<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>() {
    if let Err(why) = Structure::of::<L, NQ, NC, NU>().foot_space() {
        return not_applicable(L::NAME, "foot tracking", &why);
    }
    let (a, b) = foot_tracking::<L, NQ, NC, NU, ND, NP>(L::Params::default());
    assert!(
        a.max(b) < 1e-4,
        "{}: steady-state foot error {:e} m",
        L::NAME,
        a.max(b)
    );
}

pub fn check_mass_error_robustness<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>() {
    if let Err(why) = Structure::of::<L, NQ, NC, NU>().foot_space() {
        return not_applicable(L::NAME, "foot tracking with masses 20 % off", &why);
    }
    let mut wrong = L::Params::<f64>::default();
    scale_masses(&mut wrong, 1.2);
    // A 20 % model error acts like a disturbance of about 0.2 (g + |ÿ_ref|) ≈ 3 m/s²,
    // which a k_p = 400 loop holds to about 7 mm: bounded, and not growing.
    let (a, b) = foot_tracking::<L, NQ, NC, NU, ND, NP>(wrong);
    assert!(
        b.is_finite() && b < 1e-2,
        "{}: with masses 20 % off, foot error {b:e} m",
        L::NAME
    );
    assert!(
        b <= 1.05 * a + 1e-6,
        "{}: the error grows: {a:e} then {b:e} m",
        L::NAME
    );
}

/// Every controller is built where its method applies to the leg, and refused with the
/// reason where it does not; the refusal is decided by the leg's structure alone.
pub fn check_applicability<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>() {
    let p = L::Params::<f64>::default();
    let structure = Structure::of::<L, NQ, NC, NU>();
    let home = passive_release_state::<L, NQ, NC, NU>(&p).q;
    let theta = home_theta::<L, NQ, NC, NU>(&p);
    // The structure the generator found, against SVDs of J and J_f at home: the mobility
    // `NQ − rank J`; whether the motors determine the leg (the passive columns of J have
    // rank NQ − NU); how many directions the foot can move in with the closures held.
    let rank = |m: &DMatrix<f64>| {
        let sv = m.clone().svd(false, false).singular_values;
        let top = sv.max();
        sv.iter().filter(|&&s| s > 1e-9 * top.max(1e-300)).count()
    };
    let j = DMatrix::from_fn(NC, NQ, |r, c| L::constraint_jacobian(&home, &p)[(r, c)]);
    let passive: Vec<usize> = (0..NQ).filter(|i| !L::ACTUATED.contains(i)).collect();
    let jp = DMatrix::from_fn(NC, passive.len(), |r, c| j[(r, passive[c])]);
    let mobility = NQ - if NC > 0 { rank(&j) } else { 0 };
    assert_eq!(mobility, structure.mobility, "{}: mobility", L::NAME);
    assert_eq!(
        NC - if NC > 0 { rank(&j) } else { 0 },
        structure.redundant_rows
    );
    // The motors determine the leg when the passive joints follow them (full column rank
    // of J's passive columns) and the motors are free to move (mobility = motors).
    let determined = (NC > 0 && rank(&jp) == passive.len() || passive.is_empty()) && mobility == NU;
    assert_eq!(
        determined,
        structure.motors_determine_the_leg().is_ok(),
        "{}: do the motors determine the leg?",
        L::NAME
    );
    // Foot directions: J_f on the null space of J.
    let jf = DMatrix::from_fn(ND, NQ, |r, c| L::foot_jacobian(&home, &p)[(r, c)]);
    // The null space of J: eigenvectors of JᵀJ with (numerically) zero eigenvalues.
    let eig = (j.transpose() * &j).symmetric_eigen();
    let top = eig.eigenvalues.amax();
    let free: Vec<usize> = (0..NQ)
        .filter(|&i| eig.eigenvalues[i] <= 1e-12 * top)
        .collect();
    let null = DMatrix::from_fn(NQ, free.len(), |i, k| eig.eigenvectors[(i, free[k])]);
    let foot_directions = rank(&(&jf * null));
    assert_eq!(
        determined && foot_directions == ND && NU >= ND,
        structure.foot_space().is_ok(),
        "{}: can the motors place the foot?",
        L::NAME
    );
    let hold = Sinusoid {
        offset: theta,
        amplitude: SVector::zeros(),
        frequency: SVector::zeros(),
        phase: SVector::zeros(),
    };
    let cycle = Ellipse::step_cycle(L::foot_position(&home, &p), 0.01, 0.01);
    let expect = |built: Result<(), ControlError>, applies: Result<(), NotApplicable>| {
        assert_eq!(
            built,
            applies.map_err(ControlError::NotApplicable),
            "{}",
            L::NAME
        );
    };
    let g2 = Gains::critically_damped(100.0);
    expect(
        FootFeedbackLinearization::<L, f64, _, NQ, NC, NU, ND, NP>::new(p, g2, cycle).map(|_| ()),
        structure.foot_space(),
    );
    expect(
        FootPdGravity::<L, f64, _, NQ, NC, NU, ND, NP>::new(p, g2, cycle).map(|_| ()),
        structure.foot_space(),
    );
    let gu = Gains::critically_damped(100.0);
    expect(
        JointFeedbackLinearization::<L, f64, _, NQ, NC, NU>::new(p, gu, hold).map(|_| ()),
        structure.joint_space(),
    );
    expect(
        PdGravity::<L, f64, _, NQ, NC, NU>::new(p, gu, hold).map(|_| ()),
        structure.joint_space(),
    );
    // Where a controller applies, it acts at home (no NaN, no error).
    if let Ok(mut c) = JointFeedbackLinearization::<L, f64, _, NQ, NC, NU>::new(p, gu, hold) {
        let s = State {
            q: home,
            qd: SVector::zeros(),
        };
        let u = c.torque(0.0, &s).unwrap();
        assert!(u.iter().all(|x| x.is_finite()), "{}", L::NAME);
    }
}

macro_rules! control {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        mod $module {
            type Model = $ty;
            #[test]
            fn schur_and_null_space_reductions_agree_with_the_kkt_solve() {
                super::check_reductions::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn feedback_linearized_error_follows_the_analytic_solution() {
                super::check_error_dynamics::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn foot_tracks_the_step_cycle() {
                super::check_foot_tracking::<Model, $nq, $nc, $nu, 2, $nc>();
            }
            #[test]
            fn masses_off_by_20_percent_stay_stable() {
                super::check_mass_error_robustness::<Model, $nq, $nc, $nu, 2, $nc>();
            }
            #[test]
            fn controllers_apply_by_the_legs_structure() {
                super::check_applicability::<Model, $nq, $nc, $nu, 2, $nc>();
            }
        }
    };
}

generated::for_each_model!(control);

/// The same checks on the spatial legs: a foot with three coordinates, placed where three
/// motors determine the leg (`abducted_five_bar`), refused with the reason elsewhere.
macro_rules! spatial_control {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
        mod $module {
            type Model = $ty;
            #[test]
            fn schur_and_null_space_reductions_agree_with_the_kkt_solve() {
                super::check_reductions::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn feedback_linearized_error_follows_the_analytic_solution() {
                super::check_error_dynamics::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn foot_tracks_the_step_cycle() {
                super::check_foot_tracking::<Model, $nq, $nc, $nu, 3, $np>();
            }
            #[test]
            fn masses_off_by_20_percent_stay_stable() {
                super::check_mass_error_robustness::<Model, $nq, $nc, $nu, 3, $np>();
            }
            #[test]
            fn controllers_apply_by_the_legs_structure() {
                super::check_applicability::<Model, $nq, $nc, $nu, 3, $np>();
            }
        }
    };
}

generated::for_each_spatial_model!(spatial_control);

/// The open chain: the same controller is `u = M(q̈_ref + k_p e + k_d ė) + N`.
#[test]
fn two_link_uses_the_open_chain_law() {
    use generated::TwoLink;
    let p = generated::two_link::Params::<f64>::default();
    let reference = Sinusoid {
        offset: SVector::<f64, 2>::new(-1.0, 1.0),
        amplitude: SVector::from_element(0.2),
        frequency: SVector::from_element(1.0),
        phase: SVector::zeros(),
    };
    let gains = Gains::new(50.0, 9.0);
    let mut c =
        JointFeedbackLinearization::<TwoLink, f64, _, 2, 0, 2>::new(p, gains, reference).unwrap();
    let s = State {
        q: SVector::<f64, 2>::new(-0.9, 1.2),
        qd: SVector::<f64, 2>::new(0.3, -0.4),
    };
    let u = c.torque(0.3, &s).unwrap();
    let r = reference.sample(0.3);
    let v = r.acceleration + (r.position - s.q) * 50.0 + (r.velocity - s.qd) * 9.0;
    let expected = TwoLink::mass_matrix(&s.q, &p) * v + TwoLink::bias_forces(&s.q, &s.qd, &p);
    assert!(
        (u - expected).amax() < 1e-12 * (1.0 + expected.amax()),
        "{u} vs {expected}"
    );
}

/// Knees together: the lower links are collinear, `A22` is singular.
#[test]
fn a_singular_a22_is_a_typed_error() {
    use generated::Minitaur;
    let p = generated::minitaur::Params::<f64>::default();
    let q = SVector::<f64, 4>::new(-1.2, 0.7, -1.2, 0.7);
    let terms = Minitaur::dynamics_terms(&q, &SVector::zeros(), &p);
    assert_eq!(
        actuated_reduction::<Minitaur, f64, 4, 2, 2>(&p, &terms, &SVector::zeros()),
        Err(ControlError::SingularPassive)
    );
    assert_eq!(
        actuated_reduction_null_space::<Minitaur, f64, 4, 2, 2>(&p, &terms, &SVector::zeros()),
        Err(ControlError::SingularPassive)
    );
}

/// Torque limits clip each motor and count it; a loop that saturates still runs.
#[test]
fn torque_limits_clip_and_count() {
    use generated::Minitaur;
    use leg_models::control::Saturated;
    let p = generated::minitaur::Params::<f64>::default();
    let wants = |_: f64, _: &State<f64, 4>| SVector::<f64, 2>::new(0.5, -0.01);
    let mut limited = Saturated::new(wants, SVector::<f64, 2>::new(0.1, 0.1)).unwrap();
    let s = passive_release_state::<Minitaur, 4, 2, 2>(&p);
    let u = limited.torque(0.0, &s).unwrap();
    assert_eq!(u, SVector::<f64, 2>::new(0.1, -0.01));
    assert_eq!(limited.saturations, [1, 0]);
    assert_eq!(limited.peak_request, SVector::<f64, 2>::new(0.5, 0.01));
    // A step-cycle tracker with limits below what it needs saturates and keeps going.
    let home = s.q;
    let cycle = StepCycle {
        center: Minitaur::foot_position(&home, &p),
        half_stride: 0.03,
        half_height: 0.015,
        period: 0.25,
    };
    let fl = FootFeedbackLinearization::<Minitaur, f64, _, 4, 2, 2>::new(
        p,
        Gains::critically_damped(400.0),
        cycle,
    )
    .unwrap();
    let mut tight = Saturated::new(fl, SVector::<f64, 2>::from_element(0.05)).unwrap();
    let sim = Simulator::<Minitaur, f64, 4, 2, 2>::new(p, StepOptions::rk4(1e-3));
    let samples = sim.run(s, 500, &mut tight).unwrap();
    assert!(samples.iter().all(|x| x.u.amax() <= 0.05));
    assert!(
        tight.saturations.iter().sum::<usize>() > 10,
        "{:?}",
        tight.saturations
    );
    assert!(tight.peak_request.amax() > 0.05);
}
