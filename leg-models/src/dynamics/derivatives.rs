//! Derivatives of the constrained forward dynamics, for MPC and trajectory optimization
//! (DESIGN.md §3.2).
//!
//! `z = (q̈, F)` solves `K(q) z = r(q, q̇, u)` (the KKT system of [`crate::dynamics`]).
//! Differentiating at the solution (the implicit function theorem):
//!
//! ```text
//! ∂z/∂x = K⁻¹ (∂r/∂x − ∂(K z)/∂x |z held),   x ∈ {q, q̇, u}
//! ∂/∂q : top −∂(M q̈ + N − Jᵀ F)/∂q     bottom −∂(J q̈ + J̇ q̇)/∂q  [− 2α J̇ − β² J]
//! ∂/∂q̇ : top −∂(N + D q̇)/∂q̇           bottom −2 J̇               [− 2α J]
//! ∂/∂u : top B                         bottom 0
//! ```
//!
//! (bracketed: Baumgarte terms, when the dynamics use them). The products are the
//! generated [`LegDynamics::dynamics_derivatives`] at `a = q̈`, `f = F`, so no tensor is
//! formed, and the forward dynamics' own factorization of `K` ([`KktFactorization`])
//! solves every right-hand side. With held contacts the contact rows add the same terms
//! with `J_c` ([`ContactModel::contact_derivatives`]).

use nalgebra::{SMatrix, SVector};

use crate::dynamics::contact::{
    solve_structured_columns, ContactSolution, ContactSystem, Ground, Modes,
};
use crate::dynamics::forward::{
    actuation, classify_non_finite, kkt_rhs, Acceleration, Baumgarte, DynamicsError,
    KktFactorization,
};
use crate::model::contract::{ContactModel, DynamicsTerms, LegDynamics, Real};
use crate::model::linalg::{all_finite, negate};

/// Forward dynamics and its derivatives at one state and input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForwardDynamicsDerivatives<T: Real, const NQ: usize, const NC: usize, const NU: usize> {
    /// `q̈` and the closure forces `F`, as [`crate::dynamics::forward_dynamics`] returns them.
    pub acceleration: Acceleration<T, NQ, NC>,
    /// `∂q̈/∂q`.
    pub qdd_q: SMatrix<T, NQ, NQ>,
    /// `∂q̈/∂q̇`.
    pub qdd_qd: SMatrix<T, NQ, NQ>,
    /// `∂q̈/∂u`.
    pub qdd_u: SMatrix<T, NQ, NU>,
    /// `∂F/∂q`.
    pub forces_q: SMatrix<T, NC, NQ>,
    /// `∂F/∂q̇`.
    pub forces_qd: SMatrix<T, NC, NQ>,
    /// `∂F/∂u`.
    pub forces_u: SMatrix<T, NC, NU>,
}

/// `B`: column `k` is the generalized force of a unit torque on motor `k`.
pub fn actuation_matrix<L, T, const NQ: usize, const NC: usize, const NU: usize>(
) -> SMatrix<T, NQ, NU>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let mut b = SMatrix::<T, NQ, NU>::zeros();
    for (k, &j) in L::ACTUATED.iter().enumerate() {
        b[(j, k)] += T::one();
    }
    b
}

/// [`crate::dynamics::forward_dynamics`] and its exact derivatives with respect to `q`,
/// `q̇` and `u`, from one factorization of the KKT matrix. The same typed errors as
/// forward dynamics; allocation-free.
pub fn forward_dynamics_derivatives<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
    baumgarte: Option<Baumgarte<T>>,
) -> Result<ForwardDynamicsDerivatives<T, NQ, NC, NU>, DynamicsError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let terms = L::dynamics_terms(q, qd, params);
    forward_dynamics_derivatives_from_terms::<L, T, NQ, NC, NU>(params, &terms, q, qd, u, baumgarte)
}

