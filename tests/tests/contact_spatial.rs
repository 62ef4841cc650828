//! Contact in 3-D (DESIGN.md §3.1): the exact Coulomb cone, slip in any direction along
//! the ground, stick–slip events and plastic impacts, on `sliding_mass` (a point mass on
//! three prismatic joints, one contact), whose motions have closed forms: a block on an
//! incline that sticks below the friction angle and slides above it at
//! `g (sin θ − μ cos θ)`, a slide that stops after `v₀ / (μ g)`, a pushed slide that turns
//! as the point-mass ODE `m v̇ = F − μ m g v / |v|` (integrated here on its own), and
//! impacts that keep `|v_t| − μ v_n` of the tangential speed or stop it.

use generated::abducted_five_bar::AbductedFiveBar;
use generated::sliding_mass::{self, SlidingMass};
use leg_models::dynamics::contact::{
    forward_dynamics_with_contacts, impact_map, spec_friction, ContactMode, ContactSystem, Ground,
    Modes,
};
use leg_models::dynamics::derivatives::contact_dynamics_derivatives;
use leg_models::dynamics::{actuation, Baumgarte, DynamicsError};
use leg_models::nalgebra::{DMatrix, DVector, SMatrix, SVector, Vector3};
use leg_models::simulate::hybrid::{EventKind, HybridSimulator, HybridState};
use leg_models::simulate::State;
use leg_models::{ContactModel, LegDynamics};
use leg_tests::{random_assembled_state, Rng};

type Sim = HybridSimulator<SlidingMass, f64, 3, 0, 2, 3, 3>;
type Hs = HybridState<f64, 3, 3, 3>;

const G: f64 = 9.81;
const MASS: f64 = 2.0;
const MU: f64 = 0.5;

fn sim(dt: f64) -> Sim {
    Sim::new(sliding_mass::Params::default(), dt)
}

fn idle(_: f64, _: &Hs) -> SVector<f64, 2> {
    SVector::zeros()
}

fn at_rest() -> State<f64, 3> {
    State {
        q: SVector::zeros(),
        qd: SVector::zeros(),
    }
}

#[test]
fn the_spec_gives_the_block_its_mass_friction_and_level_ground() {
    let p = sliding_mass::Params::<f64>::default();
    let m = <SlidingMass as leg_models::LegDynamics<3, 0, 2>>::mass_matrix(&SVector::zeros(), &p);
    assert!((m - leg_models::nalgebra::Matrix3::identity() * MASS).amax() < 1e-15);
    let ground = Ground::<f64, 3>::of::<SlidingMass, 3, 0, 2, 3>();
    assert_eq!(ground.normal, Vector3::new(0.0, 0.0, 1.0));
    // Level ground: the frame is the base's (x, y, z).
    assert!((ground.frame() - leg_models::nalgebra::Matrix3::identity()).amax() < 1e-15);
    assert_eq!(
        sim(1e-3).options.friction,
        SVector::<f64, 3>::from_element(MU)
    );
}

/// The runtime's `Leg` of a spatial leg reaches its contacts with no annotation (the
/// contacts' dimension comes from the leg): its ground, friction, the block held at rest
/// carrying its weight m g, an impact that slides keeping `1 − μ v_n/|v_t|` of its
/// tangential speed, and its hybrid simulator, the same as one built by hand.
#[test]
fn the_leg_of_a_spatial_leg_reaches_its_contacts() {
    let leg = sliding_mass::Leg::default();
    assert_eq!(leg.ground().normal, Vector3::new(0.0, 0.0, 1.0));
    assert_eq!(leg.friction(), SVector::<f64, 3>::from_element(MU));
    let mut held = Modes::<3, 3>::flight();
    held.set(0, ContactMode::Stick);
    let rest = leg
        .forward_dynamics_with_contacts(
            &SVector::zeros(),
            &SVector::zeros(),
            &SVector::zeros(),
            &held,
            &SVector::zeros(),
        )
        .unwrap();
    assert!(rest.x.amax() < 1e-12);
    assert!((rest.contact - Vector3::new(0.0, 0.0, MASS * G)).amax() < 1e-12);
    let mut landing = held;
    let (vt, vn) = (1.0, 0.3);
    let impact = leg
        .impact_map(&SVector::zeros(), &Vector3::new(vt, 0.0, -vn), &mut landing)
        .unwrap();
    assert!(matches!(landing.get(0), ContactMode::Slide { .. }));
    assert!((impact.qd_plus - Vector3::new(vt - MU * vn, 0.0, 0.0)).amax() < 1e-12);
    let d = leg
        .contact_dynamics_derivatives(
            &SVector::zeros(),
            &SVector::zeros(),
            &SVector::zeros(),
            &held,
            &SVector::zeros(),
        )
        .unwrap();
    assert_eq!(d.solution, rest);
    // The simulator carries the leg's own settings: its Baumgarte terms and tolerance.
    let tuned = sliding_mass::Leg::default().with_baumgarte(4.0, 5.0);
    let built = tuned.hybrid_simulator(1e-3);
    assert!(built.options.baumgarte.is_some());
    assert_eq!(built.options.baumgarte, tuned.baumgarte());
    assert_eq!(built.options.tolerance, *tuned.tolerance());
    assert_eq!(built.options.ground, leg.ground());
}

/// The ground tilted by `theta` about x: normal `(0, sin θ, cos θ)`, downhill along
/// the frame's second tangent `(0, cos θ, −sin θ)`.
fn incline(theta: f64) -> Sim {
    let mut s = sim(1e-3);
    s.options.ground = Ground {
        normal: Vector3::new(0.0, theta.sin(), theta.cos()),
        offset: 0.0,
    };
    s
}

