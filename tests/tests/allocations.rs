//! The hot paths allocate nothing: a counting global allocator around each of them, for
//! every model. One test in this file, so that no other test allocates meanwhile.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use leg_models::assembly::{
    assemble, assemble_along, consistent_velocity, foot_inverse, project_position,
    project_velocity, Tolerance,
};
use leg_models::control::reference::{Setpoint, Sinusoid};
use leg_models::control::{
    actuated_reduction, FootFeedbackLinearization, FootPdGravity, Gains,
    JointFeedbackLinearization, PdGravity, Saturated,
};
use leg_models::dynamics::{forward_dynamics, Baumgarte};
use leg_models::nalgebra::{SMatrix, SVector};
use leg_models::simulate::Simulator;
use leg_models::simulate::{step, Method, State, StepOptions, TorqueSource};
use leg_models::LegModel;
use leg_tests::{not_applicable, passive_release_state};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    // Only the measured thread's allocations count: the test harness's own threads
    // allocate at start-up and while a test runs (on a loaded machine that raced with
    // the first measurements and failed them, one run in four).
    static MEASURED: Cell<bool> = const { Cell::new(false) };
}

fn counted() {
    if MEASURED.try_with(Cell::get).unwrap_or(false) {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        counted();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        counted();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// How many allocations `f` makes on this thread.
fn allocations<R>(f: impl FnOnce() -> R) -> (usize, R) {
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    MEASURED.with(|m| m.set(true));
    let r = std::hint::black_box(f());
    MEASURED.with(|m| m.set(false));
    (ALLOCATIONS.load(Ordering::SeqCst) - before, r)
}

/// Every hot path a leg has, planar or spatial (`ND` coordinates per point, `NP` closure
/// points).
fn check<
    L: LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>() {
    let p = L::Params::<f64>::default();
    let start = passive_release_state::<L, NQ, NC, NU>(&p);
    let (q, tol) = (start.q, Tolerance::default());
    let qd = SVector::<f64, NQ>::from_element(0.3);
    let u = SVector::<f64, NU>::from_element(0.1);
    let name = L::NAME;
    let zero = |what: &str, n: usize| assert_eq!(n, 0, "{name}: {what} allocated {n} times");

    zero(
        "dynamics_terms",
        allocations(|| L::dynamics_terms(&q, &qd, &p)).0,
    );
    zero(
        "forward dynamics",
        allocations(|| forward_dynamics::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None)).0,
    );
    // Four states on SIMD lanes, and a change of parameters (which prepares them again).
    let p4 = leg_models::dynamics::batch::broadcast::<L, NQ, NC, NU>(&p);
    let (q4, qd4, u4) = (
        leg_models::simd::pack([&q; 4]),
        leg_models::simd::pack([&qd; 4]),
        leg_models::simd::pack([&u; 4]),
    );
    zero(
        "batched dynamics_terms",
        allocations(|| L::dynamics_terms(&q4, &qd4, &p4)).0,
    );
    zero(
        "batched forward dynamics",
        allocations(|| {
            leg_models::dynamics::batch::forward_dynamics::<L, NQ, NC, NU>(&p4, &q4, &qd4, &u4)
        })
        .0,
    );
    let mut changed = p;
    zero(
        "setting a parameter",
        allocations(|| leg_models::Parameters::set(&mut changed, 0, 0.0)).0,
    );
    let b = Some(Baumgarte {
        alpha: 10.0,
        beta: 10.0,
    });
    zero(
        "forward dynamics with Baumgarte",
        allocations(|| forward_dynamics::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, b)).0,
    );
    let theta = SVector::<f64, NU>::from_fn(|k, _| q[L::ACTUATED[k]] + 0.01);
    zero(
        "assembly",
        allocations(|| assemble::<L, f64, NQ, NC, NU>(&p, &theta, &q, &tol)).0,
    );
    zero(
        "consistent velocity",
        allocations(|| consistent_velocity::<L, f64, NQ, NC, NU>(&p, &q, &u)).0,
    );
    let foot =
        L::foot_position(&q, &p) + SVector::<f64, ND>::from_fn(|i, _| [0.002, -0.001, 0.001][i]);
    zero(
        "foot inverse",
        allocations(|| foot_inverse::<L, f64, NQ, NC, NU, ND, NP>(&p, &foot, &q, &tol)).0,
    );
    zero(
        "forward dynamics derivatives",
        allocations(|| {
            leg_models::dynamics::derivatives::forward_dynamics_derivatives::<L, f64, NQ, NC, NU>(
                &p, &q, &qd, &u, None,
            )
        })
        .0,
    );
    let mut moved = q.add_scalar(0.01);
    zero(
        "position projection",
        allocations(|| project_position::<L, f64, NQ, NC, NU>(&p, &mut moved, &tol)).0,
    );
    let mut rates = qd;
    zero(
        "velocity projection",
        allocations(|| project_velocity::<L, f64, NQ, NC, NU>(&p, &q, &mut rates)).0,
    );
    for method in [Method::Rk4, Method::SemiImplicitEuler] {
        let opts = StepOptions {
            method,
            ..StepOptions::rk4(1e-3)
        };
        let mut s = State { q, qd };
        let mut hold = |_: f64, _: &State<f64, NQ>| u;
        zero(
            "a simulation step",
            allocations(|| step::<L, f64, NQ, NC, NU>(&p, &mut s, 0.0, &mut hold, &opts)).0,
        );
    }
    // A control step: every controller, and torque limits around one.
    let state = State { q, qd };
    let theta = SVector::<f64, NU>::from_fn(|k, _| q[L::ACTUATED[k]]);
    let joint_ref = Sinusoid {
        offset: theta,
        amplitude: SVector::from_element(0.1),
        frequency: SVector::from_element(1.0),
        phase: SVector::zeros(),
    };
    // The foot held where it is (a setpoint is a reference in any dimension).
    let foot_ref = Setpoint {
        position: L::foot_position(&q, &p),
        velocity: SVector::<f64, ND>::zeros(),
        acceleration: SVector::<f64, ND>::zeros(),
    };
    // Each controller where it applies to this leg (its constructor says why not).
    match JointFeedbackLinearization::<L, f64, _, NQ, NC, NU>::new(
        p,
        Gains::critically_damped(100.0),
        joint_ref,
    ) {
        Ok(mut fl) => {
            zero(
                "joint feedback linearization",
                allocations(|| fl.torque(0.1, &state)).0,
            );
            let mut limited = Saturated::new(fl, SVector::from_element(1.0)).unwrap();
            zero(
                "torque limits",
                allocations(|| limited.torque(0.1, &state)).0,
            );
        }
        Err(e) => not_applicable(name, "allocations of joint feedback linearization", &e),
    }
    match FootFeedbackLinearization::<L, f64, _, NQ, NC, NU, ND, NP>::new(
        p,
        Gains::critically_damped(400.0),
        foot_ref,
    ) {
        Ok(mut foot) => zero(
            "foot feedback linearization",
            allocations(|| foot.torque(0.1, &state)).0,
        ),
        Err(e) => not_applicable(name, "allocations of foot feedback linearization", &e),
    }
    match PdGravity::<L, f64, _, NQ, NC, NU>::new(p, Gains::new(50.0, 2.0), joint_ref) {
        Ok(mut pd) => zero(
            "PD with gravity compensation",
            allocations(|| pd.torque(0.1, &state)).0,
        ),
        Err(e) => not_applicable(name, "allocations of PD with gravity compensation", &e),
    }
    match FootPdGravity::<L, f64, _, NQ, NC, NU, ND, NP>::new(p, Gains::new(2000.0, 40.0), foot_ref)
    {
        Ok(mut foot_pd) => zero(
            "foot PD with gravity compensation",
            allocations(|| foot_pd.torque(0.1, &state)).0,
        ),
        Err(e) => not_applicable(name, "allocations of foot PD", &e),
    }
    zero(
        "assembly along a branch",
        allocations(|| assemble_along::<L, f64, NQ, NC, NU>(&p, &q, &theta, 0.05, &tol)).0,
    );
    zero(
        "actuated reduction",
        allocations(|| {
            let terms = L::dynamics_terms(&q, &qd, &p);
            actuated_reduction::<L, f64, NQ, NC, NU>(&p, &terms, &qd)
        })
        .0,
    );

    // A whole run allocates its record once, up front.
    let sim = Simulator::<L, f64, NQ, NC, NU>::new(p, StepOptions::rk4(1e-3));
    let mut source = |_: f64, _: &State<f64, NQ>| SVector::<f64, NU>::zeros();
    let (n, run) = allocations(|| sim.run(start, 200, &mut source));
    assert_eq!(run.expect("runs").len(), 201);
    assert_eq!(
        n, 1,
        "{name}: a 200-step run allocated {n} times (the record only expected)"
    );
}

