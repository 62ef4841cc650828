//! `sim` of a floating robot: it stands on its feet under the whole-body balance QP
//! (`leg_models::robot::balance`) and is pushed on its body. With `--feet held` (the
//! default) every contact is held, and the run stops, keeping what it computed, where a
//! foot's force would leave its friction cone or pull on the ground (the stance no longer
//! holds). With `--feet free` every foot may lift, slip and land
//! (`leg_models::robot::time_stepping`: each step's contact modes from one
//! complementarity solve), and the run goes on through them. Writes
//! `trajectory.csv`, `summary.json` and `report.html` (the robot drawn in 3-D in the
//! world, the body's motion, the feet's forces against their cones, the torques and the
//! residuals).

use std::fmt::Write as _;

use leg_models::dynamics::contact::{ContactMode, Ground, Modes};
use leg_models::nalgebra::{SVector, UnitQuaternion, Vector3};
use leg_models::robot::balance::{
    cone_reading, judged_forces, BalanceController, BalanceGains, BalanceTarget, ConeReading,
};
use leg_models::robot::standing::{on_its_feet, standing_start, StandingStart};
use leg_models::robot::time_stepping::{contact_step, FootContacts};
use leg_models::robot::{self, RobotState};
use leg_models::{ContactModel, LegModel, ShownNumber};
use serde_json::json;
use xtask::cli::progress::Progress;
use xtask::cli::{check_targets, write_all, Error};

use super::{body_points, frame_at, max, Settings};
use crate::report::{self, quantity, Report, Series};

/// One step's record: the state at its start, the torques and push held over it, the
/// ground forces (world; held feet: a rigid foot's split the deepest in its cones; free
/// feet: the step's mean forces), each contact's mode over the step, the largest closure
/// residual and contact height at its start.
struct Sample<const NQ: usize, const NU: usize, const NK: usize> {
    t: f64,
    state: RobotState<f64, NQ>,
    u: SVector<f64, NU>,
    push: Vector3<f64>,
    forces: SVector<f64, NK>,
    modes: Modes<NK, 3>,
    closure_gap: f64,
    contact_gap: f64,
}

/// A contact mode as `trajectory.csv` and `summary.json` name it.
fn mode_name(m: ContactMode) -> &'static str {
    match m {
        ContactMode::Flight => "flight",
        ContactMode::Stick => "stick",
        ContactMode::Slide { .. } => "slide",
    }
}

/// The flags of the swing-leg and hopping runs, which mean nothing to a standing robot,
/// and a push that would not act as asked.
fn check_flags(s: &Settings, name: &str) -> Result<(), Error> {
    let given = [
        (s.controller.is_some(), "--controller"),
        (s.trajectory.is_some(), "--trajectory"),
        (s.speed.is_some(), "--speed"),
        (s.kp.is_some(), "--kp"),
        (s.apex.is_some(), "--apex"),
    ];
    match given.iter().find(|(g, _)| *g) {
        Some((_, flag)) => Err(Error::usage(format!(
            "{flag} is for a leg; `{name}` is a floating robot, which stands under the balance QP (its flags: --feet, --push, --push-at, --push-for, --torque-limit, --duration, --dt, --every, --out)"
        ))),
        None => Ok(()),
    }?;
    // A push that would not happen, or not for as long as asked, is refused, not
    // reported as given.
    let none = s.push == Some([0.0; 3]);
    if !none && s.push_at >= s.duration {
        return Err(Error::usage(format!(
                "--push-at {} s is not before the run's end (--duration {} s): the push would never act (--push 0,0,0 for none)",
                ShownNumber(s.push_at),
                ShownNumber(s.duration)
            )));
    }
    if !none && s.push_for < s.dt {
        return Err(Error::usage(format!(
            "--push-for {} s is shorter than one step (--dt {} s): the push acts for whole steps",
            ShownNumber(s.push_for),
            ShownNumber(s.dt)
        )));
    }
    Ok(())
}

pub fn run<
    L: ContactModel<NQ, NC, NU, NK, 3> + LegModel<NQ, NC, NU, 3, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NP: usize,
    const NK: usize,
