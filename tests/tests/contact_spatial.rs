//! Contact in 3-D (DESIGN.md §3.1): the exact Coulomb cone, slip in any direction along
//! the ground, stick–slip events and plastic impacts, on `sliding_mass` (a point mass on
//! three prismatic joints, one contact), whose motions have closed forms: a block on an
//! incline that sticks below the friction angle and slides above it at
//! `g (sin θ − μ cos θ)`, a slide that stops after `v₀ / (μ g)`, a pushed slide that turns
//! as the point-mass ODE `m v̇ = F − μ m g v / |v|` (integrated here on its own), and
//! impacts that keep `|v_t| − μ v_n` of the tangential speed or stop it.

use generated::sliding_mass::{self, SlidingMass};
use leg_models::dynamics::contact::{impact_map, ContactMode, Ground, Modes};
use leg_models::nalgebra::{SVector, Vector3};
use leg_models::simulate::hybrid::{EventKind, HybridSimulator, HybridState};
use leg_models::simulate::State;

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
