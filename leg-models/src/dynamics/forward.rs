//! Constrained forward dynamics: the KKT system of DESIGN.md §3, solved with structure.
//!
//! ```text
//! [ M   −Jᵀ ] [ q̈ ]   [ B u − N − D q̇ ]
//! [ J    0  ] [ F  ] = [ −J̇ q̇ − 2α J q̇ − β² φ ]      (α = β = 0: no Baumgarte terms)
//! ```
//!
//! `M = L Lᵀ` (Cholesky), `a = M⁻¹ τ`, `Y = M⁻¹ Jᵀ`, `S = J Y` (`NC × NC`, SPD when `J` has
//! full row rank), `F = S⁻¹ (rhs − J a)`, `q̈ = a + Y F`. Everything is fixed-size and on
//! the stack.

use core::fmt;

use nalgebra::{SMatrix, SVector};

use crate::model::contract::{DynamicsTerms, LegDynamics, Real};
use crate::model::linalg::{
    all_finite, factors_along_the_tree, mul, mul_nt, mul_tn, scale_columns, Cholesky, Factored,
    MassFactor, PivotedLdlt, SubtreeEnds, TreeLdl,
};

/// Why the constrained dynamics cannot be solved at a state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DynamicsError {
    /// `M` is not positive definite (a massless, inertia-free link, or bad parameters).
    MassMatrixNotPositiveDefinite,
    /// `J M⁻¹ Jᵀ` is singular or too ill-conditioned to trust: the closure constraints
    /// lose rank here, a singular configuration of the mechanism. `rcond` is the
    /// reciprocal condition estimate (squared pivot ratio of its Cholesky factor).
    SingularConstraints {
        /// The reciprocal condition estimate of `J M⁻¹ Jᵀ`.
        rcond: f64,
    },
    /// The held contact rows repeat each other or the closures (more contacts held than
    /// the leg can satisfy independently); `rcond` is the pivot ratio of their system.
    SingularContacts {
        /// The pivot ratio of the held contact rows' system.
        rcond: f64,
    },
    /// A state, input or parameter is NaN or infinite.
    NonFinite,
    /// The state and inputs are finite but a term computed from them is not: rates or
    /// torques so large that `N`, `J̇ q̇` or the solution exceed f64's range.
    Overflow,
    /// A ball joint's angles are at (or within `√ε` of) their singularity `β = ±π/2`,
    /// where `R_x(α)` and `R_z(γ)` turn about the same axis and the three angles lose a
    /// direction of rotation.
    BallJointSingular {
        /// The coordinate of the ball joint's first angle `α` (`β` is the next).
        joint: usize,
        /// `cos β` there.
        cos_beta: f64,
    },
    /// A contact of a spatial leg slides from rest (no velocity along the ground) and no
    /// slip direction was given: the direction it starts to slip in depends on the
    /// applied forces ([`crate::dynamics::contact::ContactSystem::with_slip`]).
    SlipFromRest {
        /// The contact's index.
        contact: usize,
    },
}

impl fmt::Display for DynamicsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DynamicsError::MassMatrixNotPositiveDefinite => {
                write!(f, "the mass matrix is not positive definite")
            }
            DynamicsError::SingularConstraints { rcond } => write!(
                f,
                "singular configuration: the closure constraints lose rank (rcond {rcond:.1e})"
            ),
            DynamicsError::SingularContacts { rcond } => write!(
                f,
                "singular contacts: the held contact rows lose rank with the closures (rcond {rcond:.1e})"
            ),
            DynamicsError::NonFinite => write!(f, "non-finite state, input or parameter"),
            DynamicsError::Overflow => write!(
                f,
                "overflow: the state and torques are finite but the terms at them exceed f64's range"
            ),
            DynamicsError::BallJointSingular { joint, cos_beta } => write!(
                f,
                "the ball joint at coordinates {joint}..{} is at its angles' singularity (cos of the second angle {cos_beta:.1e}): its first and third axes line up",
                joint + 3
            ),
            DynamicsError::SlipFromRest { contact } => write!(
                f,
                "contact {contact} slides from rest with no slip direction given (a spatial contact at rest can start to slip in any direction along the ground)"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DynamicsError {}

/// Baumgarte stabilization of the closure: `J q̈ = −J̇ q̇ − 2α J q̇ − β² φ`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Baumgarte<T> {
    /// `α` (1/s): damping of the constraint velocity `J q̇`.
    pub alpha: T,
    /// `β` (1/s): stiffness of the constraint residual `φ`.
    pub beta: T,
}