>(
    s: &Settings,
) -> Result<(), Error> {
    check_flags(s, L::NAME)?;
    let out = s.out_dir(L::NAME);
    check_targets(&out, &["trajectory.csv", "summary.json", "report.html"])
        .map_err(Error::Failed)?;
    let p = <L as leg_models::LegDynamics<NQ, NC, NU>>::Params::<f64>::default();
    let (start, weight) = stand::<L, NQ, NC, NU, NK>(&p)?;
    let (ground, modes, mu) = (start.ground, start.modes, start.mu);
    if s.serve {
        return serve::<L, NQ, NC, NU, NK>(&p, &start, s);
    }
    // Sideways: along the ground, square to the body's x.
    let side = ground
        .normal
        .cross(&start.state.orientation.transform_vector(&Vector3::x()))
        .normalize();
    let push = match s.push {
        Some(f) => Vector3::from(f),
        None => side * (0.05 * weight),
    };
    let torque_limit = s.torque_limit.map(SVector::<f64, NU>::repeat);
    let mut controller = BalanceController::<NQ, NC, NU, NK>::new(
        BalanceTarget::holding(&start.state),
        BalanceGains::default(),
        torque_limit,
    );

    let steps = (s.duration / s.dt).round() as usize;
    let mut progress = Progress::new(steps as u64, &format!("simulating {}", L::NAME));
    let mut samples: Vec<Sample<NQ, NU, NK>> = Vec::with_capacity(steps);
    let mut state = start.state;
    let mut stopped: Option<(f64, String)> = None;
    let mut iterations = 0u64;
    // Free feet: the contact problem, allocated once.
    let mut free = s
        .free_feet
        .then(FootContacts::<f64>::of::<L, NQ, NC, NU, NK>);
    // The push in whole steps, as the run counts them (`t` is `i dt`).
    let pushed = {
        let first = (s.push_at / s.dt).round() as usize;
        first..first + (s.push_for / s.dt).round() as usize
    };
    for i in 0..steps {
        let t = i as f64 * s.dt;
        progress.set(i as u64);
        let before = state;
        // The QP plans every foot held: with free feet it sees the rates put back on the
        // held rows (a sliding or turning rigid foot's toe and heel rows would
        // contradict each other in its model).
        let mut seen = state;
        if s.free_feet {
            if let Err(e) =
                robot::project_held_rates::<L, f64, NQ, NC, NU, NK>(&p, &mut seen, &modes, &ground)
            {
                stopped = Some((t, format!("the balance QP's view of the state: {e}")));
                break;
            }
        }
        let (u, qp_iterations) = match controller.command::<L>(&p, &seen, &modes, &ground, &mu) {
            Ok(c) => (c.torques, c.iterations),
            Err(e) => {
                stopped = Some((t, format!("the balance QP has no command: {e}")));
                break;
            }
        };
        let force = if pushed.contains(&i) {
            push
        } else {
            Vector3::zeros()
        };
        if let Some(problem) = free.as_mut() {
            let step = match contact_step::<L, f64, NQ, NC, NU, NK>(
                problem, &p, &mut state, &u, &force, &ground, &mu, s.dt,
            ) {
                Ok(x) => x,
                Err(e) => {
                    stopped = Some((t, e.to_string()));
                    break;
                }
            };
            samples.push(Sample {
                t,
                state: before,
                u,
                push: force,
                forces: step.world_forces,
                modes: step.modes,
                closure_gap: L::closure_residual(&before.q, &p).amax(),
                contact_gap: contact_heights::<L, NQ, NC, NU, NK>(&p, &before, &ground),
            });
            iterations += u64::from(qp_iterations);
            continue;
        }
        let stance = match robot::pushed_stance_step::<L, f64, NQ, NC, NU, NK>(
            &p, &mut state, &u, &force, &modes, &ground, &mu, s.dt,
        ) {
            Ok(x) => x,
            Err(e) => {
                stopped = Some((t, e.to_string()));
                break;
            }
        };
        let forces =
            match judged_forces::<L, NQ, NC, NU, NK>(&p, &before, &stance, &modes, &ground, &mu) {
                Ok(x) => x,
                Err(e) => {
                    stopped = Some((t, format!("judging the ground forces: {e}")));
                    break;
                }
            };
        samples.push(Sample {
            t,
            state: before,
            u,
            push: force,
            forces,
            modes,
            closure_gap: L::closure_residual(&before.q, &p).amax(),
            contact_gap: contact_heights::<L, NQ, NC, NU, NK>(&p, &before, &ground),
        });
        iterations += u64::from(qp_iterations);
        // Held contacts are the model of this run: where a foot would lift or slip it no
        // longer holds, and the run ends there.
        if let Some(why) = (0..NK / 3).find_map(|k| {
            let c = cone_reading(&forces, &ground, &mu, k);
            if c.normal <= 0.0 {
                Some(format!("contact `{}` would lift off (its normal force {:.3} N): every contact is held in this run", L::CONTACT_NAMES[k], c.normal))
            } else if c.ratio > 1.0 {
                Some(format!("contact `{}` would slip (tangential {:.3} N over μ λ_n {:.3} N): every contact is held in this run", L::CONTACT_NAMES[k], c.tangential, c.tangential / c.ratio))
            } else {
                None
            }
        }) {
            stopped = Some((t, why));
            break;
        }
    }
    drop(progress);

    let end = samples.len() as f64 * s.dt;
    let offset = |x: &RobotState<f64, NQ>| {
        (
            (x.position - start.state.position).norm(),
            x.orientation.angle_to(&start.state.orientation),
        )
    };
    // Over every step's start and the state the run ended in.
    let visited = || samples.iter().map(|x| &x.state).chain([&state]);
    let excursion = max(visited().map(|x| offset(x).0));
    let turned = max(visited().map(|x| offset(x).1));
    let (end_offset, end_angle) = offset(&state);
    let readings: Vec<_> = samples
        .iter()
        .flat_map(|x| {
            // A foot off the ground has no force to read (free feet only).
            (0..NK / 3)
                .filter(|&k| x.modes.get(k).on_ground())
                .map(|k| cone_reading(&x.forces, &ground, &mu, k))
        })
        .collect();
    // A force that pulls has no finite cone ratio: the stop says so, these are over the
    // rest (null where there is none).
    let finite = |x: f64| x.is_finite().then_some(x);
    let worst_cone = readings
        .iter()
        .filter_map(|c| finite(c.ratio))
        .reduce(f64::max);
    let least_normal = readings.iter().map(|c| c.normal).reduce(f64::min);
    let closure_gap = max(samples.iter().map(|x| x.closure_gap));
    let contact_gap = max(samples.iter().map(|x| x.contact_gap));
    let recovered = stopped.is_none() && end_offset <= 1e-3 && end_angle <= 1e-3;
    // Each contact's steps off the ground and sliding, and when it first left or slid.
    let feet: Vec<_> = (0..NK / 3)
        .map(|k| {
            let when = |m: fn(ContactMode) -> bool| {
                samples.iter().find(|x| m(x.modes.get(k))).map(|x| x.t)
            };
            let count =
                |m: fn(ContactMode) -> bool| samples.iter().filter(|x| m(x.modes.get(k))).count();
            let flight = |m: ContactMode| m == ContactMode::Flight;
            let slide = |m: ContactMode| matches!(m, ContactMode::Slide { .. });
            json!({
                "contact": L::CONTACT_NAMES[k],
                "steps_in_flight": count(flight),
                "steps_sliding": count(slide),
                "first_liftoff_s": when(flight),
                "first_slip_s": when(slide),
            })
        })
        .collect();
    let (kind, integrator, recovered_means) = if s.free_feet {
        (
            "floating robot standing under the balance QP (leg_models::robot::balance, default gains; it plans every foot sticking), every foot free to lift, slip and land",
            "velocity-level time stepping (semi-implicit Euler), every contact's mode each step from one complementarity solve (Lemke), a 4-edge friction pyramid, the closures projected",
            "ran to the end, and the body within 1 mm and 1 mrad of where it stood",
        )
    } else {
        (
            "floating robot standing under the balance QP (leg_models::robot::balance, default gains), every contact held",
            "rk4",
            "ran to the end with every foot's force in its cone, and the body within 1 mm and 1 mrad of where it stood",
        )
    };
    let summary = json!({
        "model": L::NAME,
        "kind": kind,
        "weight_n": weight,
        "push": {
            "force_n": [push.x, push.y, push.z],
            "magnitude_n": push.norm(),
            "share_of_weight": push.norm() / weight,
            "default": s.push.is_none(),
            "at_s": s.push_at,
            "for_s": s.push_for,
            "steps": pushed.filter(|&i| i < samples.len()).count(),
        },
        "duration_s": s.duration,
        "simulated_s": end,
        "dt_s": s.dt,
        "integrator": integrator,
        "feet_free": s.free_feet,
        "feet": feet,
        "torque_limit_nm": s.torque_limit,
        "stopped": stopped.as_ref().map(|(t, why)| json!({"t_s": t, "why": why})),
        "recovered": recovered,
        "recovered_means": recovered_means,
        "body": {
            "largest_excursion_m": excursion,
            "largest_turn_rad": turned,
            "end_offset_m": end_offset,
            "end_angle_rad": end_angle,
        },
        "ground": {
            "normal": [ground.normal.x, ground.normal.y, ground.normal.z],
            "offset_m": ground.offset,
            "largest_cone_ratio": worst_cone,
            "least_normal_force_n": least_normal,
        },
        "largest_closure_residual": closure_gap,
        "largest_contact_height_m": contact_gap,
        "mean_qp_iterations": iterations as f64 / samples.len().max(1) as f64,
        "peak_torque_nm": max(samples.iter().map(|x| x.u.amax())),
    });

    let csv = trajectory_csv::<L, NQ, NC, NU, NP, NK>(&samples, s.every);
    let html = report_html::<L, NQ, NC, NU, NP, NK>(
        &p,
        &samples,
        &summary,
        &ground,
        &mu,
        &start.state,
        s,
    )?;
    let files = [
        ("trajectory.csv".into(), csv),
        ("summary.json".into(), format!("{summary:#}\n")),
        ("report.html".into(), html),
    ];
    write_all(&out, &files).map_err(Error::Failed)?;
    println!(
        "{} standing under the balance QP, pushed {} ({:.2} of its weight) at {} s for {} s; {} s at dt = {} s: wrote {}/{{trajectory.csv, summary.json, report.html}}",
        L::NAME,
        quantity(push.norm(), "N"),
        push.norm() / weight,
        s.push_at,
        s.push_for,
        end,
        s.dt,
        out.display()
    );
    println!(
        "  body: largest excursion {}, {} rad; at the end {} and {:.1e} rad from where it stood ({}); feet at most {:.3} of their cones, least normal force {}; largest closure residual {closure_gap:.1e}, contact height {contact_gap:.1e} m",
        quantity(excursion, "m"),
        significant(turned),
        quantity(end_offset, "m"),
        end_angle,
        if recovered { "recovered" } else { "not recovered" },
        worst_cone.unwrap_or(f64::NAN),
        least_normal.map_or("none".into(), |n| quantity(n, "N")),
    );
    if s.free_feet {
        let lifted: Vec<_> = (0..NK / 3)
            .filter_map(|k| {
                let (flight, slide) =
                    samples
                        .iter()
                        .fold((0, 0), |(f, sl), x| match x.modes.get(k) {
                            ContactMode::Flight => (f + 1, sl),
                            ContactMode::Slide { .. } => (f, sl + 1),
                            ContactMode::Stick => (f, sl),
                        });
                (flight + slide > 0).then(|| {
                    format!(
                        "`{}` {flight} steps off the ground, {slide} sliding",
                        L::CONTACT_NAMES[k]
                    )
                })
            })
            .collect();
        println!(
            "  feet free: {}",
            if lifted.is_empty() {
                "every foot stuck where it stood".to_string()
            } else {
                lifted.join("; ")
            }
        );
    }
    match stopped {
        None => Ok(()),
        Some((t, why)) => Err(Error::Failed(format!(
            "the simulation stopped at t = {t} s: {why} (the output holds everything until then)"
        ))),
    }
}

