//! A pose a floating robot can stand still in.
//!
//! A robot's home pose is rarely one it can stand in. Where a stance's closed chain runs
//! through springs (Cassie's shin and heel springs, carrying its weight from the knee to
//! the foot), the home pose has them unloaded: held there, the weight must go round the
//! loop the two feet close through the ground, and the motors' holding torques, which
//! are determined at every pose, squeeze the legs against each other with tens of kN m.
//! Standing needs the springs deflected under the weight.
//!
//! [`standing_pose`] looks for that pose near a start: over the poses with every
//! closure closed and every contact point on the ground, it minimizes
//!
//! ```text
//! |u(q) / (m g ℓ)|² + 10⁶ (ℓ / g) |q̈(q)|² + w² |q − q₀|²
//!   + Σ_k (|λ_t,k|² + (λ_n,k − λ̄_n)²) / (m g)²
//! ```
//!
//! (the `q̈` term is not dimensionless, and mixes m/s² and rad/s² rows: it only has
//! to make what the torques leave dominate, and it does), where `u(q)` are the least
//! torques that hold the robot still at `q`
//! ([`super::holding_torques`]) and `q̈(q)` what they leave (motions no motor, closure or
//! contact holds: a rod spinning about its own axis), `m g` the robot's weight, `ℓ` its
//! size, `w` a posture weight per radian (or per size, for the body's translation), and
//! `λ_k` the held contacts' forces under those torques (the least split where two share
//! a rigid foot): the last term asks every contact to bear the mean `λ̄_n` of their
//! normal forces with nothing along the ground, so that the pose
//! is one the feet hold with margin in their friction cones, not only one the torques
//! hold (the least torques alone tip the weight onto Cassie's toes and pull on its
//! heels).
//! Gauss–Newton on the poses' tangent space (the null space of the closure and contact
//! heights' Jacobian), the residual's Jacobian by central differences of poses put back
//! on the constraints, with Levenberg–Marquardt damping.
//!
//! The search runs in the chart centred on the start (its free joint's six coordinates
//! move with the rest), and the pose found is recentred.

use core::fmt;
use std::vec::Vec;

use nalgebra::{DMatrix, DVector, SVector, UnitQuaternion, Vector3};

use super::{
    chart_params, free_joint, ground_in_chart, holding_torques, stance_dynamics,
    RobotDynamicsError, RobotState,
};
use crate::assembly::{project_position, AssemblyError, Tolerance};
use crate::dynamics::contact::{spec_friction, Ground, Modes};
use crate::model::contract::{ContactModel, LegDynamics};

/// What [`standing_pose`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StandingPose<const NQ: usize, const NU: usize> {
    /// The pose, at rest, the chart centred on it.
    pub state: RobotState<f64, NQ>,
    /// The least torques that hold it still.
    pub torques: SVector<f64, NU>,
    /// The largest `|q̈|` they leave (rad/s² or m/s²).
    pub left: f64,
    /// Gauss–Newton iterations taken.
    pub iterations: usize,
}

/// Why [`standing_pose`] found no pose.
#[derive(Clone, Debug, PartialEq)]
pub enum StandingError {
    /// The stance dynamics failed at a pose tried (or the model is not a floating robot).
    Dynamics(RobotDynamicsError),
    /// The closures and the contacts' heights could not be put back to zero: `residual`
    /// (m) was left.
    OffTheGround {
        /// The largest closure or height residual left (m).
        residual: f64,
    },
    /// The start, the ground or the posture weight is not finite (or a pose tried gave a
    /// non-finite residual), the weight is not positive, or the ground's normal is zero.
    NonFinite,
    /// No contact in `modes` is held: there is nothing to stand on.
    NoStance,
}

impl From<RobotDynamicsError> for StandingError {
    fn from(e: RobotDynamicsError) -> Self {
        StandingError::Dynamics(e)
    }
}

impl fmt::Display for StandingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StandingError::Dynamics(e) => write!(f, "standing pose: {e}"),
            StandingError::OffTheGround { residual } => write!(
                f,
                "standing pose: the closures and the contacts' heights cannot be closed near the start ({residual:e} m left)"
            ),
            StandingError::NoStance => write!(f, "standing pose: no contact is held"),
            StandingError::NonFinite => write!(
                f,
                "standing pose: the start or the posture weight is not finite (or the weight is not positive)"
            ),
        }
    }
}

impl std::error::Error for StandingError {}

