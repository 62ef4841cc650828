//! Loop assembly: putting a leg together from its motor angles, consistent velocities,
//! projection back onto the constraints, and the foot → motor-angle inverse.
//!
//! All solvers are damped Gauss–Newton (Levenberg–Marquardt with the damping `μ = |r|²`,
//! which keeps quadratic convergence at a regular solution) with a backtracking line
//! search, on the generated `φ`, `J`, foot position and foot Jacobian. Where there are
//! more free joints than equations, each step is the minimal-norm one, so the solution
//! stays on the branch (assembly mode) of the starting guess. A guess far from the answer
//! may still land on another branch: [`assemble_along`] follows one branch continuously
//! from an assembled pose and reports where it ends.
//!
//! Tolerances are relative to the leg's size ([`leg_size`]), so a 1 m leg and a 10 cm
//! leg are assembled to the same number of significant digits. Closure rows that repeat
//! the others ([`LegDynamics::REDUNDANT_ROWS`] of them) are left out of each step by the
//! pivots of its factorization, and met because the rows they repeat are.

use core::fmt;

use nalgebra::{SMatrix, SVector};

use crate::dynamics::structure::factor_closure_rows;
use crate::model::contract::{LegDynamics, LegModel, Real};
use crate::model::linalg::{mul, Cholesky};

/// Why a leg cannot be assembled as asked.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AssemblyError {
    /// No configuration satisfies the request from this guess: the motor angles (or foot
    /// position) are out of the workspace, or the guess is on no branch that reaches
    /// them. `residual` is the largest residual left (m).
    Unreachable {
        /// The largest residual entry left (m).
        residual: f64,
    },
    /// The passive joints lose rank here (e.g. a five-bar's lower links are collinear),
    /// so the velocities of the passive joints are not determined by the motors'.
    Singular,
    /// Following the branch of the starting pose ([`assemble_along`]), the branch ends
    /// (a singular configuration, or the edge of the workspace) after this fraction of
    /// the way, or the solution would jump to another branch there.
    BranchEnds {
        /// The share of the way (0 to 1) followed before the branch ends.
        fraction: f64,
    },
    /// The continuation's largest step ([`assemble_along`]) is not positive, or so small
    /// that the way would take more than [`MAX_CONTINUATION_STEPS`] steps.
    StepTooSmall {
        /// The step asked for (rad, or m on a prismatic motor).
        max_step: f64,
        /// The way to go: the largest motor change (rad, or m).
        way: f64,
    },
    /// The pose given to a method that needs a pose on the closures (the design measures,
    /// a manifold chart) is off them by `residual` (m), more than `limit` (m,
    /// [`ON_CLOSURES`] of the leg's size): its numbers would be of a pose the leg cannot
    /// take. Project it first ([`project_position`]) or assemble it.
    OffClosures {
        /// The largest closure residual entry (m).
        residual: f64,
        /// The largest accepted (m).
        limit: f64,
    },
    /// An input is NaN or infinite.
    NonFinite,
}

/// How far off its closures a pose may be, relative to the leg's size, for the methods
/// that need one on them ([`check_on_closures`]): loose enough for any pose assembled or
/// projected at a [`Tolerance`] up to 1e-9 and for a pose written with nine digits.
pub const ON_CLOSURES: f64 = 1e-9;

/// The most steps [`assemble_along`] takes at its largest step: the work it may do is
/// bounded before it starts.
pub const MAX_CONTINUATION_STEPS: f64 = 1e6;

impl fmt::Display for AssemblyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AssemblyError::Unreachable { residual } => {
                write!(
                    f,
                    "unreachable from this start: the solve stops {residual:.3e} m short of the constraints (a target out of reach, or a start from which it is not reached: a singular or distant guess)"
                )
            }
            AssemblyError::Singular => {
                write!(f, "singular configuration: the passive joints lose rank")
            }
            AssemblyError::BranchEnds { fraction } => write!(
                f,
                "the assembly branch of the starting pose ends {:.1} % of the way (a singular configuration or the edge of the workspace)",
                fraction * 100.0
            ),
            AssemblyError::StepTooSmall { max_step, way } => write!(
                f,
                "the continuation step {max_step:e} must be positive and at least 1/{MAX_CONTINUATION_STEPS:e} of the way ({way:e})"
            ),
            AssemblyError::OffClosures { residual, limit } => write!(
                f,
                "the pose is off its closures by {residual:.3e} m (more than {limit:.1e} m): project it onto them first (project_position, or assemble it)"
            ),
            AssemblyError::NonFinite => write!(f, "non-finite input"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for AssemblyError {}

/// When the solvers stop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance<T> {
    /// Largest residual accepted, relative to the leg's size ([`leg_size`]): by default
    /// `1000 ε` (2.2e-13 for `f64`, 1.2e-4 for `f32`), so about 1e-13 m on a 0.5 m leg.
    pub relative_residual: T,
    /// The most Gauss–Newton iterations of one solve (default 50).
    pub max_iterations: usize,
}

