//! Property tests of the runtime, for every leg: random states, inputs and parameters —
//! zero, negative, huge, NaN and infinite ones among them — through forward dynamics,
//! assembly, the foot inverse, one integration step and every controller that applies.
//! Each call returns `Ok` with finite values or a typed error: never a panic, never a
//! non-finite `Ok`, never an assembly reported `Ok` whose closure residual exceeds its
//! tolerance.
//!
//! Cases per leg: 64 by default (fast enough for CI); a long campaign sets
//! `LEGS_PROPTEST_CASES`, e.g. `LEGS_PROPTEST_CASES=100000 cargo test --release -p
//! leg-tests --test properties`.

use leg_models::assembly::{assemble, foot_inverse, leg_size, Tolerance};
use leg_models::control::reference::{Sinusoid, StepCycle};
use leg_models::control::{
    FootFeedbackLinearization, FootPdGravity, Gains, JointFeedbackLinearization, PdGravity,
};
use leg_models::dynamics::forward_dynamics;
use leg_models::nalgebra::SVector;
use leg_models::simulate::{step, State, StepOptions, TorqueSource};
use leg_models::{LegModel, Parameters};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestRunner};

/// A fixed seed (1 unless `LEGS_PROPTEST_SEED` says otherwise), so that a run can be
/// repeated and the counts the test asserts do not depend on luck.
fn seed() -> RngSeed {
    RngSeed::Fixed(
        std::env::var("LEGS_PROPTEST_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(1),
    )
}

fn cases() -> u32 {
    std::env::var("LEGS_PROPTEST_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(64)
}

/// A state or input entry: mostly ordinary, sometimes zero, huge, tiny or not finite.
fn value(range: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        12 => -range..range,
        1 => Just(0.0),
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(1e300),
        1 => Just(-1e-300),
    ]
}

/// What happens to one parameter: kept (most), scaled, negated, or replaced.
#[derive(Clone, Copy, Debug)]
enum Edit {
    Keep,
    Scale(f64),
    Set(f64),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        20 => Just(Edit::Keep),
        4 => (0.1..10.0f64).prop_map(Edit::Scale),
        1 => Just(Edit::Scale(-1.0)),
        1 => Just(Edit::Set(0.0)),
        1 => Just(Edit::Set(f64::NAN)),
        1 => Just(Edit::Set(f64::INFINITY)),
        1 => Just(Edit::Set(1e300)),
    ]
}

#[derive(Clone, Debug)]
struct Case {
    q: Vec<f64>,
    qd: Vec<f64>,
    u: Vec<f64>,
    theta: Vec<f64>,
    foot: [f64; 2],
    edits: Vec<Edit>,
}

fn finite<const N: usize>(v: &SVector<f64, N>) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// How many calls of each kind returned `Ok`: the properties hold on `Ok` results, so a
/// function that always failed would pass them; the counts show it does not.
#[derive(Default, Debug)]
struct Oks {
    forward_dynamics: u32,
    assembled: u32,
    foot_inverse: u32,
    step: u32,
    torques: u32,
}