/// The solution of the KKT system.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Acceleration<T: Real, const NQ: usize, const NC: usize> {
    /// `q̈`.
    pub qdd: SVector<T, NQ>,
    /// The closure forces `F` (on point a; `−F` acts on point b), base frame.
    pub forces: SVector<T, NC>,
}

/// Below this reciprocal condition (relative to the scalar's epsilon) `J M⁻¹ Jᵀ` is
/// treated as singular: about 2e-13 for `f64`, 1e-4 for `f32`.
pub fn rcond_floor<T: Real>() -> T {
    T::default_epsilon() * T::lit(1000.0)
}

pub(crate) fn to_f64<T: Real>(x: T) -> f64 {
    x.to_subset().unwrap_or(f64::NAN)
}

/// The generalized forces of the motors: `B u`.
pub fn actuation<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    u: &SVector<T, NU>,
) -> SVector<T, NQ>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let mut tau = SVector::<T, NQ>::zeros();
    for (k, &j) in L::ACTUATED.iter().enumerate() {
        tau[j] += u[k];
    }
    tau
}

/// The factorization of `S = J M⁻¹ Jᵀ`: plain on a leg whose closure rows are
/// independent, pivoted on one closed redundantly.
#[derive(Clone, Copy, Debug)]
pub(crate) enum ConstraintFactor<T: Real, const NC: usize> {
    Regular(Cholesky<T, NC>),
    Redundant(PivotedLdlt<T, NC>),
}

impl<T: Real, const NC: usize> ConstraintFactor<T, NC> {
    /// Factors `S`; up to `deficiency` of its rows may repeat the others (a leg closed
    /// redundantly): pivoted then, plain (unrolled, no pivoting) otherwise.
    #[inline(always)]
    pub(crate) fn new(s: &SMatrix<T, NC, NC>, deficiency: usize) -> Result<Self, DynamicsError> {
        Ok(if deficiency == 0 {
            ConstraintFactor::Regular(regular_closure_factor(s)?)
        } else {
            ConstraintFactor::Redundant(redundant_closure_factor(s, deficiency)?)
        })
    }

    /// Overwrites `b` with `S⁻¹ b` (the forces of rows left out as redundant zero).
    #[inline(always)]
    pub(crate) fn solve_mut<const C: usize>(&self, b: &mut SMatrix<T, NC, C>) {
        match self {
            ConstraintFactor::Regular(c) => c.solve_mut(b),
            ConstraintFactor::Redundant(c) => c.solve_mut(b),
        }
    }
}

/// The KKT matrix `[M −Jᵀ; J 0]` of one state, factored once (`M` densely, `L D Lᵀ`, or
/// along the tree, `Lᵀ D L`; `Y = M⁻¹ Jᵀ`, `S = J Y` factored) for the solves of any number of right-hand sides: forward dynamics
/// solves one, its derivatives ([`crate::dynamics::derivatives`]) `2 NQ + NU` more.
#[derive(Clone, Copy, Debug)]
pub struct KktFactorization<
    T: Real,
    const NQ: usize,
    const NC: usize,
    F: Factored<T, NQ> = Cholesky<T, NQ>,
> {
    chol_m: F,
    jacobian: SMatrix<T, NC, NQ>,
    y: SMatrix<T, NQ, NC>,
    s: Option<ConstraintFactor<T, NC>>,
}

impl<T: Real, const NQ: usize, const NC: usize> KktFactorization<T, NQ, NC> {
    /// Factors the KKT matrix of `M` and `J`; up to `deficiency` closure rows may repeat
    /// the others ([`solve_kkt`]).
    #[inline(always)]
    pub fn new(
        mass_matrix: &SMatrix<T, NQ, NQ>,
        jacobian: &SMatrix<T, NC, NQ>,
        deficiency: usize,
    ) -> Result<Self, DynamicsError> {
        // A NaN or infinity anywhere shows in M's pivots or in the solutions.
        let chol_m = checked_mass_factor(Cholesky::new(mass_matrix), mass_matrix)?;
        Self::with_mass_factor(chol_m, jacobian, deficiency)
    }
}

