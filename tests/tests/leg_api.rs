//! The size-free handle `leg_models::Leg` on every generated leg: its settings reach the
//! algorithms (Baumgarte terms, tolerance, parameters by name), and each method gives what
//! the free function it stands for gives with the same arguments written out.

use leg_models::assembly::{assemble, Tolerance};
use leg_models::dynamics::contact::Modes;
use leg_models::dynamics::{forward_dynamics, Baumgarte};
use leg_models::nalgebra::SVector;
use leg_models::simulate::{State, StepOptions};
use leg_models::{ContactModel, Leg, Parameters};
use leg_tests::{random_assembled_state, Rng};

fn check<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    let leg = Leg::<L, f64, NQ, NC, NU, NK>::default();
    assert_eq!(*leg.params(), L::Params::<f64>::default(), "{}", L::NAME);
    let mut rng = Rng::new(13);
    let s = random_assembled_state::<L, NQ, NC, NU>(leg.params(), &mut rng, 1.0);
    let u = SVector::<f64, NU>::from_fn(|i, _| 0.3 - 0.2 * i as f64);

    // Baumgarte terms set on the leg are the ones the KKT solve gets. Off the closures
    // (a perturbed q) they change the answer, so a dropped setting would show.
    let off = s.q.add_scalar(1e-3);
    let b = Baumgarte {
        alpha: 7.0,
        beta: 11.0,
    };
    let stabilized = leg.with_baumgarte(b.alpha, b.beta);
    let by_leg = stabilized.forward_dynamics(&off, &s.qd, &u);
    let by_fn = forward_dynamics::<L, f64, NQ, NC, NU>(leg.params(), &off, &s.qd, &u, Some(b));
    assert_eq!(by_leg, by_fn, "{}", L::NAME);
    if NC > 0 {
        let plain = leg.forward_dynamics(&off, &s.qd, &u).unwrap();
        assert!(
            (plain.qdd - by_leg.unwrap().qdd).amax() > 1e-9,
            "{}: Baumgarte terms had no effect off the closures",
            L::NAME
        );
    }
    let d = stabilized
        .forward_dynamics_derivatives(&s.q, &s.qd, &u)
        .unwrap();
    assert_eq!(
        d.acceleration,
        forward_dynamics::<L, f64, NQ, NC, NU>(leg.params(), &s.q, &s.qd, &u, Some(b)).unwrap(),
        "{}",
        L::NAME
    );

    // A parameter by name is the parameter by index; an unknown one is an error naming it
    // and changes nothing.
    let name = L::Params::<f64>::NAMES[0];
    let mut renamed = leg;
    renamed.set_parameter(name, 0.5).unwrap();
    let mut by_index = L::Params::<f64>::default();
    by_index.set(0, 0.5);
    // A negative mass or inertia is refused by name, and nothing changes.
    if let Some(mass) = L::Params::<f64>::NAMES
        .iter()
        .find(|n| n.ends_with("_mass") || n.ends_with("_inertia"))
    {
        let err = renamed.set_parameter(mass, -1.0).unwrap_err();
        assert!(
            matches!(err, leg_models::ParameterError::Negative { .. })
                && err.to_string().contains(mass),
            "{}: {err}",
            L::NAME
        );
    }
    // The spec's other rules hold at run time too (issue 29): a gear ratio is positive, a
    // damping not negative, every value at most 1e6 in magnitude.
    for (suffix, bad) in [
        ("_gear_ratio", 0.0),
        ("_gear_ratio", -6.0),
        ("_damping", -1.0),
    ] {
        if let Some(p) = L::Params::<f64>::NAMES.iter().find(|n| n.ends_with(suffix)) {
            let err = renamed.set_parameter(p, bad).unwrap_err();
            assert!(
                matches!(
                    err,
                    leg_models::ParameterError::NotPositive { .. }
                        | leg_models::ParameterError::Negative { .. }
                ),
                "{}: {p} = {bad}: {err}",
                L::NAME
            );
        }
    }
    assert!(matches!(
        renamed.set_parameter(name, 1e308),
        Err(leg_models::ParameterError::TooLarge { .. })
    ));
    assert_eq!(*renamed.params(), by_index, "{}", L::NAME);
    assert_eq!(renamed.parameter(name), Ok(0.5));
    let err = renamed.set_parameter("no_such_parameter", 1.0).unwrap_err();
    assert_eq!(*renamed.params(), by_index, "{}", L::NAME);
    let message = err.to_string();
    assert!(
        message.contains("no_such_parameter") && message.contains(L::NAME),
        "{message}"
    );
    // A misspelt name gets the name meant; a non-finite value is refused, changing nothing.
    let misspelt = format!("{name}x");
    let err = renamed.set_parameter(&misspelt, 1.0).unwrap_err();
    assert_eq!(err.suggestion(), Some(name), "{}", L::NAME);
    assert!(
        err.to_string().contains(&format!("did you mean `{name}`")),
        "{err}"
    );
    assert!(matches!(
        renamed.set_parameter(name, f64::NAN),
        Err(leg_models::ParameterError::NotFinite { .. })
    ));
    assert_eq!(*renamed.params(), by_index, "{}", L::NAME);

    // The tolerance set on the leg is the one assembly uses: one Newton iteration is not
    // enough from a distant guess, and the default tolerance is.
    let theta = leg.motor_angles(&s.q);
    let guess = leg.home();
    let tight = Tolerance {
        relative_residual: 1e-14,
        max_iterations: 1,
    };
    assert_eq!(
        leg.with_tolerance(tight).assemble(&theta, &guess),
        assemble::<L, f64, NQ, NC, NU>(leg.params(), &theta, &guess, &tight),
        "{}",
        L::NAME
    );
    assert_eq!(
        leg.assemble(&theta, &guess),
        assemble::<L, f64, NQ, NC, NU>(leg.params(), &theta, &guess, &Tolerance::default()),
        "{}",
        L::NAME
    );

    // The assembled home is on the closures; the simulators carry the leg's settings.
    if let Ok(home) = leg.assembled_home() {
        if NC > 0 {
            assert!(leg.closure_residual(&home).amax() < 1e-12, "{}", L::NAME);
        }
    }
    let hybrid = stabilized.with_tolerance(tight).hybrid_simulator(1e-3);
    assert_eq!(hybrid.options.baumgarte, Some(b));
    assert_eq!(hybrid.options.tolerance, tight);
    assert_eq!(hybrid.options.friction, leg.friction());
    let flight =
        leg.forward_dynamics_with_contacts(&s.q, &s.qd, &u, &Modes::flight(), &SVector::zeros());
    assert_eq!(
        flight.map(|c| c.x),
        leg.forward_dynamics(&s.q, &s.qd, &u).map(|a| a.qdd),
        "{}: in flight the contacts add nothing",
        L::NAME
    );

    // A step through the leg is the free function's step.
    let opts = StepOptions::rk4(1e-3);
    let mut a = State { q: s.q, qd: s.qd };
    let mut b_state = a;
    let mut source = leg.torque_source(|_t, _s| u);
    leg.step(&mut a, 0.0, &mut source, &opts).unwrap();
    leg_models::simulate::step::<L, f64, NQ, NC, NU>(
        leg.params(),
        &mut b_state,
        0.0,
        &mut |_t: f64, _s: &State<f64, NQ>| u,
        &opts,
    )
    .unwrap();
    assert_eq!(a, b_state, "{}", L::NAME);
}

