//! A robot's feet free to lift, slip and land: time stepping at the velocity level with
//! the contact mode of every foot found at once by one complementarity solve a step
//! (Stewart & Trinkle 1996; Anitescu & Potra 1997), the closures kept exact.
//!
//! Over a step of length `h` from `(q, v)`, with `τ` the applied and passive forces,
//! the rates after it satisfy
//!
//! ```text
//! M (v⁺ − v) = h τ + Jᵀ F + Cᵀ p,        J v⁺ = 0            (closures)
//! 0 ≤ p_n   ⊥  n·C v⁺ + φ / h ≥ 0                              (each contact)
//! 0 ≤ β_j   ⊥  d_jᵀ C_t v⁺ + γ ≥ 0,     0 ≤ γ ⊥ μ p_n − Σ_j β_j ≥ 0
//! ```
//!
//! with `p` each contact's impulse in the ground's frame (`p_t = Σ_j β_j d_j` along the
//! ground, `p_n` along its normal), `φ` its height over the ground, and `d_j` the
//! friction pyramid's `m` edges (`m = 4` by default, `±t₁, ±t₂`, MuJoCo's default
//! pyramid; the pyramid is inscribed in the cone `|p_t| ≤ μ p_n`). A contact above the
//! ground takes part too: it is pushed only if it would pass through the ground within
//! the step (`φ/h` is its allowance), so touchdowns of any number of feet, together or
//! not, are plastic impacts inside the step, and a foot whose push would turn into a
//! pull lifts off. `γ` is a sliding contact's slip speed (zero when it sticks), and
//! friction then acts along the pyramid's edge most against the slip.
//!
//! Eliminating `v⁺` through the closures' KKT system leaves an LCP in `(p_n, β, γ)` on
//! the Delassus matrix `C K Cᵀ`; [`Lemke`] solves it exactly, and its basis is the step's
//! contact mode. Each step first tries the last step's basis (one linear solve, kept
//! where it is feasible): where the modes have not changed, no pivot is taken, and a
//! rigid foot's load split between its points (not unique) stays as it was rather than
//! jumping between the solutions pivoting would reach. The pose then moves by `h v⁺` and the closures are projected
//! (`project_position_near`), as in the Euler stance step; a contact's height is put
//! back by the `φ/h` of the next step rather than by a projection.

use std::vec;
use std::vec::Vec;

use core::fmt;

use nalgebra::{SMatrix, SVector, Vector3};

use super::{free_joint, ground_in_chart, into_chart, RobotError, RobotState};
use crate::assembly::{project_position_near, Tolerance};
use crate::dynamics::contact::{ContactMode, ContactRows, Ground, Modes, StructuredSolve};
use crate::dynamics::forward::factor_mass;
use crate::dynamics::lcp::{LcpError, Lemke};
use crate::dynamics::{actuation, DynamicsError};
use crate::model::contract::{ContactModel, Real};
use crate::simulate::StepError;

/// The complementarity problem of one robot's contacts, allocated once: what
/// [`contact_step`] solves in, so that a step allocates nothing.
#[derive(Clone, Debug)]
pub struct FootContacts<T: Real> {
    contacts: usize,
    /// The pyramid's edges `d_j` in the ground's tangent plane, `(cos, sin)` pairs.
    edges: Vec<(T, T)>,
    lemke: Lemke<T>,
    m: Vec<T>,
    q: Vec<T>,
}

impl<T: Real> FootContacts<T> {
    /// For `contacts` contact points and a friction pyramid of `edges` edges (at least
    /// 3; 4 is `±t₁, ±t₂`).
    pub fn new(contacts: usize, edges: usize) -> Result<Self, ContactStepError> {
        if edges < 3 {
            return Err(ContactStepError::PyramidEdges { edges });
        }
        let n = contacts * (edges + 2);
        let snap = |x: T| {
            if x.abs() < T::lit(1e-15) {
                T::zero()
            } else {
                x
            }
        };
        let edges = (0..edges)
            .map(|j| {
                let (s, c) = (T::two_pi() * T::lit(j as f64 / edges as f64)).sincos();
                (snap(c), snap(s))
            })
            .collect();
        Ok(FootContacts {
            contacts,
            edges,
            lemke: Lemke::new(n),
            m: vec![T::zero(); n * n],
            q: vec![T::zero(); n],
        })
    }

