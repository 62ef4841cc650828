//! Control in the actuated coordinates (DESIGN.md §3).
//!
//! The reduction writes the closed chain as `Ã θ̈ = b̃ + u` in the motor angles `θ`,
//! two ways that must agree: the Schur complement of the reordered KKT system
//! (`Ã = A11 − A12 A22⁻¹ A21`, `b̃ = b1 − A12 A22⁻¹ b2`, with `z = (passive q̈, F)`), and
//! the null-space form (`q̇ = G θ̇`, `q̈ = G θ̈ + c`, `Ã = Gᵀ M G`, `b̃ = Gᵀ(b − M c)`). The
//! controllers are [`TorqueSource`]s, so the simulator runs them directly.
//!
//! `A22` has a size (`passive joints + closure rows`) that stable Rust cannot write as a
//! const expression; it is solved embedded in `NQ + NC`: the actuated rows and columns
//! of `M` replaced by the identity and the actuated columns of `J` by zeros, which
//! leaves exactly `A22` acting on the passive entries.

use nalgebra::{SMatrix, SVector};

use crate::assembly::passive_solve;
use crate::dynamics::derivatives::forward_dynamics_derivatives_from_terms;
use crate::dynamics::forward::{rcond_floor, DynamicsError};
use crate::dynamics::structure::Structure;
use crate::model::contract::{DynamicsTerms, LegDynamics, Real};
use crate::model::linalg::all_finite;
use crate::model::linalg::{mul, mul_tn, Cholesky, PivotedLdlt};
use crate::simulate::source::ControlError;
use crate::simulate::source::State;

/// `Ã θ̈ = b̃ + u`: the dynamics in the motor angles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ActuatedDynamics<T: Real, const NU: usize> {
    /// `Ã`: the inertia the motors see, with the loop closed.
    pub a_tilde: SMatrix<T, NU, NU>,
    /// `b̃`: the rest of the reduced dynamics, from `−N − D q̇` and `−J̇ q̇`, with the loop
    /// closed.
    pub b_tilde: SVector<T, NU>,
}

/// `A22 z = r` for the passive joints and the closure forces, embedded in full size.
struct PassiveSystem<T: Real, const NQ: usize, const NC: usize> {
    chol_m: Cholesky<T, NQ>,
    /// `J` without its actuated columns.
    jp: SMatrix<T, NC, NQ>,
    /// `M̂⁻¹ J_pᵀ`.
    y: SMatrix<T, NQ, NC>,
    chol_s: Option<PivotedLdlt<T, NC>>,
    actuated: [bool; NQ],
}

impl<T: Real, const NQ: usize, const NC: usize> PassiveSystem<T, NQ, NC> {
    fn new(
        m: &SMatrix<T, NQ, NQ>,
        j: &SMatrix<T, NC, NQ>,
        actuated: [bool; NQ],
        deficiency: usize,
    ) -> Result<Self, ControlError> {
        let mut mp = *m;
        let mut jp = *j;
        for (a, _) in actuated.iter().enumerate().filter(|(_, &is)| is) {
            mp.row_mut(a).fill(T::zero());
            mp.column_mut(a).fill(T::zero());
            mp[(a, a)] = T::one();
            jp.column_mut(a).fill(T::zero());
        }
        let chol_m = Cholesky::new(&mp).ok_or(ControlError::Dynamics(
            DynamicsError::MassMatrixNotPositiveDefinite,
        ))?;
        let mut y = jp.transpose();
        chol_m.solve_mut(&mut y);
        let chol_s = if NC == 0 {
            None
        } else {
            let c = PivotedLdlt::new(&mul(&jp, &y), deficiency, rcond_floor::<T>())
                .ok_or(ControlError::SingularPassive)?;
            Some(c)
        };
        Ok(PassiveSystem {
            chol_m,
            jp,
            y,
            chol_s,
            actuated,
        })
    }

    /// Solves `[M_pp −J_pᵀ; J_p 0] (x_p, f) = (r_p, r_c)`; `x` has zero actuated entries.
    fn solve(
        &self,
        r_q: &SVector<T, NQ>,
        r_c: &SVector<T, NC>,
    ) -> (SVector<T, NQ>, SVector<T, NC>) {
        let mut x = *r_q;
        for (a, _) in self.actuated.iter().enumerate().filter(|(_, &is)| is) {
            x[a] = T::zero();
        }
        self.chol_m.solve_mut(&mut x);
        let Some(chol_s) = &self.chol_s else {
            return (x, SVector::zeros());
        };
        let mut f = r_c - mul(&self.jp, &x);
        chol_s.solve_mut(&mut f);
        (x + mul(&self.y, &f), f)
    }
}

