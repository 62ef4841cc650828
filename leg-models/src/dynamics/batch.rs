//! Forward dynamics of four states in one call, on [`F64x4`] lanes: the generated terms
//! evaluated on lanes, the KKT system of [`crate::dynamics`] solved without branches
//! (`M = L D Lᵀ`, `S = J M⁻¹ Jᵀ = L_S D_S L_Sᵀ`), and a flag per lane instead of an error:
//! a lane fails where the scalar path would return an error (a pivot that is not positive
//! and finite, a reciprocal condition below [`crate::dynamics::rcond_floor`], a non-finite
//! result), and its values are then meaningless. For sampling-based MPC, domain
//! randomization and parameter sweeps: lanes may hold different states, inputs and
//! parameters ([`broadcast`] and [`crate::Parameters::set`] with per-lane values).
// Index loops over fixed sizes mirror the scalar solver and unroll.
#![allow(clippy::needless_range_loop)]

use nalgebra::SVector;

use crate::dynamics::forward::rcond_floor;
use crate::model::contract::{LegDynamics, Parameters};
use crate::model::simd::F64x4;

/// Why a leg has no batched forward dynamics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BatchError {
    /// Its closure rows repeat each other ([`LegDynamics::REDUNDANT_ROWS`]): which rows to
    /// leave out depends on the state (pivoting), which is a branch per lane; solve its
    /// states one by one.
    RedundantRows,
}

impl core::fmt::Display for BatchError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "the leg's closure rows repeat each other: its batched forward dynamics would need pivoting; solve its states one by one"
        )
    }
}

#[cfg(feature = "std")]
impl std::error::Error for BatchError {}

/// `q̈` and the closure forces of four states, and which lanes are valid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BatchAcceleration<const NQ: usize, const NC: usize> {
    /// `q̈` per lane.
    pub qdd: SVector<F64x4, NQ>,
    /// The closure forces `F` per lane, as [`crate::dynamics::Acceleration::forces`].
    pub forces: SVector<F64x4, NC>,
    /// `ok[k]`: lane `k` solved (where the scalar path returns `Ok`).
    pub ok: [bool; 4],
}

/// The same parameters in every lane.
pub fn broadcast<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
) -> L::Params<F64x4>
where
    L: LegDynamics<NQ, NC, NU>,
{
    // Set in chunks, each prepared once: a `set` per parameter prepared once for each
    // one `prepare` reads (337 of Cassie's 461); in chunks of 64, 8 times.
    const CHUNK: usize = 64;
    let mut out = L::Params::<F64x4>::default();
    let n = <L::Params<F64x4> as Parameters<F64x4>>::NAMES.len();
    let mut changes = [(0, ZERO); CHUNK];
    for start in (0..n).step_by(CHUNK) {
        let mut len = 0;
        for i in start..(start + CHUNK).min(n) {
            if let Some(v) = p.get(i) {
                changes[len] = (i, F64x4::splat(v));
                len += 1;
            }
        }
        let set = out.set_many(&changes[..len]);
        debug_assert!(set, "indices below NAMES.len()");
    }
    out
}

const ZERO: F64x4 = F64x4([0.0; 4]);

/// `A = L D Lᵀ` of four symmetric matrices, unrolled, no pivoting; `ok` per lane.
struct Ldlt<const N: usize> {
    l: [[F64x4; N]; N],
    inv_d: [F64x4; N],
    ok: [bool; 4],
}

impl<const N: usize> Ldlt<N> {
    #[inline(always)]
    fn new(a: &[[F64x4; N]; N]) -> Self {
        let mut l = [[ZERO; N]; N];
        let mut d = [ZERO; N];
        let mut inv_d = [ZERO; N];
        // The smallest and largest pivot of each lane, a NaN kept (it fails every test).
        let mut lo = F64x4::splat(f64::INFINITY);
        let mut hi = F64x4::splat(0.0);
        for j in 0..N {
            let mut dj = a[j][j];
            for k in 0..j {
                dj = dj - l[j][k] * l[j][k] * d[k];
            }
            lo = F64x4(core::array::from_fn(|k| {
                let (x, m) = (dj.0[k], lo.0[k]);
                if x < m || x.is_nan() {
                    x
                } else {
                    m
                }
            }));
            hi = F64x4(core::array::from_fn(|k| {
                let (x, m) = (dj.0[k], hi.0[k]);
                if x > m || x.is_nan() {
                    x
                } else {
                    m
                }
            }));
            d[j] = dj;
            inv_d[j] = F64x4::splat(1.0) / dj;
            for i in j + 1..N {
                let mut s = a[i][j];
                for k in 0..j {
                    s = s - l[i][k] * l[j][k] * d[k];
                }
                l[i][j] = s * inv_d[j];
            }
        }
        // Positive, finite pivots whose ratio is above the scalar path's floor.
        let floor = rcond_floor::<f64>();
        let ok = core::array::from_fn(|k| {
            N == 0 || (lo.0[k] > 0.0 && hi.0[k] < f64::INFINITY && lo.0[k] / hi.0[k] >= floor)
        });
        Ldlt { l, inv_d, ok }
    }