impl<T: Real> Default for Tolerance<T> {
    fn default() -> Self {
        Tolerance {
            relative_residual: T::default_epsilon() * T::lit(1000.0),
            max_iterations: 50,
        }
    }
}

/// The leg's size at `q` (m): the largest coordinate of any joint or link tip in the base
/// frame. The closure residual is a difference of such coordinates, so its rounding
/// error scales with it.
pub fn leg_size<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
) -> T
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    L::leg_size(q, params)
}

/// Refuses a pose that is not finite or is off its closures by more than [`ON_CLOSURES`]
/// of the leg's size: the check every method shares that needs a pose the leg can take.
pub fn check_on_closures<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
) -> Result<(), AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if !q.iter().all(|x| x.is_finite()) {
        return Err(AssemblyError::NonFinite);
    }
    if NC == 0 {
        return Ok(());
    }
    let residual = L::closure_residual(q, params).amax();
    let limit = leg_size::<L, T, NQ, NC, NU>(params, q) * T::lit(ON_CLOSURES);
    if !residual.is_finite() {
        return Err(AssemblyError::NonFinite);
    }
    if residual > limit {
        return Err(AssemblyError::OffClosures {
            residual: to_f64(residual),
            limit: to_f64(limit),
        });
    }
    Ok(())
}

/// Whether every entry of `r` is finite and within `limit` (itself finite): a NaN residual
/// or an infinite tolerance (a parameter that is NaN or huge) never counts as met.
fn within<T: Real, const N: usize>(r: &SVector<T, N>, limit: T) -> bool {
    limit.is_finite() && r.iter().all(|x| x.is_finite() && x.abs() <= limit)
}

fn to_f64<T: Real>(x: T) -> f64 {
    x.to_subset().unwrap_or(f64::NAN)
}

fn is_actuated<L, const NQ: usize, const NC: usize, const NU: usize>(j: usize) -> bool
where
    L: LegDynamics<NQ, NC, NU>,
{
    L::ACTUATED.contains(&j)
}

/// Backtracking along `−step` from `q0`: the first of `q0 − step`, `q0 − step/2`, … (40
/// halvings at most) whose residual `r` has a smaller `cost` than `cost0`.
fn backtrack<T: Real, const NQ: usize, R>(
    q0: &SVector<T, NQ>,
    step: &SVector<T, NQ>,
    cost0: T,
    residual: impl Fn(&SVector<T, NQ>) -> R,
    cost: impl Fn(&R) -> T,
) -> Option<(SVector<T, NQ>, R)> {
    let mut alpha = T::one();
    for _ in 0..40 {
        let trial = q0 - step * alpha;
        let r = residual(&trial);
        if cost(&r) < cost0 {
            return Some((trial, r));
        }
        alpha *= T::lit(0.5);
    }
    None
}

