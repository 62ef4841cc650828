//! Hopping on the ground, through the hybrid simulator (impacts at every touchdown,
//! liftoffs located in the step): `minitaur_hopper` hops in place to a commanded apex
//! height with the Minitaur motors' torque limit, and `atrias_hopper` (a floating body
//! that pitches, series-elastic hips) hops forward at a commanded speed.

use generated::minitaur_hopper::{Params, NC, NK, NQ, NU};
use generated::MinitaurHopper as L;
use leg_models::assembly::project_position;
use leg_models::control::hop::{HopController, HopSettings};
use leg_models::nalgebra::SVector;
use leg_models::simulate::hybrid::{EventKind, HybridSimulator};
use leg_models::simulate::State;
use leg_models::LegModel;

/// Apexes from a record, `(t, q[forward], q[height])`: the height's rate crossing zero
/// with every contact in flight.
fn apexes<const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    record: &leg_models::simulate::hybrid::HybridRecord<f64, NQ, NC, NU, NK>,
    height: usize,
    forward: usize,
) -> Vec<(f64, f64, f64)> {
    let flight = |s: &leg_models::simulate::hybrid::HybridSample<f64, NQ, NC, NU, NK>| {
        (0..NK / 2).all(|k| !s.state.modes.get(k).on_ground())
    };
    record
        .samples
        .windows(2)
        .filter(|w| {
            flight(&w[0])
                && flight(&w[1])
                && w[0].state.state.qd[height] > 0.0
                && w[1].state.state.qd[height] <= 0.0
        })
        .map(|w| {
            let (a, b) = (&w[0].state.state.q, &w[1].state.state.q);
            (w[0].t, a[forward], a[height].max(b[height]))
        })
        .collect()
}

/// The hop controller for `minitaur_hopper`, commanding `apex` (body height, m).
pub fn minitaur_hopper_run(
    apex: f64,
    seconds: f64,
) -> (
    leg_models::simulate::hybrid::HybridRecord<f64, NQ, NC, NU, NK>,
    HopController<L, f64, NQ, NC, NU, NK>,
) {
    let p = Params::<f64>::default();
    let sim = HybridSimulator::<L, f64, NQ, NC, NU, NK>::new(p, 1e-3);
    let mut q = SVector::<f64, NQ>::from(L::HOME);
    project_position::<L, f64, NQ, NC, NU>(&p, &mut q, &Default::default()).unwrap();
    let posture = SVector::<f64, NU>::from_fn(|k, _| q[L::ACTUATED[k]]);
    q[0] += 0.03; // released 3 cm above standing
    let settings = HopSettings {
        height_joint: 0,
        apex,
        posture,
        kp: SVector::from_element(30.0),
        kd: SVector::from_element(0.6),
        stance_frequency: 18.0,
        height_gain: 0.8,
        torque_limits: SVector::from_element(3.5),
        gravity: 9.81,
        ..HopSettings::for_leg::<L, NQ, NC, NK>(&p, &q, apex, None, 3.5).unwrap()
    };
    let mut controller = HopController::<L, f64, NQ, NC, NU, NK>::new(p, sim.options, settings);
    let start = sim
        .start(
            State {
                q,
                qd: SVector::zeros(),
            },
            &SVector::zeros(),
        )
        .unwrap();
    let record = match sim.run(start, (seconds / 1e-3) as usize, &mut controller) {
        Ok(r) => r,
        Err(stopped) => panic!("{stopped}"),
    };
    (record, controller)
}

