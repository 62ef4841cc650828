//! `cargo xtask sim MODEL` for a leg with contacts: the hybrid simulator (contact modes,
//! located events, impacts) under the hopping controller (or no torque with
//! `--controller passive`); writes `trajectory.csv`, `events.csv`, `summary.json` and
//! `report.html` with the ground drawn.

use std::fmt::Write as _;

use leg_models::assembly::{project_position, Tolerance};
use leg_models::control::hop::{
    forward_joint, height_joint, HopController, HopSettings, HopSetupError,
};
use leg_models::dynamics::contact::{ContactMode, Ground};
use leg_models::nalgebra::SVector;
use leg_models::simulate::hybrid::{EventKind, HybridSample, HybridSimulator, HybridState};
use leg_models::simulate::State;
use leg_models::ContactModel;
use serde_json::json;
use xtask::cli::progress::Progress;
use xtask::cli::{check_targets, write_all, Error};

use crate::report::{self, Report, Series};
use crate::sim::{body_points, frame_at, max, Settings};

enum Source<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
where
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    Hop(Box<HopController<L, f64, NQ, NC, NU, NK>>),
    Passive,
}

struct WithProgress<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
where
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    source: Source<L, NQ, NC, NU, NK>,
    progress: Progress,
    dt: f64,
}

impl<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    leg_models::simulate::hybrid::HybridTorqueSource<f64, NQ, NK, NU>
    for WithProgress<L, NQ, NC, NU, NK>
where
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    fn torque(
        &mut self,
        t: f64,
        s: &HybridState<f64, NQ, NK>,
    ) -> Result<SVector<f64, NU>, leg_models::control::ControlError> {
        self.progress.set((t / self.dt) as u64);
        match &mut self.source {
            Source::Hop(c) => c.torque(t, s),
            Source::Passive => Ok(SVector::zeros()),
        }
    }
}