    /// For robot `L`'s contacts, with a 4-edge pyramid.
    pub fn of<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>() -> Self
    where
        L: ContactModel<NQ, NC, NU, NK, 3>,
    {
        Self::new(NK / 3, 4).expect("4 edges")
    }

    /// The pyramid's number of edges.
    pub fn edges(&self) -> usize {
        self.edges.len()
    }
}

/// What a [`contact_step`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactStep<T: Real, const NQ: usize, const NC: usize, const NK: usize> {
    /// Each contact's impulse over the step in the chart ground's frame `(t₁, t₂, n)`.
    pub impulses: SVector<T, NK>,
    /// Each contact's mean force over the step in the world (`p / h`, stacked `x, y, z`).
    pub world_forces: SVector<T, NK>,
    /// Each contact's mode over the step: flight where it takes no push, sliding where
    /// its slip speed `γ` is positive, sticking otherwise (each within `10⁴ ε` of the
    /// problem's impulses and speeds: a degenerate basis's rounding is not a mode).
    pub modes: Modes<NK, 3>,
    /// Each contact's slip speed `γ` (m/s) on its normal row, zero elsewhere and on a
    /// contact in flight.
    pub slip_speed: SVector<T, NK>,
    /// The closures' impulses.
    pub closure: SVector<T, NC>,
    /// `(v⁺ − v) / h`, in the chart centred at the step's start.
    pub acceleration: SVector<T, NQ>,
    /// `(v* − v) / h`: what it would be without the ground (the closures kept).
    pub free_acceleration: SVector<T, NQ>,
    /// Lemke's pivots (zero where the last step's contact modes solved this one).
    pub pivots: usize,
    /// Whether the last step's modes (its basis) solved this step's problem, checked
    /// feasible, with no pivot ([`Lemke::warm_start`]).
    pub warm: bool,
}

/// Why a [`contact_step`] failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ContactStepError {
    /// See [`RobotError`].
    Robot(RobotError),
    /// See [`StepError`] (the dynamics or the closures' projection).
    Step(StepError),
    /// The complementarity solve: see [`LcpError`].
    Contact(LcpError),
    /// The step length is not positive and finite.
    TimeStep {
        /// The step asked for (s).
        dt: f64,
    },
    /// A pyramid of fewer than 3 edges does not bound friction.
    PyramidEdges {
        /// The edges asked for.
        edges: usize,
    },
    /// The [`FootContacts`] was made for another number of contacts.
    Contacts {
        /// The robot's contacts.
        robot: usize,
        /// The problem's.
        problem: usize,
    },
}

impl From<RobotError> for ContactStepError {
    fn from(e: RobotError) -> Self {
        ContactStepError::Robot(e)
    }
}

impl From<StepError> for ContactStepError {
    fn from(e: StepError) -> Self {
        ContactStepError::Step(e)
    }
}

impl From<DynamicsError> for ContactStepError {
    fn from(e: DynamicsError) -> Self {
        ContactStepError::Step(StepError::from(e))
    }
}

impl From<LcpError> for ContactStepError {
    fn from(e: LcpError) -> Self {
        ContactStepError::Contact(e)
    }
}

impl fmt::Display for ContactStepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ContactStepError::Robot(e) => write!(f, "{e}"),
            ContactStepError::Step(e) => write!(f, "{e}"),
            ContactStepError::Contact(e) => write!(f, "contact mode: {e}"),
            ContactStepError::TimeStep { dt } => {
                write!(f, "the time step {dt} s is not positive and finite")
            }
            ContactStepError::PyramidEdges { edges } => write!(
                f,
                "a friction pyramid of {edges} edges bounds nothing: give at least 3"
            ),
            ContactStepError::Contacts { robot, problem } => write!(
                f,
                "the contact problem was made for {problem} contacts, the robot has {robot}"
            ),
        }
    }
}

