//! The exact linearization of one integrator step, `δx⁺ = A δx + B δu` (DESIGN.md §3.2),
//! in joint coordinates and on the constraint manifold.
//!
//! [`linearize_step`] differentiates the very step [`crate::simulate::step`] takes (RK4
//! or semi-implicit Euler, torques held over the step, Baumgarte terms as configured) by
//! the chain rule through its stages, each stage's Jacobian from
//! [`crate::dynamics::derivatives::forward_dynamics_derivatives`]; the post-step projection onto
//! the constraints, when on, is differentiated to first order at the projected state
//! (the terms proportional to the drift it removes, `φ` and `J q̇` after the step, are
//! left out). Without the projection the linearization is exact (tested to 1e-6 against
//! differences of the step); with it, differences of the step agree to about 1e-5 on most
//! legs and to 1.4e-4 in chart coordinates on `minitaur_pinned_toe`, a gap not yet
//! explained. A closed chain's `2 NQ` joint states
//! are not independent: `φ(q) = 0` and `J q̇ = 0` leave `2 m` of them free (`m` the
//! mobility). [`ManifoldChart`] picks `m` joints as coordinates of the manifold, lifts
//! them to joint states, and gives the linearization in them
//! ([`ManifoldChart::linearize_step`]): the `(A, B)` an MPC or an LQR on a closed chain
//! needs, of full rank where the chain is regular.

use nalgebra::{SMatrix, SVector};

use crate::assembly::{assemble_holding, check_on_closures, AssemblyError, Tolerance};
use crate::dynamics::derivatives::{forward_dynamics_derivatives, ForwardDynamicsDerivatives};
use crate::dynamics::forward::DynamicsError;
use crate::dynamics::structure::factor_closure_rows;
use crate::model::contract::{LegDynamics, Real};
use crate::model::linalg::{all_finite, mul, Cholesky, Lu};
pub use crate::simulate::source::LinearizationError;
use crate::simulate::source::State;
use crate::simulate::step::{advance, project_onto_closures, Method, StepOptions};

/// `δx⁺ = A δx + B δu` of one step in joint coordinates, by blocks:
/// `δq⁺ = q_q δq + q_qd δq̇ + q_u δu`, `δq̇⁺ = qd_q δq + qd_qd δq̇ + qd_u δu`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepJacobian<T: Real, const NQ: usize, const NU: usize> {
    /// `∂q⁺/∂q`.
    pub q_q: SMatrix<T, NQ, NQ>,
    /// `∂q⁺/∂q̇`.
    pub q_qd: SMatrix<T, NQ, NQ>,
    /// `∂q⁺/∂u`.
    pub q_u: SMatrix<T, NQ, NU>,
    /// `∂q̇⁺/∂q`.
    pub qd_q: SMatrix<T, NQ, NQ>,
    /// `∂q̇⁺/∂q̇`.
    pub qd_qd: SMatrix<T, NQ, NQ>,
    /// `∂q̇⁺/∂u`.
    pub qd_u: SMatrix<T, NQ, NU>,
}

/// Tangents of `C` directions: the changes of `(q, q̇)` and the torque change `δu` that
/// moves them.
#[derive(Clone, Copy)]
struct Tangent<T: Real, const NQ: usize, const NU: usize, const C: usize> {
    q: SMatrix<T, NQ, C>,
    qd: SMatrix<T, NQ, C>,
    u: SMatrix<T, NU, C>,
}

impl<T: Real, const NQ: usize, const NU: usize, const C: usize> Tangent<T, NQ, NU, C> {
    /// `δq̈` of a stage whose derivatives are `d`.
    fn acceleration<const NC: usize>(
        &self,
        d: &ForwardDynamicsDerivatives<T, NQ, NC, NU>,
    ) -> SMatrix<T, NQ, C> {
        mul(&d.qdd_q, &self.q) + mul(&d.qdd_qd, &self.qd) + mul(&d.qdd_u, &self.u)
    }

    /// The stage state `x + c (k_q, k_v)` of the tangent, for stage tangents `(k_q, k_v)`.
    fn shifted(&self, kq: &SMatrix<T, NQ, C>, kv: &SMatrix<T, NQ, C>, c: T) -> Self {
        Tangent {
            q: self.q + kq * c,
            qd: self.qd + kv * c,
            u: self.u,
        }
    }
}