macro_rules! each {
    ($module:ident, $ty:ty, $nq:expr, $nc:expr, $nu:expr, $nk:expr) => {
        check::<$ty, $nq, $nc, $nu, $nk>();
    };
}

#[test]
fn the_handle_carries_its_settings_on_every_leg() {
    generated::for_each_model!(each);
}

/// A continuation step of zero never arrived (it hung), a negative one walked backwards
/// ("-2928.1 % of the way"), a tiny one ran unbounded (issue 29): each is refused before
/// any work, and an ordinary step still follows the branch.
#[test]
fn continuation_steps_are_bounded() {
    use leg_models::assembly::{AssemblyError, MAX_CONTINUATION_STEPS};
    let leg = generated::minitaur::Leg::default();
    let start = leg.assembled_home().unwrap();
    let theta = SVector::<f64, 2>::new(-0.6, -2.5);
    for bad in [0.0, -0.05, 1e-12] {
        match leg.assemble_along(&start, &theta, bad) {
            Err(AssemblyError::StepTooSmall { max_step, way }) => {
                assert_eq!(max_step, bad);
                assert!(way > 0.0 && way / bad.abs() > MAX_CONTINUATION_STEPS || bad <= 0.0);
            }
            other => panic!("max_step {bad}: {other:?}"),
        }
    }
    let q = leg.assemble_along(&start, &theta, 0.05).unwrap();
    assert!(leg.closure_residual(&q).amax() < 1e-9);
}

