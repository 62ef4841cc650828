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

use nalgebra::{DMatrix, DVector, SVector};

use super::{
    free_joint, ground_in_chart, holding_torques, stance_dynamics, RobotDynamicsError, RobotState,
};
use crate::dynamics::contact::{Ground, Modes};
use crate::model::contract::ContactModel;

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