/// The pose near `start` (on `ground`, every contact in `modes` held) where the robot
/// stands still with the least torques, its springs settled: see the module's doc.
/// `posture_weight` is `w`, per radian; `max_iterations` bounds the Gauss–Newton steps
/// (each evaluates the stance at about twice as many poses as the stance has free
/// motions). The held contact points slide along the ground if that lowers the cost:
/// the pose is a stance, not a path to it. `mu` is read only for contacts that slide.
#[allow(clippy::too_many_arguments)]
pub fn standing_pose<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<f64>,
    start: &RobotState<f64, NQ>,
    modes: &Modes<NK, 3>,
    ground: &Ground<f64, 3>,
    mu: &SVector<f64, NK>,
    posture_weight: f64,
    max_iterations: usize,
) -> Result<StandingPose<NQ, NU>, StandingError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let f = free_joint::<L, NQ, NC, NU>().map_err(RobotDynamicsError::from)?;
    let finite = start
        .q
        .iter()
        .chain(start.position.iter())
        .chain(start.orientation.coords.iter())
        .chain(ground.normal.iter())
        .chain(core::iter::once(&ground.offset))
        .all(|x| x.is_finite());
    if !(finite && posture_weight.is_finite() && posture_weight > 0.0)
        || ground.normal.norm() == 0.0
    {
        return Err(StandingError::NonFinite);
    }
    let mut centre = *start;
    centre.v = SVector::zeros();
    centre.recentre(f);
    let q0 = centre.q;
    let local = ground_in_chart(ground, &centre.position, &centre.orientation);
    let chart = super::chart_params::<L, f64, NQ, NC, NU>(params, &centre.orientation)
        .map_err(RobotDynamicsError::from)?;
    let size = L::leg_size(&q0, params);
    let g = super::world_gravity::<L, f64, NQ, NC, NU>(params)
        .map_err(RobotDynamicsError::from)?
        .norm();
    let mass = {
        let m = L::mass_matrix(&q0, params);
        m[(f, f)]
    };
    let weight = (mass * g).max(f64::MIN_POSITIVE);
    let torque_scale = weight * size;
    let accel_weight = 1e3 * (size / g.max(f64::MIN_POSITIVE)).sqrt();
    let held: Vec<usize> = (0..NK / 3)
        .filter(|&k| modes.get(k) != crate::dynamics::contact::ContactMode::Flight)
        .collect();
    if held.is_empty() {
        return Err(StandingError::NoStance);
    }
    // The constraints: closures, then each held contact's height above the chart's
    // ground.
    let rows = NC + held.len();
    let constraint = |q: &SVector<f64, NQ>| {
        let mut h = DVector::<f64>::zeros(rows);
        let c = L::closure_residual(q, &chart);
        h.rows_mut(0, NC).copy_from(&c);
        let x = L::contact_positions(q, &chart);
        for (i, &k) in held.iter().enumerate() {
            let at = nalgebra::Vector3::new(x[3 * k], x[3 * k + 1], x[3 * k + 2]);
            h[NC + i] = local.normal.dot(&at) - local.offset;
        }
        h
    };
    let constraint_jacobian = |q: &SVector<f64, NQ>| {
        let mut j = DMatrix::<f64>::zeros(rows, NQ);
        let jc = L::constraint_jacobian(q, &chart);
        j.rows_mut(0, NC).copy_from(&jc);
        let xj = L::contact_jacobian(q, &chart);
        for (i, &k) in held.iter().enumerate() {
            for c in 0..NQ {
                j[(NC + i, c)] = (0..3).map(|a| local.normal[a] * xj[(3 * k + a, c)]).sum();
            }
        }
        j
    };
    let limit = 1e-13 * size;
    // Back onto the constraints: least-norm Gauss–Newton steps (damped for the
    // redundant rows).
    let project = |q: &mut SVector<f64, NQ>| -> Result<(), StandingError> {
        let mut h = constraint(q);
        for _ in 0..50 {
            if !h.iter().all(|x| x.is_finite()) {
                return Err(StandingError::NonFinite);
            }
            if h.amax() <= limit {
                return Ok(());
            }
            let j = constraint_jacobian(q);
            let mut a = &j * j.transpose();
            let top = (0..rows).fold(0.0f64, |m, i| m.max(a[(i, i)]));
            for i in 0..rows {
                a[(i, i)] += 1e-14 * top;
            }
            let Some(chol) = a.cholesky() else { break };
            let step = j.transpose() * chol.solve(&h);
            *q -= SVector::<f64, NQ>::from_iterator(step.iter().copied());
            h = constraint(q);
        }
        if h.amax() <= limit {
            Ok(())
        } else {
            Err(StandingError::OffTheGround { residual: h.amax() })
        }
    };
    let at = |q: &SVector<f64, NQ>| RobotState::at_rest(centre.position, centre.orientation, *q);
    // The residual: torques, what they leave, posture.
    let residual =
        |q: &SVector<f64, NQ>| -> Result<(DVector<f64>, SVector<f64, NU>, f64), StandingError> {
            let s = at(q);
            let (u, _) = holding_torques::<L, f64, NQ, NC, NU, NK>(params, &s, modes, ground, mu)?;
            let solution =
                stance_dynamics::<L, f64, NQ, NC, NU, NK>(params, &s, &u, modes, ground, mu)?
                    .solution;
            let qdd = solution.x;
            let mut r = DVector::<f64>::zeros(NU + 2 * NQ + NK);
            // The held contacts' loads, each against its share of the whole, and their
            // forces along the ground, over the weight.
            let share = held
                .iter()
                .map(|&k| solution.contact[3 * k + 2])
                .sum::<f64>()
                / held.len().max(1) as f64;
            for &k in &held {
                r[NU + 2 * NQ + 3 * k] = solution.contact[3 * k] / weight;
                r[NU + 2 * NQ + 3 * k + 1] = solution.contact[3 * k + 1] / weight;
                r[NU + 2 * NQ + 3 * k + 2] = (solution.contact[3 * k + 2] - share) / weight;
            }
            for i in 0..NU {
                r[i] = u[i] / torque_scale;
            }
            for i in 0..NQ {
                r[NU + i] = accel_weight * qdd[i];
                // The body's translation per size, every angle per radian.
                let unit = if i >= f && i < f + 3 { size } else { 1.0 };
                r[NU + NQ + i] = posture_weight * (q[i] - q0[i]) / unit;
            }
            Ok((r, u, qdd.amax()))
        };

    let mut q = q0;
    project(&mut q)?;
    let (mut r, mut u, mut left) = residual(&q)?;
    let mut damping = 1e-3;
    let mut iterations = 0;
    for _ in 0..max_iterations {
        iterations += 1;
        // The tangent space: the constraints' Jacobian's null space, from its SVD (padded
        // with zero rows to be square, so that V is whole), singular values below 1e-9
        // of the largest.
        let j = constraint_jacobian(&q);
        if !j.iter().all(|x| x.is_finite()) {
            return Err(StandingError::NonFinite);
        }
        let padded =
            DMatrix::<f64>::from_fn(
                NQ.max(rows),
                NQ,
                |i, c| {
                    if i < rows {
                        j[(i, c)]
                    } else {
                        0.0
                    }
                },
            );
        let svd = padded.svd(false, true);
        let v_t = svd.v_t.expect("asked for");
        let top = svd.singular_values.amax();
        let free: Vec<usize> = (0..NQ)
            .filter(|&i| svd.singular_values[i] <= 1e-9 * top)
            .collect();
        let tangent = v_t.select_rows(&free).transpose();
        let m = tangent.ncols();
        let h = 1e-6;
        let mut jac = DMatrix::<f64>::zeros(r.len(), m);
        for c in 0..m {
            let dir = SVector::<f64, NQ>::from_iterator(tangent.column(c).iter().copied());
            let mut plus = q + dir * h;
            let mut minus = q - dir * h;
            project(&mut plus)?;
            project(&mut minus)?;
            let (rp, _, _) = residual(&plus)?;
            let (rm, _, _) = residual(&minus)?;
            jac.set_column(c, &((rp - rm) / (2.0 * h)));
        }
        let normal = jac.transpose() * &jac;
        let gradient = jac.transpose() * &r;
        let cost = r.norm_squared();
        let mut improved = false;
        for _ in 0..20 {
            let mut a = normal.clone();
            let scale = (0..m).fold(0.0f64, |s, i| s.max(a[(i, i)]));
            for i in 0..m {
                a[(i, i)] += damping * scale;
            }
            let Some(chol) = a.cholesky() else {
                damping *= 10.0;
                continue;
            };
            let step = chol.solve(&(-&gradient));
            let mut trial =
                q + SVector::<f64, NQ>::from_iterator((&tangent * &step).iter().copied());
            if project(&mut trial).is_err() {
                damping *= 10.0;
                continue;
            }
            let (rt, ut, lt) = residual(&trial)?;
            if rt.norm_squared() < cost {
                (q, r, u, left) = (trial, rt, ut, lt);
                damping = (damping / 10.0).max(1e-12);
                improved = true;
                break;
            }
            damping *= 10.0;
        }
        if !improved || gradient.amax() <= 1e-14 * (1.0 + cost) {
            break;
        }
    }
    let mut state = at(&q);
    state.recentre(f);
    Ok(StandingPose {
        state,
        torques: u,
        left,
        iterations,
    })
}

