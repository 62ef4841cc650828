//! Small fixed-size Cholesky factorization and solves, written out so that the compiler
//! unrolls them for the sizes of a leg (nalgebra's general routines cost more here).

use nalgebra::SMatrix;

use crate::model::contract::Real;

/// The factorization `A = L D Lᵀ` (`L` unit lower triangular, `D` diagonal and positive)
/// of a symmetric positive definite `A`: the Cholesky factorization without its square
/// roots, which would lengthen the chain of dependent operations. Only the lower
/// triangle of `A` is read.
#[derive(Clone, Copy, Debug)]
pub struct Cholesky<T: Real, const N: usize> {
    /// Strictly lower part of `L`.
    l: SMatrix<T, N, N>,
    /// `1 / Dᵢᵢ`: the solves multiply instead of dividing.
    inv_diag: nalgebra::SVector<T, N>,
    /// Reciprocal condition estimate: `min Dᵢᵢ / max Dᵢᵢ` (the squared pivot ratio of
    /// the Cholesky factor).
    pub rcond: T,
}

impl<T: Real, const N: usize> Cholesky<T, N> {
    /// `None` unless every pivot is positive and finite.
    #[inline]
    pub fn new(a: &SMatrix<T, N, N>) -> Option<Self> {
        let mut l = SMatrix::<T, N, N>::zeros();
        let mut d = nalgebra::SVector::<T, N>::zeros();
        let mut inv_diag = nalgebra::SVector::<T, N>::zeros();
        let (mut lo, mut hi) = (T::zero(), T::zero());
        for j in 0..N {
            let mut dj = a[(j, j)];
            for k in 0..j {
                dj -= l[(j, k)] * l[(j, k)] * d[k];
            }
            // A NaN pivot compares as nothing, so it is refused too.
            if dj.partial_cmp(&T::zero()) != Some(core::cmp::Ordering::Greater) || !dj.is_finite() {
                return None;
            }
            d[j] = dj;
            if j == 0 {
                (lo, hi) = (dj, dj);
            } else {
                lo = lo.min(dj);
                hi = hi.max(dj);
            }
            let inv = T::one() / dj;
            inv_diag[j] = inv;
            for i in j + 1..N {
                let mut s = a[(i, j)];
                for k in 0..j {
                    s -= l[(i, k)] * l[(j, k)] * d[k];
                }
                l[(i, j)] = s * inv;
            }
        }
        let rcond = if N == 0 { T::one() } else { lo / hi };
        Some(Cholesky { l, inv_diag, rcond })
    }

    /// Overwrites `b` with `A⁻¹ b`.
    #[inline]
    pub fn solve_mut<const C: usize>(&self, b: &mut SMatrix<T, N, C>) {
        let l = &self.l;
        for c in 0..C {
            // L y = b, then D z = y
            for i in 0..N {
                let mut s = b[(i, c)];
                for k in 0..i {
                    s -= l[(i, k)] * b[(k, c)];
                }
                b[(i, c)] = s;
            }
            for i in 0..N {
                b[(i, c)] *= self.inv_diag[i];
            }
            // Lᵀ x = z
            for i in (0..N).rev() {
                let mut s = b[(i, c)];
                for k in i + 1..N {
                    s -= l[(k, i)] * b[(k, c)];
                }
                b[(i, c)] = s;
            }
        }
    }

    /// `A⁻¹`.
    pub fn inverse(&self) -> SMatrix<T, N, N> {
        let mut x = SMatrix::<T, N, N>::identity();
        self.solve_mut(&mut x);
        x
    }
}

/// One past the last coordinate of each coordinate's subtree, for coordinates in
/// depth-first order (parents first, every subtree contiguous); built only by
/// [`SubtreeEnds::of`], which checks that order, so a [`TreeLdl`] cannot be given ends that
/// do not describe a tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SubtreeEnds<const N: usize>([usize; N]);

impl<const N: usize> SubtreeEnds<N> {
    /// The ends of the tree `parents` (each coordinate's parent, `None` at a root), or
    /// `None` where the coordinates are not in depth-first order.
    pub const fn of(parents: &[Option<usize>; N]) -> Option<Self> {
        let mut ends = [0; N];
        let mut k = N;
        while k > 0 {
            k -= 1;
            if ends[k] == 0 {
                ends[k] = k + 1; // a leaf
            }
            if let Some(p) = parents[k] {
                if p >= k {
                    return None;
                }
                if ends[k] > ends[p] {
                    ends[p] = ends[k];
                }
            }
        }
        // Contiguous: everything in `k + 1 .. ends[k]` has its parent in `k .. itself`
        // (so, by induction, descends from k).
        let mut k = 0;
        while k < N {
            let mut j = k + 1;
            while j < ends[k] {
                match parents[j] {
                    Some(p) if p >= k => {}
                    _ => return None,
                }
                j += 1;
            }
            k += 1;
        }
        Some(SubtreeEnds(ends))
    }