/// The stages' derivatives of one step.
struct Stages<T: Real, const NQ: usize, const NC: usize, const NU: usize> {
    /// One for semi-implicit Euler, four for RK4.
    derivatives: [Option<ForwardDynamicsDerivatives<T, NQ, NC, NU>>; 4],
}

/// The stages' derivatives of one step.before its projection:
/// the integrator's own arithmetic ([`crate::simulate::advance`]), each stage's
/// acceleration taken from its derivatives, so no stage is solved twice.
fn stages<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &State<T, NQ>,
    u: &SVector<T, NU>,
    opts: &StepOptions<T>,
) -> Result<(Stages<T, NQ, NC, NU>, State<T, NQ>), LinearizationError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let at = |q: &SVector<T, NQ>, qd: &SVector<T, NQ>| {
        forward_dynamics_derivatives::<L, T, NQ, NC, NU>(params, q, qd, u, opts.baumgarte)
    };
    let d1 = at(&state.q, &state.qd)?;
    let mut derivatives = [Some(d1), None, None, None];
    let mut k = 1;
    let next = advance(
        opts.method,
        opts.dt,
        &state.q,
        &state.qd,
        d1.acceleration.qdd,
        |_, q, qd| {
            let d = at(&q, &qd)?;
            derivatives[k] = Some(d);
            k += 1;
            Ok::<_, DynamicsError>(d.acceleration.qdd)
        },
    )?;
    Ok((Stages { derivatives }, next))
}

/// Pushes tangents through the step's stages (before projection).
fn propagate<T: Real, const NQ: usize, const NC: usize, const NU: usize, const C: usize>(
    stages: &Stages<T, NQ, NC, NU>,
    method: Method,
    dt: T,
    x: Tangent<T, NQ, NU, C>,
) -> (SMatrix<T, NQ, C>, SMatrix<T, NQ, C>) {
    let d = |i: usize| stages.derivatives[i].as_ref().expect("stage evaluated");
    match method {
        Method::SemiImplicitEuler => {
            let qd = x.qd + x.acceleration(d(0)) * dt;
            (x.q + qd * dt, qd)
        }
        Method::Rk4 => {
            let half = dt * T::lit(0.5);
            let (k1q, k1v) = (x.qd, x.acceleration(d(0)));
            let x2 = x.shifted(&k1q, &k1v, half);
            let (k2q, k2v) = (x2.qd, x2.acceleration(d(1)));
            let x3 = x.shifted(&k2q, &k2v, half);
            let (k3q, k3v) = (x3.qd, x3.acceleration(d(2)));
            let x4 = x.shifted(&k3q, &k3v, dt);
            let (k4q, k4v) = (x4.qd, x4.acceleration(d(3)));
            let (sixth, two) = (dt / T::lit(6.0), T::lit(2.0));
            (
                x.q + (k1q + (k2q + k3q) * two + k4q) * sixth,
                x.qd + (k1v + (k2v + k3v) * two + k4v) * sixth,
            )
        }
    }
}

/// The first-order change of the post-step projection at the projected state `(q, q̇)`:
/// the position projection (least-squares) passes `δq − Jᵀ (J Jᵀ)⁻¹ J δq`, the velocity
/// projection (least kinetic energy) `δq̇ − Y S⁻¹ (J δq̇ + J̇ δq)` with `Y = M⁻¹ Jᵀ`,
/// `S = J Y` (`∂(J q̇)/∂q = J̇`).
struct ProjectionJacobian<T: Real, const NQ: usize> {
    position: SMatrix<T, NQ, NQ>,
    velocity: SMatrix<T, NQ, NQ>,
    velocity_q: SMatrix<T, NQ, NQ>,
}