#[test]
fn minitaur_hopper_hops_to_the_commanded_apex() {
    let apex = 0.30;
    let (record, controller) = minitaur_hopper_run(apex, 12.0);
    let apexes: Vec<f64> = apexes(&record, 0, 0).iter().map(|a| a.2).collect();
    let touchdowns = record
        .events
        .iter()
        .filter(|e| e.kind == EventKind::Touchdown)
        .count();
    let slips = record
        .events
        .iter()
        .filter(|e| e.kind == EventKind::Slip)
        .count();
    eprintln!(
        "apexes {apexes:?}\ntouchdowns {touchdowns}, slips {slips}, thrust {}, saturations {:?}",
        controller.thrust, controller.saturations
    );
    assert!(apexes.len() >= 25, "{} hops", apexes.len());
    let settled = &apexes[5..];
    let worst = settled.iter().map(|a| (a - apex).abs()).fold(0.0, f64::max);
    assert!(
        worst < 5e-3,
        "apex error {worst:.4} m after five hops: {settled:?}"
    );
    assert_eq!(slips, 0, "the toe slipped");
    let residual = record
        .samples
        .iter()
        .map(|s| s.closure_residual.max(s.contact_residual))
        .fold(0.0, f64::max);
    assert!(residual <= 1e-12, "residual {residual:e}");
}

/// `atrias_hopper` released at rest and commanded `speed` for 12 s: the series-elastic
/// drives, the attitude servo and Raibert's foot placement bring it to the speed and hold
/// it (hop speeds from the body's advance between apexes).
fn atrias_hopper_hops_forward_at(speed: f64) {
    use generated::atrias_hopper::{Params, NC, NK, NQ, NU};
    use generated::AtriasHopper as A;
    let p = Params::<f64>::default();
    let mut sim = HybridSimulator::<A, f64, NQ, NC, NU, NK>::new(p, 1e-3);
    sim.options.control = leg_models::simulate::ControlUpdate::PerStep;
    let mut home = SVector::<f64, NQ>::from(A::HOME);
    project_position::<A, f64, NQ, NC, NU>(&p, &mut home, &Default::default()).unwrap();
    let apex = home[1] + 0.05;
    let settings =
        HopSettings::for_leg::<A, NQ, NC, NK>(&p, &home, apex, Some(speed), f64::INFINITY).unwrap();
    assert_eq!(settings.height_joint, 1, "slide_y");
    assert_eq!(settings.forward.map(|f| f.joint), Some(0), "slide_x");
    assert_eq!(settings.pitch.map(|f| f.joint), Some(2), "torso");
    let mut controller = HopController::<A, f64, NQ, NC, NU, NK>::new(p, sim.options, settings);
    assert_eq!(
        controller.drives.map(|d| (d.motor, d.joint)),
        [(3, 5), (4, 7)],
        "each motor drives its segment through its spring"
    );
    let mut q = home;
    q[1] += 0.03;
    let start = sim
        .start(
            State {
                q,
                qd: SVector::zeros(),
            },
            &SVector::zeros(),
        )
        .unwrap();
    let record = match sim.run(start, 12_000, &mut controller) {
        Ok(r) => r,
        Err(stopped) => panic!("{stopped}"),
    };
    let apexes = apexes(&record, 1, 0);
    let speeds: Vec<f64> = apexes
        .windows(2)
        .map(|w| (w[1].1 - w[0].1) / (w[1].0 - w[0].0))
        .collect();
    eprintln!("{speed} m/s: hop speeds {speeds:?}");
    assert!(apexes.len() >= 25, "{} hops", apexes.len());
    let worst = speeds[5..]
        .iter()
        .map(|v| (v - speed).abs() / speed)
        .fold(0.0, f64::max);
    assert!(
        worst < 0.05,
        "speed error {:.1} % after five hops",
        100.0 * worst
    );
    let apex_error = apexes[5..]
        .iter()
        .map(|a| (a.2 - apex).abs())
        .fold(0.0, f64::max);
    assert!(apex_error < 5e-3, "apex error {apex_error} m");
    // Slips after the first five hops (while it speeds up from rest, a touchdown may
    // slide for a few ms): none but those as a liftoff's normal force vanishes (within
    // 1 ms of it).
    let settled = apexes[5].0;
    let slips = record
        .events
        .iter()
        .filter(|e| e.kind == EventKind::Slip && e.t > settled)
        .filter(|e| {
            !record
                .events
                .iter()
                .any(|l| l.kind == EventKind::Liftoff && l.t >= e.t && l.t - e.t < 1e-3)
        })
        .map(|e| e.t)
        .collect::<Vec<_>>();
    assert!(slips.is_empty(), "slips in stance at {slips:?}");
    let closure = record
        .samples
        .iter()
        .map(|s| s.closure_residual)
        .fold(0.0, f64::max);
    let contact = record
        .samples
        .iter()
        .map(|s| s.contact_residual)
        .fold(0.0, f64::max);
    eprintln!("residuals: closure {closure:e}, contact {contact:e}");
    assert!(closure <= 1e-12, "closure residual {closure:e}");
    assert!(contact <= 1e-11, "contact residual {contact:e}");
}

