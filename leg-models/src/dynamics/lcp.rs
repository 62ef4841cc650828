//! The linear complementarity problem, solved exactly by Lemke's complementary pivoting
//! (Cottle, Pang & Stone, *The Linear Complementarity Problem*, 1992, §4.4): given `M`
//! (`n × n`) and `q`, find `z` with
//!
//! ```text
//! w = M z + q,   w ≥ 0,   z ≥ 0,   wᵢ zᵢ = 0 for every i.
//! ```
//!
//! What a time-stepping contact step solves for the consistent contact mode of many
//! contacts at once ([`crate::robot::time_stepping`]): which contacts push, which stick,
//! which slide, found by pivoting rather than by trying modes. Lemke's method ends on a
//! solution in finitely many pivots for the Stewart–Trinkle contact LCP (Anitescu & Potra
//! 1997, including redundant rows such as a rigid foot's toe and heel), and its last basis
//! names the mode; the solution is then solved again from the original `M` and `q` on
//! that basis, so that complementarity holds exactly and the rest to rounding.
//!
//! Degenerate problems (a resting contact's `qᵢ = 0`, repeated rows) are the rule in
//! contact, not the exception: ties in the ratio test are broken lexicographically
//! (rows of `B⁻¹` over the pivot column), which keeps the path from cycling.
//!
//! Written here rather than taken from a crate: the one maintained Rust crate
//! (`lcp-solver`) is AGPL-3.0, `f64`-only and allocates its tableau on every call; this
//! one allocates once ([`Lemke::new`]) and solves in place.

use std::vec;
use std::vec::Vec;

use crate::model::contract::Real;

/// Why an LCP was not solved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LcpError {
    /// `M` or `q` is not the size the solver was made for.
    Size {
        /// The solver's size `n`.
        expected: usize,
        /// `M`'s entries (`n²` expected) or `q`'s length (`n` expected), whichever is off.
        got: usize,
    },
    /// An entry of `M` or `q` is NaN or infinite.
    NonFinite,
    /// The pivoting path ran off along a ray (no pivot row): Lemke's method certifies no
    /// solution for this `M` (one that is not copositive-plus may have none).
    Ray {
        /// Pivots taken before.
        pivots: usize,
    },
    /// More pivots than the solver allows ([`Lemke::max_pivots`]) without a solution.
    TooManyPivots {
        /// The limit.
        pivots: usize,
    },
    /// The path ended, but its solution solved again on its basis misses `z ≥ 0` or
    /// `w ≥ 0` by more than `√ε` of the problem's size (rounding has led the pivoting
    /// astray: a problem too ill-conditioned for it).
    Inaccurate {
        /// The most negative entry of `z` or `w`, over the problem's size.
        off: f64,
    },
}

impl core::fmt::Display for LcpError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LcpError::Size { expected, got } => write!(
                f,
                "the complementarity problem has the wrong size: {got} entries for a solver of size {expected}"
            ),
            LcpError::NonFinite => write!(f, "the complementarity problem has a NaN or infinite entry"),
            LcpError::Ray { pivots } => write!(
                f,
                "Lemke's pivoting ended on a ray after {pivots} pivots: no solution certified"
            ),
            LcpError::TooManyPivots { pivots } => {
                write!(f, "Lemke's pivoting took more than {pivots} pivots")
            }
            LcpError::Inaccurate { off } => write!(
                f,
                "Lemke's solution misses z ≥ 0 or w ≥ 0 by {off:.1e} of the problem's size: too ill-conditioned"
            ),
        }
    }
}

impl std::error::Error for LcpError {}

/// Lemke's method for LCPs of one size, its tableau and buffers allocated once.
#[derive(Clone, Debug)]
pub struct Lemke<T: Real> {
    n: usize,
    /// Row-major `n × (2n + 2)`: the columns of `w`, of `z`, of the artificial `z₀`,
    /// then the right-hand side; `B⁻¹` of the original system, whose `w` columns are `I`.
    tableau: Vec<T>,
    /// The variable basic in each row: `0..n` is `wᵢ`, `n..2n` is `zᵢ`, `2n` is `z₀`.
    basis: Vec<usize>,
    /// `M_BB` on the final basis, then its LU factors.
    lu: Vec<T>,
    /// The final basis's `z` indices.
    basic: Vec<usize>,
    /// The solution.
    z: Vec<T>,
    w: Vec<T>,
    /// The right-hand side of the re-solve.
    rhs: Vec<T>,
    /// The most pivots a solve may take.
    pub max_pivots: usize,
    /// Pivots the last solve took.
    pub pivots: usize,
    /// Whether a solve first tries the last solve's basis (on by default): one linear
    /// solve on it, kept where it is feasible (`z_B ≥ 0`, `w_N ≥ 0` to rounding), which
    /// it is wherever a time step's contact modes have not changed; else Lemke's path.
    pub warm_start: bool,
    /// Whether the last solve's answer came from the last basis, with no pivot.
    pub warm: bool,
}