/// Minimal-norm damped Gauss–Newton on `φ(q) = 0`, moving only the joints in `free`.
fn solve_closure<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &mut SVector<T, NQ>,
    free: &[bool; NQ],
    tol: &Tolerance<T>,
) -> Result<(), AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if !q.iter().all(|x| x.is_finite()) {
        return Err(AssemblyError::NonFinite);
    }
    let mut phi = L::closure_residual(q, params);
    // The tolerance is relative to the leg's size at the pose being judged.
    let limit =
        |q: &SVector<T, NQ>| tol.relative_residual * leg_size::<L, T, NQ, NC, NU>(params, q);
    // Evaluated once per pose (a leg's size is its forward kinematics: on Cassie a tenth
    // of a projection's cost).
    let mut at_pose = limit(q);
    if !at_pose.is_finite() || !crate::model::linalg::all_finite(&phi) {
        return Err(AssemblyError::NonFinite);
    }
    let free_count = free.iter().filter(|&&f| f).count();
    for _ in 0..tol.max_iterations {
        let err = phi.amax();
        if within(&phi, at_pose) {
            return Ok(());
        }
        let mut j = L::constraint_jacobian(q, params);
        for (c, &f) in free.iter().enumerate() {
            if !f {
                j.column_mut(c).fill(T::zero());
            }
        }
        let mu = phi.norm_squared();
        let unreachable = AssemblyError::Unreachable {
            residual: to_f64(err),
        };
        let step = if free_count >= NC - L::REDUNDANT_ROWS.min(NC) {
            // As many free joints as independent rows or more: the minimal-norm step
            // `Jᵀ (J Jᵀ + μ I)⁻¹ φ`.
            let s = j * j.transpose() + SMatrix::<T, NC, NC>::identity() * mu;
            let chol = factor_closure_rows::<L, T, NQ, NC, NU>(&s).ok_or(unreachable)?;
            let mut w = phi;
            chol.solve_mut(&mut w);
            j.transpose() * w
        } else {
            // Fewer free joints than rows (the motors of an over-actuated leg held): the
            // least-squares step `(JᵀJ + μ I)⁻¹ Jᵀ φ` over the free joints, the others
            // decoupled by unit rows.
            let mut a = j.transpose() * j + SMatrix::<T, NQ, NQ>::identity() * mu;
            for (c, &f) in free.iter().enumerate() {
                if !f {
                    a.row_mut(c).fill(T::zero());
                    a.column_mut(c).fill(T::zero());
                    a[(c, c)] = T::one();
                }
            }
            let chol = Cholesky::new(&a).ok_or(unreachable)?;
            if chol.rcond < crate::dynamics::forward::rcond_floor::<T>() {
                return Err(unreachable);
            }
            let mut step = j.transpose() * phi;
            chol.solve_mut(&mut step);
            step
        };
        let residual = |x: &SVector<T, NQ>| L::closure_residual(x, params);
        match backtrack(q, &step, mu, residual, |r| r.norm_squared()) {
            Some((next, r)) => {
                (*q, phi) = (next, r);
                at_pose = limit(q);
            }
            None => break,
        }
    }
    let err = phi.amax();
    if within(&phi, at_pose) {
        Ok(())
    } else {
        Err(AssemblyError::Unreachable {
            residual: to_f64(err),
        })
    }
}

/// Assembles the leg: the actuated joints at `theta`, the passive joints solved from
/// `φ(q) = 0` starting at `guess` (which picks the assembly mode, e.g. knee in or out).
pub fn assemble<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    theta: &SVector<T, NU>,
    guess: &SVector<T, NQ>,
    tol: &Tolerance<T>,
) -> Result<SVector<T, NQ>, AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if !theta.iter().all(|x| x.is_finite()) {
        return Err(AssemblyError::NonFinite);
    }
    let mut q = *guess;
    for (k, &j) in L::ACTUATED.iter().enumerate() {
        q[j] = theta[k];
    }
    let free: [bool; NQ] = core::array::from_fn(|j| !is_actuated::<L, NQ, NC, NU>(j));
    solve_closure::<L, T, NQ, NC, NU>(params, &mut q, &free, tol)?;
    Ok(q)
}

/// Moves `q` onto `φ(q) = 0` changing only the joints not marked in `held`: the lift of
/// a chart's coordinates onto the closed chain ([`crate::control::linearize::ManifoldChart`]).
pub fn assemble_holding<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &mut SVector<T, NQ>,
    held: &[bool; NQ],
    tol: &Tolerance<T>,
) -> Result<(), AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let free: [bool; NQ] = core::array::from_fn(|j| !held[j]);
    solve_closure::<L, T, NQ, NC, NU>(params, q, &free, tol)
}

/// Moves `q` onto `φ(q) = 0` with every joint free (the smallest correction): the
/// post-step projection of the integrators.
pub fn project_position<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &mut SVector<T, NQ>,
    tol: &Tolerance<T>,
) -> Result<(), AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    solve_closure::<L, T, NQ, NC, NU>(params, q, &[true; NQ], tol)
}

