//! Small fixed-size Cholesky factorization and solves, written out so that the compiler
//! unrolls them for the sizes of a leg (nalgebra's general routines cost more here).

use nalgebra::SMatrix;

use crate::model::Real;

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

/// Whether every entry is finite.
#[inline]
pub fn all_finite<T: Real, const R: usize, const C: usize>(a: &SMatrix<T, R, C>) -> bool {
    let mut ok = true;
    for x in a.iter() {
        ok &= x.is_finite();
    }
    ok
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
}