impl std::error::Error for ContactStepError {}

/// One step of length `dt` of the robot with every contact free to push, stick, slide or
/// leave the ground (the module's LCP), motor torques `u` and a force `push` (N, in the
/// world) on the body frame's origin held over the step, on the world's `ground` with
/// friction `mu` (per row, as [`super::stance_dynamics`]'s). Allocates nothing. On an
/// error `state` is left as it was.
#[allow(clippy::too_many_arguments)]
pub fn contact_step<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    problem: &mut FootContacts<T>,
    params: &L::Params<T>,
    state: &mut RobotState<T, NQ>,
    u: &SVector<T, NU>,
    push: &Vector3<T>,
    ground: &Ground<T, 3>,
    mu: &SVector<T, NK>,
    dt: T,
) -> Result<ContactStep<T, NQ, NC, NK>, ContactStepError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    if !(dt.is_finite() && dt > T::zero()) {
        return Err(ContactStepError::TimeStep {
            dt: dt.to_subset().unwrap_or(f64::NAN),
        });
    }
    let points = NK / 3;
    if problem.contacts != points {
        return Err(ContactStepError::Contacts {
            robot: points,
            problem: problem.contacts,
        });
    }
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut next = *state;
    next.recentre(f);
    let mut chart = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut chart, &next.orientation)?;
    let local = ground_in_chart(ground, &next.position, &next.orientation);
    let centre = next.orientation;
    let mut applied = actuation::<L, T, NQ, NC, NU>(u);
    let on_body = centre.inverse_transform_vector(push);
    for k in 0..3 {
        applied[f + k] += on_body[k];
    }
    let (q, v) = (next.q, next.v);
    let terms = L::dynamics_terms(&q, &v, &chart);
    let chol_m = factor_mass::<L, T, NQ, NC, NU>(&terms.mass_matrix)?;
    let c = local.rows(&L::contact_jacobian(&q, &chart));
    let heights = local.coordinates(&L::contact_positions(&q, &chart));
    // No contact row held: the solves see the closures only (K, the closures'
    // constrained inverse of M).
    let free = ContactRows::from_rows(c, &Modes::<NK, 3>::flight(), mu, &SVector::zeros());
    let per_dt = T::one() / dt;
    let tau = applied - terms.bias_forces - L::damping_forces(&v, &chart);
    let j = &terms.constraint_jacobian;
    // v* = v + h K τ with J v* = 0: the rates the step takes without the ground.
    let (a_free, f_free, _) = chol_m.solve_structured(
        j,
        &(-(j * v) * per_dt),
        L::REDUNDANT_ROWS,
        &free,
        &SVector::<T, NK>::zeros(),
        &tau,
    )?;
    let v_free = v + a_free * dt;
    // X = K Cᵀ: the rates an impulse on each contact row gives.
    let (x, f_x, _) = chol_m.solve_structured(
        j,
        &SMatrix::<T, NC, NK>::zeros(),
        L::REDUNDANT_ROWS,
        &free,
        &SMatrix::<T, NK, NK>::zeros(),
        &c.transpose(),
    )?;
    let delassus = c * x;
    let b = c * v_free;
    fill_problem(problem, &delassus, &b, &heights, mu, per_dt);
    problem.lemke.solve(&problem.m, &problem.q)?;
    let (z, pivots, warm) = (problem.lemke.z(), problem.lemke.pivots, problem.lemke.warm);
    // The impulses in the contact rows, and the modes from the basis.
    let edges = &problem.edges;
    let ne = edges.len();
    let mut p = SVector::<T, NK>::zeros();
    let mut modes = Modes::<NK, 3>::flight();
    let mut slip_speed = SVector::<T, NK>::zeros();
    // A push or a slip speed within rounding of zero (a degenerate basis's) is none.
    let big = |v: &[T]| v.iter().fold(T::zero(), |a, x| a.max(x.abs()));
    let rounding = T::lit(1e4) * T::default_epsilon();
    let (least_push, least_slip) = (rounding * big(z), rounding * big(&problem.q));
    for k in 0..points {
        p[3 * k + 2] = z[k];
        for (e, &(cj, sj)) in edges.iter().enumerate() {
            let beta = z[points + ne * k + e];
            p[3 * k] += beta * cj;
            p[3 * k + 1] += beta * sj;
        }
        // In flight the slip speed means nothing (γ is not unique there): left zero.
        if z[k] > least_push {
            let gamma = z[points * (ne + 1) + k];
            slip_speed[3 * k + 2] = gamma;
            modes.set(
                k,
                if gamma > least_slip {
                    ContactMode::Slide { forward: true }
                } else {
                    ContactMode::Stick
                },
            );
        }
    }
    next.v = v_free + x * p;
    let v_plus = next.v;
    next.q += next.v * dt;
    project_position_near::<L, T, NQ, NC, NU>(&chart, &mut next.q, &q, j, &Tolerance::default())
        .map_err(|e| ContactStepError::Step(StepError::Projection(e)))?;
    next.recentre(f);
    let step = ContactStep {
        world_forces: super::forces_in_world(&local, &centre, &(p * per_dt)),
        impulses: p,
        modes,
        slip_speed,
        closure: f_free * dt + f_x * p,
        acceleration: (v_plus - v) * per_dt,
        free_acceleration: a_free,
        pivots,
        warm,
    };
    *state = next;
    Ok(step)
}

