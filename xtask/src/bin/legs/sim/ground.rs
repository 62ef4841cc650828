//! `cargo xtask sim MODEL` for a leg with contacts that the hopping controller does not
//! drive (a spatial leg, or a planar one whose body has no height joint): the swing-leg
//! controllers of `drive.rs` with the ground live in the hybrid simulator (contact modes,
//! the exact Coulomb cone, located events, impacts). The step cycle's lower half presses
//! the foot onto the ground where the ground is within its reach. Writes
//! `trajectory.csv`, `events.csv`, `summary.json` and `report.html` with the ground
//! drawn. Also the outputs `hop.rs` shares: `events.csv`, the stance bands, the energy
//! balance.

use std::fmt::Write as _;

use leg_models::dynamics::contact::{ContactMode, Ground};
use leg_models::nalgebra::SVector;
use leg_models::simulate::hybrid::{Event, EventKind, HybridSample, HybridSimulator, HybridState};
use leg_models::simulate::TorqueSource;
use leg_models::{ContactModel, LegModel};
use serde_json::json;
use xtask::cli::progress::Progress;
use xtask::cli::{check_targets, write_all, Error};

use crate::report::{self, Report, Series};
use crate::sim::drive::Drive;
use crate::sim::settings::written;
use crate::sim::{
    body_points, closure_force_columns, frame_at, max, state_columns, Settings, WithProgress,
};

/// Whether no contact of `x` is on the ground.
fn in_flight<const NQ: usize, const NK: usize, const ND: usize>(
    x: &HybridState<f64, NQ, NK, ND>,
) -> bool {
    (0..NK / ND).all(|k| !x.modes.get(k).on_ground())
}

/// The intervals `(from, to)` with some contact on the ground, shaded in every plot.
pub(crate) fn stance_bands<const NQ: usize, const NK: usize, const ND: usize>(
    samples: impl Iterator<Item = (f64, HybridState<f64, NQ, NK, ND>)>,
) -> Vec<(f64, f64)> {
    let mut stance = Vec::new();
    let mut since: Option<f64> = None;
    let mut last = None;
    for (t, x) in samples {
        match (in_flight(&x), since) {
            (false, None) => since = Some(t),
            (true, Some(t0)) => {
                stance.push((t0, t));
                since = None;
            }
            _ => {}
        }
        last = Some(t);
    }
    if let (Some(t0), Some(t)) = (since, last) {
        stance.push((t0, t));
    }
    stance
}

/// `events.csv`: one row per event; the impulse is `(Λ_t, Λ_n)`, `Λ_t` signed along the
/// ground's tangent on a planar leg and the tangential impulse's magnitude on a spatial one.
pub(crate) fn events_csv(events: &[Event<f64>], names: &[&str]) -> String {
    let mut csv = String::from("t,kind,contact,impulse_t,impulse_n,energy_lost\n");
    for e in events {
        let _ = writeln!(
            csv,
            "{},{:?},{},{},{},{}",
            e.t, e.kind, names[e.contact], e.impulse[0], e.impulse[1], e.energy_lost
        );
    }
    csv
}