fn projection_jacobian<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &State<T, NQ>,
) -> Result<ProjectionJacobian<T, NQ>, LinearizationError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let (q, qd) = (&state.q, &state.qd);
    let j = L::constraint_jacobian(q, params);
    let jdot = L::constraint_derivatives(q, qd, &SVector::zeros(), &SVector::zeros(), params)
        .jacobian_rate;
    let eye = SMatrix::<T, NQ, NQ>::identity();
    // Position: the minimal-norm correction.
    let jjt = factor_closure_rows::<L, T, NQ, NC, NU>(&(j * j.transpose()))
        .ok_or(AssemblyError::Singular)?;
    let mut pj = j;
    jjt.solve_mut(&mut pj); // (J Jᵀ)⁻¹ J
    let position = eye - j.transpose() * pj;
    // Velocity: the correction in the metric of M.
    let chol_m = Cholesky::new(&L::mass_matrix(q, params))
        .ok_or(DynamicsError::MassMatrixNotPositiveDefinite)?;
    let mut y = j.transpose();
    chol_m.solve_mut(&mut y);
    let s = factor_closure_rows::<L, T, NQ, NC, NU>(&(j * y)).ok_or(AssemblyError::Singular)?;
    let (mut sj, mut sjdot) = (j, jdot);
    s.solve_mut(&mut sj);
    s.solve_mut(&mut sjdot);
    Ok(ProjectionJacobian {
        position,
        velocity: eye - y * sj,
        velocity_q: -(y * sjdot),
    })
}

/// One step of [`crate::simulate::step`] from `state` with the torques `u` held, and its
/// exact linearization. Returns the next state and `(A, B)` by blocks.
pub fn linearize_step<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &State<T, NQ>,
    u: &SVector<T, NU>,
    opts: &StepOptions<T>,
) -> Result<(State<T, NQ>, StepJacobian<T, NQ, NU>), LinearizationError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let (stages, mut next) = stages::<L, T, NQ, NC, NU>(params, state, u, opts)?;
    project_onto_closures::<L, T, NQ, NC, NU>(params, &mut next, opts)?;
    let zero_q = SMatrix::<T, NQ, NQ>::zeros();
    let eye = SMatrix::<T, NQ, NQ>::identity();
    let (mut q_q, mut qd_q) = propagate(
        &stages,
        opts.method,
        opts.dt,
        Tangent {
            q: eye,
            qd: zero_q,
            u: SMatrix::<T, NU, NQ>::zeros(),
        },
    );
    let (mut q_qd, mut qd_qd) = propagate(
        &stages,
        opts.method,
        opts.dt,
        Tangent {
            q: zero_q,
            qd: eye,
            u: SMatrix::<T, NU, NQ>::zeros(),
        },
    );
    let (mut q_u, mut qd_u) = propagate(
        &stages,
        opts.method,
        opts.dt,
        Tangent {
            q: SMatrix::<T, NQ, NU>::zeros(),
            qd: SMatrix::<T, NQ, NU>::zeros(),
            u: SMatrix::<T, NU, NU>::identity(),
        },
    );
    if opts.project && NC > 0 {
        let p = projection_jacobian::<L, T, NQ, NC, NU>(params, &next)?;
        (q_q, qd_q) = (
            p.position * q_q,
            p.velocity * qd_q + p.velocity_q * (p.position * q_q),
        );
        (q_qd, qd_qd) = (
            p.position * q_qd,
            p.velocity * qd_qd + p.velocity_q * (p.position * q_qd),
        );
        (q_u, qd_u) = (
            p.position * q_u,
            p.velocity * qd_u + p.velocity_q * (p.position * q_u),
        );
    }
    let jac = StepJacobian {
        q_q,
        q_qd,
        q_u,
        qd_q,
        qd_qd,
        qd_u,
    };
    if ![
        all_finite(&jac.q_q),
        all_finite(&jac.q_qd),
        all_finite(&jac.qd_q),
        all_finite(&jac.qd_qd),
        all_finite(&jac.q_u),
        all_finite(&jac.qd_u),
    ]
    .iter()
    .all(|&ok| ok)
    {
        return Err(DynamicsError::NonFinite.into());
    }
    Ok((next, jac))
}

/// `M` of the leg's joints as coordinates of its constraint manifold (`M` = the mobility
/// there): every other joint follows from them through `φ(q) = 0`, and the joint
/// velocities from theirs through `J q̇ = 0`. Motors are chosen first, so on a fully
/// actuated leg the coordinates are the motor angles wherever the passive joints are
/// regular; otherwise the joints whose removal leaves the closure rows best conditioned
/// (complete pivoting on `J`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ManifoldChart<T: Real, const NQ: usize, const M: usize> {
    /// The joints used as coordinates, in increasing order.
    pub coordinates: [usize; M],
    /// The pose the chart was made at: the guess from which lifts assemble (it picks the
    /// assembly mode).
    pub origin: SVector<T, NQ>,
    independent: [bool; NQ],
}