#[test]
fn a_block_sticks_on_an_incline_below_the_friction_angle() {
    let theta = 0.8 * MU.atan();
    let s = incline(theta);
    let start = s.start(at_rest(), &SVector::zeros()).unwrap();
    assert_eq!(start.modes.get(0), ContactMode::Stick);
    let record = s.run(start, 500, &mut idle).unwrap();
    assert!(record.events.is_empty(), "{:?}", record.events);
    let last = record.samples.last().unwrap();
    assert!(last.state.state.q.amax() < 1e-12, "{}", last.state.state.q);
    // The ground holds the weight: m g cos θ along the normal, m g sin θ uphill.
    let f = last.contact_forces;
    assert!((f[2] - MASS * G * theta.cos()).abs() < 1e-9, "{f}");
    assert!((f[1] + MASS * G * theta.sin()).abs() < 1e-9, "{f}");
    assert!(f[0].abs() < 1e-9, "{f}");
}

#[test]
fn a_block_slides_down_an_incline_above_the_friction_angle_at_coulombs_rate() {
    let theta = 1.5 * MU.atan();
    let s = incline(theta);
    let start = s.start(at_rest(), &SVector::zeros()).unwrap();
    assert!(
        matches!(start.modes.get(0), ContactMode::Slide { .. }),
        "{:?}",
        start.modes
    );
    // It starts to slip straight downhill (found by iteration from the sticking force).
    assert!((start.slip[1] - 1.0).abs() < 1e-12 && start.slip[0].abs() < 1e-12);
    let steps = 400;
    let record = s.run(start, steps, &mut idle).unwrap();
    assert!(record.events.is_empty(), "{:?}", record.events);
    let a = G * (theta.sin() - MU * theta.cos());
    let downhill = Vector3::new(0.0, theta.cos(), -theta.sin());
    for sample in &record.samples {
        let t = sample.t;
        let expected = downhill * (0.5 * a * t * t);
        let q = sample.state.state.q;
        assert!(
            (q - expected).amax() < 1e-9,
            "t = {t}: {q} against {expected}"
        );
        // Friction μ λ_n against the slip, exactly on the cone.
        let f = sample.contact_forces;
        assert!((f[2] - MASS * G * theta.cos()).abs() < 1e-9);
        assert!((f[1] + MU * f[2]).abs() < 1e-9 && f[0].abs() < 1e-9, "{f}");
    }
}

/// A state sliding on level ground with velocity `v` (x, y).
fn sliding(v: [f64; 2]) -> Hs {
    let speed = v[0].hypot(v[1]);
    Hs {
        state: State {
            q: SVector::zeros(),
            qd: SVector::from([v[0], v[1], 0.0]),
        },
        modes: {
            let mut m = Modes::flight();
            m.set(0, ContactMode::Slide { forward: true });
            m
        },
        anchors: SVector::zeros(),
        slip: SVector::from([v[0] / speed, v[1] / speed, 0.0]),
    }
}

#[test]
fn a_slide_on_level_ground_stops_where_and_when_coulomb_says_then_sticks() {
    let v0: [f64; 2] = [1.2, -0.5];
    let speed = v0[0].hypot(v0[1]);
    let s = sim(1e-3);
    let stop = speed / (MU * G);
    let steps = (1.5 * stop / 1e-3) as usize;
    let record = s.run(sliding(v0), steps, &mut idle).unwrap();
    let events: Vec<_> = record.events.iter().map(|e| (e.kind, e.t)).collect();
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(events[0].0, EventKind::Stick);
    assert!(
        (events[0].1 - stop).abs() < 1e-9,
        "{} against {stop}",
        events[0].1
    );
    let distance = speed * speed / (2.0 * MU * G);
    let last = record.samples.last().unwrap();
    let q = last.state.state.q;
    let expected = [distance * v0[0] / speed, distance * v0[1] / speed];
    assert!(
        (q[0] - expected[0]).abs() < 1e-9 && (q[1] - expected[1]).abs() < 1e-9,
        "{q} against {expected:?}"
    );
    assert_eq!(last.state.modes.get(0), ContactMode::Stick);
    assert!(last.state.state.qd.amax() < 1e-12);
}

/// The point mass's own ODE on level ground, `m v̇ = F − μ m g v/|v|`, by RK4 at `h`.
fn coulomb_point_mass(v0: [f64; 2], push: [f64; 2], t_end: f64, h: f64) -> [f64; 4] {
    let f = |s: [f64; 4]| {
        let (vx, vy) = (s[2], s[3]);
        let speed = vx.hypot(vy);
        [
            vx,
            vy,
            push[0] / MASS - MU * G * vx / speed,
            push[1] / MASS - MU * G * vy / speed,
        ]
    };
    let add = |a: [f64; 4], b: [f64; 4], k: f64| core::array::from_fn(|i| a[i] + k * b[i]);
    let mut s = [0.0, 0.0, v0[0], v0[1]];
    let n = (t_end / h).round() as usize;
    for _ in 0..n {
        let k1 = f(s);
        let k2 = f(add(s, k1, h / 2.0));
        let k3 = f(add(s, k2, h / 2.0));
        let k4 = f(add(s, k3, h));
        s = core::array::from_fn(|i| s[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]));
    }
    s
}

#[test]
fn a_pushed_slide_turns_as_the_point_mass_ode_says() {
    let v0 = [1.5, 0.0];
    let push = [0.0, 6.0]; // sideways, inside the cone (μ m g = 9.81 N)
    let s = sim(1e-3);
    let mut source = |_: f64, _: &Hs| SVector::<f64, 2>::from(push);
    let steps = 150;
    let record = s.run(sliding(v0), steps, &mut source).unwrap();
    assert!(record.events.is_empty(), "{:?}", record.events);
    for sample in record.samples.iter().step_by(50).skip(1) {
        let ode = coulomb_point_mass(v0, push, sample.t, 1e-5);
        let st = sample.state.state;
        let ours = [st.q[0], st.q[1], st.qd[0], st.qd[1]];
        for i in 0..4 {
            assert!(
                (ours[i] - ode[i]).abs() < 1e-8,
                "t = {}: {ours:?} against {ode:?}",
                sample.t
            );
        }
        // The slip has turned toward the push, and friction still opposes it exactly.
        let f = sample.contact_forces;
        let v = st.qd.xy();
        let along = (f[0] * v[0] + f[1] * v[1]) / (f.xy().norm() * v.norm());
        assert!(
            (along + 1.0).abs() < 1e-12,
            "friction against the slip: {along}"
        );
        assert!((f.xy().norm() - MU * f[2]).abs() < 1e-9);
    }
}