impl<T: Real, const NQ: usize, const NC: usize, F: Factored<T, NQ>> KktFactorization<T, NQ, NC, F> {
    /// [`KktFactorization::new`] from `M` already factored (along the tree where that
    /// pays, [`TreeLdl`]).
    #[inline(always)]
    pub(crate) fn with_mass_factor(
        chol_m: F,
        jacobian: &SMatrix<T, NC, NQ>,
        deficiency: usize,
    ) -> Result<Self, DynamicsError> {
        let mut y = jacobian.transpose();
        let mut s = None;
        if NC > 0 {
            chol_m.solve_mut(&mut y); // Y = M⁻¹ Jᵀ
            s = Some(ConstraintFactor::new(&mul(jacobian, &y), deficiency)?);
        }
        Ok(KktFactorization {
            chol_m,
            jacobian: *jacobian,
            y,
            s,
        })
    }

    /// Overwrites the right-hand sides `(top, bottom)` (columns of `[τ; r]`) with the
    /// solutions `(x, f)` of `M x − Jᵀ f = τ`, `J x = r`: `a = M⁻¹ τ`,
    /// `f = S⁻¹ (r − J a)`, `x = a + Y f`. Forces of rows left out as redundant are zero.
    #[inline(always)]
    pub fn solve_mut<const C: usize>(
        &self,
        top: &mut SMatrix<T, NQ, C>,
        bottom: &mut SMatrix<T, NC, C>,
    ) {
        self.chol_m.solve_mut(top);
        let Some(s) = &self.s else {
            return;
        };
        *bottom -= mul(&self.jacobian, top);
        s.solve_mut(bottom);
        *top += mul(&self.y, bottom);
    }
}

/// Solves the KKT system from evaluated terms: `tau` is the generalized force on the
/// right-hand side (`B u − N − D q̇`), `closure_rhs` the constraint row (`−J̇ q̇ − …`).
/// Up to `deficiency` closure rows may repeat the others (a leg closed redundantly,
/// [`LegDynamics::REDUNDANT_ROWS`]): the pivots leave them out and their forces are zero, so
/// the accelerations are those of the whole system and the forces one of its solutions.
pub fn solve_kkt<T: Real, const NQ: usize, const NC: usize>(
    mass_matrix: &SMatrix<T, NQ, NQ>,
    jacobian: &SMatrix<T, NC, NQ>,
    tau: &SVector<T, NQ>,
    closure_rhs: &SVector<T, NC>,
    deficiency: usize,
) -> Result<Acceleration<T, NQ, NC>, DynamicsError> {
    // A NaN or infinity anywhere shows in M's pivots or in the result, checked below.
    let chol_m = Cholesky::new(mass_matrix).ok_or(DynamicsError::MassMatrixNotPositiveDefinite)?;
    if chol_m.rcond < rcond_floor::<T>() {
        return Err(DynamicsError::MassMatrixNotPositiveDefinite);
    }
    solve_kkt_factored(&chol_m, jacobian, tau, closure_rhs, deficiency)
}

/// [`solve_kkt`] with `M` already factored.
#[inline(always)]
fn solve_kkt_factored<T: Real, const NQ: usize, const NC: usize>(
    chol_m: &Cholesky<T, NQ>,
    jacobian: &SMatrix<T, NC, NQ>,
    tau: &SVector<T, NQ>,
    closure_rhs: &SVector<T, NC>,
    deficiency: usize,
) -> Result<Acceleration<T, NQ, NC>, DynamicsError> {
    // The one-right-hand-side solve is written out rather than through `KktFactorization`
    // (the same steps): carrying the factorization costs the simulation's hot path up to
    // 8 % (minitaur_pinned_toe 2392 → 2588 instructions, braced_parallelogram 3478 → 3650).
    let mut qdd = *tau;
    chol_m.solve_mut(&mut qdd); // a = M⁻¹ τ
    let mut forces = SVector::<T, NC>::zeros();
    if NC > 0 {
        let mut y = jacobian.transpose();
        chol_m.solve_mut(&mut y); // Y = M⁻¹ Jᵀ
        let s = mul(jacobian, &y);
        forces = closure_rhs - mul(jacobian, &qdd);
        solve_closure_forces(&s, &mut forces, deficiency)?;
        qdd += mul(&y, &forces);
    }
    if !(all_finite(&qdd) && all_finite(&forces) && all_finite(tau) && all_finite(closure_rhs)) {
        return Err(DynamicsError::NonFinite);
    }
    Ok(Acceleration { qdd, forces })
}

