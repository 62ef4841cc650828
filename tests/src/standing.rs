//! Floating robots on their feet, shared by the robot tests and the `balance` example: the
//! robot's parameters with gravity, its mass from the spec, a stance on a ground through
//! its contact points, and a push run under a holding controller, judged by the forces
//! the simulator applies.

use leg_models::dynamics::contact::{spec_friction, Ground, Modes};
use leg_models::nalgebra::{SVector, UnitQuaternion, Vector3};
use leg_models::robot::balance::{cone_reading, ConeReading};
use leg_models::robot::balance::{judged_forces, BalanceController, BalanceGains, BalanceTarget};
use leg_models::robot::standing::CannotStand;
use leg_models::robot::{self, RobotState};
use leg_models::{ContactModel, LegDynamics, Parameters};

/// The robot's mass, the sum of its spec's link masses (not read off the dynamics).
pub fn spec_mass<L, const NQ: usize, const NC: usize, const NU: usize>(p: &L::Params<f64>) -> f64
where
    L: LegDynamics<NQ, NC, NU>,
{
    let names = <L::Params<f64> as Parameters<f64>>::NAMES;
    names
        .iter()
        .enumerate()
        .filter(|(_, n)| n.ends_with("_mass"))
        .map(|(i, _)| p.get(i).unwrap())
        .sum()
}

/// The default parameters with gravity `g` in the world, and without the joints' damping
/// unless `damping`.
pub fn with_gravity<L, const NQ: usize, const NC: usize, const NU: usize>(
    g: [f64; 3],
    damping: bool,
) -> L::Params<f64>
where
    L: LegDynamics<NQ, NC, NU>,
{
    let mut p = L::Params::<f64>::default();
    let names = <L::Params<f64> as Parameters<f64>>::NAMES;
    for (i, name) in names.iter().enumerate() {
        match *name {
            "gravity_x" => assert!(p.set(i, g[0])),
            "gravity_y" => assert!(p.set(i, g[1])),
            "gravity_z" => assert!(p.set(i, g[2])),
            n if !damping && n.ends_with("_damping") => assert!(p.set(i, 0.0)),
            _ => {}
        }
    }
    p
}

/// A robot standing for a check: its parameters with gravity along −z, its start on its
/// feet ([`robot::standing::on_its_feet`]) and the ground there, every contact held, the spec's friction.
pub struct Stance<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    /// The parameters, with gravity.
    pub params: L::Params<f64>,
    /// On its feet, at rest.
    pub start: RobotState<f64, NQ>,
    /// The ground through its contact points.
    pub ground: Ground<f64, 3>,
    /// Every contact sticking.
    pub modes: Modes<NK, 3>,
    /// The spec's friction coefficients.
    pub mu: SVector<f64, NK>,
}

/// [`Stance`] for the check named `check`, or `None`, said as not applicable with why:
/// where the robot cannot be put on its feet or stand still there
/// ([`robot::standing::standing_start`]). The body starts off the origin and turned, so
/// that no check leans on a level body at the world's origin.
pub fn standing_start<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    check: &str,
) -> Option<Stance<L, NQ, NC, NU, NK>>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let params = with_gravity::<L, NQ, NC, NU>([0.0, 0.0, -9.81], true);
    let turn = UnitQuaternion::from_euler_angles(0.02, -0.03, 0.4);
    match robot::standing::standing_start::<L, NQ, NC, NU, NK>(
        &params,
        Vector3::new(1.0, -2.0, 0.5),
        turn,
    ) {
        Ok(s) => Some(Stance {
            params,
            start: s.state,
            ground: s.ground,
            modes: s.modes,
            mu: s.mu,
        }),
        // A home that does not assemble, or a model that is not a robot, is a failure of
        // the model, not a robot that cannot stand.
        Err(e @ (CannotStand::Home(_) | CannotStand::Dynamics(_))) => {
            panic!("{}: {e}", L::NAME)
        }
        Err(why) => {
            crate::not_applicable(L::NAME, check, &why.to_string());
            None
        }
    }
}