/// `Ok` results must be finite; an assembled pose must meet its tolerance.
fn check<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    c: &Case,
    oks: &mut Oks,
) -> Result<(), TestCaseError> {
    let mut p = L::Params::<f64>::default();
    for (i, e) in c.edits.iter().enumerate() {
        let v = p.get(i).unwrap();
        match *e {
            Edit::Keep => {}
            Edit::Scale(s) => {
                p.set(i, v * s);
            }
            Edit::Set(x) => {
                p.set(i, x);
            }
        }
    }
    let q = SVector::<f64, NQ>::from_column_slice(&c.q);
    let qd = SVector::<f64, NQ>::from_column_slice(&c.qd);
    let u = SVector::<f64, NU>::from_column_slice(&c.u);
    let theta = SVector::<f64, NU>::from_column_slice(&c.theta);
    let foot = SVector::<f64, 2>::from_column_slice(&c.foot);
    let tol = Tolerance::default();

    if let Ok(a) = forward_dynamics::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None) {
        prop_assert!(
            finite(&a.qdd) && finite(&a.forces),
            "forward dynamics: {a:?}"
        );
        oks.forward_dynamics += 1;
    }
    // An assembled pose is finite and meets the closures to the tolerance it promises.
    let assembled = |what: &str, q: &SVector<f64, NQ>| -> Result<(), TestCaseError> {
        prop_assert!(finite(q), "{what}: {q:?}");
        let residual = if NC > 0 {
            L::closure_residual(q, &p).amax()
        } else {
            0.0
        };
        let limit = tol.relative_residual * leg_size::<L, f64, NQ, NC, NU>(&p, q);
        prop_assert!(
            residual <= limit * (1.0 + 1e-9),
            "{what}: residual {residual:e} over {limit:e} at {q:?}"
        );
        Ok(())
    };
    // The foot inverse: for the random target (rarely reachable: a one-motor leg's foot
    // moves on a curve), and for one it can reach, the foot of the assembled pose.
    let mut targets = vec![foot];
    // The foot of the nearest assembled pose is reachable on every leg (a leg whose
    // motors over-determine it assembles only for motor angles on its one-parameter
    // family, which random angles miss).
    let mut projected = q;
    if leg_models::assembly::project_position::<L, f64, NQ, NC, NU>(&p, &mut projected, &tol)
        .is_ok()
    {
        targets.push(L::foot_position(&projected, &p));
    }
    if let Ok(qa) = assemble::<L, f64, NQ, NC, NU>(&p, &theta, &q, &tol) {
        assembled("assemble", &qa)?;
        oks.assembled += 1;
        targets.push(L::foot_position(&qa, &p));
    }
    for target in targets {
        if let Ok(qf) = foot_inverse::<L, f64, NQ, NC, NU, 2, NC>(&p, &target, &q, &tol) {
            assembled("foot inverse", &qf)?;
            // The foot is where it was asked to be, to the solver's tolerance.
            let size = leg_size::<L, f64, NQ, NC, NU>(&p, &qf).max(target.amax());
            let off = (L::foot_position(&qf, &p) - target).amax();
            prop_assert!(
                off <= tol.relative_residual * size * (1.0 + 1e-9),
                "foot inverse: the foot is {off:e} from its target at {qf:?}"
            );
            oks.foot_inverse += 1;
        }
    }

    let mut state = State { q, qd };
    let mut hold = |_: f64, _: &State<f64, NQ>| u;
    if step::<L, f64, NQ, NC, NU>(&p, &mut state, 0.0, &mut hold, &StepOptions::rk4(1e-3)).is_ok() {
        prop_assert!(finite(&state.q) && finite(&state.qd), "step: {state:?}");
        oks.step += 1;
    }

    let state = State { q, qd };
    let joint_ref = Sinusoid {
        offset: theta,
        amplitude: SVector::from_element(0.1),
        frequency: SVector::from_element(1.0),
        phase: SVector::zeros(),
    };
    let foot_ref = StepCycle {
        center: foot,
        half_stride: 0.03,
        half_height: 0.015,
        period: 0.5,
    };
    let mut torques: Vec<(&str, Result<SVector<f64, NU>, _>)> = Vec::new();
    if let Ok(mut c) = JointFeedbackLinearization::<L, f64, _, NQ, NC, NU>::new(
        p,
        Gains::critically_damped(100.0),
        joint_ref,
    ) {
        torques.push(("joint FL", c.torque(0.1, &state)));
    }
    if let Ok(mut c) = PdGravity::<L, f64, _, NQ, NC, NU>::new(p, Gains::new(1.0, 0.1), joint_ref) {
        torques.push(("joint PD+g", c.torque(0.1, &state)));
    }
    if let Ok(mut c) = FootFeedbackLinearization::<L, f64, _, NQ, NC, NU>::new(
        p,
        Gains::critically_damped(400.0),
        foot_ref,
    ) {
        torques.push(("foot FL", c.torque(0.1, &state)));
    }
    if let Ok(mut c) =
        FootPdGravity::<L, f64, _, NQ, NC, NU>::new(p, Gains::new(10.0, 1.0), foot_ref)
    {
        torques.push(("foot PD+g", c.torque(0.1, &state)));
    }
    for (what, t) in torques {
        if let Ok(t) = t {
            prop_assert!(finite(&t), "{what}: {t:?}");
            oks.torques += 1;
        }
    }
    Ok(())
}