/// The design measures at one pose (with the spatial force polytope), and the impact
/// mitigation factor on a body, planar and spatial.
fn check_analysis<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>()
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    let p = L::Params::<f64>::default();
    let q = passive_release_state::<L, NQ, NC, NU>(&p).q;
    let name = L::NAME;
    let zero = |what: &str, n: usize| assert_eq!(n, 0, "{name}: {what} allocated {n} times");
    let frame = leg_models::analysis::LegFrame::of::<L, NC, NU>();
    let limits = leg_models::analysis::MotorLimits {
        torque: SVector::<f64, NU>::from_element(1.0),
        speed: SVector::<f64, NU>::from_element(10.0),
    };
    match frame.motor_coordinates() {
        Ok(()) => zero(
            "design measures at a pose",
            allocations(|| {
                let m = leg_models::analysis::point_measures::<L, f64, NQ, NC, NU, ND, NP>(
                    &p, &q, &frame, &limits,
                );
                // The force and speed sets (a spatial foot's polytope) on the stack too.
                if let Ok(m) = &m {
                    let sets = leg_models::analysis::capacity_sets::<L, f64, NQ, NC, NU, ND>(
                        &p,
                        &q,
                        &frame,
                        &m.kinematics,
                        &limits,
                    );
                    assert_eq!(sets.is_ok(), frame.foot_spans(ND).is_ok());
                }
                m
            })
            .0,
        ),
        Err(e) => not_applicable(name, "allocations of the design measures", &e),
    }
    let coupling = leg_models::analysis::BodyCoupling::new::<L, f64, NQ, NC, NU>(&p);
    let body = leg_models::analysis::Body::Translating { mass: 10.0 };
    zero(
        "impact mitigation factor",
        allocations(|| {
            leg_models::analysis::impact_mitigation::<L, f64, NQ, NC, NU, ND, NP>(
                &p,
                &q,
                &frame,
                &body,
                coupling.as_ref(),
            )
        })
        .0,
    );
}