impl<T: Real> Lemke<T> {
    /// A solver for LCPs of size `n`, every buffer allocated here.
    pub fn new(n: usize) -> Self {
        Lemke {
            n,
            tableau: vec![T::zero(); n * (2 * n + 2)],
            basis: vec![0; n],
            lu: vec![T::zero(); n * n],
            basic: Vec::with_capacity(n),
            z: vec![T::zero(); n],
            w: vec![T::zero(); n],
            rhs: vec![T::zero(); n],
            // Lemke's path is short on contact problems (a few pivots a contact); the
            // limit only stops a path that has lost its way to rounding.
            max_pivots: 50 * (n + 1),
            pivots: 0,
            warm_start: true,
            warm: false,
        }
    }

    /// The size `n`.
    pub fn size(&self) -> usize {
        self.n
    }

    /// Solves `w = M z + q ≥ 0`, `z ≥ 0`, `wᵀ z = 0`: `m` row-major `n × n`, `q` of
    /// length `n`; the solution is then [`Lemke::z`] and [`Lemke::w`]: `wᵢ = 0` exactly
    /// wherever `zᵢ` is basic, `zᵢ = 0` exactly elsewhere, and every entry is
    /// non-negative to rounding. Allocates nothing.
    pub fn solve(&mut self, m: &[T], q: &[T]) -> Result<(), LcpError> {
        let n = self.n;
        if m.len() != n * n {
            return Err(LcpError::Size {
                expected: n,
                got: m.len(),
            });
        }
        if q.len() != n {
            return Err(LcpError::Size {
                expected: n,
                got: q.len(),
            });
        }
        if !m.iter().chain(q.iter()).all(|x| x.is_finite()) {
            return Err(LcpError::NonFinite);
        }
        self.pivots = 0;
        self.warm = false;
        // z = 0 solves it where q ≥ 0.
        let mut lowest = None;
        for (i, &qi) in q.iter().enumerate() {
            // Ties to the last row: the lexicographic rule's choice for the first pivot
            // (rows of I over −1, the smallest is the last).
            if qi < T::zero() && lowest.is_none_or(|r: usize| qi <= q[r]) {
                lowest = Some(i);
            }
        }
        let Some(first) = lowest else {
            self.z.iter_mut().for_each(|z| *z = T::zero());
            self.w.copy_from_slice(q);
            self.basic.clear();
            return Ok(());
        };
        if self.warm_start && !self.basic.is_empty() && self.try_last_basis(m, q) {
            self.warm = true;
            return Ok(());
        }
        // I w − M z − 1 z₀ = q.
        let width = 2 * n + 2;
        for i in 0..n {
            let row = &mut self.tableau[i * width..(i + 1) * width];
            row.iter_mut().for_each(|x| *x = T::zero());
            row[i] = T::one();
            for j in 0..n {
                row[n + j] = -m[i * n + j];
            }
            row[2 * n] = -T::one();
            row[2 * n + 1] = q[i];
            self.basis[i] = i;
        }
        let z0 = 2 * n;
        let mut leaving = self.pivot(first, z0);
        loop {
            if leaving == z0 {
                break;
            }
            // The complement of the variable that left enters.
            let entering = if leaving < n {
                leaving + n
            } else {
                leaving - n
            };
            let Some(row) = self.ratio_row(entering) else {
                return Err(LcpError::Ray {
                    pivots: self.pivots,
                });
            };
            if self.pivots >= self.max_pivots {
                return Err(LcpError::TooManyPivots {
                    pivots: self.max_pivots,
                });
            }
            leaving = self.pivot(row, entering);
        }
        self.read_solution(m, q)
    }

    /// The last solution's `z`.
    pub fn z(&self) -> &[T] {
        &self.z
    }