/// [`solve_kkt`] with `M = Lᵀ D L` factored along the tree, in half solves: with
/// `W = L⁻ᵀ Jᵀ` and `t = L⁻ᵀ τ`, `S = J M⁻¹ Jᵀ = Wᵀ D⁻¹ W`, `F = S⁻¹ (r − Wᵀ D⁻¹ t)`,
/// `q̈ = L⁻¹ D⁻¹ (t + W F)`. That is `NC + 2` half solves where the full form takes
/// `2 NC + 2`, and a symmetric product in place of `J Y` (Featherstone, RBDA §8.5).
#[inline(always)]
pub(crate) fn solve_kkt_on_tree<T: Real, const NQ: usize, const NC: usize>(
    chol_m: &TreeLdl<T, NQ>,
    jacobian: &SMatrix<T, NC, NQ>,
    tau: &SVector<T, NQ>,
    closure_rhs: &SVector<T, NC>,
    deficiency: usize,
) -> Result<Acceleration<T, NQ, NC>, DynamicsError> {
    let mut t = *tau;
    chol_m.solve_lt_mut(&mut t);
    let inv_d = chol_m.inv_diag();
    let mut forces = SVector::<T, NC>::zeros();
    if NC > 0 {
        // Kept as rows, P = J L⁻¹ = Wᵀ (J's layout as stored): the half solve and
        // `S = P D⁻¹ Pᵀ` then run over contiguous columns, which the compiler vectorizes
        // (cassie 125 050 → 108 455 instructions).
        // S dense: skipping a leg's columns for the other legs' rows (`linalg::Spans`, as
        // the stance does) cost Cassie's forward dynamics 3.7 % more instructions here,
        // where S is the one product.
        let mut p = *jacobian;
        chol_m.solve_lt_rows_mut(&mut p);
        let p_d = scale_columns(&p, inv_d);
        let s = mul_nt(&p, &p_d);
        forces = closure_rhs - mul(&p_d, &t);
        solve_closure_forces(&s, &mut forces, deficiency)?;
        t += mul_tn(&p, &forces);
    }
    let mut qdd = t.component_mul(inv_d);
    chol_m.solve_l_mut(&mut qdd);
    if !(all_finite(&qdd) && all_finite(&forces) && all_finite(tau) && all_finite(closure_rhs)) {
        return Err(DynamicsError::NonFinite);
    }
    Ok(Acceleration { qdd, forces })
}

/// Overwrites `forces` with `S⁻¹ forces`, `S = J M⁻¹ Jᵀ`; up to `deficiency` of its rows
/// may repeat the others (their forces are zero).
#[inline(always)]
fn solve_closure_forces<T: Real, const NC: usize>(
    s: &SMatrix<T, NC, NC>,
    forces: &mut SVector<T, NC>,
    deficiency: usize,
) -> Result<(), DynamicsError> {
    if deficiency == 0 {
        regular_closure_factor(s)?.solve_mut(forces);
    } else {
        redundant_closure_factor(s, deficiency)?.solve_mut(forces);
    }
    Ok(())
}

/// `S = J M⁻¹ Jᵀ` factored where no closure row repeats the others; refused as
/// [`DynamicsError::SingularConstraints`] where a pivot is not positive or the pivots'
/// ratio is below [`rcond_floor`]. Inlined, so that a caller that avoids
/// [`ConstraintFactor`]'s enum (the contact solve: it cost the small legs' contact paths)
/// pays nothing for it.
#[inline(always)]
pub(crate) fn regular_closure_factor<T: Real, const NC: usize>(
    s: &SMatrix<T, NC, NC>,
) -> Result<Cholesky<T, NC>, DynamicsError> {
    let chol_s = Cholesky::new(s).ok_or(DynamicsError::SingularConstraints { rcond: 0.0 })?;
    if chol_s.rcond < rcond_floor::<T>() {
        return Err(DynamicsError::SingularConstraints {
            rcond: to_f64(chol_s.rcond),
        });
    }
    Ok(chol_s)
}