pub(crate) fn actuated_mask<L, const NQ: usize, const NC: usize, const NU: usize>() -> [bool; NQ]
where
    L: LegDynamics<NQ, NC, NU>,
{
    core::array::from_fn(|j| L::ACTUATED.contains(&j))
}

/// `b = −N − D q̇`: the right-hand side of the joint rows without the motors.
pub(crate) fn passive_forces<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    terms: &DynamicsTerms<T, NQ, NC>,
    qd: &SVector<T, NQ>,
) -> SVector<T, NQ>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    -terms.bias_forces - L::damping_forces(qd, params)
}

pub(crate) fn check_finite<T: Real, const NQ: usize>(
    state: &State<T, NQ>,
) -> Result<(), ControlError> {
    if state.q.iter().chain(state.qd.iter()).all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(ControlError::NonFinite)
    }
}

/// `Ã` and `b̃` by the Schur complement of the reordered KKT system, as in the notes.
/// It applies to every leg whose motors do not over-determine it; on an under-actuated
/// leg `Ã θ̈ = b̃ + u` holds with the passive joints moving on their own (collocated
/// partial feedback linearization).
pub fn actuated_reduction<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    terms: &DynamicsTerms<T, NQ, NC>,
    qd: &SVector<T, NQ>,
) -> Result<ActuatedDynamics<T, NU>, ControlError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    Structure::of::<L, NQ, NC, NU>().joint_space()?;
    let (m, j) = (&terms.mass_matrix, &terms.constraint_jacobian);
    let a22 = PassiveSystem::new(m, j, actuated_mask::<L, NQ, NC, NU>(), L::REDUNDANT_ROWS)
        .map_err(|e| {
            // A NaN pose shows as a singular system: said as what it is.
            if all_finite(m) && all_finite(j) {
                e
            } else {
                ControlError::NonFinite
            }
        })?;
    // A12 z for z = (x, f): the actuated rows of M x − Jᵀ f.
    let a12 = |(x, f): (SVector<T, NQ>, SVector<T, NC>)| mul(m, &x) - mul_tn(j, &f);
    let mut a_tilde = SMatrix::<T, NU, NU>::zeros();
    for (k, &ak) in L::ACTUATED.iter().enumerate() {
        // A21's column for θ_k: the passive rows of M's column and J's column.
        let col = a12(a22.solve(&m.column(ak).into_owned(), &j.column(ak).into_owned()));
        for (i, &ai) in L::ACTUATED.iter().enumerate() {
            a_tilde[(i, k)] = m[(ai, ak)] - col[ai];
        }
    }
    let b = passive_forces::<L, T, NQ, NC, NU>(params, terms, qd);
    let col = a12(a22.solve(&b, &-terms.constraint_bias));
    let b_tilde = SVector::<T, NU>::from_fn(|i, _| b[L::ACTUATED[i]] - col[L::ACTUATED[i]]);
    if !a_tilde.iter().chain(b_tilde.iter()).all(|x| x.is_finite()) {
        // Finite rates on a finite pose: the terms overflowed, the input was not bad.
        let finite_input = all_finite(qd) && all_finite(m) && all_finite(j);
        return Err(if finite_input {
            ControlError::Dynamics(DynamicsError::Overflow)
        } else {
            ControlError::NonFinite
        });
    }
    Ok(ActuatedDynamics { a_tilde, b_tilde })
}

/// The constrained motion in motor coordinates: `q̇ = G θ̇` and `q̈ = G θ̈ + c`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NullSpace<T: Real, const NQ: usize, const NU: usize> {
    /// `G` (`NQ × NU`): column `k`, the joint rates when motor `k` turns at unit rate.
    pub g: SMatrix<T, NQ, NU>,
    /// `c`: the joint accelerations that keep `J q̈ + J̇ q̇ = 0` when `θ̈ = 0`.
    pub c: SVector<T, NQ>,
}