    /// The last solution's `w = M z + q`.
    pub fn w(&self) -> &[T] {
        &self.w
    }

    /// The solution on the last solve's basis `B` (`M_BB z_B = −q_B`, `w = M z + q`), kept
    /// where it is feasible to rounding (`z_B ≥ 0`, `w_N ≥ 0` within `10⁴ ε` of the
    /// problem's size; a `z_B` within that of zero is put at zero); `false` where it is
    /// not (the buffers then hold nothing the caller reads).
    fn try_last_basis(&mut self, m: &[T], q: &[T]) -> bool {
        if !self.solve_on_basis(m, q) {
            return false;
        }
        let k = self.basic.len();
        let tol = T::lit(1e4) * T::default_epsilon() * self.problem_size(m, q, &self.rhs[..k]);
        if self.rhs[..k].iter().any(|&x| x < -tol) {
            return false;
        }
        self.z.iter_mut().for_each(|z| *z = T::zero());
        for a in 0..k {
            self.z[self.basic[a]] = self.rhs[a].max(T::zero());
        }
        self.set_w(m, q);
        // w_N as computed: non-negative to rounding, as on Lemke's path.
        !self.w.iter().any(|&x| x < -tol)
    }

    /// `M_BB x = −q_B` on the basis `self.basic` into `self.rhs`; `false` where it is
    /// singular or its solution not finite.
    fn solve_on_basis(&mut self, m: &[T], q: &[T]) -> bool {
        let (n, k) = (self.n, self.basic.len());
        for (a, &i) in self.basic.iter().enumerate() {
            for (b, &j) in self.basic.iter().enumerate() {
                self.lu[a * k + b] = m[i * n + j];
            }
            self.rhs[a] = -q[i];
        }
        lu_solve(&mut self.lu[..k * k], &mut self.rhs[..k], k)
            && self.rhs[..k].iter().all(|x| x.is_finite())
    }

    /// `w = M z + q`, then `w_B = 0` exactly.
    fn set_w(&mut self, m: &[T], q: &[T]) {
        let n = self.n;
        for i in 0..n {
            let mut wi = q[i];
            for j in 0..n {
                wi += m[i * n + j] * self.z[j];
            }
            self.w[i] = wi;
        }
        for &i in &self.basic {
            self.w[i] = T::zero();
        }
    }

    /// The problem's size at a solution `z`: `max |q| + max |M| max |z|`.
    fn problem_size(&self, m: &[T], q: &[T], z: &[T]) -> T {
        let big = |v: &[T]| v.iter().fold(T::zero(), |a, x| a.max(x.abs()));
        big(q) + big(m) * big(z)
    }

    /// Pivots on `(row, col)`; returns the variable that left the basis.
    fn pivot(&mut self, row: usize, col: usize) -> usize {
        let width = 2 * self.n + 2;
        let p = self.tableau[row * width + col];
        for x in &mut self.tableau[row * width..(row + 1) * width] {
            *x /= p;
        }
        for i in 0..self.n {
            if i == row {
                continue;
            }
            let f = self.tableau[i * width + col];
            if f == T::zero() {
                continue;
            }
            for j in 0..width {
                let v = self.tableau[row * width + j];
                self.tableau[i * width + j] -= f * v;
            }
        }
        self.pivots += 1;
        core::mem::replace(&mut self.basis[row], col)
    }

