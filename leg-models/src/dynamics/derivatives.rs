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
    tangential_velocity, ContactMode, ContactSolution, ContactSystem, Ground, Modes,
};
use crate::dynamics::forward::{
    actuation, checked_mass_factor, classify_non_finite, kkt_rhs, mass_tree, Acceleration,
    Baumgarte, DynamicsError, KktFactorization,
};
use crate::model::contract::{ContactModel, DynamicsTerms, LegDynamics, Real};
use crate::model::linalg::{all_finite, negate, Factored, TreeLdl};

/// Forward dynamics and its derivatives at one state and input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForwardDynamicsDerivatives<T: Real, const NQ: usize, const NC: usize, const NU: usize> {
    /// `q̈` and the closure forces `F`, as [`crate::dynamics::forward_dynamics`] returns them
    /// (bit for bit where `M` is factored densely; to rounding on a robot, whose forward
    /// dynamics takes half solves on the tree factor where this takes full ones).
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
    let (m, j) = (&terms.mass_matrix, &terms.constraint_jacobian);
    let explained = |e| classify_non_finite(e, q, qd, u);
    if let Some(ends) = mass_tree::<L, NQ, NC, NU>() {
        let kkt = checked_mass_factor(TreeLdl::new(m, ends), m)
            .and_then(|f| KktFactorization::with_mass_factor(f, j, L::REDUNDANT_ROWS))
            .map_err(explained)?;
        derivatives_with::<L, T, _, NQ, NC, NU>(&kkt, params, terms, q, qd, u, baumgarte)
    } else {
        let kkt = KktFactorization::new(m, j, L::REDUNDANT_ROWS).map_err(explained)?;
        derivatives_with::<L, T, _, NQ, NC, NU>(&kkt, params, terms, q, qd, u, baumgarte)
    }
}