#[test]
fn impacts_keep_mu_times_the_normal_speed_less_of_the_tangential_or_stop_it() {
    let p = sliding_mass::Params::<f64>::default();
    let ground = Ground::<f64, 3>::of::<SlidingMass, 3, 0, 2, 3>();
    let mu = SVector::<f64, 3>::from_element(MU);
    let vz = 2.0;
    for (v_t, sticks) in [([0.6, -0.5], true), ([1.8, 1.1], false)] {
        let qd = SVector::from([v_t[0], v_t[1], -vz]);
        let mut modes = Modes::<3, 3>::flight();
        modes.set(0, ContactMode::Stick);
        let imp = impact_map::<SlidingMass, f64, 3, 0, 2, 3, 3>(
            &p,
            &SVector::zeros(),
            &qd,
            &mut modes,
            &ground,
            &mu,
        )
        .unwrap();
        let speed = v_t[0].hypot(v_t[1]);
        let kept = if sticks { 0.0 } else { 1.0 - MU * vz / speed };
        let expected = SVector::from([v_t[0] * kept, v_t[1] * kept, 0.0]);
        assert!(
            (imp.qd_plus - expected).amax() < 1e-12,
            "{} against {expected}",
            imp.qd_plus
        );
        assert_eq!(modes.get(0) == ContactMode::Stick, sticks, "{modes:?}");
        assert!((imp.impulses[2] - MASS * vz).abs() < 1e-12);
        let lost = 0.5 * MASS * (qd.norm_squared() - expected.norm_squared());
        assert!((imp.energy_lost - lost).abs() < 1e-12);
        if !sticks {
            assert!((imp.slip.xy() - SVector::from(v_t) / speed).amax() < 1e-12);
        }
    }
}

#[test]
fn a_block_thrown_onto_the_ground_lands_slides_and_stops_as_coulomb_says() {
    // Thrown from 5 cm up at (1.5, 1.0) m/s sideways: it lands at t₁ = √(2h/g) with
    // v_z = −g t₁, keeps |v_t| − μ |v_z| of its tangential speed, and slides to a stop.
    let h = 0.05;
    let v_t = [1.5, 1.0];
    let s = sim(1e-3);
    let start = Hs::flight(State {
        q: SVector::from([0.0, 0.0, h]),
        qd: SVector::from([v_t[0], v_t[1], 0.0]),
    });
    let record = s.run(start, 600, &mut idle).unwrap();
    let kinds: Vec<_> = record.events.iter().map(|e| e.kind).collect();
    assert_eq!(
        kinds,
        [EventKind::Touchdown, EventKind::Stick],
        "{:?}",
        record.events
    );
    let t1 = (2.0 * h / G).sqrt();
    let touchdown = &record.events[0];
    assert!(
        (touchdown.t - t1).abs() < 1e-9,
        "{} against {t1}",
        touchdown.t
    );
    let (speed, vz) = (v_t[0].hypot(v_t[1]), G * t1);
    assert!((touchdown.impulse[1] - MASS * vz).abs() < 1e-6);
    assert!((touchdown.impulse[0] - MU * MASS * vz).abs() < 1e-6);
    let after = speed - MU * vz;
    let stop = t1 + after / (MU * G);
    assert!((record.events[1].t - stop).abs() < 1e-8);
    let travel = speed * t1 + after * after / (2.0 * MU * G);
    let q = record.samples.last().unwrap().state.state.q;
    let expected = [travel * v_t[0] / speed, travel * v_t[1] / speed, 0.0];
    for i in 0..3 {
        assert!(
            (q[i] - expected[i]).abs() < 1e-8,
            "{q} against {expected:?}"
        );
    }
}

// Every spatial leg with contacts: the structured solve against one dense solve (SVD,
// least squares) of the whole KKT system written in the base frame, and the impact map's identities. Run on
// `sliding_mass` and on `abducted_five_bar`, whose toe touches the ground while its loop,
// with one structurally redundant row, stays closed.

/// The ground's frame built here on its own (not `Ground::frame`), by its documented
/// rule: `t₁` along the base's x projected on the ground (its y where `|n_x| ≥ 0.9`),
/// `t₂ = n × t₁`.
fn frame_of(n: &Vector3<f64>) -> [Vector3<f64>; 3] {
    let e = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let t1 = (e - n * n.dot(&e)).normalize();
    [t1, n.cross(&t1), *n]
}

/// Random modes, each contact flying, sticking or sliding.
fn random_modes<const NK: usize>(rng: &mut Rng) -> Modes<NK, 3> {
    let mut m = Modes::<NK, 3>::flight();
    for k in 0..NK / 3 {
        let mode = match (rng.range(0.0, 3.0)) as usize {
            0 => ContactMode::Flight,
            1 => ContactMode::Stick,
            _ => ContactMode::Slide { forward: true },
        };
        m.set(k, mode);
    }
    m
}

/// On the spec's ground, or on `tilted` (its normal normalized here), at random assembled
/// states.
fn check_against_dense<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    tilted: Option<[f64; 3]>,
) where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    check_against_dense_at::<L, NQ, NC, NU, NK>(tilted, |p, rng| {
        random_assembled_state::<L, NQ, NC, NU>(p, rng, 2.0)
    });
}

/// A floating robot's state near its home (random joints assemble rarely with Cassie's
/// rods): the joints moved by up to 0.2 rad, the body's chart by up to 0.2, then projected
/// onto the closures, and random rates (±2) projected onto them.
fn near_home<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    rng: &mut Rng,
) -> State<f64, NQ>
where
    L: LegDynamics<NQ, NC, NU>,
{
    use leg_models::assembly::{project_position, project_velocity, Tolerance};
    let home = leg_models::robot::standing::assembled_home::<L, NQ, NC, NU>(p)
        .unwrap_or_else(|e| panic!("{}: {e}", L::NAME));
    for _ in 0..100 {
        let mut q = home + SVector::<f64, NQ>::from_fn(|_, _| rng.range(-0.2, 0.2));
        let mut qd = SVector::<f64, NQ>::from_fn(|_, _| rng.range(-2.0, 2.0));
        if project_position::<L, f64, NQ, NC, NU>(p, &mut q, &Tolerance::default()).is_ok()
            && project_velocity::<L, f64, NQ, NC, NU>(p, &q, &mut qd).is_ok()
        {
            return State { q, qd };
        }
    }
    panic!("{}: no state near home assembles in 100 tries", L::NAME);
}

