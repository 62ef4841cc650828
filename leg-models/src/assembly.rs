//! Loop assembly: putting a leg together from its motor angles, consistent velocities,
//! projection back onto the constraints, and the foot → motor-angle inverse.
//!
//! All solvers are damped Gauss–Newton (Levenberg–Marquardt with the damping `μ = |r|²`,
//! which keeps quadratic convergence at a regular solution) with a backtracking line
//! search, on the generated `φ`, `J`, foot position and foot Jacobian. Where there are
//! more free joints than equations, each step is the minimal-norm one, so the solution
//! stays on the branch (assembly mode) of the starting guess.

use core::fmt;

use nalgebra::{SMatrix, SVector};

use crate::dynamics::rcond_floor;
use crate::linalg::{mul, Cholesky};
use crate::model::{LegModel, Real};

/// Why a leg cannot be assembled as asked.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AssemblyError {
    /// No configuration satisfies the request from this guess: the motor angles (or foot
    /// position) are out of the workspace, or the guess is on no branch that reaches
    /// them. `residual` is the largest residual left (m).
    Unreachable { residual: f64 },
    /// The passive joints lose rank here (e.g. a five-bar's lower links are collinear),
    /// so the velocities of the passive joints are not determined by the motors'.
    Singular,
    /// An input is NaN or infinite.
    NonFinite,
}

impl fmt::Display for AssemblyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AssemblyError::Unreachable { residual } => {
                write!(
                    f,
                    "unreachable: the closure cannot be met (residual {residual:.3e} m)"
                )
            }
            AssemblyError::Singular => {
                write!(f, "singular configuration: the passive joints lose rank")
            }
            AssemblyError::NonFinite => write!(f, "non-finite input"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for AssemblyError {}

/// When the solvers stop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance<T> {
    /// Largest residual accepted (m): about 2e-14 m for `f64`, 1e-5 m for `f32`.
    pub residual: T,
    pub max_iterations: usize,
}

impl<T: Real> Default for Tolerance<T> {
    fn default() -> Self {
        Tolerance {
            residual: T::default_epsilon() * T::lit(100.0),
            max_iterations: 50,
        }
    }
}

fn to_f64<T: Real>(x: T) -> f64 {
    x.to_subset().unwrap_or(f64::NAN)
}

fn is_actuated<L, const NQ: usize, const NC: usize, const NU: usize>(j: usize) -> bool
where
    L: LegModel<NQ, NC, NU>,
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
    L: LegModel<NQ, NC, NU>,
    T: Real,
{
    if !q.iter().all(|x| x.is_finite()) {
        return Err(AssemblyError::NonFinite);
    }
    let mut phi = L::closure_residual(q, params);
    for _ in 0..tol.max_iterations {
        let err = phi.amax();
        if err <= tol.residual {
            return Ok(());
        }
        let mut j = L::constraint_jacobian(q, params);
        for (c, &f) in free.iter().enumerate() {
            if !f {
                j.column_mut(c).fill(T::zero());
            }
        }
        let mu = phi.norm_squared();
        let s = j * j.transpose() + SMatrix::<T, NC, NC>::identity() * mu;
        let chol = Cholesky::new(&s).ok_or(AssemblyError::Unreachable {
            residual: to_f64(err),
        })?;
        let mut w = phi;
        chol.solve_mut(&mut w);
        let step = j.transpose() * w;
        let residual = |x: &SVector<T, NQ>| L::closure_residual(x, params);
        match backtrack(q, &step, phi.norm_squared(), residual, |r| r.norm_squared()) {
            Some((next, r)) => (*q, phi) = (next, r),
            None => break,
        }
    }
    let err = phi.amax();
    if err <= tol.residual {
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
    L: LegModel<NQ, NC, NU>,
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

/// Moves `q` onto `φ(q) = 0` with every joint free (the smallest correction): the
/// post-step projection of the integrators.
pub fn project_position<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &mut SVector<T, NQ>,
    tol: &Tolerance<T>,
) -> Result<(), AssemblyError>
where
    L: LegModel<NQ, NC, NU>,
    T: Real,
{
    solve_closure::<L, T, NQ, NC, NU>(params, q, &[true; NQ], tol)
}

/// Removes from `q̇` the part that violates `J q̇ = 0`, in the metric of `M` (the
/// correction of least kinetic energy): `q̇ ← q̇ − M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁻¹ J q̇`.
pub fn project_velocity<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &mut SVector<T, NQ>,
) -> Result<(), AssemblyError>
where
    L: LegModel<NQ, NC, NU>,
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
    let chol_s = Cholesky::new(&(j * y)).ok_or(AssemblyError::Singular)?;
    if chol_s.rcond < rcond_floor::<T>() {
        return Err(AssemblyError::Singular);
    }
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
    L: LegModel<NQ, NC, NU>,
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
    L: LegModel<NQ, NC, NU>,
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
    let chol = Cholesky::new(&mul(&jp, &jpt)).ok_or(AssemblyError::Singular)?;
    if chol.rcond < rcond_floor::<T>() {
        return Err(AssemblyError::Singular);
    }
    let mut w = *rhs;
    chol.solve_mut(&mut w);
    Ok(mul(&jpt, &w))
}

/// The assembled configuration that puts the foot at `foot` (base frame), from `guess`
/// (which picks the branch); the motor angles are its actuated entries.
pub fn foot_inverse<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    foot: &SVector<T, 2>,
    guess: &SVector<T, NQ>,
    tol: &Tolerance<T>,
) -> Result<SVector<T, NQ>, AssemblyError>
where
    L: LegModel<NQ, NC, NU>,
    T: Real,
{
    if !foot.iter().chain(guess.iter()).all(|x| x.is_finite()) {
        return Err(AssemblyError::NonFinite);
    }
    let residuals = |q: &SVector<T, NQ>| {
        (
            L::closure_residual(q, params),
            L::foot_position(q, params) - foot,
        )
    };
    let cost = |(phi, e): &(SVector<T, NC>, SVector<T, 2>)| phi.norm_squared() + e.norm_squared();
    let worst = |(phi, e): &(SVector<T, NC>, SVector<T, 2>)| phi.amax().max(e.amax());
    let mut q = *guess;
    let mut r = residuals(&q);
    for _ in 0..tol.max_iterations {
        if worst(&r) <= tol.residual {
            return Ok(q);
        }
        let j = L::constraint_jacobian(&q, params);
        let jf = L::foot_jacobian(&q, params);
        let mu = cost(&r);
        let h = j.transpose() * j + jf.transpose() * jf + SMatrix::<T, NQ, NQ>::identity() * mu;
        let chol = Cholesky::new(&h).ok_or(AssemblyError::Unreachable {
            residual: to_f64(worst(&r)),
        })?;
        let mut step = j.transpose() * r.0 + jf.transpose() * r.1;
        chol.solve_mut(&mut step);
        match backtrack(&q, &step, cost(&r), residuals, cost) {
            Some((next, rn)) => (q, r) = (next, rn),
            None => break,
        }
    }
    if worst(&r) <= tol.residual {
        Ok(q)
    } else {
        Err(AssemblyError::Unreachable {
            residual: to_f64(worst(&r)),
        })
    }
}