/// A hybrid step allocates nothing, through flight, touchdown (impact), stance and every
/// event on the way: a leg with contacts dropped onto the ground, step by step.
fn check_hybrid<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    use leg_models::simulate::hybrid::{HybridSimulator, HybridState};
    if NK == 0 {
        return;
    }
    let p = L::Params::<f64>::default();
    let sim = HybridSimulator::<L, f64, NQ, NC, NU, NK>::new(p, 1e-3);
    let mut q = SVector::<f64, NQ>::from(L::HOME);
    project_position::<L, f64, NQ, NC, NU>(&p, &mut q, &Tolerance::default()).unwrap();
    let mut hs = HybridState::flight(State {
        q,
        qd: SVector::zeros(),
    });
    let mut source = |_: f64, _: &HybridState<f64, NQ, NK>| SVector::<f64, NU>::zeros();
    let mut events = 0;
    for k in 0..300 {
        let t = k as f64 * 1e-3;
        let (n, r) = allocations(|| sim.step(&mut hs, t, &mut source));
        assert_eq!(n, 0, "{}: a hybrid step allocated {n} times", L::NAME);
        match r {
            Ok(e) => events += e.len(),
            Err(_) => break, // a leg folding under its weight may reach a singularity
        }
    }
    assert!(events > 0, "{}: the drop made no contact event", L::NAME);
}