    /// Overwrites `b` with `A⁻¹ b`.
    #[inline(always)]
    fn solve(&self, b: &mut [F64x4; N]) {
        for i in 0..N {
            for k in 0..i {
                b[i] = b[i] - self.l[i][k] * b[k];
            }
        }
        for i in 0..N {
            b[i] = b[i] * self.inv_d[i];
        }
        for i in (0..N).rev() {
            for k in i + 1..N {
                b[i] = b[i] - self.l[k][i] * b[k];
            }
        }
    }
}

/// Forward dynamics (no Baumgarte terms) of four states: what
/// [`crate::dynamics::forward_dynamics`] computes for each lane.
pub fn forward_dynamics<L, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<F64x4>,
    q: &SVector<F64x4, NQ>,
    qd: &SVector<F64x4, NQ>,
    u: &SVector<F64x4, NU>,
) -> Result<BatchAcceleration<NQ, NC>, BatchError>
where
    L: LegDynamics<NQ, NC, NU>,
{
    if L::REDUNDANT_ROWS > 0 {
        return Err(BatchError::RedundantRows);
    }
    let terms = L::dynamics_terms(q, qd, params);
    let damping = L::damping_forces(qd, params);
    let mut tau: [F64x4; NQ] = core::array::from_fn(|i| -terms.bias_forces[i] - damping[i]);
    for (k, &j) in L::ACTUATED.iter().enumerate() {
        tau[j] = tau[j] + u[k];
    }
    let m: [[F64x4; NQ]; NQ] =
        core::array::from_fn(|i| core::array::from_fn(|j| terms.mass_matrix[(i, j)]));
    let chol_m = Ldlt::new(&m);
    let mut ok = chol_m.ok;
    let mut qdd = tau;
    chol_m.solve(&mut qdd); // a = M⁻¹ τ
    let j = &terms.constraint_jacobian;
    let mut forces = [ZERO; NC];
    if NC > 0 {
        // Y = M⁻¹ Jᵀ, column by column; S = J Y.
        let y: [[F64x4; NQ]; NC] = core::array::from_fn(|c| {
            let mut col = core::array::from_fn(|i| j[(c, i)]);
            chol_m.solve(&mut col);
            col
        });
        let s: [[F64x4; NC]; NC] = core::array::from_fn(|r| {
            core::array::from_fn(|c| {
                let mut acc = ZERO;
                for i in 0..NQ {
                    acc = acc + j[(r, i)] * y[c][i];
                }
                acc
            })
        });
        for r in 0..NC {
            let mut acc = -terms.constraint_bias[r];
            for i in 0..NQ {
                acc = acc - j[(r, i)] * qdd[i];
            }
            forces[r] = acc;
        }
        let chol_s = Ldlt::new(&s);
        for k in 0..4 {
            ok[k] &= chol_s.ok[k];
        }
        chol_s.solve(&mut forces);
        for i in 0..NQ {
            for (c, f) in forces.iter().enumerate() {
                qdd[i] = qdd[i] + y[c][i] * *f;
            }
        }
    }
    // Σ 0·x is NaN in a lane where any x is infinite or NaN.
    let mut poison = ZERO;
    for x in qdd.iter().chain(&forces).chain(&tau) {
        poison = poison + *x * ZERO;
    }
    for k in 0..4 {
        ok[k] &= poison.0[k] == 0.0;
    }
    Ok(BatchAcceleration {
        qdd: SVector::from_data(nalgebra::ArrayStorage([qdd])),
        forces: SVector::from_data(nalgebra::ArrayStorage([forces])),
        ok,
    })
}