pub fn run<
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>(
    s: &Settings,
) -> Result<(), Error> {
    // A target in the way is found before the simulation runs, not after.
    check_targets(
        &s.out_dir(L::NAME),
        &[
            "trajectory.csv",
            "events.csv",
            "summary.json",
            "report.html",
        ],
    )
    .map_err(Error::Failed)?;
    let p = <L as leg_models::LegDynamics<NQ, NC, NU>>::Params::<f64>::default();
    let fail =
        |what: &str, e: &dyn std::fmt::Display| Error::Failed(format!("{}: {what}: {e}", L::NAME));
    let mut home = SVector::<f64, NQ>::from_column_slice(&L::HOME);
    project_position::<L, f64, NQ, NC, NU>(&p, &mut home, &Tolerance::default())
        .map_err(|e| fail("the home pose does not assemble", &e))?;
    // A leg whose body cannot rise (a fixed base) does not hop: the swing-leg controllers
    // drive it on the ground.
    let Some(h) = height_joint::<L, f64, NQ, NC, NU, NK>(&p, &home) else {
        return crate::sim::ground::run::<L, NQ, NC, NU, 2, NC, NK>(
            s,
            Some("no prismatic joint of its body raises its contacts (no height joint), so it does not hop: it runs on the ground under the swing-leg controllers"),
        );
    };
    if let Some(name) = s.swing_only() {
        return Err(Error::usage(format!(
            "{} has contacts: `sim` runs it on the ground under the hopping controller (or with --controller passive); `{name}` is for legs in the air",
            L::NAME
        )));
    }
    if s.kp_given() {
        return Err(Error::usage(format!(
            "{} has contacts: `--kp` sets the swing-leg controllers' stiffness; the hopping controller's gains come from the leg's inertias",
            L::NAME
        )));
    }
    // The hopping controller's settings mean nothing to a passive drop: refused, not ignored.
    if s.passive() {
        for (flag, given) in [("--apex", s.apex.is_some()), ("--speed", s.speed.is_some())] {
            if given {
                return Err(Error::usage(format!(
                    "{flag} sets the hopping controller's {}; with --controller passive there is none (leave out one or the other)",
                    if flag == "--apex" { "apex height" } else { "forward speed" }
                )));
            }
        }
    }
    let mut sim = HybridSimulator::<L, f64, NQ, NC, NU, NK>::new(p, s.dt);
    sim.options.control = leg_models::simulate::ControlUpdate::PerStep;
    let apex = s.apex.unwrap_or(home[h] + 0.05);
    if apex <= home[h] {
        return Err(Error::usage(format!(
            "--apex {apex}: at or below the standing height {:.4} m of {}'s `{}`: a hop's apex is above it",
            home[h],
            L::NAME,
            L::JOINT_NAMES[h]
        )));
    }
    // Hopping forward where the body can move along the ground (in place unless --speed).
    let speed = match forward_joint::<L, f64, NQ, NC, NU, NK>(&p, &home) {
        Some(_) => Some(s.speed.unwrap_or(0.0)),
        None if s.speed.is_some() && !s.passive() => {
            return Err(Error::usage(format!(
                "--speed: {}: {}",
                L::NAME,
                HopSetupError::NoForwardJoint
            )))
        }
        None => None,
    };
    let limit = s.torque_limit.unwrap_or(f64::INFINITY);
    let settings = HopSettings::for_leg::<L, NQ, NC, NK>(&p, &home, apex, speed, limit)
        .map_err(|e| fail("the hopping controller", &e))?;
    // Released 3 cm above standing, at rest.
    let mut q0 = home;
    q0[h] += 0.03;
    let start = sim
        .start(
            State {
                q: q0,
                qd: SVector::zeros(),
            },
            &SVector::zeros(),
        )
        .map_err(|e| fail("the start", &e))?;
    let controller = HopController::<L, f64, NQ, NC, NU, NK>::new(p, sim.options, settings);
    let source = if s.passive() {
        Source::Passive
    } else {
        // Stance authority at home, toes held: the drives must move the body's height.
        let mut stance = HybridState::flight(State {
            q: home,
            qd: SVector::zeros(),
        });
        let coords =
            Ground::<f64>::of::<L, NQ, NC, NU, NK>().coordinates(&L::contact_positions(&home, &p));
        for k in 0..NK / 2 {
            stance.modes.set(k, ContactMode::Stick);
            stance.anchors[2 * k] = coords[2 * k];
        }
        let authority = controller
            .height_authority(&stance)
            .map_err(|e| fail("the hopping controller", &e))?;
        if authority < 1e-9 {
            return Err(Error::usage(format!(
                "{}: the hopping controller does not apply: in stance the motors do not move the body's height; run it with --controller passive",
                L::NAME
            )));
        }
        Source::Hop(Box::new(controller))
    };
    if s.serve {
        return match source {
            Source::Hop(mut c) => serve::<L, NQ, NC, NU, NK>(&sim, &mut c),
            Source::Passive => Err(Error::usage(
                "--serve serves the hopping controller's torques; --controller passive has none",
            )),
        };
    }
    let steps = (s.duration / s.dt).round() as usize;
    // Refused before the run, as bad input, not after it with empty files.
    leg_models::simulate::check_record(
        steps,
        std::mem::size_of::<leg_models::simulate::hybrid::HybridSample<f64, NQ, NC, NU, NK>>(),
    )
    .map_err(|e| Error::usage(format!("`--duration` over `--dt`: {e}")))?;
    let mut source = WithProgress {
        source,
        progress: Progress::new(
            steps as u64,
            &format!("simulating {} on the ground", L::NAME),
        ),
        dt: s.dt,
    };
    let (record, stopped) = match sim.run(start, steps, &mut source) {
        Ok(r) => (r, None),
        Err(stop) => {
            let why = (stop.t, stop.cause.to_string());
            (stop.record, Some(why))
        }
    };
    let WithProgress {
        source, progress, ..
    } = source;
    drop(progress);
    let samples = &record.samples;
    let events = &record.events;

    // Apexes: the height's rate crossing zero in flight.
    let in_flight = |x: &HybridSample<f64, NQ, NC, NU, NK>| {
        (0..NK / 2).all(|k| !x.state.modes.get(k).on_ground())
    };
    // Apexes (time, height, the forward coordinate if any): the height's rate crossing
    // zero in flight.
    let forward =
        speed.and_then(|v| forward_joint::<L, f64, NQ, NC, NU, NK>(&p, &home).map(|j| (j, v)));
    let apexes: Vec<(f64, f64, f64)> = samples
        .windows(2)
        .filter(|w| {
            in_flight(&w[0])
                && in_flight(&w[1])
                && w[0].state.state.qd[h] > 0.0
                && w[1].state.state.qd[h] <= 0.0
        })
        .map(|w| {
            let (a, b) = (&w[0].state.state, &w[1].state.state);
            (
                w[0].t,
                a.q[h].max(b.q[h]),
                forward.map_or(0.0, |(j, _)| a.q[j]),
            )
        })
        .collect();
    let settled: Vec<f64> = apexes.iter().skip(5).map(|a| a.1 - apex).collect();
    // Forward speed per hop: the body's advance from one apex to the next over the time.
    let apex_x: Vec<(f64, f64)> = match forward {
        Some(_) => apexes.iter().map(|a| (a.0, a.2)).collect(),
        None => Vec::new(),
    };
    let hop_speeds: Vec<f64> = apex_x
        .windows(2)
        .map(|w| (w[1].1 - w[0].1) / (w[1].0 - w[0].0))
        .collect();
    let speed_errors: Vec<f64> = match forward {
        Some((_, v)) => hop_speeds.iter().skip(5).map(|s| s - v).collect(),
        None => Vec::new(),
    };
    let count = |k: EventKind| events.iter().filter(|e| e.kind == k).count();
    // Whether the contact of `e` lifts off within `within` seconds after it.
    let lifts_off_within = |e: &leg_models::simulate::hybrid::Event<f64>, within: f64| {
        events.iter().any(|l| {
            l.kind == EventKind::Liftoff
                && l.contact == e.contact
                && l.t >= e.t
                && l.t - e.t < within
        })
    };
    // A slip in the last millisecond before the same contact lifts off: the normal force
    // is vanishing, so any tangential force, however small, leaves the cone.
    let slips_at_liftoff = events
        .iter()
        .filter(|e| e.kind == EventKind::Slip && lifts_off_within(e, 1e-3))
        .count();
    // A rebound: the contact leaves the ground within 10 ms of touching down (a light
    // leg whose springs were relaxed in flight bounces off before it presses).
    let rebounds = events
        .iter()
        .filter(|e| e.kind == EventKind::Touchdown && lifts_off_within(e, 1e-2))
        .count();
    // Slips in stance after the fifth apex, other than those as a liftoff's normal force
    // vanishes.
    let settled_from = apexes.get(5).map(|a| a.0);
    let slips_after_five = settled_from.map(|t0| {
        events
            .iter()
            .filter(|e| e.kind == EventKind::Slip && e.t > t0 && !lifts_off_within(e, 1e-3))
            .count()
    });
    let energy_lost: f64 = events.iter().map(|e| e.energy_lost).sum();
    let (saturations, passive) = match &source {
        Source::Hop(c) => (c.saturations.to_vec(), false),
        Source::Passive => (vec![0; NU], true),
    };
    let out = s.out_dir(L::NAME);
    let summary = json!({
        "model": L::NAME,
        "controller": if passive { "passive" } else { "hop" },
        "height_joint": L::JOINT_NAMES[h],
        "apex_command_m": if passive { json!(null) } else { json!(apex) },
        "settings": {
            "duration_s": s.duration,
            "dt_s": s.dt,
            "integrator": "RK4 in the contact modes, events located by root finding, plastic impacts, projection onto every active constraint",
            "torque_update": "once per step and after each event",
            "torque_limit_nm": s.torque_limit,
            "friction": sim.options.friction.iter().step_by(2).copied().collect::<Vec<_>>(),
        },
        "hops": if passive { json!(null) } else { json!(apexes.len()) },
        "apex_heights_m": if passive { json!(null) } else { json!(apexes.iter().map(|a| a.1).collect::<Vec<_>>()) },
        "apex_error_after_five_hops_m": if settled.is_empty() || passive { json!(null) } else { json!({
            "max": max(settled.iter().map(|e| e.abs())),
            "rms": (settled.iter().map(|e| e * e).sum::<f64>() / settled.len() as f64).sqrt(),
        }) },
        "speed_command_m_s": match forward { Some((_, v)) if !passive => json!(v), _ => json!(null) },
        "hop_speeds_m_s": if forward.is_some() && !passive { json!(hop_speeds) } else { json!(null) },
        "speed_error_after_five_hops_m_s": match forward {
            Some((_, v)) if !passive && !speed_errors.is_empty() => json!({
                "max": max(speed_errors.iter().map(|e| e.abs())),
                "max_relative": if v != 0.0 { json!(max(speed_errors.iter().map(|e| (e / v).abs()))) } else { json!(null) },
            }),
            _ => json!(null),
        },
        "events": {
            "touchdowns": count(EventKind::Touchdown),
            "liftoffs": count(EventKind::Liftoff),
            "slips": count(EventKind::Slip),
            "slips_within_1_ms_of_liftoff": slips_at_liftoff,
            "slips_in_stance_after_five_hops": slips_after_five,
            "rebounds_within_10_ms": rebounds,
            "sticks": count(EventKind::Stick),
        },
        "impact_energy_lost_j": energy_lost,
        "peak_torque_nm": max(samples.iter().map(|x| x.u.amax())),
        "saturations_per_motor": saturations,
        "max_closure_residual_m": max(samples.iter().map(|x| x.closure_residual)),
        "max_contact_residual_m": max(samples.iter().map(|x| x.contact_residual)),
        "stopped": stopped.as_ref().map(|(t, why)| json!({"t": t, "cause": why})),
    });

    // trajectory.csv and events.csv
    let mut csv = crate::sim::state_columns::<L, NQ, NC, NU, 2, NC>();
    for c in L::CONTACT_NAMES {
        let _ = write!(csv, ",mode_{c},lambda_t_{c},lambda_n_{c}");
    }
    csv.push_str(",energy,closure_residual,contact_residual\n");
    for (k, x) in samples.iter().enumerate() {
        if !crate::sim::settings::written(k, samples.len(), s.every) {
            continue;
        }
        let mut row = format!("{}", x.t);
        for v in x
            .state
            .state
            .q
            .iter()
            .chain(x.state.state.qd.iter())
            .chain(x.u.iter())
        {
            let _ = write!(row, ",{v}");
        }
        for k in 0..NK / 2 {
            let mode = match x.state.modes.get(k) {
                ContactMode::Flight => "flight",
                ContactMode::Stick => "stick",
                ContactMode::Slide { .. } => "slide",
            };
            let _ = write!(
                row,
                ",{mode},{},{}",
                x.contact_forces[2 * k],
                x.contact_forces[2 * k + 1]
            );
        }
        let _ = writeln!(
            row,
            ",{},{},{}",
            x.energy, x.closure_residual, x.contact_residual
        );
        csv.push_str(&row);
    }
    let events_csv = crate::sim::ground::events_csv(events, L::CONTACT_NAMES);

    // report.html: the leg on the ground, heights, forces and the cone, energy.
    let members = body_points(L::NAME, NQ);
    let frame_every = ((0.01 / s.dt).round() as usize).max(1);
    let frames: Vec<report::Frame> = samples
        .iter()
        .step_by(frame_every)
        .map(|x| frame_at::<L, NQ, NC, NU, 2, NC>(&p, &members, x.t, &x.state.state.q, None))
        .collect();
    let t: Vec<f64> = samples.iter().map(|x| x.t).collect();
    // Stance phases (any contact on the ground), shaded in every plot over time.
    let stance = crate::sim::ground::stance_bands(samples.iter().map(|x| (x.t, x.state)));
    let mut plots = vec![Series::new(
        "Body height",
        &t,
        vec![
            (
                "height".into(),
                samples.iter().map(|x| x.state.state.q[h]).collect(),
            ),
            (
                "apex command".into(),
                samples.iter().map(|_| apex).collect(),
            ),
        ],
    )
    .axis("body height", "m")
    .caption(&format!(
        "The body's height (joint `{}`) and the commanded apex height.",
        L::JOINT_NAMES[h]
    ))];
    for (k, c) in L::CONTACT_NAMES.iter().enumerate() {
        let mu = sim.options.friction[2 * k];
        plots.push(Series::new(
            &format!("Ground force on `{c}`"),
            &t,
            vec![
                (
                    "λ_n".into(),
                    samples
                        .iter()
                        .map(|x| x.contact_forces[2 * k + 1])
                        .collect(),
                ),
                (
                    "λ_t".into(),
                    samples.iter().map(|x| x.contact_forces[2 * k]).collect(),
                ),
                (
                    "μ λ_n".into(),
                    samples
                        .iter()
                        .map(|x| mu * x.contact_forces[2 * k + 1])
                        .collect(),
                ),
                (
                    "−μ λ_n".into(),
                    samples
                        .iter()
                        .map(|x| -mu * x.contact_forces[2 * k + 1])
                        .collect(),
                ),
            ],
        )
        .axis("force", "N")
        .caption(&format!("The normal force λ_n and the tangential force λ_t, inside the friction cone ±μ λ_n (μ = {mu}) while the foot sticks.")));
        plots.push(
            Series::new(
                &format!("Contact `{c}`: on the ground (1) or in flight (0)"),
                &t,
                vec![(
                    "stance".into(),
                    samples
                        .iter()
                        .map(|x| {
                            if x.state.modes.get(k).on_ground() {
                                1.0
                            } else {
                                0.0
                            }
                        })
                        .collect(),
                )],
            )
            .axis("contact", ""),
        );
    }
    plots.push(crate::sim::ground::energy_plot(
        samples,
        events,
        &L::ACTUATED,
    ));
    plots.push(crate::sim::torque_plot(
        &t,
        &crate::sim::motor_names::<L, NQ, NC, NU>(),
        samples.iter().map(|x| x.u),
    ));
    plots.push(crate::sim::ground::residual_plot(
        &t,
        samples
            .iter()
            .map(|x| (x.closure_residual, x.contact_residual)),
    ));
    let plots: Vec<Series> = plots.into_iter().map(|p| p.shaded(&stance)).collect();
    let ground = Ground::<f64>::of::<L, NQ, NC, NU, NK>();
    let html = report::html(&Report {
        title: format!(
            "{} — {}",
            L::NAME,
            if passive { "passive drop" } else { "hopping" }
        ),
        summary: &summary,
        plots: &plots,
        frames: &frames,
        ground: Some(vec![ground.normal[0], ground.normal[1], ground.offset]),
        rods: L::DISTANCE_CLOSURES,
        robot: false,
    })
    .map_err(Error::Failed)?;
    let files = [
        ("trajectory.csv".into(), csv),
        ("events.csv".into(), events_csv),
        ("summary.json".into(), format!("{summary:#}\n")),
        ("report.html".into(), html),
    ];
    write_all(&out, &files).map_err(Error::Failed)?;
    println!(
        "{} on the ground, {} ({} s at dt = {} s): wrote {}/{{trajectory.csv, events.csv, summary.json, report.html}}",
        L::NAME,
        if passive { "passive" } else { "hopping" },
        s.duration,
        s.dt,
        out.display()
    );
    if let (Some((_, v)), false) = (forward, passive) {
        println!(
            "  forward speed command {v} m/s; after five hops speed error max {}",
            if speed_errors.is_empty() {
                "— (fewer than seven hops)".to_string()
            } else {
                format!("{:.3} m/s", max(speed_errors.iter().map(|e| e.abs())))
            }
        );
    }
    if !passive {
        println!(
            "  {} hops, apex command {apex} m; after five hops apex error max {}",
            apexes.len(),
            if settled.is_empty() {
                "— (fewer than six hops)".to_string()
            } else {
                format!("{:.2e} m", max(settled.iter().map(|e| e.abs())))
            }
        );
    }
    println!(
        "  {} touchdowns ({:.4} J lost in impacts; {rebounds} rebounds within 10 ms), {} liftoffs, {} slips ({slips_at_liftoff} within 1 ms of a liftoff, as the normal force vanishes; {} in stance after five hops); peak torque {:.3} N m, saturations {:?}; max residual closures {:.1e} m, contacts {:.1e} m",
        count(EventKind::Touchdown),
        energy_lost,
        count(EventKind::Liftoff),
        count(EventKind::Slip),
        slips_after_five.map_or("—".to_string(), |n| n.to_string()),
        max(samples.iter().map(|x| x.u.amax())),
        saturations,
        max(samples.iter().map(|x| x.closure_residual)),
        max(samples.iter().map(|x| x.contact_residual)),
    );
    match stopped {
        None => Ok(()),
        Some((t, why)) => Err(Error::Failed(format!(
            "the simulation stopped at t = {t} s: {why} (the output holds everything until then)"
        ))),
    }
}