/// The robot on its feet as `sim` stands it, and its weight (N): stood first as its spec
/// has it, then turned and lifted so that the ground is the world's z = 0 and the body is
/// above it, so that pushes are given in that world.
fn stand<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
) -> Result<(StandingStart<NQ, NK>, f64), Error>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let failed = |e: String| Error::Failed(format!("{}: {e}", L::NAME));
    let (_, spec_ground) =
        on_its_feet::<L, NQ, NC, NU, NK>(p, Vector3::zeros(), UnitQuaternion::identity())
            .map_err(|e| failed(e.to_string()))?;
    let level = UnitQuaternion::rotation_between(&spec_ground.normal, &Vector3::z())
        .unwrap_or_else(UnitQuaternion::identity);
    let start = standing_start::<L, NQ, NC, NU, NK>(p, Vector3::z() * -spec_ground.offset, level)
        .map_err(|e| failed(e.to_string()))?;
    let f = robot::free_joint::<L, NQ, NC, NU>().map_err(|e| failed(e.to_string()))?;
    let gravity =
        robot::world_gravity::<L, f64, NQ, NC, NU>(p).map_err(|e| failed(e.to_string()))?;
    let mass = L::mass_matrix(&start.state.q, p)[(f, f)];
    Ok((start, mass * gravity.norm()))
}