/// What holds the robot up during a push run.
#[derive(Clone, Copy, Debug)]
pub enum Holding {
    /// The balance QP ([`BalanceController`]) with these gains, holding the start.
    Balance(BalanceGains),
    /// The torques that hold the start still ([`robot::holding_torques`]) plus a PD on
    /// the motors about the start, stiffness the weight times the robot's size per
    /// radian, damping that over 10 rad/s (the standing test's holding).
    JointPd,
}

/// How a push run went.
#[derive(Clone, Debug)]
pub struct PushRun {
    /// `None` if the robot stayed on its feet and came back; else why not, and when (s).
    pub failed: Option<(f64, String)>,
    /// The largest `|λ_t| / (μ λ_n)` of any foot over the run, from the simulator's
    /// forces, a rigid foot's split between its points the deepest in their cones
    /// ([`judged_forces`]; above 1: a foot would slip).
    pub worst_friction: f64,
    /// The least normal force of any foot over the run (N).
    pub least_normal: f64,
    /// The body's largest distance from where it started (m).
    pub excursion: f64,
    /// At the end: the body's distance from the start (m), its angle (rad), `|v|` (NaN
    /// where the run failed before its end).
    pub end: (f64, f64, f64),
    /// The QP's mean interior-point iterations (zero for the joint PD).
    pub mean_iterations: f64,
}

/// From standing at rest at `start` on `ground` with every contact held: a force `push`
/// (N, world) on the body's origin for `push_time` seconds, then nothing, `duration`
/// seconds in all at step `dt`, held by `holding`. The run fails where the controller
/// has no command, where a foot's force from the simulator leaves its friction cone or
/// pulls (the held contacts no longer hold), or where at the end the body is more than
/// 1 mm (0.001 rad, 0.001 m/s or rad/s) from where it started.
#[allow(clippy::too_many_arguments)]
pub fn push_run<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
    start: &RobotState<f64, NQ>,
    ground: &Ground<f64, 3>,
    holding: Holding,
    push: Vector3<f64>,
    push_time: f64,
    duration: f64,
    dt: f64,
) -> PushRun
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let modes = Modes::<NK, 3>::stick();
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, 3>();
    let mut balance = match holding {
        Holding::Balance(gains) => Some(BalanceController::<NQ, NC, NU, NK>::new(
            BalanceTarget::holding(start),
            gains,
            None,
        )),
        Holding::JointPd => None,
    };
    let hold = match holding {
        Holding::JointPd => {
            robot::holding_torques::<L, f64, NQ, NC, NU, NK>(p, start, &modes, ground, &mu)
                .map(|(u, _)| u)
        }
        Holding::Balance(_) => Ok(SVector::zeros()),
    };
    let weight = spec_mass::<L, NQ, NC, NU>(p) * 9.81;
    let stiffness = weight * L::leg_size(&start.q, p);
    let damping = stiffness / 10.0;
    let mut run = PushRun {
        failed: None,
        worst_friction: 0.0,
        least_normal: f64::INFINITY,
        excursion: 0.0,
        end: (f64::NAN, f64::NAN, f64::NAN),
        mean_iterations: 0.0,
    };
    let hold = match hold {
        Ok(u) => u,
        Err(e) => {
            run.failed = Some((0.0, format!("no holding torques: {e}")));
            return run;
        }
    };
    let steps = (duration / dt).round() as usize;
    let pushed = (push_time / dt).round() as usize;
    let mut s = *start;
    let mut iterations = 0u64;
    for i in 0..steps {
        let t = i as f64 * dt;
        let u = match balance.as_mut() {
            Some(c) => match c.command::<L>(p, &s, &modes, ground, &mu) {
                Ok(cmd) => {
                    iterations += u64::from(cmd.iterations);
                    cmd.torques
                }
                Err(e) => {
                    run.failed = Some((t, e.to_string()));
                    return run;
                }
            },
            None => {
                hold + SVector::<f64, NU>::from_fn(|j, _| {
                    let a = L::ACTUATED[j];
                    -stiffness * (s.q[a] - start.q[a]) - damping * s.v[a]
                })
            }
        };
        let force = if i < pushed { push } else { Vector3::zeros() };
        let before = s;
        let stance = match robot::pushed_stance_step::<L, f64, NQ, NC, NU, NK>(
            p, &mut s, &u, &force, &modes, ground, &mu, dt,
        ) {
            Ok(x) => x,
            Err(e) => {
                run.failed = Some((t, e.to_string()));
                return run;
            }
        };
        let forces = judged_forces::<L, NQ, NC, NU, NK>(p, &before, &stance, &modes, ground, &mu)
            .unwrap_or_else(|e| panic!("{}: judging the ground forces: {e}", L::NAME));
        for k in 0..NK / 3 {
            let ConeReading {
                normal,
                tangential,
                ratio,
                ..
            } = cone_reading(&forces, ground, &mu, k);
            run.least_normal = run.least_normal.min(normal);
            run.worst_friction = run.worst_friction.max(ratio);
            if normal <= 0.0 && run.failed.is_none() {
                run.failed = Some((
                    t,
                    format!("contact {k} pulls on the ground ({normal:.3} N)"),
                ));
            } else if ratio > 1.0 && run.failed.is_none() {
                run.failed = Some((
                    t,
                    format!(
                        "contact {k} leaves its friction cone (normal {normal:.3} N, tangential {tangential:.3} N)"
                    ),
                ));
            }
        }
        run.excursion = run.excursion.max((s.position - start.position).norm());
        if run.failed.is_some() {
            return run;
        }
    }
    run.mean_iterations = iterations as f64 / steps.max(1) as f64;
    run.end = (
        (s.position - start.position).norm(),
        s.orientation.angle_to(&start.orientation),
        s.v.amax(),
    );
    if run.end.0 > 1e-3 || run.end.1 > 1e-3 || run.end.2 > 1e-3 {
        run.failed = Some((
            duration,
            format!(
                "not back where it started: {:.2e} m, {:.2e} rad, |v| {:.2e}",
                run.end.0, run.end.1, run.end.2
            ),
        ));
    }
    run
}