/// Why a robot cannot be put on its feet ([`on_its_feet`], [`standing_start`]).
#[derive(Clone, Debug, PartialEq)]
pub enum CannotStand {
    /// The model is not a floating robot, or its dynamics failed putting it on its feet.
    Dynamics(RobotDynamicsError),
    /// The stance at the start has no holding torques (its dynamics failed there).
    Holding(RobotDynamicsError),
    /// Fewer than three contact points: nothing spans a plane to stand on.
    FewerThanThreeContacts,
    /// The home pose does not assemble (its closures cannot be closed).
    Home(AssemblyError),
    /// The contact points cannot be put on one plane from home
    /// ([`super::feet_on_a_plane`]).
    NotFlat(AssemblyError),
    /// The contact points, put flat, are still not on one plane to rounding, or the
    /// first three are on one line.
    NotOnOnePlane,
    /// The least holding torques leave `|q̈|` `at_home` at home, and no pose near it
    /// that [`standing_pose`] finds holds still either (`at_best`, or why it found none).
    NoStandingPose {
        /// What the least torques leave at home (m/s² or rad/s²).
        at_home: f64,
        /// What they leave at the best pose found, or why none was found.
        at_best: Result<f64, StandingError>,
    },
}

impl fmt::Display for CannotStand {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CannotStand::Dynamics(e) => write!(f, "cannot stand: {e}"),
            CannotStand::Holding(e) => {
                write!(f, "cannot stand: no torques hold its stance: {e}")
            }
            CannotStand::FewerThanThreeContacts => {
                write!(f, "cannot stand: fewer than three contact points")
            }
            CannotStand::Home(e) => write!(f, "cannot stand: its home does not assemble: {e}"),
            CannotStand::NotFlat(e) => write!(
                f,
                "cannot stand: its contact points cannot be put on one plane from home: {e}"
            ),
            CannotStand::NotOnOnePlane => {
                write!(f, "cannot stand: its contact points are not on one plane")
            }
            CannotStand::NoStandingPose { at_home, at_best } => match at_best {
                Ok(best) => write!(
                    f,
                    "cannot stand still: its least holding torques leave |q̈| {at_home:.1e} at home and {best:.1e} at the best standing pose found near it"
                ),
                Err(e) => write!(
                    f,
                    "cannot stand still: its least holding torques leave |q̈| {at_home:.1e} at home, and no standing pose was found near it: {e}"
                ),
            },
        }
    }
}