    /// The ends, one per coordinate.
    pub const fn get(&self) -> &[usize; N] {
        &self.0
    }
}

/// One past the last coordinate of each coordinate's subtree, where the coordinates are
/// in depth-first order (parents first, every subtree contiguous); `None` otherwise, and
/// the mass matrix is then factored densely ([`SubtreeEnds::of`]).
pub const fn subtree_ends<const N: usize>(parents: &[Option<usize>; N]) -> Option<[usize; N]> {
    match SubtreeEnds::of(parents) {
        Some(ends) => Some(*ends.get()),
        None => None,
    }
}

/// Multiply–adds of factoring a mass matrix with the tree `parents` and solving one
/// right-hand side: `(dense, along the tree)`. Dense is `Σⱼ j (N − j)` for the factor and
/// `N²` for the solve; along the tree, a coordinate with `s` descendants costs their
/// depths below it in the factor and `2 s` in the solve. `None` along the tree where the
/// coordinates are not in depth-first order ([`subtree_ends`]).
pub const fn mass_factor_operations<const N: usize>(
    parents: &[Option<usize>; N],
) -> (usize, Option<usize>) {
    let mut dense = N * N;
    let mut k = 0;
    while k < N {
        dense += k * (N - k);
        k += 1;
    }
    let Some(ends) = subtree_ends(parents) else {
        return (dense, None);
    };
    let mut tree = 0;
    let mut i = 0;
    while i < N {
        tree += 2 * (ends[i] - i - 1);
        let mut j = i + 1;
        while j < ends[i] {
            tree += ends[j] - j; // Uᵢⱼ: one multiply–add per descendant of j, and itself
            j += 1;
        }
        i += 1;
    }
    (dense, Some(tree))
}

/// Whether the mass matrix of a mechanism with the tree `parents` is factored along the
/// tree ([`TreeLdl`]) rather than densely. The tree's loops run over stretches whose
/// lengths are known only at run time, where the dense ones unroll; counted under
/// callgrind that costs about 16 multiply–adds' worth a coordinate, so the tree is chosen
/// where its multiply–adds plus `16 N` are at most half the dense ones: a body carrying
/// legs (`minitaur_quadruped`, `cassie`), not a single leg.
pub const fn factors_along_the_tree<const N: usize>(parents: &[Option<usize>; N]) -> bool {
    match mass_factor_operations(parents) {
        (dense, Some(tree)) => 2 * (tree + 16 * N) <= dense,
        _ => false,
    }
}

/// `A = Lᵀ D L` (`L` unit lower triangular, `D` diagonal and positive) of a joint-space
/// mass matrix whose sparsity is a tree's: `Aᵢⱼ` is zero unless one of `i`, `j` descends
/// from the other. With the coordinates in depth-first order (every subtree contiguous,
/// `i`'s descendants `i + 1 .. ends[i]`) and eliminated from the leaves up, nothing fills
/// in (Featherstone's LTDL, RBDA §6.5): column `i` of `L` is nonzero on `i`'s descendants
/// only, so every loop runs over one contiguous stretch of a column. The work is
/// `Σ dₖ²/2` for coordinates at depth `dₖ`, not `N³/6`: on a body carrying legs, whose
/// branches meet only at the body, a fraction of the dense factorization. Only entries of
/// `A` between a coordinate and its descendants are read (upper triangle).
#[derive(Clone, Copy, Debug)]
pub struct TreeLdl<T: Real, const N: usize> {
    /// `Lⱼᵢ` below the diagonal for `j` a descendant of `i` (`A`'s upper triangle above it,
    /// not read again); other entries are not read.
    l: SMatrix<T, N, N>,
    inv_diag: nalgebra::SVector<T, N>,
    /// One past the last descendant of each coordinate: the model's constant, referred to
    /// rather than copied.
    ends: &'static [usize; N],
    /// Reciprocal condition estimate: `min Dᵢᵢ / max Dᵢᵢ`.
    pub rcond: T,
}