/// [`check_against_dense`] at the states `state` draws.
fn check_against_dense_at<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    tilted: Option<[f64; 3]>,
    mut state: impl FnMut(&L::Params<f64>, &mut Rng) -> State<f64, NQ>,
) where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    assert!(NK > 0, "{} has contacts", L::NAME);
    let p = L::Params::<f64>::default();
    let mut ground = Ground::<f64, 3>::of::<L, NQ, NC, NU, NK>();
    if let Some(n) = tilted {
        ground.normal = Vector3::from(n).normalize();
    }
    let frame = frame_of(&ground.normal);
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, 3>();
    let mut rng = Rng::new(33);
    let (mut compared, mut refused) = (0, 0);
    for _ in 0..100 {
        let s = state(&p, &mut rng);
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-3.0, 3.0));
        let modes = random_modes::<NK>(&mut rng);
        let ours = forward_dynamics_with_contacts::<L, f64, NQ, NC, NU, NK, 3>(
            &p,
            &s.q,
            &s.qd,
            &u,
            &modes,
            &SVector::zeros(),
            &ground,
            &mu,
            None,
        );
        let terms = L::dynamics_terms(&s.q, &s.qd, &p);
        let mut tau = -terms.bias_forces - L::damping_forces(&s.qd, &p);
        for (k, &a) in L::ACTUATED.iter().enumerate() {
            tau[a] += u[k];
        }
        // Rows of contact k along a direction: d · J_c (base frame), and d · (−J̇_c q̇).
        let jc = L::contact_jacobian(&s.q, &p);
        let bias = L::contact_bias(&s.q, &s.qd, &p);
        let row = |k: usize, d: &Vector3<f64>| {
            DVector::from_fn(NQ, |c, _| (0..3).map(|i| d[i] * jc[(3 * k + i, c)]).sum())
        };
        let rhs = |k: usize, d: &Vector3<f64>| -(0..3).map(|i| d[i] * bias[3 * k + i]).sum::<f64>();
        let mut cons = Vec::new(); // (C row, W row, rhs)
        let mut held = Vec::new();
        for k in 0..NK / 3 {
            match modes.get(k) {
                ContactMode::Flight => {}
                ContactMode::Stick => {
                    for (i, d) in frame.iter().enumerate() {
                        cons.push((row(k, d), row(k, d), rhs(k, d)));
                        held.push(3 * k + i);
                    }
                }
                ContactMode::Slide { .. } => {
                    // Friction −μ λ_n ŝ against the slip velocity along the ground.
                    let v = Vector3::from_fn(|i, _| {
                        (0..NQ).map(|c| jc[(3 * k + i, c)] * s.qd[c]).sum()
                    });
                    let slip = (v - frame[2] * frame[2].dot(&v)).normalize();
                    let w = row(k, &frame[2]) - row(k, &slip) * mu[3 * k];
                    cons.push((row(k, &frame[2]), w, rhs(k, &frame[2])));
                    held.push(3 * k + 2);
                }
            }
        }
        let size = NQ + NC + cons.len();
        let mut a = DMatrix::<f64>::zeros(size, size);
        let mut b = DVector::<f64>::zeros(size);
        for r in 0..NQ {
            for c in 0..NQ {
                a[(r, c)] = terms.mass_matrix[(r, c)];
            }
            b[r] = tau[r];
        }
        for i in 0..NC {
            for c in 0..NQ {
                a[(NQ + i, c)] = terms.constraint_jacobian[(i, c)];
                a[(c, NQ + i)] = -terms.constraint_jacobian[(i, c)];
            }
            b[NQ + i] = -terms.constraint_bias[i];
        }
        for (i, (crow, wrow, r)) in cons.iter().enumerate() {
            for c in 0..NQ {
                a[(NQ + NC + i, c)] = crow[c];
                a[(c, NQ + NC + i)] = -wrow[c];
            }
            b[NQ + NC + i] = *r;
        }
        // A redundant closure row makes the dense system singular: least squares by SVD
        // (the accelerations and contact forces are unique; the closure forces are not).
        // Refined: on the quadruped the SVD's own solution leaves residuals of 3e-7 where
        // the system's conditioning allows 1e-13, and three passes bring them there.
        let svd = a.clone().svd(true, true);
        let mut x = svd.solve(&b, 1e-12).unwrap();
        for _ in 0..3 {
            let r = &b - &a * &x;
            x += svd.solve(&r, 1e-12).unwrap();
        }
        // Held rows that repeat each other (two contacts of one foot on a leg with fewer
        // coordinates than held rows) with right-hand sides that contradict: no motion
        // keeps them all, so ours refuses; the dense system then has no exact solution.
        let ours = match ours {
            Ok(ours) => ours,
            Err(DynamicsError::SingularContacts { .. }) => {
                let residual = (&a * &x - &b).amax();
                assert!(
                    residual > 1e-9 * (1.0 + b.amax()),
                    "{}: refused held rows the dense system solves (residual {residual:e}, {modes:?})",
                    L::NAME
                );
                refused += 1;
                continue;
            }
            Err(e) => panic!("{}: {e} ({modes:?})", L::NAME),
        };
        let scale = 1.0 + x.rows(0, NQ).amax();
        for r in 0..NQ {
            assert!(
                (ours.x[r] - x[r]).abs() < 1e-8 * scale,
                "{}: q̈[{r}] {} against the dense {} ({:?})",
                L::NAME,
                ours.x[r],
                x[r],
                modes
            );
        }
        for (i, &r) in held.iter().enumerate() {
            assert!(
                (ours.contact[r] - x[NQ + NC + i]).abs() < 1e-8 * scale,
                "{}: contact row {r}: {} against the dense {}",
                L::NAME,
                ours.contact[r],
                x[NQ + NC + i]
            );
        }
        for k in 0..NK / 3 {
            let f = ours.contact.fixed_rows::<3>(3 * k);
            match modes.get(k) {
                ContactMode::Flight => assert_eq!(f.amax(), 0.0),
                // Exactly on the cone while sliding.
                ContactMode::Slide { .. } => {
                    assert!((f.xy().norm() - mu[3 * k] * f[2].abs()).abs() < 1e-9 * scale)
                }
                ContactMode::Stick => {}
            }
        }
        compared += 1;
    }
    assert_eq!(compared + refused, 100);
    // A refusal is only for held rows that repeat each other: one contact's rows never do
    // (on these legs), two contacts' on one foot of a three-coordinate leg may.
    if NK / 3 == 1 {
        assert_eq!(refused, 0, "{}", L::NAME);
    }
    assert!(
        compared >= 60,
        "{}: {compared} compared, {refused} refused",
        L::NAME
    );
}

