//! Floating robots on their feet, shared by the robot tests and the `balance` example: the
//! robot's parameters with gravity, its mass from the spec, a stance on a ground through
//! its contact points, and a push run under a holding controller, judged by the forces
//! the simulator applies.

use leg_models::dynamics::contact::{spec_friction, Ground, Modes};
use leg_models::nalgebra::{SVector, UnitQuaternion, Vector3};
use leg_models::robot::balance::{BalanceController, BalanceGains, BalanceTarget};
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

/// The robot at home, its contact points on a ground plane through them (the plane's
/// normal up along the body's side), or why it cannot stand there. Where they are not on
/// one plane at home, the joints put them flat under the body first
/// ([`robot::feet_on_a_plane`], the plane square to the body's `z`).
pub fn on_its_feet<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
) -> Result<(RobotState<f64, NQ>, Ground<f64, 3>), &'static str>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    if NK < 9 {
        return Err("fewer than three contact points");
    }
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let mut q = assembled_home::<L, NQ, NC, NU>(p);
    if !coplanar::<L, NQ, NC, NU, NK>(p, &q) {
        robot::feet_on_a_plane::<L, f64, NQ, NC, NU, NK>(
            p,
            &mut q,
            &Vector3::z(),
            &leg_models::assembly::Tolerance::default(),
        )
        .map_err(|_| {
            "its contact points cannot be put on one plane, its centre of mass over them, from home"
        })?;
    }

    let turn = UnitQuaternion::from_euler_angles(0.02, -0.03, 0.4);
    let mut s = RobotState::at_rest(Vector3::new(1.0, -2.0, 0.5), turn, q);
    // Closing the loops may have moved the chart's six (Cassie's home is off its
    // closures): centred again, the state's rates are the body's velocity.
    s.recentre(f);
    let chart = robot::chart_params::<L, f64, NQ, NC, NU>(p, &s.orientation).unwrap();
    let x = L::contact_positions(&s.q, &chart);
    let at = |k: usize| {
        s.position
            + s.orientation
                .transform_vector(&Vector3::new(x[3 * k], x[3 * k + 1], x[3 * k + 2]))
    };
    let mut n = (at(1) - at(0)).cross(&(at(2) - at(0))).normalize();
    if n.dot(&(s.position - at(0))) < 0.0 {
        n = -n;
    }
    let size = (at(1) - at(0)).norm();
    for k in 3..NK / 3 {
        if n.dot(&(at(k) - at(0))).abs() > 1e-12 * size {
            return Err("its contact points at home are not on one plane");
        }
    }
    Ok((
        s,
        Ground {
            normal: n,
            offset: n.dot(&at(0)),
        },
    ))
}

/// Whether the contact points at `q` (a chart centred on the body) are on one plane, to
/// rounding of their spread.
fn coplanar<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
) -> bool
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let x = L::contact_positions(q, p);
    let at = |k: usize| Vector3::new(x[3 * k], x[3 * k + 1], x[3 * k + 2]);
    let n = (at(1) - at(0)).cross(&(at(2) - at(0)));
    if n.norm() == 0.0 {
        return false;
    }
    let n = n.normalize();
    let size = (at(1) - at(0)).norm();
    (3..NK / 3).all(|k| n.dot(&(at(k) - at(0))).abs() <= 1e-12 * size)
}

/// Contact `k`'s force from `world_forces` (three a contact, in the world), its normal
/// and tangential parts on `ground`, and how far it is into its friction cone:
/// `‖λ_t‖ / (μ λ_n)`, at most 1 inside the cone, 0 for a contact that bears nothing,
/// infinite where it pulls or slides on no load.
pub fn cone_reading<const NK: usize>(
    world_forces: &SVector<f64, NK>,
    ground: &Ground<f64, 3>,
    mu: &SVector<f64, NK>,
    k: usize,
) -> ConeReading {
    let force = Vector3::new(
        world_forces[3 * k],
        world_forces[3 * k + 1],
        world_forces[3 * k + 2],
    );
    let normal = force.dot(&ground.normal);
    let tangential = (force - ground.normal * normal).norm();
    let ratio = if normal > 0.0 {
        tangential / (mu[3 * k + 2] * normal)
    } else if normal == 0.0 && tangential == 0.0 {
        0.0
    } else {
        f64::INFINITY
    };
    ConeReading {
        force,
        normal,
        tangential,
        ratio,
    }
}

/// What [`cone_reading`] reads.
#[derive(Clone, Copy, Debug)]
pub struct ConeReading {
    /// The force (N, world).
    pub force: Vector3<f64>,
    /// Along the ground's normal (N).
    pub normal: f64,
    /// Along the ground (N).
    pub tangential: f64,
    /// `‖λ_t‖ / (μ λ_n)`.
    pub ratio: f64,
}