/// The largest push (N, along `direction`, for `push_time` s) that `holding` survives
/// (see [`push_run`]), found by doubling from a tenth of the weight and then halving the
/// bracket `refinements` times; the push that failed first at the bracket's top and why.
#[allow(clippy::too_many_arguments)]
pub fn largest_push<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
    start: &RobotState<f64, NQ>,
    ground: &Ground<f64, 3>,
    holding: Holding,
    direction: Vector3<f64>,
    push_time: f64,
    duration: f64,
    dt: f64,
    refinements: usize,
) -> (f64, f64, String)
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let weight = spec_mass::<L, NQ, NC, NU>(p) * 9.81;
    let d = direction.normalize();
    let run = |f: f64| {
        push_run::<L, NQ, NC, NU, NK>(p, start, ground, holding, d * f, push_time, duration, dt)
            .failed
    };
    let (mut lo, mut hi) = (0.0, 0.1 * weight);
    let mut why;
    loop {
        match run(hi) {
            None => {
                lo = hi;
                hi *= 2.0;
                if hi > 1e3 * weight {
                    return (
                        lo,
                        f64::INFINITY,
                        "no push up to 1000 times the weight fails".into(),
                    );
                }
            }
            Some((_, w)) => {
                why = w;
                break;
            }
        }
    }
    for _ in 0..refinements {
        let mid = 0.5 * (lo + hi);
        match run(mid) {
            None => lo = mid,
            Some((_, w)) => {
                hi = mid;
                why = w;
            }
        }
    }
    (lo, hi, why)
}