impl<T: Real, const N: usize> TreeLdl<T, N> {
    /// `None` unless every pivot is positive and finite. The pivots are taken from the
    /// leaves up, so `rcond` is not the dense factor's estimate for the same matrix (both
    /// are pivot ratios of an `L D Lᵀ`-type factor, of different orderings).
    // Inlined: the factor (`L` is N × N) is then built where its caller keeps it, not
    // moved through the `Option` and the `MassFactor` that wrap it.
    #[inline(always)]
    pub fn new(a: &SMatrix<T, N, N>, tree: &'static SubtreeEnds<N>) -> Option<Self> {
        let ends = &tree.0;
        // Factored in place in a copy of A: L below the diagonal (column-major, so a
        // column's stretch is contiguous), A read from above it.
        let mut l = *a;
        let mut d = nalgebra::SVector::<T, N>::zeros();
        let mut inv_diag = nalgebra::SVector::<T, N>::zeros();
        let (mut lo, mut hi) = (T::zero(), T::zero());
        let data = l.as_mut_slice();
        for i in (0..N).rev() {
            // Lⱼᵢ for j below i, from the deepest up:
            // Lⱼᵢ Dⱼ = Aᵢⱼ − Σ_{k below j} Lₖᵢ Dₖ Lₖⱼ.
            let mut di = data[i + i * N];
            for j in (i + 1..ends[i]).rev() {
                let mut s = data[i + j * N];
                let below = j + 1..ends[j];
                let col_i = &data[i * N + below.start..i * N + below.end];
                let col_j = &data[j * N + below.start..j * N + below.end];
                for ((x, y), dk) in col_i.iter().zip(col_j).zip(&d.as_slice()[below]) {
                    s -= *x * *dk * *y;
                }
                let lji = s * inv_diag[j];
                data[j + i * N] = lji;
                di -= lji * s;
            }
            // A NaN pivot compares as nothing, so it is refused too.
            if di.partial_cmp(&T::zero()) != Some(core::cmp::Ordering::Greater) || !di.is_finite() {
                return None;
            }
            if i == N - 1 {
                (lo, hi) = (di, di);
            } else {
                lo = lo.min(di);
                hi = hi.max(di);
            }
            d[i] = di;
            inv_diag[i] = T::one() / di;
        }
        let rcond = if N == 0 { T::one() } else { lo / hi };
        Some(TreeLdl {
            l,
            inv_diag,
            ends,
            rcond,
        })
    }

    /// Overwrites `b` with `A⁻¹ b`: `Lᵀ y = b` from the leaves up, `D z = y`, `L x = z`
    /// from the root down, each over a column's contiguous stretch.
    #[inline]
    pub fn solve_mut<const C: usize>(&self, b: &mut SMatrix<T, N, C>) {
        self.solve_lt_mut(b);
        for c in 0..C {
            for i in 0..N {
                b[(i, c)] *= self.inv_diag[i];
            }
        }
        self.solve_l_mut(b);
    }

    /// `1 / Dᵢᵢ`.
    #[inline(always)]
    pub fn inv_diag(&self) -> &nalgebra::SVector<T, N> {
        &self.inv_diag
    }

    /// Overwrites `b` with `L⁻ᵀ b` (`Lᵀ y = b`, from the leaves up): the first half of a
    /// solve, `A⁻¹ = L⁻¹ D⁻¹ L⁻ᵀ`.
    #[inline]
    pub fn solve_lt_mut<const C: usize>(&self, b: &mut SMatrix<T, N, C>) {
        let l = self.l.as_slice();
        for bc in b.as_mut_slice().chunks_exact_mut(N.max(1)).take(C) {
            for i in (0..N).rev() {
                let (head, tail) = bc.split_at_mut(i + 1);
                let below = &tail[..self.ends[i] - i - 1];
                let col = &l[i * N + i + 1..i * N + self.ends[i]];
                let mut s = head[i];
                for (x, y) in col.iter().zip(below) {
                    s -= *x * *y;
                }
                head[i] = s;
            }
        }
    }

    /// Overwrites `b` with `b L⁻¹`: [`TreeLdl::solve_lt_mut`] of `bᵀ`, for `R` right-hand
    /// sides laid out as the rows of `b` (a constraint Jacobian as it is stored). Each step
    /// takes a whole column of `b` (the `R` sides' entries of one coordinate, contiguous)
    /// less multiples of its descendants' columns: loops the compiler vectorizes over the
    /// sides, where a side at a time is a chain of dependent multiply–adds.
    #[inline]
    pub fn solve_lt_rows_mut<const R: usize>(&self, b: &mut SMatrix<T, R, N>) {
        let l = self.l.as_slice();
        let data = b.as_mut_slice();
        for i in (0..N).rev() {
            let (head, tail) = data.split_at_mut((i + 1) * R);
            let col_i = &mut head[i * R..];
            for k in i + 1..self.ends[i] {
                let lki = l[i * N + k];
                let col_k = &tail[(k - i - 1) * R..(k - i) * R];
                for (y, x) in col_i.iter_mut().zip(col_k) {
                    *y -= lki * *x;
                }
            }
        }
    }

    /// Overwrites `b` with `L⁻¹ b` (`L x = b`, from the root down): the last half of a
    /// solve.
    #[inline]
    pub fn solve_l_mut<const C: usize>(&self, b: &mut SMatrix<T, N, C>) {
        let l = self.l.as_slice();
        for bc in b.as_mut_slice().chunks_exact_mut(N.max(1)).take(C) {
            for i in 0..N {
                let (head, tail) = bc.split_at_mut(i + 1);
                let xi = head[i];
                let col = &l[i * N + i + 1..i * N + self.ends[i]];
                for (y, x) in tail[..self.ends[i] - i - 1].iter_mut().zip(col) {
                    *y -= *x * xi;
                }
            }
        }
    }
}