#[test]
fn sliding_mass_contact_dynamics_solve_the_dense_kkt_system() {
    check_against_dense::<SlidingMass, 3, 0, 2, 3>(None);
    check_against_dense::<SlidingMass, 3, 0, 2, 3>(Some([0.3, -0.2, 0.9]));
}

#[test]
fn abducted_five_bar_contact_dynamics_solve_the_dense_kkt_system() {
    check_against_dense::<AbductedFiveBar, 5, 3, 3, 3>(None);
    // A ground steep enough that its frame's first tangent is the base's y projected.
    check_against_dense::<AbductedFiveBar, 5, 3, 3, 3>(Some([0.95, 0.1, 0.3]));
}

/// Central differences of `f` at `x`, one column per coordinate.
fn central<const N: usize, const R: usize>(
    x: &SVector<f64, N>,
    h: f64,
    f: impl Fn(&SVector<f64, N>) -> SVector<f64, R>,
) -> SMatrix<f64, R, N> {
    let mut out = SMatrix::<f64, R, N>::zeros();
    for i in 0..N {
        let mut e = SVector::<f64, N>::zeros();
        e[i] = h;
        out.set_column(i, &((f(&(x + e)) - f(&(x - e))) / (2.0 * h)));
    }
    out
}

/// The derivatives of the 3-D contact dynamics (`contact_dynamics_derivatives` with
/// `ND = 3`) against central differences of the dynamics themselves, at random assembled
/// states, torques and modes, with and without Baumgarte terms: a sticking contact's
/// rows, and a sliding one's friction `−μ λ_n ŝ` turning with its slip velocity (`ŝ`
/// depends on `q` and `q̇`). Returns the largest error relative to the derivative's size.
fn check_derivatives<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>() -> f64
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let p = L::Params::<f64>::default();
    let ground = Ground::<f64, 3>::of::<L, NQ, NC, NU, NK>();
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, 3>();
    let mut rng = Rng::new(71);
    let (mut checked, mut sliding, mut tried) = (0, 0, 0);
    let (mut kept_rest, mut followed) = (0, 0);
    let mut worst = 0.0f64;
    while checked < 36 && tried < 3000 {
        tried += 1;
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 2.0);
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-3.0, 3.0));
        let modes = random_modes::<NK>(&mut rng);
        let anchors = ground.coordinates(&L::contact_positions(&s.q, &p));
        let baumgarte = (tried % 2 == 0).then_some(Baumgarte {
            alpha: 5.0,
            beta: 5.0,
        });
        // A third of the states give each slide a direction of its own (`rest`): where
        // the slip runs against it (v_t · d ≤ 0) the slide keeps it, a constant; else
        // it follows the slip velocity, as with none.
        let rest = (tried % 3 == 0).then(|| {
            let mut d = SVector::<f64, NK>::zeros();
            for k in 0..NK / 3 {
                let a = rng.range(0.0, std::f64::consts::TAU);
                (d[3 * k], d[3 * k + 1]) = (a.cos(), a.sin());
            }
            d
        });
        let solve = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, u: &SVector<f64, NU>| {
            ContactSystem::<f64, NQ, NC, NK, 3>::with_slip::<L, NU>(
                &p,
                q,
                qd,
                &modes,
                &anchors,
                &ground,
                &mu,
                baumgarte,
                rest.as_ref(),
            )
            .and_then(|sys| sys.solve(&actuation::<L, f64, NQ, NC, NU>(u)))
        };
        let Ok(d) = contact_dynamics_derivatives::<L, f64, NQ, NC, NU, NK, 3>(
            &p,
            &s.q,
            &s.qd,
            &u,
            &modes,
            &anchors,
            &ground,
            &mu,
            baumgarte,
            rest.as_ref(),
        ) else {
            continue;
        };
        // Near a singular stance the differences are noise: regular states only.
        let h = 1e-6;
        let regular = L::REDUNDANT_ROWS > 0
            || (0..NQ).all(|i| {
                let mut e = SVector::<f64, NQ>::zeros();
                e[i] = h;
                [s.q + e, s.q - e]
                    .iter()
                    .all(|q| solve(q, &s.qd, &u).is_ok_and(|x| x.x.amax() < 1e4))
            });
        if !regular {
            continue;
        }
        assert_eq!(d.solution, solve(&s.q, &s.qd, &u).unwrap());
        let sol = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, u: &SVector<f64, NU>| {
            solve(q, qd, u).unwrap()
        };
        let mut compare = |got: DMatrix<f64>, want: DMatrix<f64>, what: &str| {
            let e = (&got - &want).amax() / (1.0 + want.amax());
            assert!(e < 1e-5, "{}: {what} off by {e:.1e} ({modes:?})", L::NAME);
            worst = worst.max(e);
        };
        let dense = |m: &[f64], r: usize| DMatrix::from_column_slice(r, m.len() / r, m);
        if L::REDUNDANT_ROWS == 0 {
            let dq = central(&s.q, h, |x| sol(x, &s.qd, &u).x);
            let dc = central(&s.q, h, |x| sol(x, &s.qd, &u).contact);
            compare(
                dense(d.qdd_q.as_slice(), NQ),
                dense(dq.as_slice(), NQ),
                "∂q̈/∂q",
            );
            compare(
                dense(d.contact_q.as_slice(), NK),
                dense(dc.as_slice(), NK),
                "∂λ/∂q",
            );
        } else {
            // Off the closures a redundantly closed leg's rows are no longer dependent and
            // its dynamics are not smooth in q: along the manifold instead (the null space
            // of J, each direction projected back onto φ = 0, q̇ kept consistent), where
            // d/ds f(q(s), q̇(s)) = ∂f/∂q q' + ∂f/∂q̇ q̇'.
            let jq = L::constraint_jacobian(&s.q, &p);
            let j = DMatrix::from_fn(NQ, NQ, |r, c| if r < NC { jq[(r, c)] } else { 0.0 });
            let svd = j.transpose().svd(true, false);
            let (basis, top) = (svd.u.unwrap(), svd.singular_values.max());
            let tol = leg_models::assembly::Tolerance::default();
            for k in (0..NQ).filter(|&k| svd.singular_values[k] <= 1e-9 * top) {
                let t = SVector::<f64, NQ>::from_fn(|r, _| basis[(r, k)]);
                let curve = |x: f64| {
                    let mut q = s.q + t * x;
                    leg_models::assembly::project_position::<L, f64, NQ, NC, NU>(&p, &mut q, &tol)
                        .unwrap();
                    let mut qd = s.qd;
                    leg_models::assembly::project_velocity::<L, f64, NQ, NC, NU>(&p, &q, &mut qd)
                        .unwrap();
                    (q, qd)
                };
                let (plus, minus) = (curve(h), curve(-h));
                let (dq, dqd) = (
                    (plus.0 - minus.0) / (2.0 * h),
                    (plus.1 - minus.1) / (2.0 * h),
                );
                let (a, b) = (sol(&plus.0, &plus.1, &u), sol(&minus.0, &minus.1, &u));
                let want_x = (a.x - b.x) / (2.0 * h);
                let want_c = (a.contact - b.contact) / (2.0 * h);
                let got_x = d.qdd_q * dq + d.qdd_qd * dqd;
                let got_c = d.contact_q * dq + d.contact_qd * dqd;
                compare(
                    dense(got_x.as_slice(), NQ),
                    dense(want_x.as_slice(), NQ),
                    "∂q̈/∂q along the manifold",
                );
                compare(
                    dense(got_c.as_slice(), NK),
                    dense(want_c.as_slice(), NK),
                    "∂λ/∂q along the manifold",
                );
            }
        }
        let dq = central(&s.qd, h, |x| sol(&s.q, x, &u).x);
        let dc = central(&s.qd, h, |x| sol(&s.q, x, &u).contact);
        compare(
            dense(d.qdd_qd.as_slice(), NQ),
            dense(dq.as_slice(), NQ),
            "∂q̈/∂q̇",
        );
        compare(
            dense(d.contact_qd.as_slice(), NK),
            dense(dc.as_slice(), NK),
            "∂λ/∂q̇",
        );
        let want = central(&u, 1e-3, |x| sol(&s.q, &s.qd, x).x);
        let e = (d.qdd_u - want).amax() / (1.0 + want.amax());
        assert!(e < 1e-6, "{}: ∂q̈/∂u off by {e:.1e}", L::NAME);
        checked += 1;
        if (0..NK / 3).any(|k| matches!(modes.get(k), ContactMode::Slide { .. })) {
            sliding += 1;
            if let Some(d) = &rest {
                // Which way each slide went: kept `rest` (v_t · d ≤ 0) or followed v_t.
                let c = ground.rows(&L::contact_jacobian(&s.q, &p)) * s.qd;
                for k in 0..NK / 3 {
                    if matches!(modes.get(k), ContactMode::Slide { .. }) {
                        let ahead = d[3 * k] * c[3 * k] + d[3 * k + 1] * c[3 * k + 1];
                        kept_rest += usize::from(ahead <= 0.0);
                        followed += usize::from(ahead > 0.0);
                    }
                }
            }
        }
    }
    assert!(
        checked >= 36 && sliding >= 6,
        "{}: {checked} states checked, {sliding} sliding",
        L::NAME
    );
    assert!(
        kept_rest >= 1 && followed >= 1,
        "{}: slides given a direction: {kept_rest} kept it, {followed} followed the slip",
        L::NAME
    );
    worst
}