/// `S` factored with pivoting where up to `deficiency` of its rows may repeat the others
/// (their forces are then zero); refused as [`DynamicsError::SingularConstraints`] where
/// more than that do.
#[inline(always)]
pub(crate) fn redundant_closure_factor<T: Real, const NC: usize>(
    s: &SMatrix<T, NC, NC>,
    deficiency: usize,
) -> Result<PivotedLdlt<T, NC>, DynamicsError> {
    PivotedLdlt::new(s, deficiency, rcond_floor::<T>())
        .ok_or(DynamicsError::SingularConstraints { rcond: 0.0 })
}

/// The subtree ends of `L`'s coordinates ([`SubtreeEnds`]) where its mass matrix is
/// factored along the tree ([`factors_along_the_tree`]); `None` where it is dense.
pub(crate) const fn mass_tree<L, const NQ: usize, const NC: usize, const NU: usize>(
) -> Option<&'static SubtreeEnds<NQ>>
where
    L: LegDynamics<NQ, NC, NU>,
{
    const {
        if factors_along_the_tree(&L::PARENTS) {
            Some(&ends_of(&L::PARENTS))
        } else {
            None
        }
    }
}

/// `M` factored as `L`'s model pays for ([`mass_tree`]), for a system solved several
/// times; not positive definite, or a pivot ratio below [`rcond_floor`], is
/// `MassMatrixNotPositiveDefinite` (a NaN in `M` too: it shows in the pivots).
#[inline(always)]
pub(crate) fn factor_mass<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    m: &SMatrix<T, NQ, NQ>,
) -> Result<MassFactor<T, NQ>, DynamicsError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let factor = match mass_tree::<L, NQ, NC, NU>() {
        Some(ends) => TreeLdl::new(m, ends).map(MassFactor::Tree),
        None => Cholesky::new(m).map(MassFactor::Dense),
    }
    .ok_or(DynamicsError::MassMatrixNotPositiveDefinite)?;
    if factor.rcond() < rcond_floor::<T>() {
        return Err(DynamicsError::MassMatrixNotPositiveDefinite);
    }
    Ok(factor)
}

/// [`SubtreeEnds::of`] where they exist (`factors_along_the_tree` says so): a value of
/// the const to refer to, never evaluated otherwise.
const fn ends_of<const N: usize>(parents: &[Option<usize>; N]) -> SubtreeEnds<N> {
    match SubtreeEnds::of(parents) {
        Some(ends) => ends,
        None => panic!("not in depth-first order"),
    }
}

/// A factor of `M` checked: a NaN or infinity in `M` is `NonFinite`; a pivot that is not
/// positive, or a pivot ratio below [`rcond_floor`], `MassMatrixNotPositiveDefinite`.
#[inline(always)]
pub(crate) fn checked_mass_factor<T: Real, F: Factored<T, NQ>, const NQ: usize>(
    factor: Option<F>,
    m: &SMatrix<T, NQ, NQ>,
) -> Result<F, DynamicsError> {
    match factor {
        Some(f) if f.rcond() >= rcond_floor::<T>() => Ok(f),
        _ => Err(not_positive_definite(m)),
    }
}

/// Why `M` has no factor: a NaN or infinity in it (a non-finite pose or parameter) is
/// said as such, not as a mass matrix that is not positive definite.
#[cold]
pub(crate) fn not_positive_definite<T: Real, const NQ: usize>(
    m: &SMatrix<T, NQ, NQ>,
) -> DynamicsError {
    if all_finite(m) {
        DynamicsError::MassMatrixNotPositiveDefinite
    } else {
        DynamicsError::NonFinite
    }
}

impl DynamicsError {
    /// The error said as what caused it, from the state and torques it was computed at:
    /// any failure at a NaN or infinite input is `NonFinite` (a NaN angle showed as "the
    /// mass matrix is not positive definite"), and `NonFinite` at finite inputs is an
    /// `Overflow`. The hot paths return the raw error; the [`Leg`](crate::Leg) methods,
    /// the command line and the Python bindings say it explained.
    #[cold]
    pub fn explained<T: Real, const NQ: usize, const NU: usize>(
        self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        u: &SVector<T, NU>,
    ) -> DynamicsError {
        classify_non_finite(self, q, qd, u)
    }
}