#[test]
fn atrias_hopper_hops_forward_at_half_a_metre_per_second() {
    atrias_hopper_hops_forward_at(0.5);
}

#[test]
fn atrias_hopper_hops_forward_at_one_metre_per_second() {
    atrias_hopper_hops_forward_at(1.0);
}

/// `knee_runner` (a user's leg, written from the README alone: a floating body on a hip
/// and a knee motor) hops in place and forward at 0.5 m/s under the same controller with
/// no setting of its own, from rest for 10 s.
#[test]
fn knee_runner_hops_in_place_and_forward() {
    use generated::knee_runner::{Params, NC, NK, NQ, NU};
    use generated::KneeRunner as K;
    let p = Params::<f64>::default();
    let mut sim = HybridSimulator::<K, f64, NQ, NC, NU, NK>::new(p, 1e-3);
    sim.options.control = leg_models::simulate::ControlUpdate::PerStep;
    let mut home = SVector::<f64, NQ>::from(K::HOME);
    project_position::<K, f64, NQ, NC, NU>(&p, &mut home, &Default::default()).unwrap();
    let apex = home[1] + 0.05;
    // (command, largest speed error after five hops), m/s.
    for (speed, tolerance) in [(0.0, 0.1), (0.5, 0.05)] {
        let settings =
            HopSettings::for_leg::<K, NQ, NC, NK>(&p, &home, apex, Some(speed), f64::INFINITY)
                .unwrap();
        let mut controller = HopController::<K, f64, NQ, NC, NU, NK>::new(p, sim.options, settings);
        let mut q = home;
        q[1] += 0.03;
        let start = sim
            .start(
                State {
                    q,
                    qd: SVector::zeros(),
                },
                &SVector::zeros(),
            )
            .unwrap();
        let record = match sim.run(start, 10_000, &mut controller) {
            Ok(r) => r,
            Err(stopped) => panic!("{speed} m/s: {stopped}"),
        };
        let apexes = apexes(&record, 1, 0);
        let speeds: Vec<f64> = apexes
            .windows(2)
            .map(|w| (w[1].1 - w[0].1) / (w[1].0 - w[0].0))
            .collect();
        eprintln!("{speed} m/s: hop speeds {speeds:?}");
        assert!(apexes.len() >= 20, "{} hops", apexes.len());
        let error = |from: usize| {
            speeds[from..]
                .iter()
                .map(|v| (v - speed).abs())
                .fold(0.0, f64::max)
        };
        assert!(
            error(5) < tolerance,
            "{speed} m/s: speed error {} m/s after five hops",
            error(5)
        );
        let last = error(speeds.len() - 5);
        assert!(
            last < 0.02,
            "{speed} m/s: speed error {last} m/s over the last five hops"
        );
        let apex_error = apexes[5..]
            .iter()
            .map(|a| (a.2 - apex).abs())
            .fold(0.0, f64::max);
        assert!(apex_error < 5e-3, "{speed} m/s: apex error {apex_error} m");
    }
}