/// The closure rows chosen by the pivoting (`rank` of them) and which joints they solve for.
struct Pivots<const NQ: usize, const NC: usize> {
    rows: [usize; NC],
    rank: usize,
    dependent: [bool; NQ],
}

/// Complete pivoting on `J` with the columns' magnitudes scaled by `weight` (a column of
/// weight zero is never a pivot: it stays a coordinate).
fn pivot_closure<T: Real, const NQ: usize, const NC: usize>(
    j: &SMatrix<T, NC, NQ>,
    weight: &[T; NQ],
) -> Pivots<NQ, NC> {
    let mut a = *j;
    let (mut row_used, mut dependent) = ([false; NC], [false; NQ]);
    let mut rows = [0usize; NC];
    let scale = a.amax();
    let mut rank = 0;
    for _ in 0..NC {
        let (mut best, mut at) = (T::zero(), None);
        for i in (0..NC).filter(|&i| !row_used[i]) {
            for c in (0..NQ).filter(|&c| !dependent[c]) {
                let v = a[(i, c)].abs() * weight[c];
                if v > best {
                    (best, at) = (v, Some((i, c)));
                }
            }
        }
        let Some((i, c)) = at else { break };
        if a[(i, c)].abs() <= T::default_epsilon().sqrt() * T::lit(1e-2) * scale {
            break;
        }
        row_used[i] = true;
        dependent[c] = true;
        rows[rank] = i;
        rank += 1;
        for i2 in (0..NC).filter(|&i2| !row_used[i2]) {
            let factor = a[(i2, c)] / a[(i, c)];
            for c2 in 0..NQ {
                let v = a[(i, c2)];
                a[(i2, c2)] -= factor * v;
            }
        }
    }
    Pivots {
        rows,
        rank,
        dependent,
    }
}

/// `δq = G δθ`, `δq̇ = G δθ̇ + W δθ`: how chart coordinates move the joint state at a state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChartTangent<T: Real, const NQ: usize, const M: usize> {
    /// `G = ∂q/∂θ`: `J G = 0`, the identity on the coordinates.
    pub g: SMatrix<T, NQ, M>,
    /// `W`: keeps `J q̇ = 0` to first order (`J W δθ + J̇ G δθ = 0`).
    pub w: SMatrix<T, NQ, M>,
}

/// The linearization of one step on the constraint manifold: `δx⁺ = A δx + B δu` with
/// `x = (θ, θ̇)` the chart's coordinates and their rates (`NX = 2 M`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ManifoldLinearization<T: Real, const NQ: usize, const NX: usize, const NU: usize> {
    /// `A = ∂x⁺/∂x`.
    pub a: SMatrix<T, NX, NX>,
    /// `B = ∂x⁺/∂u`.
    pub b: SMatrix<T, NX, NU>,
    /// The joint state after the step.
    pub next: State<T, NQ>,
}

impl<T: Real, const NQ: usize, const M: usize> ManifoldChart<T, NQ, M> {
    /// A chart at `q` (assembled): fails with [`LinearizationError::Dimension`] unless the
    /// leg has `M` degrees of freedom there.
    pub fn new<L, const NC: usize, const NU: usize>(
        params: &L::Params<T>,
        q: &SVector<T, NQ>,
    ) -> Result<Self, LinearizationError>
    where
        L: LegDynamics<NQ, NC, NU>,
    {
        if !q.iter().all(|x| x.is_finite()) {
            return Err(DynamicsError::NonFinite.into());
        }
        // A chart is of the constraint manifold: a pose off it is refused, not linearized.
        check_on_closures::<L, T, NQ, NC, NU>(params, q)?;
        let j = L::constraint_jacobian(q, params);
        // A motor's column is a pivot only when no passive column is nearly as good.
        let weight: [T; NQ] = core::array::from_fn(|c| {
            if L::ACTUATED.contains(&c) {
                T::lit(1e-3)
            } else {
                T::one()
            }
        });
        let pivots = pivot_closure(&j, &weight);
        let mobility = NQ - pivots.rank;
        if mobility != M {
            return Err(LinearizationError::Dimension {
                mobility,
                states: 2 * M,
            });
        }
        let mut coordinates = [0usize; M];
        for (k, c) in (0..NQ).filter(|&c| !pivots.dependent[c]).enumerate() {
            coordinates[k] = c;
        }
        Ok(ManifoldChart {
            coordinates,
            origin: *q,
            independent: core::array::from_fn(|c| !pivots.dependent[c]),
        })
    }