    /// The minimum-ratio row for the entering column `col`: `z₀`'s row where it ties
    /// (the path ends there), else the lexicographically least row of `B⁻¹` over the
    /// pivot entry. `None` on a ray.
    fn ratio_row(&self, col: usize) -> Option<usize> {
        let (n, width) = (self.n, 2 * self.n + 2);
        let scale = (0..n).fold(T::zero(), |a, i| a.max(self.tableau[i * width + col].abs()));
        // An entry below this is rounding of a zero: pivoting on it would blow up.
        let floor = scale * T::lit(1e5) * T::default_epsilon();
        let mut best: Option<(usize, T)> = None;
        for i in 0..n {
            let a = self.tableau[i * width + col];
            if a <= floor {
                continue;
            }
            let ratio = self.tableau[i * width + 2 * n + 1] / a;
            best = match best {
                None => Some((i, ratio)),
                Some((_, r)) if ratio < r => Some((i, ratio)),
                keep => keep,
            };
        }
        let (_, least) = best?;
        // Every row within rounding of the least ratio ties (relative to it, or to the
        // ratios' own size where it is zero).
        let rhs_size = (0..n).fold(T::zero(), |a, i| {
            a.max(self.tableau[i * width + 2 * n + 1].abs())
        });
        let tie = T::lit(1e4) * T::default_epsilon() * (least.abs() + rhs_size / scale);
        let ties = |i: &usize| {
            let a = self.tableau[i * width + col];
            a > floor && self.tableau[i * width + 2 * n + 1] / a <= least + tie
        };
        if let Some(i) = (0..n).filter(ties).find(|&i| self.basis[i] == 2 * n) {
            return Some(i);
        }
        (0..n).filter(ties).reduce(|b, i| {
            let (ab, ai) = (self.tableau[b * width + col], self.tableau[i * width + col]);
            for j in 0..n {
                let (xb, xi) = (
                    self.tableau[b * width + j] / ab,
                    self.tableau[i * width + j] / ai,
                );
                if xi < xb {
                    return i;
                }
                if xb < xi {
                    return b;
                }
            }
            b
        })
    }

    /// The solution on the final basis, solved again from `M` and `q`: `M_BB z_B = −q_B`
    /// (the basic `z`), `w = M z + q`, so that `w_B = 0` and `z_N = 0` exactly (kept
    /// from the tableau instead where that solve strays from it, a basis singular to
    /// rounding); then checked: `z` and `w` non-negative within `√ε` of the problem's
    /// size, else [`LcpError::Inaccurate`].
    fn read_solution(&mut self, m: &[T], q: &[T]) -> Result<(), LcpError> {
        let (n, width) = (self.n, 2 * self.n + 2);
        self.z.iter_mut().for_each(|z| *z = T::zero());
        self.basic.clear();
        for i in 0..n {
            let v = self.basis[i];
            if (n..2 * n).contains(&v) {
                self.z[v - n] = self.tableau[i * width + 2 * n + 1];
                self.basic.push(v - n);
            }
        }
        let k = self.basic.len();
        if self.solve_on_basis(m, q) {
            let size = self.problem_size(m, q, &self.z);
            let agrees = (0..k).all(|a| {
                (self.rhs[a] - self.z[self.basic[a]]).abs() <= T::default_epsilon().sqrt() * size
            });
            if agrees {
                for a in 0..k {
                    self.z[self.basic[a]] = self.rhs[a];
                }
            }
        }
        self.set_w(m, q);
        let size = self.problem_size(m, q, &self.z);
        let lowest = self
            .z
            .iter()
            .chain(self.w.iter())
            .fold(T::zero(), |a, &x| a.min(x));
        if -lowest > T::default_epsilon().sqrt() * size {
            return Err(LcpError::Inaccurate {
                off: (-lowest / size).to_subset().unwrap_or(f64::NAN),
            });
        }
        // Rounding's negatives of z put at zero (w_B stays zero: complementarity exact).
        for z in &mut self.z {
            *z = z.max(T::zero());
        }
        Ok(())
    }
}

/// Solves `A x = b` in place (`a` row-major `k × k`, overwritten by its factors; `b`
/// becomes `x`) by Gaussian elimination with partial pivoting; `false` if a pivot is
/// zero.
fn lu_solve<T: Real>(a: &mut [T], b: &mut [T], k: usize) -> bool {
    for c in 0..k {
        let p = (c..k)
            .max_by(|&i, &j| {
                a[i * k + c]
                    .abs()
                    .partial_cmp(&a[j * k + c].abs())
                    .unwrap_or(core::cmp::Ordering::Equal)
            })
            .unwrap_or(c);
        if a[p * k + c] == T::zero() {
            return false;
        }
        if p != c {
            for j in 0..k {
                a.swap(p * k + j, c * k + j);
            }
            b.swap(p, c);
        }
        for i in c + 1..k {
            let f = a[i * k + c] / a[c * k + c];
            if f == T::zero() {
                continue;
            }
            for j in c..k {
                let v = a[c * k + j];
                a[i * k + j] -= f * v;
            }
            let v = b[c];
            b[i] -= f * v;
        }
    }
    for c in (0..k).rev() {
        let mut s = b[c];
        for j in c + 1..k {
            s -= a[c * k + j] * b[j];
        }
        b[c] = s / a[c * k + c];
    }
    true
}