/// A parameter name from a user is echoed escaped and short (issue 29: a newline or
/// U+2028 split the message, ANSI escapes passed through, a 100,000-character name made
/// a 100,069-character message).
#[test]
fn parameter_names_are_echoed_escaped_and_short() {
    let mut leg = generated::minitaur::Leg::default();
    let hostile = format!("bad\nname\u{2028}\x1b[31mred{}", "x".repeat(100_000));
    let e = leg.set_parameter(&hostile, 1.0).unwrap_err().to_string();
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(!e.contains('\u{2028}') && !e.contains('\x1b'), "{e}");
    assert!(e.contains(r"bad\nname\u{2028}\u{1b}[31mred"), "{e}");
    assert!(e.chars().count() < 200, "{} characters", e.chars().count());
    // A plain misspelling still gets its suggestion, unescaped.
    let e = leg
        .set_parameter("lower_a_mas", 1.0)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no parameter `lower_a_mas`; did you mean `lower_a_mass`?"),
        "{e}"
    );
}

/// A recording run is bounded before it allocates: a record over the budget is refused
/// with its size, with nothing recorded (issue 29: 10^10 steps aborted the process).
#[test]
fn a_record_over_its_budget_is_refused_before_it_is_allocated() {
    use leg_models::simulate::{RecordTooLarge, StepError, MAX_RECORD_BYTES};
    let leg = generated::minitaur::Leg::default();
    let q = leg.assembled_home().unwrap();
    let sim = leg.simulator(StepOptions::rk4(1e-3));
    let mut none = |_: f64, _: &State<f64, 4>| SVector::<f64, 2>::zeros();
    for steps in [10_000_000_000usize, usize::MAX] {
        let stopped = sim
            .run(
                State {
                    q,
                    qd: SVector::zeros(),
                },
                steps,
                &mut none,
            )
            .unwrap_err();
        assert!(stopped.samples.is_empty());
        match stopped.cause {
            StepError::RecordTooLarge(RecordTooLarge { bytes, budget, .. }) => {
                assert!(bytes > budget && budget == MAX_RECORD_BYTES)
            }
            other => panic!("{steps} steps: {other}"),
        }
    }
    // A run within the budget records every step.
    let run = sim
        .run(
            State {
                q,
                qd: SVector::zeros(),
            },
            10,
            &mut none,
        )
        .unwrap();
    assert_eq!(run.len(), 11);
}

/// Setting parameters one at a time or together leaves each model's prepared quantities
/// equal to preparing all its values afresh (`update`), though `set_many` prepares again
/// only when a changed parameter enters them; an index past the end changes nothing.
fn setting_equals_preparing_afresh<P>(name: &str, fresh: impl Fn(&P) -> P)
where
    P: Parameters<f64> + Default + Copy + PartialEq + core::fmt::Debug,
{
    let n = P::NAMES.len();
    let changed = |p: &P, i: usize| p.get(i).unwrap() * 1.25 + 0.5;
    for i in 0..n {
        let mut p = P::default();
        let v = changed(&p, i);
        assert!(p.set(i, v), "{name}: {}", P::NAMES[i]);
        assert_eq!(p.get(i), Some(v));
        assert_eq!(p, fresh(&p), "{name}: set {}", P::NAMES[i]);
    }
    let mut all = P::default();
    let mut changes: Vec<(usize, f64)> = (0..n).map(|i| (i, changed(&all, i))).collect();
    // In order: a later change of the same parameter wins.
    let last = (n - 1, -3.0);
    changes.push(last);
    assert!(all.set_many(&changes));
    assert_eq!(all.get(last.0), Some(last.1));
    assert_eq!(all.get(0), Some(changed(&P::default(), 0)));
    assert_eq!(all, fresh(&all), "{name}: set_many");
    let before = all;
    assert!(!all.set_many(&[(0, 9.0), (n, 1.0)]), "{name}");
    assert_eq!(all, before, "{name}: a refused set_many changed something");
}

macro_rules! set_planar {
    ($module:ident, $ty:ty, $nq:expr, $nc:expr, $nu:expr, $nk:expr) => {
        setting_equals_preparing_afresh::<generated::$module::Params<f64>>(
            stringify!($module),
            |p| {
                let mut r = *p;
                r.update(|_| {});
                r
            },
        );
    };
}
macro_rules! set_spatial {
    ($module:ident, $ty:ty, $nq:expr, $nc:expr, $nu:expr, $np:expr, $nk:expr) => {
        set_planar!($module, $ty, $nq, $nc, $nu, $nk);
    };
}

#[test]
fn setting_parameters_equals_preparing_afresh_on_every_model() {
    generated::for_each_model!(set_planar);
    generated::for_each_spatial_model!(set_spatial);
    generated::for_each_floating_model!(set_spatial);
}