/// [`project_position`] for a pose one step's move from `near`, whose closure Jacobian
/// `j` the caller already has (a step's start): chord Gauss–Newton steps
/// `Jᵀ (J Jᵀ)⁻¹ φ` with that `J` held, each shrinking `φ` by about the step's move, judged
/// against the tolerance at the leg's size at `near` (a step changes that size by far
/// less than the tolerance's own scale), at most four. Where they do not get there (a
/// long step, a pose near a singularity) the full projection runs from where they
/// started, so the result is held to the same tolerance either way.
pub fn project_position_near<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &mut SVector<T, NQ>,
    near: &SVector<T, NQ>,
    j: &SMatrix<T, NC, NQ>,
    tol: &Tolerance<T>,
) -> Result<(), AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if NC == 0 {
        return Ok(());
    }
    let start = *q;
    let limit = tol.relative_residual * leg_size::<L, T, NQ, NC, NU>(params, near);
    if let Some(f) = factor_closure_rows::<L, T, NQ, NC, NU>(&(j * j.transpose())) {
        for _ in 0..4 {
            let mut w = L::closure_residual(q, params);
            if within(&w, limit) {
                return Ok(());
            }
            if !crate::model::linalg::all_finite(&w) {
                break;
            }
            f.solve_mut(&mut w);
            *q -= j.transpose() * w;
        }
        if within(&L::closure_residual(q, params), limit) {
            return Ok(());
        }
    }
    *q = start;
    project_position::<L, T, NQ, NC, NU>(params, q, tol)
}

/// Removes from `q̇` the part that violates `J q̇ = 0`, in the metric of `M` (the
/// correction of least kinetic energy): `q̇ ← q̇ − M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁻¹ J q̇`.
pub fn project_velocity<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &mut SVector<T, NQ>,
) -> Result<(), AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if NC == 0 {
        return Ok(());
    }
    if !qd.iter().chain(q.iter()).all(|x| x.is_finite()) {
        return Err(AssemblyError::NonFinite);
    }
    let m = L::mass_matrix(q, params);
    let j = L::constraint_jacobian(q, params);
    let chol_m = Cholesky::new(&m).ok_or(AssemblyError::Singular)?;
    let mut y = j.transpose();
    chol_m.solve_mut(&mut y); // M⁻¹ Jᵀ
    let chol_s =
        factor_closure_rows::<L, T, NQ, NC, NU>(&(j * y)).ok_or(AssemblyError::Singular)?;
    let mut lambda = j * *qd;
    chol_s.solve_mut(&mut lambda);
    *qd -= y * lambda;
    Ok(())
}

/// The joint velocities of an assembled leg whose motors turn at `theta_dot`: the
/// passive rates solve `J q̇ = 0`. Fails with [`AssemblyError::Singular`] where the
/// passive joints lose rank.
pub fn consistent_velocity<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    theta_dot: &SVector<T, NU>,
) -> Result<SVector<T, NQ>, AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if !theta_dot.iter().chain(q.iter()).all(|x| x.is_finite()) {
        return Err(AssemblyError::NonFinite);
    }
    let mut qd = SVector::<T, NQ>::zeros();
    for (k, &j) in L::ACTUATED.iter().enumerate() {
        qd[j] = theta_dot[k];
    }
    if NC == 0 {
        return Ok(qd);
    }
    let j = L::constraint_jacobian(q, params);
    qd += passive_solve::<L, T, NQ, NC, NU>(&j, &-(j * qd))?;
    Ok(qd)
}

/// The smallest `x` with zero actuated entries that solves `J x = rhs`:
/// `x = J_pᵀ (J_p J_pᵀ)⁻¹ rhs`, `J_p` being `J` without its actuated columns. Moving the
/// passive joints by `x` changes `J q̇` by `rhs`.
pub(crate) fn passive_solve<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    j: &SMatrix<T, NC, NQ>,
    rhs: &SVector<T, NC>,
) -> Result<SVector<T, NQ>, AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if NC == 0 {
        return Ok(SVector::zeros());
    }
    let mut jp = *j;
    for &a in L::ACTUATED.iter() {
        jp.column_mut(a).fill(T::zero());
    }
    let jpt = jp.transpose();
    let chol =
        factor_closure_rows::<L, T, NQ, NC, NU>(&mul(&jp, &jpt)).ok_or(AssemblyError::Singular)?;
    let mut w = *rhs;
    chol.solve_mut(&mut w);
    Ok(mul(&jpt, &w))
}