#[test]
fn sliding_mass_contact_derivatives_match_central_differences() {
    let worst = check_derivatives::<SlidingMass, 3, 0, 2, 3>();
    println!("sliding_mass: worst relative error {worst:.1e}");
}

#[test]
fn abducted_five_bar_contact_derivatives_match_central_differences() {
    let worst = check_derivatives::<AbductedFiveBar, 5, 3, 3, 3>();
    println!("abducted_five_bar: worst relative error {worst:.1e}");
}

/// At random assembled states and velocities: after the impact every closure and every
/// held contact row is at rest, a sticking impact loses exactly `½ Δq̇ᵀ M Δq̇`, a sliding
/// contact's impulse lies on the cone against the slip it leaves, and the normal impulses
/// push.
fn check_impact_identities<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let p = L::Params::<f64>::default();
    let ground = Ground::<f64, 3>::of::<L, NQ, NC, NU, NK>();
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, 3>();
    let mut rng = Rng::new(34);
    let (mut sticking, mut sliding) = (0, 0);
    for _ in 0..200 {
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 2.0);
        let mut modes = Modes::<NK, 3>::flight();
        for k in 0..NK / 3 {
            modes.set(k, ContactMode::Stick);
        }
        let Ok(imp) =
            impact_map::<L, f64, NQ, NC, NU, NK, 3>(&p, &s.q, &s.qd, &mut modes, &ground, &mu)
        else {
            continue; // pulling: the contact separates instead
        };
        let m = L::mass_matrix(&s.q, &p);
        let scale = 1.0 + s.qd.amax();
        if NC > 0 {
            let jq = L::constraint_jacobian(&s.q, &p) * imp.qd_plus;
            assert!(jq.amax() < 1e-10 * scale, "{}: J q̇⁺ = {jq}", L::NAME);
        }
        let v = ground.rows(&(L::contact_jacobian(&s.q, &p) * imp.qd_plus));
        for k in 0..NK / 3 {
            let lambda = imp.impulses.fixed_rows::<3>(3 * k);
            assert!(lambda[2] >= 0.0, "{}: pulling {lambda}", L::NAME);
            assert!(
                v[3 * k + 2].abs() < 1e-10 * scale,
                "{}: normal v⁺ {}",
                L::NAME,
                v[3 * k + 2]
            );
            match modes.get(k) {
                ContactMode::Stick => {
                    sticking += 1;
                    assert!(v.fixed_rows::<3>(3 * k).amax() < 1e-10 * scale);
                    assert!(lambda.xy().norm() <= mu[3 * k] * lambda[2] * (1.0 + 1e-12));
                    let dq = s.qd - imp.qd_plus;
                    let lost = 0.5 * dq.dot(&(m * dq));
                    assert!(
                        (imp.energy_lost - lost).abs() < 1e-10 * (1.0 + lost),
                        "{}: {} against ½ Δq̇ᵀ M Δq̇ = {lost}",
                        L::NAME,
                        imp.energy_lost
                    );
                }
                ContactMode::Slide { .. } => {
                    sliding += 1;
                    let vt = v.fixed_rows::<2>(3 * k);
                    assert!(
                        (lambda.xy().norm() - mu[3 * k] * lambda[2]).abs()
                            < 1e-9 * (1.0 + lambda[2])
                    );
                    // Against the slip after the impact (to the iteration's √ε).
                    if vt.norm() > 1e-9 {
                        let cos = lambda.xy().dot(&vt) / (lambda.xy().norm() * vt.norm());
                        assert!(
                            cos < -1.0 + 1e-6,
                            "{}: friction impulse at cos {cos} to the slip",
                            L::NAME
                        );
                    }
                }
                ContactMode::Flight => unreachable!("held contacts stay held or slide"),
            }
        }
    }
    assert!(
        sticking >= 5 && sliding >= 5,
        "{}: {sticking} sticking, {sliding} sliding",
        L::NAME
    );
}