/// The balance QP as a torque server (`--serve`, for the MuJoCo push run): holding the
/// robot where [`stand`] puts it, each line on stdin is a state — the body's position and
/// orientation (`w x y z`) in the world, the chart's coordinates (the free joint's six
/// zero) and its rates `v` (the body's linear and angular velocity in its own frame, then
/// the joints') — and each line out the torques, or `error: …`. A state off the closures
/// (a soft-loop simulator's) is put on them first, and its rates on the closures and the
/// held feet (a foot's two points moving apart make its held rows contradict each other),
/// as the controller's model holds them.
fn serve<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
    start: &StandingStart<NQ, NK>,
    s: &Settings,
) -> Result<(), Error>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::assembly::{project_position, Tolerance};
    use leg_models::dynamics::contact::project_held_velocity;
    use leg_models::nalgebra::Quaternion;
    let f = robot::free_joint::<L, NQ, NC, NU>()
        .map_err(|e| Error::Failed(format!("{}: {e}", L::NAME)))?;
    let mut controller = BalanceController::<NQ, NC, NU, NK>::new(
        BalanceTarget::holding(&start.state),
        BalanceGains::default(),
        s.torque_limit.map(SVector::<f64, NU>::repeat),
    );
    super::serve_lines::<NU>(7 + 2 * NQ, |v| {
        let mut state = RobotState {
            position: Vector3::new(v[0], v[1], v[2]),
            orientation: UnitQuaternion::from_quaternion(Quaternion::new(v[3], v[4], v[5], v[6])),
            q: SVector::from_column_slice(&v[7..7 + NQ]),
            v: SVector::from_column_slice(&v[7 + NQ..]),
        };
        project_position::<L, f64, NQ, NC, NU>(p, &mut state.q, &Tolerance::default())
            .map_err(|e| e.to_string())?;
        state.recentre(f);
        let local = robot::ground_in_chart(&start.ground, &state.position, &state.orientation);
        project_held_velocity::<L, f64, NQ, NC, NU, NK, 3>(
            p,
            &state.q,
            &mut state.v,
            &start.modes,
            &local,
        )
        .map_err(|e| e.to_string())?;
        controller
            .command::<L>(p, &state, &start.modes, &start.ground, &start.mu)
            .map(|c| c.torques)
            .map_err(|e| e.to_string())
    })
}