    /// `(θ, θ̇)`: the chart's coordinates of a joint state.
    pub fn coordinates_of(&self, state: &State<T, NQ>) -> (SVector<T, M>, SVector<T, M>) {
        (
            SVector::from_fn(|k, _| state.q[self.coordinates[k]]),
            SVector::from_fn(|k, _| state.qd[self.coordinates[k]]),
        )
    }

    /// The joint state of chart coordinates `(θ, θ̇)`: the other joints assembled from the
    /// chart's origin, their rates from `J q̇ = 0`.
    pub fn lift<L, const NC: usize, const NU: usize>(
        &self,
        params: &L::Params<T>,
        theta: &SVector<T, M>,
        theta_dot: &SVector<T, M>,
        tol: &Tolerance<T>,
    ) -> Result<State<T, NQ>, LinearizationError>
    where
        L: LegDynamics<NQ, NC, NU>,
    {
        let mut q = self.origin;
        for (k, &c) in self.coordinates.iter().enumerate() {
            q[c] = theta[k];
        }
        assemble_holding::<L, T, NQ, NC, NU>(params, &mut q, &self.independent, tol)?;
        let tangent = self.tangent::<L, NC, NU>(params, &q, &SVector::zeros())?;
        Ok(State {
            q,
            qd: tangent.g * theta_dot,
        })
    }

    /// [`ChartTangent`] at `(q, q̇)`: `G` solves `J G = 0` with the identity on the
    /// coordinates; `W` keeps `J q̇ = 0` to first order, `J δq̇ + J̇ δq = 0`.
    pub fn tangent<L, const NC: usize, const NU: usize>(
        &self,
        params: &L::Params<T>,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
    ) -> Result<ChartTangent<T, NQ, M>, LinearizationError>
    where
        L: LegDynamics<NQ, NC, NU>,
    {
        let j = L::constraint_jacobian(q, params);
        let jdot = L::constraint_derivatives(q, qd, &SVector::zeros(), &SVector::zeros(), params)
            .jacobian_rate;
        let weight: [T; NQ] = core::array::from_fn(|c| {
            if self.independent[c] {
                T::zero()
            } else {
                T::one()
            }
        });
        let pivots = pivot_closure(&j, &weight);
        if NQ - pivots.rank != M {
            // The passive joints lose rank at this pose for these coordinates.
            return Err(AssemblyError::Singular.into());
        }
        // E = [J rows; unit rows of the coordinates]: E δq = (J δq, δθ).
        let mut e = SMatrix::<T, NQ, NQ>::zeros();
        for (r, &row) in pivots.rows[..pivots.rank].iter().enumerate() {
            e.set_row(r, &j.row(row));
        }
        for (k, &c) in self.coordinates.iter().enumerate() {
            e[(pivots.rank + k, c)] = T::one();
        }
        let lu = Lu::new(&e).ok_or(AssemblyError::Singular)?;
        let mut rhs = SMatrix::<T, NQ, M>::zeros();
        for k in 0..M {
            rhs[(pivots.rank + k, k)] = T::one();
        }
        let g = lu.solve(&rhs);
        let jdg = jdot * g;
        let mut rhs_w = SMatrix::<T, NQ, M>::zeros();
        for (r, &row) in pivots.rows[..pivots.rank].iter().enumerate() {
            for k in 0..M {
                rhs_w[(r, k)] = -jdg[(row, k)];
            }
        }
        let w = lu.solve(&rhs_w);
        if !(all_finite(&g) && all_finite(&w)) {
            return Err(AssemblyError::Singular.into());
        }
        Ok(ChartTangent { g, w })
    }

