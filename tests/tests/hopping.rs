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
use leg_models::LegDynamics;

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

/// The peak motor torque of atrias_hopper hopping in place does not grow as the step
/// shrinks: the efforts' rate was a one-step difference, so a slide turning to stick
/// made a spike of Δτ*/dt (`sim atrias_hopper` over 3 s: 7.2 kN m at 1 ms, 35 kN m at
/// 0.1 ms). Filtered over the drive's 1/ω, the peak is a property of the controller, not
/// of the step.
#[test]
fn atrias_hopper_peak_torque_does_not_grow_as_the_step_shrinks() {
    use generated::atrias_hopper::{Params, NC, NK, NQ, NU};
    use generated::AtriasHopper as A;
    let p = Params::<f64>::default();
    let mut home = SVector::<f64, NQ>::from(A::HOME);
    project_position::<A, f64, NQ, NC, NU>(&p, &mut home, &Default::default()).unwrap();
    let peak = |dt: f64| {
        let mut sim = HybridSimulator::<A, f64, NQ, NC, NU, NK>::new(p, dt);
        sim.options.control = leg_models::simulate::ControlUpdate::PerStep;
        let settings =
            HopSettings::for_leg::<A, NQ, NC, NK>(&p, &home, home[1] + 0.05, None, f64::INFINITY)
                .unwrap();
        let mut controller = HopController::<A, f64, NQ, NC, NU, NK>::new(p, sim.options, settings);
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
        let record = match sim.run(start, (1.5 / dt).round() as usize, &mut controller) {
            Ok(r) => r,
            Err(stopped) => panic!("dt = {dt}: {stopped}"),
        };
        record
            .samples
            .iter()
            .map(|s| s.u.amax())
            .fold(0.0, f64::max)
    };
    let (coarse, fine) = (peak(1e-3), peak(1e-4));
    eprintln!("peak torque: {coarse} N m at 1 ms, {fine} N m at 0.1 ms");
    assert!(
        fine < 1.3 * coarse,
        "peak torque {fine} N m at 0.1 ms, {coarse} N m at 1 ms"
    );
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

/// A torque source that counts how often it is asked: once per piece of a step (torques
/// held over each step and asked again after each event).
struct Counted<S>(S, usize);

impl<S, const NQ: usize, const NK: usize, const NU: usize>
    leg_models::simulate::hybrid::HybridTorqueSource<f64, NQ, NK, NU> for Counted<S>
where
    S: leg_models::simulate::hybrid::HybridTorqueSource<f64, NQ, NK, NU>,
{
    fn torque(
        &mut self,
        t: f64,
        state: &leg_models::simulate::hybrid::HybridState<f64, NQ, NK>,
    ) -> Result<SVector<f64, NU>, leg_models::control::ControlError> {
        self.1 += 1;
        self.0.torque(t, state)
    }
}

/// `atrias_hopper` lifts off wherever in a step the liftoff falls, at any step size (issue
/// 29, part 5: `sim atrias_hopper --dt 1e-4 --duration 50` stopped at 25.1 s on "the
/// contacts chatter", the default step held). A toe that lifts off leaves the ground at
/// rest (its normal force has vanished), from where the projection held it — up to its
/// tolerance under the ground — and rises as the cube of the time: microseconds to clear
/// the ground. A liftoff that left less of the step than that saw the toe still "under
/// the ground" at the step's end, a crossing a picosecond after the liftoff, then after
/// each picosecond (a graze, or a touchdown and a liftoff), until the step's events ran
/// over; the shorter the step, the more often a liftoff fell that close to its end. Each
/// case here puts the hop's first liftoff `left` seconds before the end of a step of
/// `dt`, the toe held at 0.9 of the tolerance under the ground, and steps on for 2 ms: no
/// step cut into more pieces than its events, no touchdown after the liftoff.
#[test]
fn atrias_hopper_lifts_off_however_little_of_the_step_is_left() {
    use generated::atrias_hopper::{Params, NC, NK, NQ, NU};
    use generated::AtriasHopper as A;
    use leg_models::dynamics::contact::ContactMode;
    let p = Params::<f64>::default();
    let dt0 = 1e-3;
    let mut sim = HybridSimulator::<A, f64, NQ, NC, NU, NK>::new(p, dt0);
    sim.options.control = leg_models::simulate::ControlUpdate::PerStep;
    let mut home = SVector::<f64, NQ>::from(A::HOME);
    project_position::<A, f64, NQ, NC, NU>(&p, &mut home, &Default::default()).unwrap();
    let settings =
        HopSettings::for_leg::<A, NQ, NC, NK>(&p, &home, home[1] + 0.05, Some(0.0), f64::INFINITY)
            .unwrap();
    let mut controller = HopController::<A, f64, NQ, NC, NU, NK>::new(p, sim.options, settings);
    let mut q = home;
    q[1] += 0.03;
    let mut hs = sim
        .start(
            State {
                q,
                qd: SVector::zeros(),
            },
            &SVector::zeros(),
        )
        .unwrap();
    // Hop at 1 ms steps to the first liftoff, keeping each step's start.
    let mut starts = Vec::new();
    let mut k = 0;
    let lifted_at = 'hop: loop {
        let t = dt0 * k as f64;
        assert!(t < 1.0, "no liftoff in the first second");
        starts.push((t, hs, controller));
        for e in sim.step(&mut hs, t, &mut controller).unwrap().iter() {
            if e.kind == EventKind::Liftoff {
                break 'hop e.t;
            }
        }
        k += 1;
    };
    // From two steps before the liftoff's step: a first step (longer than every `dt`,
    // ending before the liftoff) sets where the steps of `dt` fall.
    let (t0, mut hs0, controller0) = starts[starts.len() - 3];
    // The projection holds a contact on the ground to within its tolerance, on either
    // side (2.0e-13 m under it at the liftoff of 25.13 s with dt = 1e-4); here the
    // toe is held at 0.9 of that tolerance under the ground, the body lowered by the
    // difference.
    let band = leg_models::assembly::Tolerance::<f64>::default().relative_residual
        * leg_models::assembly::leg_size::<A, f64, NQ, NC, NU>(&p, &hs0.state.q);
    let gap = sim.contact_coordinates(&hs0.state).0[1];
    hs0.state.q[1] -= gap + 0.9 * band;
    let gap = sim.contact_coordinates(&hs0.state).0[1];
    assert!(
        (gap + 0.9 * band).abs() < 0.01 * band,
        "the toe {gap:e} m above the ground"
    );
    // Steps on from the first step of `first` for 2 ms after the liftoff: the liftoff's
    // time, the end of its step, the final state; or the case's failure.
    let run = |first: f64, dt: f64, case: &str| {
        let (mut t, mut hs) = (t0, hs0);
        let mut controller = Counted(controller0, 0);
        let mut s = sim;
        s.options.dt = first;
        s.step(&mut hs, t, &mut controller).unwrap();
        t += first;
        s.options.dt = dt;
        controller.0.options.dt = dt;
        let mut liftoff = None;
        while t < lifted_at + 2e-3 {
            controller.1 = 0;
            let events = s
                .step(&mut hs, t, &mut controller)
                .unwrap_or_else(|e| panic!("{case}: {e}"));
            // The step cut into one piece, and one more after each event.
            assert!(
                controller.1 <= events.len() + 1,
                "{case}: the step at {t} s cut into {} pieces for {} events",
                controller.1,
                events.len()
            );
            // Slips (and sticks) as the normal force vanishes, the liftoff, and no
            // touchdown after it.
            for e in events.iter() {
                match e.kind {
                    EventKind::Slip | EventKind::Stick if liftoff.is_none() => {}
                    EventKind::Liftoff if liftoff.is_none() => liftoff = Some((e.t, t + dt)),
                    kind => panic!("{case}: {kind:?} at {} s", e.t),
                }
            }
            t += dt;
        }
        let (at, end) = liftoff.unwrap_or_else(|| panic!("{case}: no liftoff"));
        (at, end, hs, s)
    };
    for dt in [1e-3, 1e-4, 1e-5] {
        for left in [1e-5, 1e-6, 1e-7, 1e-8] {
            if left >= dt {
                continue;
            }
            let case = format!("dt = {dt} s, the liftoff {left} s before a step's end");
            // The torques are held over each step, so the liftoff moves a little with
            // the steps: the first step is corrected until it falls where asked.
            let mut first = lifted_at + left - dt - t0;
            let (mut at, mut end, mut hs, mut s) = run(first, dt, &case);
            let mut tries = 1;
            while ((end - at) - left).abs() >= 0.1 * left && tries < 20 {
                // Just after a step's start is just before the previous step's end.
                let behind = if end - at > 0.5 * dt {
                    end - at - dt
                } else {
                    end - at
                };
                first += left - behind;
                (at, end, hs, s) = run(first, dt, &case);
                tries += 1;
            }
            eprintln!("{case}: {:e} s left after {tries} runs", end - at);
            assert!(
                ((end - at) - left).abs() < 0.1 * left && (at - lifted_at).abs() < 1e-5,
                "{case}: lifted off at {at} s, {} s before its step's end",
                end - at
            );
            assert_eq!(hs.modes.get(0), ContactMode::Flight, "{case}");
            let (x, _) = s.contact_coordinates(&hs.state);
            assert!(x[1] > 0.0, "{case}: the toe {} m above the ground", x[1]);
        }
    }
}