fn run<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>() {
    let n_params = <L::Params<f64> as Parameters<f64>>::NAMES.len();
    // Half the cases ordinary (states, inputs and scaled parameters), where the calls
    // mostly succeed and their results are checked; half hostile (NaN, infinite, zero,
    // negative and huge entries), where they must fail cleanly.
    let ordinary = |range: f64| -> BoxedStrategy<f64> { (-range..range).boxed() };
    let hostile = |range: f64| -> BoxedStrategy<f64> { value(range).boxed() };
    let case = |v: &dyn Fn(f64) -> BoxedStrategy<f64>, e: BoxedStrategy<Edit>| {
        (
            prop::collection::vec(v(4.0), NQ),
            prop::collection::vec(v(10.0), NQ),
            prop::collection::vec(v(5.0), NU),
            prop::collection::vec(v(4.0), NU),
            (v(0.5), v(0.5)),
            prop::collection::vec(e, n_params),
        )
            .prop_map(|(q, qd, u, theta, (fx, fy), edits)| Case {
                q,
                qd,
                u,
                theta,
                foot: [fx, fy],
                edits,
            })
            .boxed()
    };
    let scaled = prop_oneof![
        20 => Just(Edit::Keep),
        4 => (0.5..2.0f64).prop_map(Edit::Scale),
    ]
    .boxed();
    let strategy = prop_oneof![case(&ordinary, scaled), case(&hostile, edit().boxed())];
    let mut runner = TestRunner::new(Config {
        cases: cases(),
        failure_persistence: None,
        rng_seed: seed(),
        ..Config::default()
    });
    let oks = std::cell::RefCell::new(Oks::default());
    if let Err(e) = runner.run(&strategy, |c| {
        check::<L, NQ, NC, NU>(&c, &mut oks.borrow_mut())
    }) {
        panic!("{}: {e}", L::NAME);
    }
    // Most inputs are ordinary: every kind of call succeeds on a share of them.
    let oks = oks.into_inner();
    eprintln!("{}: Ok results in {} cases: {oks:?}", L::NAME, cases());
    let share = cases() / 10;
    assert!(
        oks.forward_dynamics >= share && oks.step >= share,
        "{}: too few Ok results to test anything: {oks:?} of {} cases",
        L::NAME,
        cases()
    );
    assert!(
        oks.foot_inverse >= 1,
        "{}: no foot inverse succeeded: {oks:?}",
        L::NAME
    );
    // Controllers and assembly from motor angles need motors that do not over-determine
    // the leg; on one that they do, both are refused by structure.
    let structure = leg_models::dynamics::structure::Structure::of::<L, NQ, NC, NU>();
    match structure.joint_space() {
        Ok(()) => {
            assert!(
                oks.torques >= share,
                "{}: too few torques: {oks:?}",
                L::NAME
            );
            assert!(
                oks.assembled >= 1,
                "{}: no assembly succeeded: {oks:?}",
                L::NAME
            );
        }
        Err(why) => {
            assert_eq!(oks.torques, 0, "{}: a controller acted: {oks:?}", L::NAME);
            leg_tests::not_applicable(L::NAME, "property tests of controllers and assembly", &why);
        }
    }
}