/// A factored symmetric positive definite matrix: what the solves need of it, so that a
/// path that factors and solves in one place is compiled for the factor its model uses
/// (no enum to match in the hot loop).
pub trait Factored<T: Real, const N: usize> {
    /// Reciprocal condition estimate: the pivots' `min / max`.
    fn rcond(&self) -> T;
    /// Overwrites `b` with `A⁻¹ b`.
    fn solve_mut<const C: usize>(&self, b: &mut SMatrix<T, N, C>);
}

impl<T: Real, const N: usize> Factored<T, N> for Cholesky<T, N> {
    #[inline(always)]
    fn rcond(&self) -> T {
        self.rcond
    }
    #[inline(always)]
    fn solve_mut<const C: usize>(&self, b: &mut SMatrix<T, N, C>) {
        Cholesky::solve_mut(self, b)
    }
}

impl<T: Real, const N: usize> Factored<T, N> for TreeLdl<T, N> {
    #[inline(always)]
    fn rcond(&self) -> T {
        self.rcond
    }
    #[inline(always)]
    fn solve_mut<const C: usize>(&self, b: &mut SMatrix<T, N, C>) {
        TreeLdl::solve_mut(self, b)
    }
}

/// `M` factored the way its model pays for ([`factors_along_the_tree`]): densely, or along
/// the tree. For a system built once and solved several times (the stance's
/// `ContactSystem`), where one match a solve is nothing beside the solve.
#[derive(Clone, Copy, Debug)]
pub enum MassFactor<T: Real, const N: usize> {
    /// `M = L Lᵀ`.
    Dense(Cholesky<T, N>),
    /// `M = Lᵀ D L` along the tree.
    Tree(TreeLdl<T, N>),
}

impl<T: Real, const N: usize> Factored<T, N> for MassFactor<T, N> {
    #[inline(always)]
    fn rcond(&self) -> T {
        match self {
            MassFactor::Dense(f) => f.rcond,
            MassFactor::Tree(f) => f.rcond,
        }
    }
    #[inline(always)]
    fn solve_mut<const C: usize>(&self, b: &mut SMatrix<T, N, C>) {
        match self {
            MassFactor::Dense(f) => f.solve_mut(b),
            MassFactor::Tree(f) => f.solve_mut(b),
        }
    }
}

/// `P A Pᵀ = L D Lᵀ` with symmetric (diagonal) pivoting, for a positive semidefinite `A`
/// whose rank may fall short of `N` by up to `deficiency`: the closure rows of a leg
/// closed redundantly (a parallelogram closed twice). Which rows repeat the others
/// depends on the configuration, so the pivots choose them: the last `deficiency` pivots
/// may be negligible (below `rcond_floor` of the largest), and their unknowns are set to
/// zero; any other negligible pivot refuses the factorization.
#[derive(Clone, Copy, Debug)]
pub struct PivotedLdlt<T: Real, const N: usize> {
    l: SMatrix<T, N, N>,
    inv_diag: nalgebra::SVector<T, N>,
    perm: [usize; N],
    /// Pivots used (`N` minus the rows left out).
    pub rank: usize,
    /// `min Dᵢᵢ / max Dᵢᵢ` over the pivots used.
    pub rcond: T,
}

impl<T: Real, const N: usize> PivotedLdlt<T, N> {
    /// `None` if a pivot other than the last `deficiency` is negligible or not finite.
    pub fn new(a: &SMatrix<T, N, N>, deficiency: usize, rcond_floor: T) -> Option<Self> {
        let mut w = *a;
        let mut l = SMatrix::<T, N, N>::zeros();
        let mut inv_diag = nalgebra::SVector::<T, N>::zeros();
        let mut perm: [usize; N] = core::array::from_fn(|i| i);
        let (mut lo, mut hi) = (T::one(), T::zero());
        let mut rank = N;
        for k in 0..N {
            let mut p = k;
            for i in k + 1..N {
                if w[(i, i)] > w[(p, p)] {
                    p = i;
                }
            }
            if p != k {
                w.swap_rows(k, p);
                w.swap_columns(k, p);
                l.swap_rows(k, p);
                perm.swap(k, p);
            }
            let d = w[(k, k)];
            if !d.is_finite() {
                return None;
            }
            if k == 0 {
                hi = d;
                lo = d;
            }
            // A NaN compares as nothing, so it counts as negligible.
            let above = |x: T| d.partial_cmp(&x) == Some(core::cmp::Ordering::Greater);
            if !above(rcond_floor * hi) || (k == 0 && !above(T::zero())) {
                if N - k <= deficiency {
                    rank = k;
                    break;
                }
                return None;
            }
            lo = lo.min(d);
            let inv = T::one() / d;
            inv_diag[k] = inv;
            for i in k + 1..N {
                l[(i, k)] = w[(i, k)] * inv;
            }
            for j in k + 1..N {
                for i in j..N {
                    let v = w[(i, j)] - l[(i, k)] * l[(j, k)] * d;
                    w[(i, j)] = v;
                    w[(j, i)] = v;
                }
            }
        }
        let rcond = if N == 0 || rank == 0 {
            T::one()
        } else {
            lo / hi
        };
        Some(PivotedLdlt {
            l,
            inv_diag,
            perm,
            rank,
            rcond,
        })
    }