/// The derivatives, the linearizations and the LQR allocate nothing (the LQR's Riccati
/// solve included: it is fixed-size too).
fn check_derivatives<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const M: usize,
    const NX: usize,
>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    use leg_models::control::linearize::{linearize_step, ManifoldChart};
    use leg_models::control::lqr::ManifoldLqr;
    use leg_models::control::reduction_derivatives;
    use leg_models::dynamics::contact::{spec_friction, ContactMode, Ground, Modes};
    use leg_models::dynamics::derivatives::{
        contact_dynamics_derivatives, forward_dynamics_derivatives,
    };
    let p = L::Params::<f64>::default();
    let start = passive_release_state::<L, NQ, NC, NU>(&p);
    let (q, qd) = (start.q, SVector::<f64, NQ>::zeros());
    let u = SVector::<f64, NU>::from_element(0.1);
    let name = L::NAME;
    let zero = |what: &str, n: usize| assert_eq!(n, 0, "{name}: {what} allocated {n} times");
    zero(
        "forward dynamics derivatives",
        allocations(|| forward_dynamics_derivatives::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None)).0,
    );
    zero(
        "reduction derivatives",
        allocations(|| reduction_derivatives::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u)).0,
    );
    if NK > 0 {
        let (ground, mu) = (
            Ground::of::<L, NQ, NC, NU, NK>(),
            spec_friction::<L, f64, NQ, NC, NU, NK, 2>(),
        );
        let mut modes = Modes::<NK>::flight();
        modes.set(0, ContactMode::Stick);
        let anchors = ground.coordinates(&L::contact_positions(&q, &p));
        zero(
            "contact dynamics derivatives",
            allocations(|| {
                contact_dynamics_derivatives::<L, f64, NQ, NC, NU, NK, 2>(
                    &p, &q, &qd, &u, &modes, &anchors, &ground, &mu, None, None,
                )
            })
            .0,
        );
    }
    let opts = StepOptions::rk4(1e-3);
    zero(
        "step linearization",
        allocations(|| linearize_step::<L, f64, NQ, NC, NU>(&p, &start, &u, &opts)).0,
    );
    let (n, chart) = allocations(|| ManifoldChart::<f64, NQ, M>::new::<L, NC, NU>(&p, &q));
    zero("a manifold chart", n);
    let chart = chart.expect("regular home");
    zero(
        "a manifold linearization",
        allocations(|| chart.linearize_step::<L, NC, NU, NX>(&p, &start, &u, &opts)).0,
    );
    let weights = SMatrix::<f64, NX, NX>::identity();
    let r = SMatrix::<f64, NU, NU>::identity();
    let theta = chart.coordinates_of(&start).0;
    let hold = Sinusoid {
        offset: theta,
        amplitude: SVector::zeros(),
        frequency: SVector::zeros(),
        phase: SVector::zeros(),
    };
    let limit = SVector::from_element(10.0);
    let (n, lqr) = allocations(|| {
        ManifoldLqr::<L, f64, _, NQ, NC, NU, M, NX>::at_pose(
            p, &q, &opts, &weights, &r, hold, limit,
        )
    });
    zero("an LQR's construction", n);
    match lqr {
        Ok(mut lqr) => zero("an LQR step", allocations(|| lqr.torque(0.1, &start)).0),
        Err(e) => not_applicable(name, "allocations of the LQR", &e),
    }
}