/// Issue 29: the analysis and the hybrid simulator under the same kind of input. Poses near
/// home (projected, or left off the closures), hostile poses, parameters edited; limits
/// ordinary, zero or huge; a start on, above or under the ground. Each call is `Ok` with
/// finite values in their ranges (ranks in [0, 1], `Λ⁻¹` symmetric, `ξ` in [0, 1]) and
/// only at a pose on the closures, or a typed error; a hybrid run keeps every contact on
/// or above the ground and a start under it is refused.
fn run_analysis_and_hybrid<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    use leg_models::analysis::{
        foot_inverse_inertia, impact_mitigation, point_measures, Body, BodyCoupling, LegFrame,
        MotorLimits,
    };
    use leg_models::simulate::hybrid::{HybridError, HybridSimulator, HybridState};
    let n_params = <L::Params<f64> as Parameters<f64>>::NAMES.len();
    let strategy = (
        prop::collection::vec(-0.3..0.3f64, NQ),
        prop::collection::vec(value(4.0), NQ),
        prop_oneof![3 => Just(true), 1 => Just(false)],
        prop::collection::vec(-2.0..2.0f64, NQ),
        prop_oneof![Just(1e-3), Just(0.5), Just(1e9), Just(0.0), Just(f64::NAN)],
        prop_oneof![Just(-0.05), Just(0.0), Just(0.02), Just(0.2)],
        prop::collection::vec(
            prop_oneof![8 => Just(Edit::Keep), 1 => (0.5..2.0f64).prop_map(Edit::Scale), 1 => edit()],
            n_params,
        ),
        prop_oneof![3 => Just(true), 1 => Just(false)],
    );
    let mut runner = TestRunner::new(Config {
        cases: (cases() / 2).max(8),
        failure_persistence: None,
        rng_seed: seed(),
        ..Config::default()
    });
    let oks = std::cell::RefCell::new([0u32; 3]);
    let frame = LegFrame::<NQ>::of::<L, NC, NU>();
    let result = runner.run(
        &strategy,
        |(noise, hostile, near, qd, limit, lift, edits, ordinary)| {
            let mut p = L::Params::<f64>::default();
            if !ordinary {
                for (i, e) in edits.iter().enumerate() {
                    let v = p.get(i).unwrap();
                    match *e {
                        Edit::Keep => {}
                        Edit::Scale(s) => {
                            p.set(i, v * s);
                        }
                        Edit::Set(x) => {
                            p.set(i, x);
                        }
                    }
                }
            }
            let home = SVector::<f64, NQ>::from_column_slice(&L::HOME);
            let mut q = if near {
                home + SVector::<f64, NQ>::from_column_slice(&noise)
            } else {
                SVector::<f64, NQ>::from_column_slice(&hostile)
            };
            let projected = leg_models::assembly::project_position::<L, f64, NQ, NC, NU>(
                &p,
                &mut q.clone(),
                &Tolerance::default(),
            )
            .is_ok();
            if near && projected {
                let _ = leg_models::assembly::project_position::<L, f64, NQ, NC, NU>(
                    &p,
                    &mut q,
                    &Tolerance::default(),
                );
            }
            let on_closures = q.iter().all(|x| x.is_finite())
                && (NC == 0
                    || L::closure_residual(&q, &p).amax()
                        <= leg_models::assembly::ON_CLOSURES
                            * leg_size::<L, f64, NQ, NC, NU>(&p, &q));
            let limits = MotorLimits {
                torque: SVector::<f64, NU>::from_element(limit),
                speed: SVector::<f64, NU>::from_element(limit),
            };
            if let Ok(m) = point_measures::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame, &limits) {
                prop_assert!(on_closures, "measures off the closures at {q:?}");
                prop_assert!(
                    m.passive_rank.abs() <= 1.0 + 1e-12 && m.foot_rank.abs() <= 1.0 + 1e-12,
                    "ranks {} {}",
                    m.passive_rank,
                    m.foot_rank
                );
                prop_assert!(
                    m.foot.iter().all(|x| x.is_finite())
                        && m.inverse_inertia.iter().all(|x| x.is_finite())
                        && (m.inverse_inertia - m.inverse_inertia.transpose()).amax()
                            <= 1e-9 * m.inverse_inertia.amax(),
                    "{m:?}"
                );
                oks.borrow_mut()[0] += 1;
            }
            if let Ok(inv) = foot_inverse_inertia::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame, true)
            {
                prop_assert!(on_closures && inv.iter().all(|x| x.is_finite()), "{inv:?}");
            }
            let coupling = BodyCoupling::new::<L, f64, NQ, NC, NU>(&p);
            let body = Body::Translating { mass: 10.0 };
            if let Ok(xi) = impact_mitigation::<L, f64, NQ, NC, NU, 2, NC>(
                &p,
                &q,
                &frame,
                &body,
                coupling.as_ref(),
            ) {
                prop_assert!(on_closures, "ξ off the closures at {q:?}");
                prop_assert!((-1e-9..=1.0 + 1e-9).contains(&xi), "ξ = {xi}");
            }
            if NK == 0 || !(near && projected && ordinary) {
                return Ok(());
            }
            // The hybrid simulator from the pose lifted by `lift` above its lowest contact.
            let sim = HybridSimulator::<L, f64, NQ, NC, NU, NK>::new(p, 1e-3);
            let x = L::contact_positions(&q, &p);
            let lowest = (0..NK / 2)
                .map(|k| x[2 * k + 1])
                .fold(f64::INFINITY, f64::min);
            let Some(h) = leg_models::control::hop::height_joint::<L, f64, NQ, NC, NU, NK>(&p, &q)
            else {
                return Ok(());
            };
            let mut start = q;
            start[h] += lift - lowest;
            let qd = SVector::<f64, NQ>::from_column_slice(&qd);
            let state = State { q: start, qd };
            match sim.start(state, &SVector::zeros()) {
                // (On a slope the lift is not the gap: only its sign is checked on a level
                // ground.)
                Err(HybridError::StartsUnderGround { depth, .. }) => {
                    prop_assert!(depth > 0.0, "{depth} for {lift}");
                }
                Err(_) => {}
                Ok(s) => {
                    let mut zero =
                        |_: f64, _: &HybridState<f64, NQ, NK>| SVector::<f64, NU>::zeros();
                    let record = match sim.run(s, 30, &mut zero) {
                        Ok(r) => r,
                        Err(stopped) => stopped.record,
                    };
                    let ground =
                        leg_models::dynamics::contact::Ground::<f64>::of::<L, NQ, NC, NU, NK>();
                    for sample in &record.samples {
                        let hq = &sample.state.state;
                        prop_assert!(finite(&hq.q) && finite(&hq.qd), "{hq:?}");
                        let gap = ground.coordinates(&L::contact_positions(&hq.q, &p));
                        let size = leg_size::<L, f64, NQ, NC, NU>(&p, &hq.q);
                        for k in 0..NK / 2 {
                            prop_assert!(
                                gap[2 * k + 1] >= -1e-9 * size,
                                "contact {k} {} m under the ground at t = {}",
                                -gap[2 * k + 1],
                                sample.t
                            );
                        }
                    }
                    oks.borrow_mut()[2] += 1;
                }
            }
            oks.borrow_mut()[1] += 1;
            Ok(())
        },
    );
    if let Err(e) = result {
        panic!("{}: {e}", L::NAME);
    }
    let oks = oks.into_inner();
    eprintln!(
        "{}: measures Ok {}, hybrid starts {} (runs {})",
        L::NAME,
        oks[0],
        oks[1],
        oks[2]
    );
    if frame.foot_polygons().is_ok() {
        assert!(oks[0] >= 1, "{}: no measures succeeded", L::NAME);
    }
    if NK > 0 && oks[1] > 0 {
        assert!(oks[2] >= 1, "{}: no hybrid run started", L::NAME);
    }
}

macro_rules! property_tests {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        mod $module {
            #[test]
            fn runtime() {
                super::run::<$ty, $nq, $nc, $nu>();
            }
            #[test]
            fn analysis_and_hybrid() {
                super::run_analysis_and_hybrid::<$ty, $nq, $nc, $nu, $nk>();
            }
        }
    };
}

generated::for_each_model!(property_tests);