    /// Overwrites `b` with the solution that uses the pivoted rows (the others' unknowns
    /// are zero; their equations hold when they repeat the others).
    pub fn solve_mut<const C: usize>(&self, b: &mut SMatrix<T, N, C>) {
        let r = self.rank;
        for c in 0..C {
            let mut y = nalgebra::SVector::<T, N>::zeros();
            for i in 0..N {
                y[i] = b[(self.perm[i], c)];
            }
            for i in 0..r {
                let mut s = y[i];
                for k in 0..i {
                    s -= self.l[(i, k)] * y[k];
                }
                y[i] = s;
            }
            for i in 0..r {
                y[i] *= self.inv_diag[i];
            }
            for i in (0..r).rev() {
                let mut s = y[i];
                for k in i + 1..r {
                    s -= self.l[(k, i)] * y[k];
                }
                y[i] = s;
            }
            for i in r..N {
                y[i] = T::zero();
            }
            for i in 0..N {
                b[(self.perm[i], c)] = y[i];
            }
        }
    }
}

/// `P A = L U` with partial pivoting, for a general square `A` (nalgebra's `LU` needs
/// its dimension as a type number, which generic const code cannot name).
#[derive(Clone, Copy, Debug)]
pub struct Lu<T: Real, const N: usize> {
    /// `L` below the diagonal (unit diagonal implied), `U` on and above it.
    lu: SMatrix<T, N, N>,
    perm: [usize; N],
}

impl<T: Real, const N: usize> Lu<T, N> {
    /// `None` if a pivot is zero, negligible (below `ε` of the largest entry) or not finite.
    pub fn new(a: &SMatrix<T, N, N>) -> Option<Self> {
        let mut lu = *a;
        let mut perm: [usize; N] = core::array::from_fn(|i| i);
        let scale = a.amax();
        if !scale.is_finite() {
            return None;
        }
        for k in 0..N {
            let mut p = k;
            for i in k + 1..N {
                if lu[(i, k)].abs() > lu[(p, k)].abs() {
                    p = i;
                }
            }
            let pivot = lu[(p, k)];
            let floor = T::default_epsilon() * scale;
            if pivot.abs().partial_cmp(&floor) != Some(core::cmp::Ordering::Greater) {
                return None;
            }
            lu.swap_rows(k, p);
            perm.swap(k, p);
            for i in k + 1..N {
                let f = lu[(i, k)] / pivot;
                lu[(i, k)] = f;
                for j in k + 1..N {
                    let v = lu[(k, j)];
                    lu[(i, j)] -= f * v;
                }
            }
        }
        Some(Lu { lu, perm })
    }

    /// `A⁻¹ B`.
    pub fn solve<const C: usize>(&self, b: &SMatrix<T, N, C>) -> SMatrix<T, N, C> {
        let mut x = SMatrix::<T, N, C>::zeros();
        for c in 0..C {
            for i in 0..N {
                let mut s = b[(self.perm[i], c)];
                for k in 0..i {
                    s -= self.lu[(i, k)] * x[(k, c)];
                }
                x[(i, c)] = s;
            }
            for i in (0..N).rev() {
                let mut s = x[(i, c)];
                for k in i + 1..N {
                    s -= self.lu[(i, k)] * x[(k, c)];
                }
                x[(i, c)] = s / self.lu[(i, i)];
            }
        }
        x
    }
}

/// `A B`, as plain loops over the fixed sizes (unrolled by the compiler).
#[inline]
pub fn mul<T: Real, const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, C>,
) -> SMatrix<T, R, C> {
    let mut out = SMatrix::<T, R, C>::zeros();
    for c in 0..C {
        for k in 0..K {
            let bkc = b[(k, c)];
            for r in 0..R {
                out[(r, c)] += a[(r, k)] * bkc;
            }
        }
    }
    out
}