impl std::error::Error for CannotStand {}

impl From<RobotDynamicsError> for CannotStand {
    fn from(e: RobotDynamicsError) -> Self {
        CannotStand::Dynamics(e)
    }
}

/// The largest `|q̈|` (m/s² or rad/s²) the least holding torques may leave for a pose to
/// count as one the robot stands still in: 1e-10 g.
pub const HELD: f64 = 1e-10 * 9.81;

/// The robot's home with the body's six chart coordinates zeroed, put on its closures
/// (an imported home is off them by a little); the body may have moved in closing them.
pub fn assembled_home<L, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<f64>,
) -> Result<SVector<f64, NQ>, CannotStand>
where
    L: LegDynamics<NQ, NC, NU>,
{
    let f = free_joint::<L, NQ, NC, NU>().map_err(RobotDynamicsError::from)?;
    let mut q = SVector::<f64, NQ>::from_column_slice(&L::HOME);
    for k in 0..6 {
        q[f + k] = 0.0;
    }
    project_position::<L, f64, NQ, NC, NU>(params, &mut q, &Tolerance::default())
        .map_err(CannotStand::Home)?;
    Ok(q)
}

/// The robot at home with its body at `position`, turned by `orientation`, at rest, and
/// the ground plane through its contact points (its normal up along the body's side of
/// them). Where the points are not on one plane at home, the joints put them flat under
/// the body first ([`super::feet_on_a_plane`], the plane square to the body's `z`).
pub fn on_its_feet<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<f64>,
    position: Vector3<f64>,
    orientation: UnitQuaternion<f64>,
) -> Result<(RobotState<f64, NQ>, Ground<f64, 3>), CannotStand>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    if NK < 9 {
        return Err(CannotStand::FewerThanThreeContacts);
    }
    let f = free_joint::<L, NQ, NC, NU>().map_err(RobotDynamicsError::from)?;
    let mut q = assembled_home::<L, NQ, NC, NU>(params)?;
    if !coplanar::<L, NQ, NC, NU, NK>(params, &q) {
        super::feet_on_a_plane::<L, f64, NQ, NC, NU, NK>(
            params,
            &mut q,
            &Vector3::z(),
            &Tolerance::default(),
        )
        .map_err(CannotStand::NotFlat)?;
    }
    let mut s = RobotState::at_rest(position, orientation, q);
    // Closing the loops may have moved the chart's six (Cassie's home is off its
    // closures): centred again, the state's rates are the body's velocity.
    s.recentre(f);
    let chart = chart_params::<L, f64, NQ, NC, NU>(params, &s.orientation)
        .map_err(RobotDynamicsError::from)?;
    let x = L::contact_positions(&s.q, &chart);
    let at = |k: usize| {
        s.position
            + s.orientation
                .transform_vector(&Vector3::new(x[3 * k], x[3 * k + 1], x[3 * k + 2]))
    };
    let n = (at(1) - at(0)).cross(&(at(2) - at(0)));
    if n.norm() == 0.0 || !n.norm().is_finite() {
        return Err(CannotStand::NotOnOnePlane);
    }
    let mut n = n.normalize();
    if n.dot(&(s.position - at(0))) < 0.0 {
        n = -n;
    }
    let size = (at(1) - at(0)).norm();
    if (3..NK / 3).any(|k| n.dot(&(at(k) - at(0))).abs() > 1e-12 * size) {
        return Err(CannotStand::NotOnOnePlane);
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
    params: &L::Params<f64>,
    q: &SVector<f64, NQ>,
) -> bool
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let x = L::contact_positions(q, params);
    let at = |k: usize| Vector3::new(x[3 * k], x[3 * k + 1], x[3 * k + 2]);
    let n = (at(1) - at(0)).cross(&(at(2) - at(0)));
    if n.norm() == 0.0 {
        return false;
    }
    let n = n.normalize();
    let size = (at(1) - at(0)).norm();
    (3..NK / 3).all(|k| n.dot(&(at(k) - at(0))).abs() <= 1e-12 * size)
}