/// [`forward_dynamics_derivatives`] from terms already evaluated at `(q, q̇)` (as
/// [`crate::dynamics::forward_dynamics_from_terms`]).
#[inline(always)]
pub fn forward_dynamics_derivatives_from_terms<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    params: &L::Params<T>,
    terms: &DynamicsTerms<T, NQ, NC>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
    baumgarte: Option<Baumgarte<T>>,
) -> Result<ForwardDynamicsDerivatives<T, NQ, NC, NU>, DynamicsError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let kkt = KktFactorization::new(
        &terms.mass_matrix,
        &terms.constraint_jacobian,
        L::REDUNDANT_ROWS,
    )
    .map_err(|e| classify_non_finite(e, q, qd, u))?;
    let j = &terms.constraint_jacobian;
    let (mut qdd, mut forces) = kkt_rhs::<L, T, NQ, NC, NU>(params, terms, q, qd, u, baumgarte);
    if !(all_finite(&qdd) && all_finite(&forces)) {
        return Err(classify_non_finite(DynamicsError::NonFinite, q, qd, u));
    }
    kkt.solve_mut(&mut qdd, &mut forces);
    let d = L::dynamics_derivatives(q, qd, &qdd, &forces, params);
    let two = T::lit(2.0);
    let (mut qdd_q, mut forces_q) = (negate(d.dynamics_q), negate(d.constraint_q));
    let (mut qdd_qd, mut forces_qd) = (negate(d.dynamics_qd), d.jacobian_rate * -two);
    if let Some(b) = baumgarte {
        let two_alpha = b.alpha * two;
        forces_q -= d.jacobian_rate * two_alpha + j * (b.beta * b.beta);
        forces_qd -= j * two_alpha;
    }
    let mut qdd_u = actuation_matrix::<L, T, NQ, NC, NU>();
    let mut forces_u = SMatrix::<T, NC, NU>::zeros();
    kkt.solve_mut(&mut qdd_q, &mut forces_q);
    kkt.solve_mut(&mut qdd_qd, &mut forces_qd);
    kkt.solve_mut(&mut qdd_u, &mut forces_u);
    // (`∂/∂u` is K⁻¹ [B; 0] from factors whose pivots were checked finite and regular: it
    // needs no check of its own.)
    let out = ForwardDynamicsDerivatives {
        acceleration: Acceleration { qdd, forces },
        qdd_q,
        qdd_qd,
        qdd_u,
        forces_q,
        forces_qd,
        forces_u,
    };
    if !(all_finite(&out.acceleration.qdd)
        && all_finite(&out.acceleration.forces)
        && all_finite(&qdd_q)
        && all_finite(&qdd_qd)
        && all_finite(&forces_q)
        && all_finite(&forces_qd))
    {
        return Err(classify_non_finite(DynamicsError::NonFinite, q, qd, u));
    }
    Ok(out)
}

/// Forward dynamics with contacts and its derivatives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactDynamicsDerivatives<
    T: Real,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
> {
    /// As [`crate::dynamics::contact::forward_dynamics_with_contacts`] returns it.
    pub solution: ContactSolution<T, NQ, NC, NK>,
    /// `∂q̈/∂q`.
    pub qdd_q: SMatrix<T, NQ, NQ>,
    /// `∂q̈/∂q̇`.
    pub qdd_qd: SMatrix<T, NQ, NQ>,
    /// `∂q̈/∂u`.
    pub qdd_u: SMatrix<T, NQ, NU>,
    /// `∂F/∂q` of the closure forces.
    pub forces_q: SMatrix<T, NC, NQ>,
    /// `∂F/∂q̇`.
    pub forces_qd: SMatrix<T, NC, NQ>,
    /// `∂F/∂u`.
    pub forces_u: SMatrix<T, NC, NU>,
    /// Derivatives of the ground forces `(λ_t, λ_n)` per contact (zero rows in flight).
    pub contact_q: SMatrix<T, NK, NQ>,
    /// `∂λ/∂q̇`.
    pub contact_qd: SMatrix<T, NK, NQ>,
    /// `∂λ/∂u`.
    pub contact_u: SMatrix<T, NK, NU>,
}