/// `A Bᵀ`, as rank-one updates over the shared columns (each a contiguous run the
/// compiler vectorizes).
#[inline]
pub fn mul_nt<T: Real, const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, C, K>,
) -> SMatrix<T, R, C> {
    let mut out = SMatrix::<T, R, C>::zeros();
    for k in 0..K {
        for c in 0..C {
            let bck = b[(c, k)];
            for r in 0..R {
                out[(r, c)] += a[(r, k)] * bck;
            }
        }
    }
    out
}

/// `A diag(d)`: column `k` of `A` times `dₖ` (the rows' factors `P D⁻¹` of a tree solve).
#[inline]
pub fn scale_columns<T: Real, const R: usize, const N: usize>(
    a: &SMatrix<T, R, N>,
    d: &nalgebra::SVector<T, N>,
) -> SMatrix<T, R, N> {
    let mut out = *a;
    for (k, mut column) in out.column_iter_mut().enumerate() {
        column *= d[k];
    }
    out
}

/// `diag(d) A`: row `k` of `A` times `dₖ` (`D⁻¹ t` of a tree solve, for `C` sides).
#[inline]
pub fn scale_rows<T: Real, const N: usize, const C: usize>(
    a: &SMatrix<T, N, C>,
    d: &nalgebra::SVector<T, N>,
) -> SMatrix<T, N, C> {
    let mut out = *a;
    for mut column in out.column_iter_mut() {
        column.component_mul_assign(d);
    }
    out
}

/// The rows of each column of a matrix that may be nonzero, `[lo, hi)` from its first to
/// its last nonzero entry (`lo == hi` for a zero column). A constraint or contact row of one
/// leg of a robot is zero on every other leg's coordinates (its half solve along the tree
/// too: a coordinate's value comes from its descendants), so where the rows are stored leg
/// by leg, a leg's column meets only that leg's rows and the body's meet all of them:
/// [`mul_nt_spans`] skips the rest.
pub type Spans<const K: usize> = [(usize, usize); K];

/// The [`Spans`] of `a`'s columns.
#[inline]
pub fn column_spans<T: Real, const R: usize, const K: usize>(a: &SMatrix<T, R, K>) -> Spans<K> {
    core::array::from_fn(|k| {
        let column = &a.as_slice()[k * R..(k + 1) * R];
        match column.iter().position(|x| *x != T::zero()) {
            Some(lo) => (
                lo,
                R - column
                    .iter()
                    .rev()
                    .position(|x| *x != T::zero())
                    .unwrap_or(0),
            ),
            None => (0, 0),
        }
    })
}

/// `A Bᵀ` as [`mul_nt`], each shared column's rank-one update made only for the columns of
/// the result where `B`'s column may be nonzero (`b_spans`), and not at all where `A`'s
/// column is zero (`a_spans`). Each update still runs over all of `A`'s column: a fixed
/// length the compiler unrolls and vectorizes, where a span's varying length would cost
/// more than its zeros (Cassie's forward dynamics took 15 % more instructions). The
/// skipped terms are exact zeros, so for finite factors the result is the dense one to the
/// bit (the same sums in the same order).
#[inline]
pub fn mul_nt_spans<T: Real, const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<T, R, K>,
    a_spans: &Spans<K>,
    b: &SMatrix<T, C, K>,
    b_spans: &Spans<K>,
) -> SMatrix<T, R, C> {
    let mut out = SMatrix::<T, R, C>::zeros();
    for k in 0..K {
        let ((alo, ahi), (blo, bhi)) = (a_spans[k], b_spans[k]);
        if alo >= ahi {
            continue;
        }
        for c in blo..bhi {
            let bck = b[(c, k)];
            for r in 0..R {
                out[(r, c)] += a[(r, k)] * bck;
            }
        }
    }
    out
}

/// `Aᵀ B`, as plain loops.
#[inline]
pub fn mul_tn<T: Real, const K: usize, const R: usize, const C: usize>(
    a: &SMatrix<T, K, R>,
    b: &SMatrix<T, K, C>,
) -> SMatrix<T, R, C> {
    let mut out = SMatrix::<T, R, C>::zeros();
    for c in 0..C {
        for r in 0..R {
            let mut s = T::zero();
            for k in 0..K {
                s += a[(k, r)] * b[(k, c)];
            }
            out[(r, c)] = s;
        }
    }
    out
}

/// Whether every entry is finite: `0 · x` is zero for a finite `x` and NaN otherwise, so
/// one sum over the entries (a loop the compiler vectorizes) says it.
#[inline]
pub fn all_finite<T: Real, const R: usize, const C: usize>(a: &SMatrix<T, R, C>) -> bool {
    let mut acc = T::zero();
    for &x in a.as_slice() {
        acc += x * T::zero();
    }
    acc == T::zero()
}