/// A robot on its feet, at rest where it stands still ([`standing_start`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StandingStart<const NQ: usize, const NK: usize> {
    /// On its feet, at rest.
    pub state: RobotState<f64, NQ>,
    /// The ground through its contact points.
    pub ground: Ground<f64, 3>,
    /// Every contact held.
    pub modes: Modes<NK, 3>,
    /// The spec's friction coefficients.
    pub mu: SVector<f64, NK>,
}

/// The robot on its feet ([`on_its_feet`], its body at `position` turned by
/// `orientation`), every contact held, where its least holding torques hold it still
/// ([`HELD`]); where they do not at home, the pose [`standing_pose`] finds near it
/// (springs settled under the weight, posture weight 0.1 per radian).
pub fn standing_start<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<f64>,
    position: Vector3<f64>,
    orientation: UnitQuaternion<f64>,
) -> Result<StandingStart<NQ, NK>, CannotStand>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let (start, ground) = on_its_feet::<L, NQ, NC, NU, NK>(params, position, orientation)?;
    let modes = Modes::stick();
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, 3>();
    let (_, at_home) =
        holding_torques::<L, f64, NQ, NC, NU, NK>(params, &start, &modes, &ground, &mu)
            .map_err(CannotStand::Holding)?;
    let state = if at_home < HELD {
        start
    } else {
        let pose =
            standing_pose::<L, NQ, NC, NU, NK>(params, &start, &modes, &ground, &mu, 0.1, 100);
        match pose {
            Ok(pose) if pose.left < HELD => pose.state,
            other => {
                return Err(CannotStand::NoStandingPose {
                    at_home,
                    at_best: other.map(|p| p.left),
                })
            }
        }
    };
    Ok(StandingStart {
        state,
        ground,
        modes,
        mu,
    })
}