/// [`forward_dynamics_derivatives_from_terms`] on the factored KKT matrix (its mass matrix
/// factored densely or along the tree).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn derivatives_with<L, T, F, const NQ: usize, const NC: usize, const NU: usize>(
    kkt: &KktFactorization<T, NQ, NC, F>,
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
    F: Factored<T, NQ>,
{
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

/// Contact `k` of a spatial leg sliding along its own velocity (not from rest in a given
/// direction): `(−μ λ_n, ∂ŝ/∂q, ∂ŝ/∂q̇)` with `ŝ = v_t / |v_t|`, `v_t = C_t q̇`, so
/// `∂ŝ = (I − ŝ ŝᵀ) ∂v_t / |v_t|`, `∂v_t/∂q̇ = C_t`, `∂v_t/∂q = R_t J̇_c` (`rate_rows`).
/// `None` for every other contact, and on a planar leg.
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn turning_slip<T: Real, const NQ: usize, const NK: usize, const ND: usize>(
    k: usize,
    modes: &Modes<NK, ND>,
    c: &SMatrix<T, NK, NQ>,
    rate_rows: &SMatrix<T, NK, NQ>,
    qd: &SVector<T, NQ>,
    slip: &SVector<T, NK>,
    rest: Option<&SVector<T, NK>>,
    mu: &SVector<T, NK>,
    contact: &SVector<T, NK>,
) -> Option<(T, SMatrix<T, 2, NQ>, SMatrix<T, 2, NQ>)> {
    if ND != 3 || !matches!(modes.get(k), ContactMode::Slide { .. }) {
        return None;
    }
    let (t0, t1) = (ND * k, ND * k + 1);
    let (v, moving) = tangential_velocity::<T, NQ, NK, ND>(c, qd, k);
    // Where `slip_directions` took the velocity's direction, not the given one.
    let ahead = rest.map_or(T::one(), |d| d[t0] * v[t0] + d[t1] * v[t1]);
    if !(moving && ahead > T::zero()) {
        return None;
    }
    let speed = (v[t0] * v[t0] + v[t1] * v[t1]).sqrt();
    let s = SVector::<T, 2>::new(slip[t0], slip[t1]);
    let p = (SMatrix::<T, 2, 2>::identity() - s * s.transpose()) / speed;
    let ds_q = p * rate_rows.fixed_rows::<2>(t0);
    let ds_qd = p * c.fixed_rows::<2>(t0);
    Some((-(mu[t0] * contact[ND * k + 2]), ds_q, ds_qd))
}

/// [`crate::dynamics::contact::forward_dynamics_with_contacts`] (contacts in `modes`, Baumgarte on
/// closures and held contacts as there) and its derivatives with respect to `q`, `q̇` and
/// `u`, holding the modes: the linearization of stance (or of flight, or sliding). On a
/// spatial leg (`ND = 3`) a sliding contact's friction `−μ λ_n ŝ` turns with its slip
/// velocity `v_t = C_t q̇` (`ŝ = v_t / |v_t|`), so the derivatives carry
/// `∂ŝ/∂q̇ = (I − ŝ ŝᵀ) C_t / |v_t|` and `∂ŝ/∂q = (I − ŝ ŝᵀ) R_t J̇_c / |v_t|`
/// (`∂(J_c q̇)/∂q = J̇_c`); a contact sliding from rest keeps the direction `rest` gives
/// it (as [`ContactSystem::with_slip`]), a constant. A planar slide's direction is its
/// mode's, a constant too.
#[allow(clippy::too_many_arguments)]
pub fn contact_dynamics_derivatives<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
    modes: &Modes<NK, ND>,
    anchors: &SVector<T, NK>,
    ground: &Ground<T, ND>,
    mu: &SVector<T, NK>,
    baumgarte: Option<Baumgarte<T>>,
    rest: Option<&SVector<T, NK>>,
) -> Result<ContactDynamicsDerivatives<T, NQ, NC, NU, NK>, DynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK, ND>,
    T: Real,
{
    // The system forward dynamics with contacts solves, so that the solution is the same
    // to the bit.
    let sys = ContactSystem::with_slip::<L, NU>(
        params, q, qd, modes, anchors, ground, mu, baumgarte, rest,
    )?;
    let (j, rows) = (&sys.jacobian, &sys.rows);
    let (two, zero) = (T::lit(2.0), T::zero());
    let (two_alpha, beta2) = baumgarte.map_or((zero, zero), |b| (b.alpha * two, b.beta * b.beta));
    let tau = actuation::<L, T, NQ, NC, NU>(u) + sys.passive;
    let (x, closure, contact) = sys.solve_columns(&tau, &sys.r_j, &sys.r_c)?;
    // The ground forces in the base frame (Σ_j λ_j e_j over the frame's rows: the
    // tangents, then the normal) for J_cᵀ λ.
    let frame = ground.frame();
    let lambda = SVector::<T, NK>::from_fn(|r, _| {
        let (k, i) = (r - r % ND, r % ND);
        let mut s = frame[(0, i)] * contact[k];
        for j in 1..ND {
            s += frame[(j, i)] * contact[k + j];
        }
        s
    });
    let d = L::dynamics_derivatives(q, qd, &x, &closure, params);
    let dc = L::contact_derivatives(q, qd, &x, &lambda, params);
    // Contact rows: C = R J_c, so ∂(C a + R J̇_c q̇)/∂q = R (∂(J_c a)/∂q + ∂(J̇_c q̇)/∂q).
    let mut tau_q = dc.force_q - d.dynamics_q;
    let rate_rows = ground.rows(&dc.jacobian_rate);
    let rj_q = -d.constraint_q - d.jacobian_rate * two_alpha - j * beta2;
    let rc_q = -ground.rows(&(dc.jacobian_q + dc.bias_q)) - rate_rows * two_alpha - rows.c * beta2;
    let mut tau_qd = -d.dynamics_qd;
    let rj_qd = -(d.jacobian_rate * two) - j * two_alpha;
    let rc_qd = -(rate_rows * two) - rows.c * two_alpha;
    // A spatial slide's direction follows its velocity: the friction force's change with
    // it, at the solved λ_n, on the right-hand side; its share of λ_t after the solve.
    let turning = |k: usize| {
        turning_slip::<T, NQ, NK, ND>(
            k, modes, &rows.c, &rate_rows, qd, &sys.slip, rest, mu, &contact,
        )
    };
    for k in 0..NK / ND {
        if let Some((scale, ds_q, ds_qd)) = turning(k) {
            // τ += C_tᵀ (−μ λ_n) ∂ŝ.
            let ct = rows.c.fixed_rows::<2>(ND * k).transpose() * scale;
            tau_q += ct * ds_q;
            tau_qd += ct * ds_qd;
        }
    }
    let tau_u = actuation_matrix::<L, T, NQ, NC, NU>();
    let (rj_u, rc_u) = (SMatrix::<T, NC, NU>::zeros(), SMatrix::<T, NK, NU>::zeros());
    let (qdd_q, forces_q, mut contact_q) = sys.solve_columns(&tau_q, &rj_q, &rc_q)?;
    let (qdd_qd, forces_qd, mut contact_qd) = sys.solve_columns(&tau_qd, &rj_qd, &rc_qd)?;
    let (qdd_u, forces_u, contact_u) = sys.solve_columns(&tau_u, &rj_u, &rc_u)?;
    // λ_t = −μ λ_n ŝ: its change with ŝ.
    for k in 0..NK / ND {
        if let Some((scale, ds_q, ds_qd)) = turning(k) {
            for a in 0..2 {
                for c in 0..NQ {
                    contact_q[(ND * k + a, c)] += scale * ds_q[(a, c)];
                    contact_qd[(ND * k + a, c)] += scale * ds_qd[(a, c)];
                }
            }
        }
    }
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