#[test]
fn sliding_mass_impacts_hold_the_impact_identities() {
    check_impact_identities::<SlidingMass, 3, 0, 2, 3>();
}

#[test]
fn abducted_five_bar_impacts_hold_the_impact_identities() {
    check_impact_identities::<AbductedFiveBar, 5, 3, 3, 3>();
}

#[test]
fn abducted_five_bar_lands_its_toe_and_stands_with_its_loop_closed() {
    // Home, the toe 5 mm over the floor, moving down at 0.5 m/s along the closures (the
    // least-norm q̇ with J q̇ = 0 and the toe's velocity (0, 0, −0.5)); motors off.
    type L = AbductedFiveBar;
    let p = <L as LegDynamics<5, 3, 3>>::Params::<f64>::default();
    let q = SVector::<f64, 5>::from(<L as LegDynamics<5, 3, 3>>::HOME);
    let mut q = q;
    leg_models::assembly::project_position::<L, f64, 5, 3, 3>(
        &p,
        &mut q,
        &leg_models::assembly::Tolerance::default(),
    )
    .unwrap();
    let j = <L as LegDynamics<5, 3, 3>>::constraint_jacobian(&q, &p);
    let jc = <L as ContactModel<5, 3, 3, 3, 3>>::contact_jacobian(&q, &p);
    let a = DMatrix::from_fn(6, 5, |r, c| if r < 3 { j[(r, c)] } else { jc[(r - 3, c)] });
    let b = DVector::from_vec(vec![0.0, 0.0, 0.0, 0.0, 0.0, -0.5]);
    let qd = a.svd(true, true).solve(&b, 1e-12).unwrap();
    let qd = SVector::<f64, 5>::from_fn(|i, _| qd[i]);
    let mut s = HybridSimulator::<L, f64, 5, 3, 3, 3, 3>::new(p, 1e-3);
    s.options.tolerance = leg_models::assembly::Tolerance::default();
    let start = HybridState::<f64, 5, 3, 3>::flight(State { q, qd });
    let toe = <L as ContactModel<5, 3, 3, 3, 3>>::contact_positions(&q, &p);
    assert!(
        (toe[2] + 0.245).abs() < 1e-3,
        "the toe 5 mm over the floor: {toe}"
    );
    let mut off = |_: f64, _: &HybridState<f64, 5, 3, 3>| SVector::<f64, 3>::zeros();
    let record = s.run(start, 300, &mut off).unwrap();
    let touchdown = record.events.first().expect("the toe lands");
    assert_eq!(touchdown.kind, EventKind::Touchdown);
    assert!(touchdown.energy_lost > 0.0 && touchdown.impulse[1] > 0.0);
    let mu = s.options.friction[0];
    let mut energy = f64::INFINITY;
    for sample in &record.samples {
        assert!(
            sample.closure_residual < 1e-12,
            "loop open {}",
            sample.closure_residual
        );
        assert!(
            sample.contact_residual < 1e-12,
            "toe off its anchor {}",
            sample.contact_residual
        );
        let x = s.contact_coordinates(&sample.state.state).0;
        assert!(x[2] > -1e-12, "the toe under the floor: {}", x[2]);
        let f = sample.contact_forces;
        if sample.state.modes.get(0).on_ground() {
            assert!(
                f[2] >= 0.0 && f.xy().norm() <= mu * f[2] + 1e-9,
                "outside the cone: {f}"
            );
        }
        // Passive, damped, plastic: the energy never grows (beyond RK4's error).
        assert!(
            sample.energy <= energy + 1e-9,
            "energy grew to {}",
            sample.energy
        );
        energy = sample.energy;
    }
    let last = record.samples.last().unwrap();
    assert!(last.state.modes.get(0).on_ground(), "{:?}", record.events);
}

// `ankle_rod_leg`, written from the docs by a new user: two contacts (heel and toe on one
// foot) and two loops (a five-bar with a redundant row, an ankle rod). The checks above
// on it exercise the multi-contact paths: the held rows of two contacts at once, the
// impact map's slip directions contact by contact, the derivatives with two slides.