/// The energy plot of a run on the ground: `T + V`, with every impact's loss so far added
/// back, and with the motors' work subtracted too (the torques held over each step, the
/// motors at joints `actuated`).
pub(crate) fn energy_plot<
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    samples: &[HybridSample<f64, NQ, NC, NU, NK, ND>],
    events: &[Event<f64>],
    actuated: &[usize],
) -> Series {
    let t: Vec<f64> = samples.iter().map(|x| x.t).collect();
    let mut lost = 0.0;
    let mut next = 0;
    let with_losses: Vec<f64> = samples
        .iter()
        .map(|x| {
            while next < events.len() && events[next].t <= x.t {
                lost += events[next].energy_lost;
                next += 1;
            }
            x.energy + lost
        })
        .collect();
    // The motors' work: the torques are held over each step (and after each event), so
    // W = Σ u · Δθ over the samples is exact up to the events inside a step.
    let mut w = 0.0;
    let balance: Vec<f64> = samples
        .iter()
        .enumerate()
        .map(|(i, x)| {
            if i > 0 {
                let prev = &samples[i - 1];
                for (k, &a) in actuated.iter().enumerate() {
                    w += prev.u[k] * (x.state.state.q[a] - prev.state.state.q[a]);
                }
            }
            with_losses[i] - w
        })
        .collect();
    let spread = balance.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - balance.iter().copied().fold(f64::INFINITY, f64::min);
    Series::new(
        "Energy",
        &t,
        vec![
            ("T + V".into(), samples.iter().map(|x| x.energy).collect()),
            ("T + V + impact losses".into(), with_losses),
            ("T + V + losses − motor work".into(), balance),
        ],
    )
    .axis("energy", "J")
    .caption(&format!("The energy T + V (blue) falls at each touchdown by what the plastic impact dissipates and changes in stance because the motors do work W = Σ ∫ u θ̇ dt. The impacts' losses added back (red), only the motors' work remains; with that subtracted too (green) what is left moves by {} over the run: what neither the impacts nor the motors account for (joint damping, if the leg has any, and integration error).", crate::report::quantity(spread, "J")))
}

/// The ground as the report draws it: the normal's entries, then the offset.
pub(crate) fn drawn<const ND: usize>(ground: &Ground<f64, ND>) -> Vec<f64> {
    ground
        .normal
        .iter()
        .copied()
        .chain([ground.offset])
        .collect()
}

/// The report's log plot of the residuals after each step's projection: the closures'
/// largest gap and the held contacts' largest distance from their anchors, per sample.
pub(crate) fn residual_plot(
    t: &[f64],
    residuals: impl Iterator<Item = (f64, f64)> + Clone,
) -> Series {
    Series::log(
        "Residuals",
        t,
        vec![
            (
                "closures max |φ|".into(),
                residuals.clone().map(|r| r.0).collect(),
            ),
            ("held contacts".into(), residuals.map(|r| r.1).collect()),
        ],
    )
    .axis("residual", "m")
    .caption("The largest gap of the closure constraints and of the contacts held on the ground, after each step's projection: rounding error.")
}

/// The largest `|λ_t| / (μ λ_n)` over the contacts on the ground in `x`: at most 1 inside
/// the cone (equal to 1 while sliding).
fn cone_ratio<
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    x: &HybridSample<f64, NQ, NC, NU, NK, ND>,
    friction: &SVector<f64, NK>,
) -> f64 {
    max((0..NK / ND).filter_map(|k| {
        if !x.state.modes.get(k).on_ground() {
            return None;
        }
        let f = &x.contact_forces;
        let tangential = (0..ND - 1)
            .map(|i| f[ND * k + i] * f[ND * k + i])
            .sum::<f64>()
            .sqrt();
        let normal = f[ND * k + ND - 1];
        let mu = friction[ND * k];
        (normal > 0.0 && mu > 0.0).then(|| tangential / (mu * normal))
    }))
}

/// Runs leg `L` on its ground under the swing-leg controllers; `note` says why, where the
/// leg has contacts but the hopping controller does not apply to it.
pub fn run<
    L: ContactModel<NQ, NC, NU, NK, ND> + LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
    const NK: usize,