/// The failure said as what caused it: a NaN or infinite state or input, whatever it
/// broke first (a NaN angle shows as singular constraints), is `NonFinite`; a non-finite
/// result at a finite state and input is an overflow, not bad input.
#[cold]
pub(crate) fn classify_non_finite<T: Real, const NQ: usize, const NU: usize>(
    e: DynamicsError,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
) -> DynamicsError {
    let finite_input = all_finite(q) && all_finite(qd) && all_finite(u);
    match e {
        _ if !finite_input => DynamicsError::NonFinite,
        DynamicsError::NonFinite => DynamicsError::Overflow,
        other => other,
    }
}

/// `Err(BallJointSingular)` where a ball joint's second angle is within `√ε` of `±π/2`
/// (its chart's singularity). A leg without ball joints loops over an empty constant.
#[inline(always)]
pub fn check_ball_joints<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    q: &SVector<T, NQ>,
) -> Result<(), DynamicsError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    for &b in L::BALL_JOINTS {
        let cos_beta = q[b + 1].cos();
        if cos_beta.abs() <= T::default_epsilon().sqrt() {
            return Err(DynamicsError::BallJointSingular {
                joint: b,
                cos_beta: to_f64(cos_beta),
            });
        }
    }
    Ok(())
}

/// Forward dynamics of the closed chain at `(q, q̇)` under motor torques `u`, with joint
/// damping, reflected rotor inertia and, optionally, Baumgarte stabilization.
pub fn forward_dynamics<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
    baumgarte: Option<Baumgarte<T>>,
) -> Result<Acceleration<T, NQ, NC>, DynamicsError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let terms = L::dynamics_terms(q, qd, params);
    forward_dynamics_from_terms::<L, T, NQ, NC, NU>(params, &terms, q, qd, u, baumgarte)
}

/// [`forward_dynamics`] from terms already evaluated (a controller evaluating the same
/// terms in the same step shares them).
pub fn forward_dynamics_from_terms<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    terms: &DynamicsTerms<T, NQ, NC>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
    baumgarte: Option<Baumgarte<T>>,
) -> Result<Acceleration<T, NQ, NC>, DynamicsError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    check_ball_joints::<L, T, NQ, NC, NU>(q)?;
    let (tau, rhs) = kkt_rhs::<L, T, NQ, NC, NU>(params, terms, q, qd, u, baumgarte);
    // The error is said as what caused it by `DynamicsError::explained`, off this path:
    // mapping it here copied the result, 2 to 3 % of a small leg's forward dynamics.
    let (m, j) = (&terms.mass_matrix, &terms.constraint_jacobian);
    if let Some(ends) = mass_tree::<L, NQ, NC, NU>() {
        // The same raw error as the dense path's (`solve_kkt`); said by `explained`.
        let chol_m = match TreeLdl::new(m, ends) {
            Some(f) if f.rcond >= rcond_floor::<T>() => f,
            _ => return Err(DynamicsError::MassMatrixNotPositiveDefinite),
        };
        solve_kkt_on_tree(&chol_m, j, &tau, &rhs, L::REDUNDANT_ROWS)
    } else {
        solve_kkt(m, j, &tau, &rhs, L::REDUNDANT_ROWS)
    }
}

/// The right-hand side of the KKT system at a state: `(B u − N − D q̇, −J̇ q̇ − 2α J q̇ − β² φ)`.
#[inline(always)]
pub(crate) fn kkt_rhs<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    terms: &DynamicsTerms<T, NQ, NC>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
    baumgarte: Option<Baumgarte<T>>,
) -> (SVector<T, NQ>, SVector<T, NC>)
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let tau = actuation::<L, T, NQ, NC, NU>(u) - terms.bias_forces - L::damping_forces(qd, params);
    let mut rhs = -terms.constraint_bias;
    if let Some(b) = baumgarte {
        if NC > 0 {
            let phi = L::closure_residual(q, params);
            rhs -= (terms.constraint_jacobian * qd) * (b.alpha + b.alpha) + phi * (b.beta * b.beta);
        }
    }
    (tau, rhs)
}