use generated::ankle_rod_leg::AnkleRodLeg;

#[test]
fn ankle_rod_leg_contact_dynamics_solve_the_dense_kkt_system() {
    check_against_dense::<AnkleRodLeg, 6, 4, 3, 6>(None);
    check_against_dense::<AnkleRodLeg, 6, 4, 3, 6>(Some([0.2, 0.3, 0.9]));
}

#[test]
fn ankle_rod_leg_contact_derivatives_match_central_differences() {
    let worst = check_derivatives::<AnkleRodLeg, 6, 4, 3, 6>();
    println!("ankle_rod_leg: worst relative error {worst:.1e}");
}

#[test]
fn ankle_rod_leg_impacts_hold_the_impact_identities() {
    check_impact_identities::<AnkleRodLeg, 6, 4, 3, 6>();
}

/// The foot put flat on the ground (home moved onto the closures and both contacts' gaps
/// to zero, along the ground as it must) at rest, both contacts sticking, and released
/// with the motors off. A fixed-base leg of three coordinates cannot move with six held
/// rows: they repeat each other, their forces are not unique (the solve takes the least), and
/// where the pick leaves a cone the contact slips at that instant. Throughout, the loops
/// stay closed, a held contact on its anchor, every force (but at the instant of a change
/// of mode) inside its cone and pushing, and the energy never grows.
#[test]
fn ankle_rod_leg_stands_on_heel_and_toe_with_its_loops_closed() {
    type L = AnkleRodLeg;
    let p = <L as LegDynamics<6, 4, 3>>::Params::<f64>::default();
    let sim = HybridSimulator::<L, f64, 6, 4, 3, 6, 3>::new(p, 1e-3);
    let mut q = SVector::<f64, 6>::from(<L as LegDynamics<6, 4, 3>>::HOME);
    leg_models::assembly::project_position::<L, f64, 6, 4, 3>(
        &p,
        &mut q,
        &leg_models::assembly::Tolerance::default(),
    )
    .unwrap();
    let mut hs = HybridState::<f64, 6, 6, 3>::flight(State {
        q,
        qd: SVector::zeros(),
    });
    let (x, _) = sim.contact_coordinates(&hs.state);
    assert!(
        x[2] > 0.01 && x[5] > 0.01,
        "both above the ground at home: {x}"
    );
    // A sliding contact holds its gap only: both onto the ground, free along it.
    for k in 0..2 {
        hs.modes.set(k, ContactMode::Slide { forward: true });
    }
    sim.project(&mut hs).unwrap();
    let (x, _) = sim.contact_coordinates(&hs.state);
    assert!(
        x[2].abs() < 1e-12 && x[5].abs() < 1e-12,
        "both on the ground: {x}"
    );
    for k in 0..2 {
        hs.modes.set(k, ContactMode::Stick);
        hs.anchors[3 * k] = x[3 * k];
        hs.anchors[3 * k + 1] = x[3 * k + 1];
    }
    let mut off = |_: f64, _: &HybridState<f64, 6, 6, 3>| SVector::<f64, 3>::zeros();
    let record = sim.run(hs, 1000, &mut off).unwrap();
    let mu = sim.options.friction[0];
    let switching = |t: f64| record.events.iter().any(|e| (e.t - t).abs() < 1e-9);
    let mut energy = f64::INFINITY;
    let (mut both, mut on_ground) = (0, 0);
    for sample in &record.samples {
        assert!(
            sample.closure_residual < 1e-12,
            "{}",
            sample.closure_residual
        );
        assert!(
            sample.contact_residual < 1e-12,
            "{}",
            sample.contact_residual
        );
        let x = sim.contact_coordinates(&sample.state.state).0;
        let f = sample.contact_forces;
        let mut held = 0;
        for k in 0..2 {
            assert!(x[3 * k + 2] > -1e-12, "contact {k} under the floor");
            let fk = f.fixed_rows::<3>(3 * k);
            if sample.state.modes.get(k).on_ground() {
                held += 1;
                if !switching(sample.t) {
                    assert!(fk[2] >= -1e-9, "pulling at {}: {fk}", sample.t);
                    assert!(
                        fk.xy().norm() <= mu * fk[2] + 1e-9,
                        "outside the cone at {}: {fk}",
                        sample.t
                    );
                }
            } else {
                assert_eq!(fk.amax(), 0.0);
            }
        }
        both += usize::from(held == 2);
        on_ground += usize::from(held > 0);
        assert!(
            sample.energy <= energy + 1e-9,
            "energy grew to {}",
            sample.energy
        );
        energy = sample.energy;
    }
    println!(
        "ankle_rod_leg: {both} of {} samples on heel and toe, {on_ground} on the ground, events {:?}",
        record.samples.len(),
        record.events.iter().map(|e| (e.t, e.kind, e.contact)).collect::<Vec<_>>()
    );
    assert!(
        both == record.samples.len(),
        "{both} of {}",
        record.samples.len()
    );
}

// The floating robots: their mass matrix is factored along the tree and their stance
// solved in half solves (`solve_structured_on_tree`), against the same dense system.

use generated::cassie::Cassie;
use generated::minitaur_quadruped::MinitaurQuadruped;

#[test]
fn cassie_contact_dynamics_solve_the_dense_kkt_system() {
    check_against_dense_at::<Cassie, 32, 12, 10, 12>(None, near_home::<Cassie, 32, 12, 10>);
    check_against_dense_at::<Cassie, 32, 12, 10, 12>(
        Some([0.2, 0.3, 0.9]),
        near_home::<Cassie, 32, 12, 10>,
    );
}

#[test]
fn minitaur_quadruped_contact_dynamics_solve_the_dense_kkt_system() {
    type Q = MinitaurQuadruped;
    check_against_dense_at::<Q, 22, 12, 8, 12>(None, near_home::<Q, 22, 12, 8>);
    check_against_dense_at::<Q, 22, 12, 8, 12>(Some([0.2, 0.3, 0.9]), near_home::<Q, 22, 12, 8>);
}
