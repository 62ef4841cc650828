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
        if let Ok(qf) = foot_inverse::<L, f64, NQ, NC, NU>(&p, &target, &q, &tol) {
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

macro_rules! property_tests {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        #[test]
        fn $module() {
            run::<$ty, $nq, $nc, $nu>();
        }
    };
}

generated::for_each_model!(property_tests);