/// The assembled configuration that puts the foot at `foot` (base frame), from `guess`
/// (which picks the branch); the motor angles are its actuated entries.
pub fn foot_inverse<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    params: &L::Params<T>,
    foot: &SVector<T, ND>,
    guess: &SVector<T, NQ>,
    tol: &Tolerance<T>,
) -> Result<SVector<T, NQ>, AssemblyError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    foot_inverse_holding::<L, T, NQ, NC, NU, ND, NP>(params, foot, guess, tol, &[false; NQ])
}

/// [`foot_inverse`] with the joints marked in `held` kept at `guess`'s values: the
/// leg's joints placing the foot (base frame) under a body that stays where it is (the
/// body's joints held), as a controller places a hopper's foot in flight.
pub fn foot_inverse_holding<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    params: &L::Params<T>,
    foot: &SVector<T, ND>,
    guess: &SVector<T, NQ>,
    tol: &Tolerance<T>,
    held: &[bool; NQ],
) -> Result<SVector<T, NQ>, AssemblyError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    let held_count = held.iter().filter(|&&h| h).count();
    let hold = |mut m: SMatrix<T, NC, NQ>, mut f: SMatrix<T, ND, NQ>| {
        for (i, &h) in held.iter().enumerate() {
            if h {
                m.column_mut(i).fill(T::zero());
                f.column_mut(i).fill(T::zero());
            }
        }
        (m, f)
    };
    if !foot.iter().chain(guess.iter()).all(|x| x.is_finite()) {
        return Err(AssemblyError::NonFinite);
    }
    let residuals = |q: &SVector<T, NQ>| {
        (
            L::closure_residual(q, params),
            L::foot_position(q, params) - foot,
        )
    };
    let cost = |(phi, e): &(SVector<T, NC>, SVector<T, ND>)| phi.norm_squared() + e.norm_squared();
    let worst = |(phi, e): &(SVector<T, NC>, SVector<T, ND>)| phi.amax().max(e.amax());
    let mut q = *guess;
    let mut r = residuals(&q);
    // The tolerances are relative to the leg's size at the pose being judged: the
    // closures' to that size alone (as in `assemble`), the foot's to the larger of it and
    // the target's coordinates.
    let limit =
        |q: &SVector<T, NQ>| tol.relative_residual * leg_size::<L, T, NQ, NC, NU>(params, q);
    let met = |q: &SVector<T, NQ>, (phi, e): &(SVector<T, NC>, SVector<T, ND>)| {
        let limit = limit(q);
        within(phi, limit) && within(e, limit.max(tol.relative_residual * foot.amax()))
    };
    if !(limit(&q).is_finite()
        && crate::model::linalg::all_finite(&r.0)
        && crate::model::linalg::all_finite(&r.1))
    {
        return Err(AssemblyError::NonFinite);
    }
    for _ in 0..tol.max_iterations {
        if met(&q, &r) {
            return Ok(q);
        }
        let (j, jf) = hold(
            L::constraint_jacobian(&q, params),
            L::foot_jacobian(&q, params),
        );
        let mu = cost(&r);
        let unreachable = AssemblyError::Unreachable {
            residual: to_f64(worst(&r)),
        };
        let phi = r.0;
        let step = if L::MOBILITY >= ND + held_count {
            // At least as many free motions as the foot's coordinates: the minimal-norm
            // step `Aᵀ (A Aᵀ + μ I)⁻¹ r` of the stacked residual, A = [J; J_f], by block
            // elimination (JᵀJ + J_fᵀJ_f would be singular at the solution).
            let s11 = mul(&j, &j.transpose()) + SMatrix::<T, NC, NC>::identity() * mu;
            let s12 = mul(&j, &jf.transpose());
            let chol1 = factor_closure_rows::<L, T, NQ, NC, NU>(&s11).ok_or(unreachable)?;
            let mut x = s12;
            chol1.solve_mut(&mut x); // S11⁻¹ S12
            let schur = mul(&jf, &jf.transpose()) + SMatrix::<T, ND, ND>::identity() * mu
                - s12.transpose() * x;
            let chol2 = Cholesky::new(&schur).ok_or(unreachable)?;
            let mut w1 = phi;
            chol1.solve_mut(&mut w1);
            let mut w2 = r.1 - s12.transpose() * w1;
            chol2.solve_mut(&mut w2);
            w1 -= x * w2;
            j.transpose() * w1 + jf.transpose() * w2
        } else {
            // Fewer free motions than foot coordinates: more equations than unknowns, a
            // least-squares step `(AᵀA + μ I)⁻¹ Aᵀ r`. A may lack full column rank (a foot
            // that cannot move at all, e.g. pinned by a closure): a damping floor of
            // `1000 ε` of AᵀA's largest diagonal keeps the step regular there.
            let ata = j.transpose() * j + jf.transpose() * jf;
            let floor = (0..NQ).fold(T::zero(), |m, i| m.max(ata[(i, i)]))
                * T::default_epsilon()
                * T::lit(1000.0);
            let h = ata + SMatrix::<T, NQ, NQ>::identity() * (mu + floor);
            let chol = Cholesky::new(&h).ok_or(unreachable)?;
            let mut step = j.transpose() * phi + jf.transpose() * r.1;
            chol.solve_mut(&mut step);
            step
        };
        match backtrack(&q, &step, cost(&r), residuals, cost) {
            Some((next, rn)) => (q, r) = (next, rn),
            None => break,
        }
    }
    if met(&q, &r) {
        Ok(q)
    } else {
        Err(AssemblyError::Unreachable {
            residual: to_f64(worst(&r)),
        })
    }
}