/// The hopping controller as a torque server (`--serve`): each line on stdin is a state,
/// `t`, the NQ positions, the NQ rates, then per contact `on_ground` (0 or 1) and its
/// anchor (the tangential ground coordinate where it touched down); each answer on stdout
/// is the NU torques, or `error: …`. Another simulator (the MuJoCo cross-check) closes
/// the loop through it. The state is first projected onto the closures and the contacts
/// on the ground, at their anchors (`HybridSimulator::project`): another simulator's
/// soft contact lets a flat foot rock and sink a little, which the exact stance's
/// repeated rows of two contacts on one foot would refuse.
fn serve<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    sim: &HybridSimulator<L, f64, NQ, NC, NU, NK>,
    controller: &mut HopController<L, f64, NQ, NC, NU, NK>,
) -> Result<(), Error>
where
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    use leg_models::simulate::hybrid::HybridTorqueSource;
    crate::sim::serve_lines::<NU>(1 + 2 * NQ + NK, |v| {
        let mut hs = HybridState::flight(State {
            q: SVector::from_column_slice(&v[1..1 + NQ]),
            qd: SVector::from_column_slice(&v[1 + NQ..1 + 2 * NQ]),
        });
        for k in 0..NK / 2 {
            if v[1 + 2 * NQ + 2 * k] != 0.0 {
                hs.modes.set(k, ContactMode::Stick);
                hs.anchors[2 * k] = v[2 + 2 * NQ + 2 * k];
            }
        }
        let mut projected = hs;
        if sim.project(&mut projected).is_ok() {
            hs = projected;
        }
        controller.torque(v[0], &hs).map_err(|e| e.to_string())
    })
}