fn significant(x: f64) -> String {
    report::significant(x, 3)
}

/// The largest distance of a contact point from the ground plane (m).
fn contact_heights<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
    s: &RobotState<f64, NQ>,
    ground: &Ground<f64, 3>,
) -> f64
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let x = L::contact_positions(&s.q, p);
    (0..NK / 3)
        .map(|k| {
            let at = s.position
                + s.orientation.transform_vector(&Vector3::new(
                    x[3 * k],
                    x[3 * k + 1],
                    x[3 * k + 2],
                ));
            (ground.normal.dot(&at) - ground.offset).abs()
        })
        .fold(0.0, f64::max)
}

/// trajectory.csv: the time; the body's position and orientation (a unit quaternion,
/// `w` first) in the world; the chart's coordinates and the velocity `v` (the free
/// joint's: the body's linear and angular velocity in the body frame); the torques; each
/// contact's ground force in the world; the push; the residuals.
fn trajectory_csv<
    L: ContactModel<NQ, NC, NU, NK, 3> + LegModel<NQ, NC, NU, 3, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NP: usize,
    const NK: usize,
>(
    samples: &[Sample<NQ, NU, NK>],
    every: usize,
) -> String {
    let mut csv = String::from("t,body_x,body_y,body_z,body_qw,body_qx,body_qy,body_qz");
    for j in L::JOINT_NAMES {
        let _ = write!(csv, ",q_{j}");
    }
    for j in L::JOINT_NAMES {
        let _ = write!(csv, ",v_{j}");
    }
    for name in super::motor_names::<L, NQ, NC, NU>() {
        let _ = write!(csv, ",u_{name}");
    }
    for c in L::CONTACT_NAMES {
        let _ = write!(csv, ",F_{c}_x,F_{c}_y,F_{c}_z");
    }
    csv.push_str(",push_x,push_y,push_z,closure_residual,contact_height");
    for c in L::CONTACT_NAMES {
        let _ = write!(csv, ",mode_{c}");
    }
    csv.push('\n');
    for (k, x) in samples.iter().enumerate() {
        if !super::written(k, samples.len(), every) {
            continue;
        }
        let o = x.state.orientation.quaternion();
        let _ = write!(
            csv,
            "{},{},{},{},{},{},{},{}",
            x.t, x.state.position.x, x.state.position.y, x.state.position.z, o.w, o.i, o.j, o.k
        );
        for v in x.state.q.iter().chain(x.state.v.iter()).chain(x.u.iter()) {
            let _ = write!(csv, ",{v}");
        }
        for v in x.forces.iter().chain(x.push.iter()) {
            let _ = write!(csv, ",{v}");
        }
        let _ = write!(csv, ",{},{}", x.closure_gap, x.contact_gap);
        for k in 0..NK / 3 {
            let _ = write!(csv, ",{}", mode_name(x.modes.get(k)));
        }
        csv.push('\n');
    }
    csv
}