/// `G` (each column: the joint rates when one motor turns at unit rate) and `c` (the
/// passive accelerations that keep `J q̈ + J̇ q̇ = 0` when `θ̈ = 0`). Only where the motors
/// determine the leg ([`Structure::motors_determine_the_leg`]).
pub fn null_space<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    jacobian: &SMatrix<T, NC, NQ>,
    constraint_bias: &SVector<T, NC>,
) -> Result<NullSpace<T, NQ, NU>, ControlError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    Structure::of::<L, NQ, NC, NU>().motors_determine_the_leg()?;
    let mut g = SMatrix::<T, NQ, NU>::zeros();
    for (k, &ak) in L::ACTUATED.iter().enumerate() {
        let mut col =
            passive_solve::<L, T, NQ, NC, NU>(jacobian, &-jacobian.column(ak).into_owned())?;
        col[ak] = T::one();
        g.set_column(k, &col);
    }
    let c = passive_solve::<L, T, NQ, NC, NU>(jacobian, &-constraint_bias)?;
    Ok(NullSpace { g, c })
}

/// `Ã = Gᵀ M G`, `b̃ = Gᵀ (b − M c)`: the null-space form of [`actuated_reduction`].
pub fn actuated_reduction_null_space<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    terms: &DynamicsTerms<T, NQ, NC>,
    qd: &SVector<T, NQ>,
) -> Result<ActuatedDynamics<T, NU>, ControlError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let ns = null_space::<L, T, NQ, NC, NU>(&terms.constraint_jacobian, &terms.constraint_bias)?;
    Ok(reduce_with(
        &ns,
        terms,
        &passive_forces::<L, T, NQ, NC, NU>(params, terms, qd),
    ))
}

/// `Ã = Gᵀ M G`, `b̃ = Gᵀ (b − M c)` from a null space already computed.
pub(crate) fn reduce_with<T: Real, const NQ: usize, const NC: usize, const NU: usize>(
    ns: &NullSpace<T, NQ, NU>,
    terms: &DynamicsTerms<T, NQ, NC>,
    b: &SVector<T, NQ>,
) -> ActuatedDynamics<T, NU> {
    let mg = mul(&terms.mass_matrix, &ns.g);
    ActuatedDynamics {
        a_tilde: mul_tn(&ns.g, &mg),
        b_tilde: mul_tn(&ns.g, &(b - mul(&terms.mass_matrix, &ns.c))),
    }
}

/// The derivatives of the reduction to the motor angles (`Ã θ̈ = b̃ + u`,
/// [`crate::control::actuated_reduction`]) through its inverse dynamics: the torques
/// `u(q, q̇, v) = Ã(q) v − b̃(q, q̇)` that give the motors the accelerations `v`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReductionDerivatives<T: Real, const NQ: usize, const NU: usize> {
    /// `Ã` (`= ∂u/∂v`).
    pub a_tilde: SMatrix<T, NU, NU>,
    /// `b̃`.
    pub b_tilde: SVector<T, NU>,
    /// `∂u/∂q = ∂(Ã v)/∂q − ∂b̃/∂q` (at `v = 0`: `−∂b̃/∂q`).
    pub torque_q: SMatrix<T, NU, NQ>,
    /// `∂u/∂q̇ = −∂b̃/∂q̇`.
    pub torque_qd: SMatrix<T, NU, NQ>,
}

/// [`ReductionDerivatives`] at `(q, q̇)` and motor accelerations `v`. Forward dynamics
/// under `u(v)` gives the motors `θ̈ = v`, so differentiating that identity,
/// `∂u/∂x = −Ã ∂θ̈/∂x` with `∂θ̈/∂x` the motor rows of [`crate::dynamics::derivatives::forward_dynamics_derivatives`].
/// Where the reduction applies (not on an over-actuated leg).
pub fn reduction_derivatives<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    v: &SVector<T, NU>,
) -> Result<ReductionDerivatives<T, NQ, NU>, ControlError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let terms = L::dynamics_terms(q, qd, params);
    let reduced = actuated_reduction::<L, T, NQ, NC, NU>(params, &terms, qd)?;
    let u = reduced.a_tilde * v - reduced.b_tilde;
    let d = forward_dynamics_derivatives_from_terms::<L, T, NQ, NC, NU>(
        params, &terms, q, qd, &u, None,
    )
    .map_err(ControlError::Dynamics)?;
    let motor_rows =
        |m: &SMatrix<T, NQ, NQ>| SMatrix::<T, NU, NQ>::from_fn(|i, c| m[(L::ACTUATED[i], c)]);
    let torque_q = -(reduced.a_tilde * motor_rows(&d.qdd_q));
    let torque_qd = -(reduced.a_tilde * motor_rows(&d.qdd_qd));
    if !(all_finite(&torque_q) && all_finite(&torque_qd)) {
        return Err(ControlError::NonFinite);
    }
    Ok(ReductionDerivatives {
        a_tilde: reduced.a_tilde,
        b_tilde: reduced.b_tilde,
        torque_q,
        torque_qd,
    })
}