/// The ground forces of `stance` (a step from `before`, centred, on `ground`) in the world,
/// with their internal part split as puts every held contact deepest inside its cone
/// ([`leg_models::robot::balance::deepest_split`]): two points of one rigid foot hold if
/// any split of its load between them does, whatever split the stance solve reports (the
/// least). Where no held rows repeat each other, the stance's own forces.
pub fn judged_forces<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
    before: &RobotState<f64, NQ>,
    stance: &robot::Stance<f64, NQ, NC, NK>,
    modes: &Modes<NK, 3>,
    ground: &Ground<f64, 3>,
    mu: &SVector<f64, NK>,
) -> SVector<f64, NK>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::robot::balance::{deepest_split, internal_forces};
    let internal = internal_forces::<L, NQ, NC, NU, NK>(p, before, modes, ground).unwrap();
    if internal.ncols() == 0 {
        return stance.world_forces;
    }
    let (split, _) = deepest_split(&stance.solution.contact, &internal, modes, mu).unwrap();
    let local = robot::ground_in_chart(ground, &before.position, &before.orientation);
    robot::forces_in_world(&local, &before.orientation, &split)
}

/// The robot's home with the body's six chart coordinates zeroed, put on its closures
/// (an imported home is off them by a little); the body may have moved in closing them.
pub fn assembled_home<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
) -> SVector<f64, NQ>
where
    L: LegDynamics<NQ, NC, NU>,
{
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let mut q = SVector::<f64, NQ>::from_column_slice(&L::HOME);
    for k in 0..6 {
        q[f + k] = 0.0;
    }
    leg_models::assembly::project_position::<L, f64, NQ, NC, NU>(
        p,
        &mut q,
        &leg_models::assembly::Tolerance::default(),
    )
    .unwrap_or_else(|e| panic!("{}: home does not assemble: {e}", L::NAME));
    q
}

/// A robot standing for a check: its parameters with gravity along −z, its start on its
/// feet ([`on_its_feet`]) and the ground there, every contact held, the spec's friction.
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
/// where the robot cannot be put on its feet or stand still there. Where its home is not
/// a pose its least torques hold, it starts where [`robot::standing::standing_pose`]
/// puts it.
pub fn standing_start<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    check: &str,
) -> Option<Stance<L, NQ, NC, NU, NK>>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let params = with_gravity::<L, NQ, NC, NU>([0.0, 0.0, -9.81], true);
    let (start, ground) = match on_its_feet::<L, NQ, NC, NU, NK>(&params) {
        Ok(x) => x,
        Err(why) => {
            crate::not_applicable(L::NAME, check, &why);
            return None;
        }
    };
    let modes = Modes::stick();
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, 3>();
    let start = match held_start::<L, NQ, NC, NU, NK>(&params, &start, &modes, &ground, &mu) {
        Ok(s) => s,
        Err(why) => {
            crate::not_applicable(L::NAME, check, &why);
            return None;
        }
    };
    Some(Stance {
        params,
        start,
        ground,
        modes,
        mu,
    })
}

/// The largest `|q̈|` (m/s² or rad/s²) the least holding torques may leave for a pose
/// to count as one the robot stands still in: 1e-10 g.
pub const HELD: f64 = 1e-10 * 9.81;

/// `start` where its least holding torques hold it still ([`HELD`]); else the pose
/// [`robot::standing::standing_pose`] finds near it (springs settled under the weight,
/// posture weight 0.1 per radian), or why there is none.
fn held_start<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<f64>,
    start: &RobotState<f64, NQ>,
    modes: &Modes<NK, 3>,
    ground: &Ground<f64, 3>,
    mu: &SVector<f64, NK>,
) -> Result<RobotState<f64, NQ>, String>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let (_, left) =
        robot::holding_torques::<L, f64, NQ, NC, NU, NK>(params, start, modes, ground, mu)
            .map_err(|e| e.to_string())?;
    if left < HELD {
        return Ok(*start);
    }
    let pose = robot::standing::standing_pose::<L, NQ, NC, NU, NK>(
        params, start, modes, ground, mu, 0.1, 100,
    )
    .map_err(|e| e.to_string())?;
    if pose.left < HELD {
        Ok(pose.state)
    } else {
        Err(format!(
            "its least holding torques leave |q̈| {left:.1e} at home, and {:.1e} at the best standing pose found near it",
            pose.left
        ))
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
        let forces = judged_forces::<L, NQ, NC, NU, NK>(p, &before, &stance, &modes, ground, &mu);
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