/// Every point of a frame drawn in the chart, moved into the world by the body's pose.
fn into_world<const NQ: usize>(frame: &mut report::Frame, s: &RobotState<f64, NQ>) {
    let moved = |xs: &mut Vec<f64>| {
        for c in xs.chunks_exact_mut(3) {
            let w = s.position
                + s.orientation
                    .transform_vector(&Vector3::new(c[0], c[1], c[2]));
            c.copy_from_slice(w.as_slice());
        }
    };
    frame.bodies.iter_mut().flatten().for_each(moved);
    frame.links.iter_mut().for_each(moved);
    frame.closures.iter_mut().for_each(moved);
    moved(&mut frame.foot);
    if let Some(r) = frame.reference.as_mut() {
        moved(r);
    }
}

/// report.html: the robot over its ground, its body's motion, the feet's forces against
/// their cones, the torques and the residuals; the push shaded.
#[allow(clippy::too_many_arguments)]
fn report_html<
    L: ContactModel<NQ, NC, NU, NK, 3> + LegModel<NQ, NC, NU, 3, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NP: usize,
    const NK: usize,
>(
    p: &L::Params<f64>,
    samples: &[Sample<NQ, NU, NK>],
    summary: &serde_json::Value,
    ground: &Ground<f64, 3>,
    mu: &SVector<f64, NK>,
    start: &RobotState<f64, NQ>,
    s: &Settings,
) -> Result<String, Error> {
    let members = body_points(L::NAME, NQ);
    let frame_every = ((0.01 / s.dt).round() as usize).max(1);
    let frames: Vec<report::Frame> = samples
        .iter()
        .step_by(frame_every)
        .map(|x| {
            let mut frame = frame_at::<L, NQ, NC, NU, 3, NP>(p, &members, x.t, &x.state.q, None);
            into_world(&mut frame, &x.state);
            frame
        })
        .collect();
    let t: Vec<f64> = samples.iter().map(|x| x.t).collect();
    let axes = ["x", "y", "z"];
    let mut plots = vec![
        Series::new(
            "The body's position, from where it stood",
            &t,
            (0..3)
                .map(|a| {
                    (
                        axes[a].to_string(),
                        samples
                            .iter()
                            .map(|x| x.state.position[a] - start.position[a])
                            .collect(),
                    )
                })
                .collect(),
        )
        .axis("offset", "m")
        .caption("The body frame's origin in the world less where it stood; the balance QP holds it there (stiffness (10 rad/s)², critically damped)."),
        Series::new(
            "The body's orientation, from how it stood",
            &t,
            (0..3)
                .map(|a| {
                    (
                        format!("about {}", axes[a]),
                        samples
                            .iter()
                            .map(|x| {
                                (start.orientation.inverse() * x.state.orientation).scaled_axis()[a]
                            })
                            .collect(),
                    )
                })
                .collect(),
        )
        .axis("rotation", "rad")
        .caption("The rotation from the standing orientation to the body's, as a rotation vector in the standing body's frame."),
    ];
    // One line per contact of what `read` reads of its force.
    let per_contact = |read: fn(&ConeReading) -> f64| -> Vec<(String, Vec<f64>)> {
        L::CONTACT_NAMES
            .iter()
            .enumerate()
            .map(|(k, name)| {
                let line = samples
                    .iter()
                    .map(|x| {
                        // A foot off the ground (free feet) has no force: a gap in the line.
                        if x.modes.get(k).on_ground() {
                            read(&cone_reading(&x.forces, ground, mu, k))
                        } else {
                            f64::NAN
                        }
                    })
                    .collect();
                (name.to_string(), line)
            })
            .collect()
    };
    plots.push(
        Series::new("Ground forces: normal", &t, per_contact(|c| c.normal))
            .axis("force", "N")
            .caption(if s.free_feet {
                "Each contact's mean force over a step along the ground's normal; they sum to the weight at rest. A gap: the contact is off the ground (feet free)."
            } else {
                "Each contact's force along the ground's normal; they sum to the weight at rest. A contact whose normal force would reach zero would lift off, which ends this run: every contact is held."
            }),
    );
    plots.push(
        Series::new(
            "Ground forces in their friction cones: |λ_t| / (μ λ_n)",
            &t,
            per_contact(|c| c.ratio),
        )
        .axis("share of the cone", "")
        .caption(if s.free_feet {
            "How far each contact's force is towards its friction cone's edge. Feet free: friction is bounded by a 4-edge pyramid inscribed in the cone, and a sliding contact's force is on the pyramid's edge (up to 1 along its edges, 0.71 between them); each foot's force is the complementarity solve's own split between its points."
        } else {
            "How far each contact's force is towards its friction cone's edge (1: about to slip, which ends this run). Where a rigid foot is held at two points, its load is split between them as deep in their cones as any split goes."
        }),
    );
    plots.push(super::torque_plot(
        &t,
        &super::motor_names::<L, NQ, NC, NU>(),
        samples.iter().map(|x| x.u),
    ));
    plots.push(super::ground::residual_plot(
        &t,
        samples.iter().map(|x| (x.closure_gap, x.contact_gap)),
    ));
    let pushed = [(s.push_at, s.push_at + s.push_for)];
    let plots: Vec<Series> = plots
        .into_iter()
        .map(|p| p.shaded_as(&pushed, "the push on the body"))
        .collect();
    report::html(&Report {
        title: format!(
            "{} — standing under the balance QP, pushed{}",
            L::NAME,
            if s.free_feet { ", feet free" } else { "" }
        ),
        summary,
        plots: &plots,
        frames: &frames,
        ground: Some(super::ground::drawn(ground)),
        rods: L::DISTANCE_CLOSURES,
        robot: true,
    })
    .map_err(Error::Failed)
}