/// The LCP in `(p_n, β, γ)` (contact `k`'s `p_n` at `k`, its edges' `β` at `P + m k + j`,
/// its `γ` at `P (m + 1) + k`) from the Delassus matrix `G = C K Cᵀ`, the free contact
/// rates `b = C v*` and the heights `φ` (on each contact's normal row).
fn fill_problem<T: Real, const NK: usize>(
    problem: &mut FootContacts<T>,
    delassus: &SMatrix<T, NK, NK>,
    b: &SVector<T, NK>,
    heights: &SVector<T, NK>,
    mu: &SVector<T, NK>,
    per_dt: T,
) {
    let points = problem.contacts;
    let ne = problem.edges.len();
    let n = points * (ne + 2);
    let edges = &problem.edges;
    // Each variable's direction in the contact rows, as (row, weight) pairs: an edge's
    // `β` two (its `cos`, `sin` on the tangential rows), a normal impulse one (its
    // second pair weighs nothing).
    let dir = |a: usize| -> [(usize, T); 2] {
        if a < points {
            [(3 * a + 2, T::one()), (3 * a + 2, T::zero())]
        } else {
            let (k, e) = ((a - points) / ne, (a - points) % ne);
            [(3 * k, edges[e].0), (3 * k + 1, edges[e].1)]
        }
    };
    let m = &mut problem.m;
    m.iter_mut().for_each(|x| *x = T::zero());
    let force_vars = points * (ne + 1);
    for a in 0..force_vars {
        let da = dir(a);
        for bb in 0..force_vars {
            let db = dir(bb);
            let mut s = T::zero();
            for &(ra, wa) in &da {
                for &(rb, wb) in &db {
                    s += wa * wb * delassus[(ra, rb)];
                }
            }
            m[a * n + bb] = s;
        }
        let mut qa = T::zero();
        for &(ra, wa) in &da {
            qa += wa * b[ra];
        }
        problem.q[a] = qa;
    }
    for k in 0..points {
        let g = force_vars + k;
        problem.q[k] += heights[3 * k + 2] * per_dt;
        problem.q[g] = T::zero();
        m[g * n + k] = mu[3 * k];
        for e in 0..ne {
            let beta = points + ne * k + e;
            m[beta * n + g] = T::one();
            m[g * n + beta] = -T::one();
        }
    }
}