    /// One step from `state` (on the manifold) with torques `u` held, linearized in the
    /// chart: `A = S A_q [G 0; W G]`, `B = S B_q` with `S` the rows of the coordinates and
    /// `A_q`, `B_q` the joint-space linearization ([`linearize_step`]). `NX` must be
    /// `2 M`.
    pub fn linearize_step<L, const NC: usize, const NU: usize, const NX: usize>(
        &self,
        params: &L::Params<T>,
        state: &State<T, NQ>,
        u: &SVector<T, NU>,
        opts: &StepOptions<T>,
    ) -> Result<ManifoldLinearization<T, NQ, NX, NU>, LinearizationError>
    where
        L: LegDynamics<NQ, NC, NU>,
    {
        if NX != 2 * M {
            return Err(LinearizationError::Dimension {
                mobility: M,
                states: NX,
            });
        }
        let tangent = self.tangent::<L, NC, NU>(params, &state.q, &state.qd)?;
        let (next, jac) = linearize_step::<L, T, NQ, NC, NU>(params, state, u, opts)?;
        let (g, w) = (&tangent.g, &tangent.w);
        // Columns for δθ and for δθ̇, joint rows.
        let (q_theta, q_rate) = (jac.q_q * g + jac.q_qd * w, jac.q_qd * g);
        let (qd_theta, qd_rate) = (jac.qd_q * g + jac.qd_qd * w, jac.qd_qd * g);
        let mut a = SMatrix::<T, NX, NX>::zeros();
        let mut b = SMatrix::<T, NX, NU>::zeros();
        for (k, &c) in self.coordinates.iter().enumerate() {
            for l in 0..M {
                a[(k, l)] = q_theta[(c, l)];
                a[(k, M + l)] = q_rate[(c, l)];
                a[(M + k, l)] = qd_theta[(c, l)];
                a[(M + k, M + l)] = qd_rate[(c, l)];
            }
            for l in 0..NU {
                b[(k, l)] = jac.q_u[(c, l)];
                b[(M + k, l)] = jac.qd_u[(c, l)];
            }
        }
        Ok(ManifoldLinearization { a, b, next })
    }

    /// The torques that hold the leg at rest at `q` (`q̈ = 0` at `q̇ = 0`), least squares
    /// over the motors when they outnumber the degrees of freedom; fails with
    /// [`LinearizationError::NotAnEquilibrium`] when no torque does (fewer motors than
    /// degrees of freedom, and the passive joints away from their equilibrium).
    pub fn holding_torque<L, const NC: usize, const NU: usize>(
        &self,
        params: &L::Params<T>,
        q: &SVector<T, NQ>,
    ) -> Result<SVector<T, NU>, LinearizationError>
    where
        L: LegDynamics<NQ, NC, NU>,
    {
        let rest = SVector::<T, NQ>::zeros();
        let d = forward_dynamics_derivatives::<L, T, NQ, NC, NU>(
            params,
            q,
            &rest,
            &SVector::zeros(),
            None,
        )?;
        // On the manifold at rest q̈ = G θ̈, so q̈ = 0 ⇔ the coordinates' θ̈ = 0: solve
        // A u = −θ̈(0), A = the coordinates' rows of ∂q̈/∂u (M × NU).
        let a = SMatrix::<T, M, NU>::from_fn(|k, l| d.qdd_u[(self.coordinates[k], l)]);
        let b = SVector::<T, M>::from_fn(|k, _| -d.acceleration.qdd[self.coordinates[k]]);
        let u = if M >= NU {
            let chol = Cholesky::new(&(a.transpose() * a))
                .ok_or(LinearizationError::MotorsDoNotMoveCoordinates)?;
            let mut u = a.transpose() * b;
            chol.solve_mut(&mut u);
            u
        } else {
            let chol = Cholesky::new(&(a * a.transpose()))
                .ok_or(LinearizationError::MotorsDoNotMoveCoordinates)?;
            let mut y = b;
            chol.solve_mut(&mut y);
            a.transpose() * y
        };
        let residual = (a * u - b).amax();
        let scale = b.amax().max(T::one());
        // (A NaN residual is refused too: it is not finite.)
        if !residual.is_finite() || residual > T::default_epsilon().sqrt() * scale {
            return Err(LinearizationError::NotAnEquilibrium {
                residual: residual.to_subset().unwrap_or(f64::NAN),
            });
        }
        Ok(u)
    }
}