/// `a ← −a`, entry by entry.
#[inline]
pub fn negate<T: Real, const R: usize, const C: usize>(
    mut a: SMatrix<T, R, C>,
) -> SMatrix<T, R, C> {
    for x in a.as_mut_slice() {
        *x = -*x;
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    #[test]
    fn factors_solves_and_refuses() {
        let a = Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0);
        let c = Cholesky::new(&a).unwrap();
        let mut x = SMatrix::<f64, 3, 2>::new(1.0, 0.0, 2.0, 1.0, 3.0, -1.0);
        let b = x;
        c.solve_mut(&mut x);
        assert!((a * x - b).amax() < 1e-14);
        assert!((c.inverse() * a - Matrix3::identity()).amax() < 1e-14);
        // L D Lᵀ against nalgebra's Cholesky factor: L_chol = L √D.
        let reference = a.cholesky().unwrap().l();
        for i in 0..3 {
            let d = 1.0 / c.inv_diag[i];
            assert!((reference[(i, i)] - d.sqrt()).abs() < 1e-15);
            for j in 0..i {
                assert!(
                    (reference[(i, j)] - c.l[(i, j)] * (1.0 / c.inv_diag[j]).sqrt()).abs() < 1e-15
                );
            }
        }
        assert!(
            Cholesky::new(&Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0)).is_none()
        );
        assert!(Cholesky::new(&Matrix3::from_element(f64::NAN)).is_none());
        assert_eq!(
            Cholesky::new(&SMatrix::<f64, 0, 0>::zeros()).unwrap().rcond,
            1.0
        );
    }

    /// The tree factorization against the dense one on a mass matrix with a tree's
    /// sparsity (a chain of three carrying two branches, one of them forked), built as
    /// `Σ vₖ vₖᵀ` over vectors supported on each coordinate's path to the root: it solves
    /// to rounding, refuses what the dense one refuses, and never reads off the tree.
    #[test]
    fn tree_ldl_solves_as_the_dense_factor() {
        const N: usize = 8;
        const PARENTS: [Option<usize>; N] = [
            None,
            Some(0),
            Some(1),
            Some(2),
            Some(3),
            Some(3),
            Some(2),
            Some(6),
        ];
        const ENDS: SubtreeEnds<N> = match SubtreeEnds::of(&PARENTS) {
            Some(ends) => ends,
            None => panic!("not depth-first"),
        };
        let (parents, ends) = (PARENTS, &ENDS);
        assert_eq!(*ends.get(), [8, 8, 8, 6, 5, 6, 8, 8]);
        let mut a = SMatrix::<f64, N, N>::identity() * 0.5;
        for k in 0..N {
            let mut v = SMatrix::<f64, N, 1>::zeros();
            let mut i = Some(k);
            while let Some(j) = i {
                v[j] = 1.0 + 0.37 * ((k * 7 + j * 3) % 5) as f64 - 0.6;
                i = parents[j];
            }
            a += v * v.transpose() * (1.0 + k as f64);
        }
        // Off the tree (4 and 5 are siblings; 4 and 6 in different branches) it is zero.
        assert_eq!(a[(4, 5)], 0.0);
        assert_eq!(a[(4, 6)], 0.0);
        let tree = TreeLdl::new(&a, ends).unwrap();
        let dense = Cholesky::new(&a).unwrap();
        let b = SMatrix::<f64, N, 2>::from_fn(|i, j| (i as f64 - 2.5) * (j as f64 + 1.0));
        let (mut x, mut y) = (b, b);
        tree.solve_mut(&mut x);
        dense.solve_mut(&mut y);
        assert!((a * x - b).amax() < 1e-13, "{}", a * x - b);
        assert!((x - y).amax() < 1e-13);
        assert!(tree.rcond > 0.0 && tree.rcond <= 1.0);
        // The half solve on sides laid out as rows is the column one's transpose, and the
        // halves with D⁻¹ between them give the whole solve (A⁻¹ = L⁻¹ D⁻¹ L⁻ᵀ), x.
        let mut columns = b;
        tree.solve_lt_mut(&mut columns);
        let mut rows = b.transpose();
        tree.solve_lt_rows_mut(&mut rows);
        assert!((rows.transpose() - columns).amax() < 1e-15);
        let mut whole = SMatrix::<f64, N, 2>::from_fn(|i, j| rows[(j, i)] * tree.inv_diag()[i]);
        tree.solve_l_mut(&mut whole);
        assert!((whole - x).amax() < 1e-13);
        // A Bᵀ by rank-one updates against nalgebra's product.
        let c = SMatrix::<f64, 3, N>::from_fn(|i, j| (i * N + j) as f64 * 0.1 - 1.0);
        assert!((mul_nt(&rows, &c) - rows * c.transpose()).amax() < 1e-13);
        // Rows of two branches (as a robot's legs' loops): rows 0 and 1 on the branch
        // under 3, rows 2 and 3 on the one under 6 (row 3 reaching into the chain at 1).
        // After the half solve a branch's columns meet only its own rows; the chain's meet
        // every row (spans read off the tree by hand).
        let mut branches = SMatrix::<f64, 4, N>::zeros();
        branches[(0, 4)] = 0.7;
        branches[(1, 5)] = -1.3;
        branches[(1, 3)] = 0.4;
        branches[(2, 7)] = 2.1;
        branches[(3, 7)] = -0.6;
        branches[(3, 1)] = 0.9;
        let mut dense_half = branches;
        tree.solve_lt_rows_mut(&mut dense_half);
        let spans = column_spans(&dense_half);
        assert_eq!(
            spans,
            [
                (0, 4),
                (0, 4),
                (0, 4),
                (0, 2),
                (0, 1),
                (1, 2),
                (2, 4),
                (2, 4)
            ]
        );
        // The products over the spans are nalgebra's (and an empty column is skipped).
        let mut other = c;
        other.column_mut(5).fill(0.0);
        let other_spans = column_spans(&other);
        assert_eq!(other_spans[5], (0, 0));
        let near = |x: f64, y: f64| (x - y).abs() <= 1e-14 * (1.0 + y.abs());
        let same = |p: &[f64], q: &[f64]| p.iter().zip(q).all(|(x, y)| near(*x, *y));
        let (h, h_spans) = (dense_half, spans);
        let nt = mul_nt_spans(&h, &h_spans, &other, &other_spans);
        assert!(same(nt.as_slice(), (h * other.transpose()).as_slice()));
        // and to the bit the dense rank-one updates' (the same sums in the same order).
        assert_eq!(nt, mul_nt(&h, &other));
        // With the branch rows on the right, each update reaches only the result's columns
        // of the rows its column meets: the skipping the stance relies on.
        let tn = mul_nt_spans(&other, &other_spans, &h, &h_spans);
        assert!(same(tn.as_slice(), (other * h.transpose()).as_slice()));
        assert_eq!(tn, mul_nt(&other, &h));
        // Whatever is off the tree is not read.
        let mut noisy = a;
        noisy[(4, 6)] = 7.0;
        noisy[(6, 4)] = 7.0;
        let mut z = b;
        TreeLdl::new(&noisy, ends).unwrap().solve_mut(&mut z);
        assert_eq!(z, x);
        // Not positive definite, NaN: refused.
        let mut indefinite = a;
        indefinite[(7, 7)] = -1.0;
        assert!(TreeLdl::new(&indefinite, ends).is_none());
        let mut nan = a;
        nan[(0, 0)] = f64::NAN;
        assert!(TreeLdl::new(&nan, ends).is_none());
    }

    /// The general LU against its definition (`A x = b` for a non-symmetric `A` that needs
    /// a row exchange) and refusing a singular matrix.
    #[test]
    fn lu_solves_and_refuses() {
        let a = Matrix3::new(0.0, 2.0, 1.0, 3.0, -1.0, 0.5, 1.0, 4.0, -2.0);
        let lu = Lu::new(&a).unwrap();
        let b = SMatrix::<f64, 3, 2>::new(1.0, 0.0, -2.0, 1.0, 0.5, 3.0);
        assert!((a * lu.solve(&b) - b).amax() < 1e-14);
        let singular = Matrix3::new(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 1.0, 1.0);
        assert!(Lu::new(&singular).is_none());
        assert!(Lu::new(&Matrix3::from_element(f64::NAN)).is_none());
    }

    /// A rank-2 3×3 system (its third row is the sum of the first two): solved where it is
    /// consistent, refused without the allowance, and equal to Cholesky when regular.
    #[test]
    fn pivoted_ldlt_solves_rank_deficient_systems() {
        let j = nalgebra::Matrix3x2::new(1.0, 0.5, -0.3, 2.0, 0.7, 2.5);
        let a = j * j.transpose(); // rows 0 + 1 = row 2
        let floor = 1e-13;
        assert!(PivotedLdlt::new(&a, 0, floor).is_none());
        let f = PivotedLdlt::new(&a, 1, floor).unwrap();
        assert_eq!(f.rank, 2);
        let b = a * nalgebra::Vector3::new(0.3, -1.0, 2.0); // consistent
        let mut x = b;
        f.solve_mut(&mut x);
        assert!((a * x - b).amax() < 1e-12, "{}", a * x - b);
        assert!(x.iter().filter(|v| **v == 0.0).count() >= 1);
        let spd = Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0);
        let mut y = nalgebra::Vector3::new(1.0, 2.0, 3.0);
        let mut z = y;
        PivotedLdlt::new(&spd, 1, floor).unwrap().solve_mut(&mut y);
        Cholesky::new(&spd).unwrap().solve_mut(&mut z);
        assert!((y - z).amax() < 1e-14);
    }
}