/// [`crate::dynamics::contact::forward_dynamics_with_contacts`] (contacts in `modes`, Baumgarte on
/// closures and held contacts as there) and its derivatives with respect to `q`, `q̇` and
/// `u`, holding the modes: the linearization of stance (or of flight, or sliding).
#[allow(clippy::too_many_arguments)]
pub fn contact_dynamics_derivatives<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
    modes: &Modes<NK>,
    anchors: &SVector<T, NK>,
    ground: &Ground<T>,
    mu: &SVector<T, NK>,
    baumgarte: Option<Baumgarte<T>>,
) -> Result<ContactDynamicsDerivatives<T, NQ, NC, NU, NK>, DynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK>,
    T: Real,
{
    // The system forward dynamics with contacts solves, so that the solution is the same
    // to the bit.
    let sys = ContactSystem::new::<L, NU>(params, q, qd, modes, anchors, ground, mu, baumgarte)?;
    let (chol_m, j, rows) = (&sys.chol_m, &sys.jacobian, &sys.rows);
    let (two, zero) = (T::lit(2.0), T::zero());
    let (two_alpha, beta2) = baumgarte.map_or((zero, zero), |b| (b.alpha * two, b.beta * b.beta));
    let tau = actuation::<L, T, NQ, NC, NU>(u) + sys.passive;
    let (x, closure, contact) =
        solve_structured_columns(chol_m, j, &sys.r_j, L::REDUNDANT_ROWS, rows, &sys.r_c, &tau)?;
    // The ground forces in the base frame (λ_t t + λ_n n per contact) for J_cᵀ λ.
    let (t, n) = (ground.tangent(), ground.normal);
    let lambda = SVector::<T, NK>::from_fn(|r, _| {
        let k = r - r % 2;
        t[r % 2] * contact[k] + n[r % 2] * contact[k + 1]
    });
    let d = L::dynamics_derivatives(q, qd, &x, &closure, params);
    let dc = L::contact_derivatives(q, qd, &x, &lambda, params);
    // Contact rows: C = R J_c, so ∂(C a + R J̇_c q̇)/∂q = R (∂(J_c a)/∂q + ∂(J̇_c q̇)/∂q).
    let tau_q = dc.force_q - d.dynamics_q;
    let rj_q = -d.constraint_q - d.jacobian_rate * two_alpha - j * beta2;
    let rc_q = -ground.rows(&(dc.jacobian_q + dc.bias_q))
        - ground.rows(&dc.jacobian_rate) * two_alpha
        - rows.c * beta2;
    let tau_qd = -d.dynamics_qd;
    let rj_qd = -(d.jacobian_rate * two) - j * two_alpha;
    let rc_qd = -(ground.rows(&dc.jacobian_rate) * two) - rows.c * two_alpha;
    let tau_u = actuation_matrix::<L, T, NQ, NC, NU>();
    let (rj_u, rc_u) = (SMatrix::<T, NC, NU>::zeros(), SMatrix::<T, NK, NU>::zeros());
    let (qdd_q, forces_q, contact_q) =
        solve_structured_columns(chol_m, j, &rj_q, L::REDUNDANT_ROWS, rows, &rc_q, &tau_q)?;
    let (qdd_qd, forces_qd, contact_qd) =
        solve_structured_columns(chol_m, j, &rj_qd, L::REDUNDANT_ROWS, rows, &rc_qd, &tau_qd)?;
    let (qdd_u, forces_u, contact_u) =
        solve_structured_columns(chol_m, j, &rj_u, L::REDUNDANT_ROWS, rows, &rc_u, &tau_u)?;
    Ok(ContactDynamicsDerivatives {
        solution: ContactSolution {
            x,
            closure,
            contact,
        },
        qdd_q,
        qdd_qd,
        qdd_u,
        forces_q,
        forces_qd,
        forces_u,
        contact_q,
        contact_qd,
        contact_u,
    })
}