>(
    s: &Settings,
    note: Option<&str>,
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
    for (flag, given, what) in [
        (
            "--apex",
            s.apex.is_some(),
            "the hopping controller's apex height",
        ),
        (
            "--serve",
            s.serve,
            "serves the hopping controller's torques",
        ),
    ] {
        if given {
            return Err(Error::usage(format!(
                "{flag}: {what}; {} has no body that hops (it is driven on the ground by the swing-leg controllers)",
                L::NAME
            )));
        }
    }
    let p = <L as leg_models::LegDynamics<NQ, NC, NU>>::Params::<f64>::default();
    let fail =
        |what: &str, e: &dyn std::fmt::Display| Error::Failed(format!("{}: {what}: {e}", L::NAME));
    let (drive, source) = Drive::<L, NQ, NC, NU, ND, NP>::new(s, &p)?;
    let sim = HybridSimulator::<L, f64, NQ, NC, NU, NK, ND>::new(p, s.dt);
    let mut sim = sim;
    // As in the air: torques held over each step (and re-asked after each event); the
    // swing controllers answer a landing (the modes after it settle under their torques).
    sim.options.control = leg_models::simulate::ControlUpdate::PerStep;
    sim.options.ask_after_impact = true;
    // A contact on the ground at the start holds it: the start is at rest there (the
    // simulator applies no impact at its start, and would drop the reference's rates
    // unsaid). Elsewhere it is on the reference, at its rates.
    let mut initial = drive.initial;
    let (gaps, _) = sim.contact_coordinates(&initial);
    let size = leg_models::assembly::leg_size::<L, f64, NQ, NC, NU>(&p, &initial.q);
    let touching = (0..NK / ND)
        .any(|k| gaps[ND * k + ND - 1] <= sim.options.tolerance.relative_residual * size);
    let at_rest = touching && initial.qd.amax() > 0.0;
    if at_rest {
        initial.qd = SVector::zeros();
    }
    // The contacts' modes at the start are those under the controller's first torques
    // there. (Asked of the controller itself, so the saturation counts are the run's.)
    let mut source = source;
    let first = source
        .inner
        .torque(0.0, &initial)
        .map_err(|e| fail("the controller at the start", &e))?
        .zip_map(&source.limits, |u, l| u.clamp(-l, l));
    let start = sim
        .start(initial, &first)
        .map_err(|e| fail("the start (on the controller's reference)", &e))?;
    let start_note = if at_rest {
        "at rest on the reference's first pose: a contact touches the ground there"
    } else {
        "on the reference (a foot task at rest, a joint task at its rates)"
    };
    let steps = (s.duration / s.dt).round() as usize;
    // Refused before the run, as bad input, not after it with empty files.
    leg_models::simulate::check_record(
        steps,
        std::mem::size_of::<HybridSample<f64, NQ, NC, NU, NK, ND>>(),
    )
    .map_err(|e| Error::usage(format!("`--duration` over `--dt`: {e}")))?;
    let mut source = WithProgress {
        inner: source,
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
        inner: source,
        progress,
        ..
    } = source;
    drop(progress);
    let samples = &record.samples;
    let events = &record.events;
    let contacts = NK / ND;
    let friction = sim.options.friction;

    let t: Vec<f64> = samples.iter().map(|x| x.t).collect();
    let errors: Vec<f64> = samples
        .iter()
        .map(|x| drive.error(&p, x.t, &x.state.state.q))
        .collect();
    let count = |k: EventKind| events.iter().filter(|e| e.kind == k).count();
    // A landing whose impulse leaves the cone slides from the impact on: no Slip event
    // marks it, so it is counted here (the contact's mode at the first sample after it).
    let landed_sliding = events
        .iter()
        .filter(|e| e.kind == EventKind::Touchdown)
        .filter(|e| {
            samples
                .iter()
                .find(|x| x.t > e.t)
                .is_some_and(|x| matches!(x.state.modes.get(e.contact), ContactMode::Slide { .. }))
        })
        .count();
    // (From +0: a sum of no impacts is 0, not −0.)
    let energy_lost = events.iter().fold(0.0, |a, e| a + e.energy_lost);
    // Over the samples whose modes hold: at a step's start the new torques may push a
    // sticking contact out of the cone, and it slips at that instant (an event within
    // 1e-9 s of the sample); that sample's forces are the stick's, before the switch.
    let switching = |t: f64| events.iter().any(|e| (e.t - t).abs() < 1e-9);
    let cone = max(samples
        .iter()
        .filter(|x| !switching(x.t))
        .map(|x| cone_ratio(x, &friction)));
    let summary = json!({
        "model": L::NAME,
        "controller": drive.kind.name(),
        "controller_choice": drive.choice,
        "why_not_hopping": note,
        "start": start_note,
        "structure": drive.structure_summary(),
        "trajectory": if drive.tracked() { json!(drive.trajectory.name()) } else { json!(null) },
        "settings": {
            "duration_s": s.duration,
            "dt_s": s.dt,
            "integrator": "RK4 in the contact modes, events located by root finding, plastic impacts, projection onto every active constraint",
            "torque_update": "once per step and after each event (zero-order hold)",
            "gains": drive.gains,
            "torque_limit_nm": s.torque_limit,
            "spin_speed_rad_s": drive.spin_speed(s),
            "friction": friction.iter().step_by(ND).copied().collect::<Vec<_>>(),
            "ground": {
                "normal": sim.options.ground.normal.iter().copied().collect::<Vec<_>>(),
                "offset_m": sim.options.ground.offset,
            },
        },
        "samples": samples.len(),
        "tracking_error": drive.tracking_summary(&t, &errors),
        "events": {
            "touchdowns": count(EventKind::Touchdown),
            "touchdowns_sliding": landed_sliding,
            "liftoffs": count(EventKind::Liftoff),
            "slips": count(EventKind::Slip),
            "sticks": count(EventKind::Stick),
        },
        "impact_energy_lost_j": energy_lost,
        "max_friction_cone_ratio": cone,
        "max_friction_cone_ratio_means": "the largest |λ_t| / (μ λ_n) over the contacts on the ground, at the samples not at a change of mode: at most 1 (inside the cone), 1 while sliding",
        "peak_torque_nm": max(samples.iter().map(|x| x.u.amax())),
        "saturations": source.saturations.iter().sum::<usize>(),
        "saturations_per_motor": source.saturations.to_vec(),
        "max_closure_residual_m": max(samples.iter().map(|x| x.closure_residual)),
        "max_contact_residual_m": max(samples.iter().map(|x| x.contact_residual)),
        "stopped": stopped.as_ref().map(|(t, why)| json!({"t": t, "cause": why})),
    });

    // trajectory.csv: the state, torques, closure forces, each contact's mode and ground
    // force (in the ground's frame: the tangents, then the normal), then the foot and its
    // tracking.
    let tangents: &[&str] = if ND == 2 { &["t"] } else { &["t1", "t2"] };
    let mut csv = state_columns::<L, NQ, NC, NU, ND, NP>();
    closure_force_columns::<L, NQ, NC, NU, ND, NP>(&mut csv);
    for c in L::CONTACT_NAMES {
        let _ = write!(csv, ",mode_{c}");
        for tangent in tangents {
            let _ = write!(csv, ",lambda_{tangent}_{c}");
        }
        let _ = write!(csv, ",lambda_n_{c}");
    }
    csv.push_str(",energy,closure_residual,contact_residual");
    drive.csv_header(&mut csv);
    csv.push('\n');
    for (k, x) in samples.iter().enumerate() {
        if !written(k, samples.len(), s.every) {
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
            .chain(x.closure_forces.iter())
        {
            let _ = write!(row, ",{v}");
        }
        for c in 0..contacts {
            let mode = match x.state.modes.get(c) {
                ContactMode::Flight => "flight",
                ContactMode::Stick => "stick",
                ContactMode::Slide { .. } => "slide",
            };
            let _ = write!(row, ",{mode}");
            for i in 0..ND {
                let _ = write!(row, ",{}", x.contact_forces[ND * c + i]);
            }
        }
        let _ = write!(
            row,
            ",{},{},{}",
            x.energy, x.closure_residual, x.contact_residual
        );
        drive.csv_row(&p, x.t, &x.state.state.q, &mut row);
        row.push('\n');
        csv.push_str(&row);
    }

    // report.html: the leg over its ground, the tracking, the forces in the cone, energy.
    let members = body_points(L::NAME, NQ);
    let frame_every = ((0.01 / s.dt).round() as usize).max(1);
    let frames: Vec<report::Frame> = samples
        .iter()
        .step_by(frame_every)
        .map(|x| {
            frame_at::<L, NQ, NC, NU, ND, NP>(
                &p,
                &members,
                x.t,
                &x.state.state.q,
                drive.drawn_reference(x.t),
            )
        })
        .collect();
    let mut plots: Vec<Series> = drive.tracking_plot(&t, &errors).into_iter().collect();
    for (c, name) in L::CONTACT_NAMES.iter().enumerate() {
        let mu = friction[ND * c];
        let normal: Vec<f64> = samples
            .iter()
            .map(|x| x.contact_forces[ND * c + ND - 1])
            .collect();
        let tangential: Vec<f64> = samples
            .iter()
            .map(|x| {
                (0..ND - 1)
                    .map(|i| x.contact_forces[ND * c + i].powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        plots.push(
            Series::new(
                &format!("Ground force on `{name}`"),
                &t,
                vec![
                    ("λ_n".into(), normal.to_vec()),
                    ("|λ_t|".into(), tangential),
                    ("μ λ_n".into(), normal.iter().map(|n| mu * n).collect()),
                ],
            )
            .axis("force", "N")
            .caption(&format!(
                "The normal force λ_n and the tangential force's magnitude |λ_t|, at most μ λ_n (μ = {mu}: the friction cone) while the contact sticks and equal to it while it slides."
            )),
        );
        plots.push(
            Series::new(
                &format!("Contact `{name}`: on the ground (1) or in flight (0)"),
                &t,
                vec![(
                    "stance".into(),
                    samples
                        .iter()
                        .map(|x| f64::from(u8::from(x.state.modes.get(c).on_ground())))
                        .collect(),
                )],
            )
            .axis("contact", ""),
        );
    }
    plots.push(energy_plot(samples, events, &L::ACTUATED));
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
    let stance = stance_bands(samples.iter().map(|x| (x.t, x.state)));
    let plots: Vec<Series> = plots.into_iter().map(|p| p.shaded(&stance)).collect();
    let ground = Ground::<f64, ND>::of::<L, NQ, NC, NU, NK>();
    let html = report::html(&Report {
        title: format!("{} — {}, on the ground", L::NAME, drive.title()),
        summary: &summary,
        plots: &plots,
        frames: &frames,
        ground: Some(drawn(&ground)),
        rods: L::DISTANCE_CLOSURES,
        robot: false,
    })
    .map_err(Error::Failed)?;
    let out = s.out_dir(L::NAME);
    let files = [
        ("trajectory.csv".into(), csv),
        ("events.csv".into(), events_csv(events, L::CONTACT_NAMES)),
        ("summary.json".into(), format!("{summary:#}\n")),
        ("report.html".into(), html),
    ];
    write_all(&out, &files).map_err(Error::Failed)?;
    if let Some(note) = note {
        println!("{}: {note}", L::NAME);
    }
    println!(
        "{} on the ground with {} ({}; {} s at dt = {} s): wrote {}/{{trajectory.csv, events.csv, summary.json, report.html}}",
        L::NAME,
        drive.kind.name(),
        drive.choice,
        s.duration,
        s.dt,
        out.display()
    );
    if drive.tracked() {
        println!(
            "  tracking error: max {:.3e} {unit}, steady-state max {:.3e} {unit}",
            max(errors.iter().copied()),
            max(drive.steady(&t, &errors).iter().copied()),
            unit = drive.unit(),
        );
    }
    println!(
        "  {} touchdowns ({landed_sliding} sliding from the impact on; {:.4} J lost in impacts), {} liftoffs, {} slips, {} sticks; ground forces at most {:.3} of the friction cone's bound; peak torque {:.4} N m, {} saturations; max residual closures {:.1e} m, contacts {:.1e} m",
        count(EventKind::Touchdown),
        energy_lost,
        count(EventKind::Liftoff),
        count(EventKind::Slip),
        count(EventKind::Stick),
        cone,
        max(samples.iter().map(|x| x.u.amax())),
        source.saturations.iter().sum::<usize>(),
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