#[test]
fn hot_paths_do_not_allocate() {
    // The counter works: a Vec allocates.
    assert_eq!(allocations(|| vec![1u8; 16]).0, 1);
    macro_rules! each {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            check::<$ty, $nq, $nc, $nu, 2, $nc>();
            check_analysis::<$ty, $nq, $nc, $nu, 2, $nc>();
            check_hybrid::<$ty, $nq, $nc, $nu, $nk>();
            {
                const M: usize = <$ty as leg_models::LegDynamics<$nq, $nc, $nu>>::MOBILITY;
                check_derivatives::<$ty, $nq, $nc, $nu, $nk, M, { 2 * M }>();
            }
        };
    }
    generated::for_each_model!(each);
    macro_rules! spatial {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            check::<$ty, $nq, $nc, $nu, 3, $np>();
            check_analysis::<$ty, $nq, $nc, $nu, 3, $np>();
        };
    }
    generated::for_each_spatial_model!(spatial);
    macro_rules! floating {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            check::<$ty, $nq, $nc, $nu, 3, $np>();
            check_robot::<$ty, $nq, $nc, $nu, $nk>();
        };
    }
    generated::for_each_floating_model!(floating);
}

/// A floating robot's step (its chart centred on the body before and after), forward
/// dynamics, energies and momentum.
fn check_robot<
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>() {
    use leg_models::dynamics::contact::{ContactMode, Ground, Modes};
    use leg_models::nalgebra::{UnitQuaternion, Vector3};
    use leg_models::robot::{self, RobotState};
    let p = L::Params::<f64>::default();
    let name = L::NAME;
    let start = passive_release_state::<L, NQ, NC, NU>(&p);
    let mut s = RobotState::at_rest(
        Vector3::new(0.1, 0.2, 0.5),
        UnitQuaternion::from_euler_angles(0.2, 0.1, -0.3),
        start.q,
    );
    s.v = SVector::from_element(0.2);
    // Rates along the closures, so that every call below has a state it solves at.
    leg_models::assembly::project_velocity::<L, f64, NQ, NC, NU>(&p, &s.q, &mut s.v).unwrap();
    let u = SVector::<f64, NU>::from_element(0.1);
    let opts = StepOptions::rk4(1e-3);
    let mut source = |_: f64, _: &State<f64, NQ>| u;
    // Each call allocates nothing and succeeds (an early error would allocate nothing
    // too, and prove nothing).
    macro_rules! none_and_ok {
        ($what:expr, $call:expr) => {{
            let (n, r) = allocations(|| $call);
            assert_eq!(n, 0, "{name}: {} allocated {n} times", $what);
            r.unwrap_or_else(|e| panic!("{name}: {}: {e}", $what))
        }};
    }
    none_and_ok!(
        "robot::step",
        robot::step::<L, f64, NQ, NC, NU>(&p, &mut s, 0.0, &mut source, &opts)
    );
    none_and_ok!(
        "robot::forward_dynamics_at",
        robot::forward_dynamics_at::<L, f64, NQ, NC, NU>(&p, &s, &u)
    );
    none_and_ok!(
        "robot::energies",
        robot::energies::<L, f64, NQ, NC, NU>(&p, &s)
    );
    none_and_ok!(
        "robot::momentum",
        robot::momentum::<L, f64, NQ, NC, NU>(&p, &s)
    );
    // On the ground, every contact sticking.
    let mut modes = Modes::<NK, 3>::flight();
    for k in 0..NK / 3 {
        modes.set(k, ContactMode::Stick);
    }
    let ground = Ground {
        normal: Vector3::z(),
        offset: -1.0,
    };
    let mu = SVector::<f64, NK>::from_element(1.0);
    // Standing still: rates that move a held contact contradict themselves where two
    // contacts share a rigid foot (Cassie's toe and heel: their distance's second
    // derivative is then the foot's centripetal term, not zero), and the solve refuses.
    let mut standing = s;
    standing.v = SVector::zeros();
    none_and_ok!(
        "robot::stance_dynamics",
        robot::stance_dynamics::<L, f64, NQ, NC, NU, NK>(&p, &standing, &u, &modes, &ground, &mu)
    );
    none_and_ok!(
        "robot::holding_torques",
        robot::holding_torques::<L, f64, NQ, NC, NU, NK>(&p, &standing, &modes, &ground, &mu)
    );
    // A landing: the whole robot moving straight down, 1 m/s.
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let mut landing = s;
    landing.v = SVector::zeros();
    let down = landing
        .orientation
        .inverse_transform_vector(&Vector3::new(0.0, 0.0, -1.0));
    for k in 0..3 {
        landing.v[f + k] = down[k];
    }
    let mut m = modes;
    none_and_ok!(
        "robot::impact",
        robot::impact::<L, f64, NQ, NC, NU, NK>(&p, &mut landing, &mut m, &ground, &mu)
    );
    none_and_ok!(
        "robot::stance_step",
        robot::stance_step::<L, f64, NQ, NC, NU, NK>(
            &p,
            &mut standing,
            &u,
            &modes,
            &ground,
            &mu,
            1e-3
        )
    );
    none_and_ok!(
        "robot::pushed_stance_step_by (semi-implicit Euler)",
        robot::pushed_stance_step_by::<L, f64, NQ, NC, NU, NK>(
            leg_models::simulate::Method::SemiImplicitEuler,
            &p,
            &mut standing,
            &u,
            &leg_models::nalgebra::Vector3::new(1.0, 0.0, 0.0),
            &modes,
            &ground,
            &mu,
            5e-4
        )
    );
    // Feet free: the contact problem is allocated once, before the step; the step (its
    // Delassus matrix, Lemke's pivoting on the problem's tableau) allocates nothing. A
    // landing, so that the pivoting has contacts to push.
    let mut problem = leg_models::robot::time_stepping::FootContacts::of::<L, NQ, NC, NU, NK>();
    let mut falling = landing;
    falling.v = SVector::zeros();
    for k in 0..3 {
        falling.v[f + k] = down[k];
    }
    // The ground 0.1 mm over the lowest contact: the step must push it out.
    let chart = robot::chart_params::<L, f64, NQ, NC, NU>(&p, &falling.orientation).unwrap();
    let x = L::contact_positions(&falling.q, &chart);
    let lowest = (0..NK / 3)
        .map(|k| {
            (falling.position
                + falling.orientation.transform_vector(&Vector3::new(
                    x[3 * k],
                    x[3 * k + 1],
                    x[3 * k + 2],
                )))
            .z
        })
        .fold(f64::INFINITY, f64::min);
    let touched = Ground {
        normal: Vector3::z(),
        offset: lowest + 1e-4,
    };
    let step = none_and_ok!(
        "robot::time_stepping::contact_step",
        leg_models::robot::time_stepping::contact_step::<L, f64, NQ, NC, NU, NK>(
            &mut problem,
            &p,
            &mut falling,
            &u,
            &leg_models::nalgebra::Vector3::new(1.0, 0.0, 0.0),
            &touched,
            &mu,
            5e-4
        )
    );
    assert!(
        NK == 0 || step.pivots > 0,
        "{name}: the landing step took no pivot"
    );
    // The balance QP: its first command sets the solver up (and allocates); the next,
    // with the same held contacts, update it in place. Clarabel 0.11.1's `solve` itself
    // allocates once a call (measured on Clarabel alone: its updates allocate nothing,
    // its `solve` one block: its timers, cleared and filled again each call), so a command may allocate that once and no more.
    use leg_models::robot::balance::{BalanceController, BalanceGains, BalanceTarget};
    let mut control = BalanceController::<NQ, NC, NU, NK>::new(
        BalanceTarget::holding(&standing),
        BalanceGains::default(),
        None,
    );
    match control.command::<L>(&p, &standing, &modes, &ground, &mu) {
        Ok(_) => {
            let (n, r) = allocations(|| control.command::<L>(&p, &standing, &modes, &ground, &mu));
            r.unwrap_or_else(|e| panic!("{name}: balance: {e}"));
            assert!(
                n <= 1,
                "{name}: the balance QP's command allocated {n} times"
            );
        }
        Err(e) => leg_tests::not_applicable(name, "balance QP allocations", &e),
    }
}