/// Follows the assembly branch of `from` (an assembled pose) while the motor angles move
/// on a straight line from `from`'s to `theta`: steps of at most `max_step` rad, each
/// predicted to first order (`q + G Δθ`, the passive rates of [`consistent_velocity`])
/// and corrected by [`assemble`]. A step whose correction is more than a quarter of its
/// size (the solution would jump), or that meets a singular configuration, is halved;
/// when a step would fall below 1e-7 of the way, the branch ends there:
/// [`AssemblyError::BranchEnds`] says how far it got. A sweep or a start pose computed
/// this way stays in the assembly mode of `from`. A `max_step` that is not positive, or
/// would take more than [`MAX_CONTINUATION_STEPS`] steps, is refused
/// ([`AssemblyError::StepTooSmall`]).
pub fn assemble_along<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    from: &SVector<T, NQ>,
    theta: &SVector<T, NU>,
    max_step: T,
    tol: &Tolerance<T>,
) -> Result<SVector<T, NQ>, AssemblyError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if !theta.iter().chain(from.iter()).all(|x| x.is_finite()) || !max_step.is_finite() {
        return Err(AssemblyError::NonFinite);
    }
    let start = SVector::<T, NU>::from_fn(|k, _| from[L::ACTUATED[k]]);
    let delta = theta - start;
    let total = delta.amax();
    if total == T::zero() || NC == 0 {
        return assemble::<L, T, NQ, NC, NU>(params, theta, from, tol);
    }
    // A step of zero never arrives, a negative one walks backwards: bounded work only.
    if !(max_step > T::zero() && total / max_step <= T::lit(MAX_CONTINUATION_STEPS)) {
        return Err(AssemblyError::StepTooSmall {
            max_step: to_f64(max_step),
            way: to_f64(total),
        });
    }
    let longest = (max_step / total).min(T::one());
    let (mut q, mut done, mut h) = (*from, T::zero(), longest);
    while done < T::one() {
        let h_now = h.min(T::one() - done);
        let step = delta * h_now;
        let target = start + delta * (done + h_now);
        let next = consistent_velocity::<L, T, NQ, NC, NU>(params, &q, &step).and_then(|dq| {
            let predicted = q + dq;
            let next = assemble::<L, T, NQ, NC, NU>(params, &target, &predicted, tol)?;
            if (next - predicted).amax() <= step.amax() * T::lit(0.25) {
                Ok(next)
            } else {
                Err(AssemblyError::BranchEnds {
                    fraction: to_f64(done),
                })
            }
        });
        match next {
            Ok(next) => {
                q = next;
                done += h_now;
                h = (h + h).min(longest);
            }
            Err(AssemblyError::NonFinite) => return Err(AssemblyError::NonFinite),
            Err(_) => {
                h *= T::lit(0.5);
                if h < T::lit(1e-7) {
                    return Err(AssemblyError::BranchEnds {
                        fraction: to_f64(done),
                    });
                }
            }
        }
    }
    Ok(q)
}
