//! SIMD lanes as the scalar of generated code: four states (or four parameter sets) in
//! one call, for sampling-based MPC, domain randomization and parameter sweeps.
//!
//! [`F64x4`] implements [`Arithmetic`], so every generated function runs on it unchanged
//! (`Minitaur::dynamics_terms(&q4, &qd4, &p4)`), lane by lane, without branches: the
//! compiler turns its element-wise array operations into vector instructions (two SSE2
//! registers per value on a baseline x86-64, one with AVX). The trigonometry is
//! [`crate::Real::sincos`]'s, made branch-free (every reduction round, quadrants selected by
//! bit masks); a lane whose angle is beyond the reduction's range goes to libm.
//! [`crate::dynamics::batch`] solves the constrained dynamics of all lanes at once.

use core::ops::{Add, Div, Mul, Neg, Sub};

use nalgebra::{ComplexField, RealField, SVector};

use crate::model::contract::Arithmetic;

/// Four `f64` lanes.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub struct F64x4(pub [f64; 4]);

impl F64x4 {
    /// Lanes per value.
    pub const LANES: usize = 4;

    /// Every lane `x`.
    #[inline(always)]
    pub fn splat(x: f64) -> Self {
        F64x4([x; 4])
    }

    /// Lane `i`.
    #[inline(always)]
    pub fn lane(self, i: usize) -> f64 {
        self.0[i]
    }

    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        F64x4([f(self.0[0]), f(self.0[1]), f(self.0[2]), f(self.0[3])])
    }

    #[inline(always)]
    fn zip(self, o: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        F64x4([
            f(self.0[0], o.0[0]),
            f(self.0[1], o.0[1]),
            f(self.0[2], o.0[2]),
            f(self.0[3], o.0[3]),
        ])
    }
}

macro_rules! binary {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for F64x4 {
            type Output = F64x4;
            #[inline(always)]
            fn $f(self, o: F64x4) -> F64x4 {
                self.zip(o, |a, b| a $op b)
            }
        }
    };
}
binary!(Add, add, +);
binary!(Sub, sub, -);
binary!(Mul, mul, *);
binary!(Div, div, /);

impl Neg for F64x4 {
    type Output = F64x4;
    #[inline(always)]
    fn neg(self) -> F64x4 {
        self.map(|a| -a)
    }
}

impl Arithmetic for F64x4 {
    #[inline(always)]
    fn lit(value: f64) -> Self {
        F64x4::splat(value)
    }
    #[inline(always)]
    fn sincos(self) -> (Self, Self) {
        let (s, c) = crate::model::trig::sincos_lanes(self.0);
        (F64x4(s), F64x4(c))
    }
    fn sqrt(self) -> Self {
        self.map(<f64 as ComplexField>::sqrt)
    }
    fn sin(self) -> Self {
        self.sincos().0
    }
    fn cos(self) -> Self {
        self.sincos().1
    }
    fn tan(self) -> Self {
        self.map(<f64 as ComplexField>::tan)
    }
    fn asin(self) -> Self {
        self.map(<f64 as ComplexField>::asin)
    }
    fn acos(self) -> Self {
        self.map(<f64 as ComplexField>::acos)
    }
    fn atan(self) -> Self {
        self.map(<f64 as ComplexField>::atan)
    }
    fn sinh(self) -> Self {
        self.map(<f64 as ComplexField>::sinh)
    }
    fn cosh(self) -> Self {
        self.map(<f64 as ComplexField>::cosh)
    }
    fn tanh(self) -> Self {
        self.map(<f64 as ComplexField>::tanh)
    }
    fn exp(self) -> Self {
        self.map(<f64 as ComplexField>::exp)
    }
    fn ln(self) -> Self {
        self.map(<f64 as ComplexField>::ln)
    }
    fn abs(self) -> Self {
        self.map(<f64 as ComplexField>::abs)
    }
    fn powf(self, exponent: Self) -> Self {
        self.zip(exponent, <f64 as ComplexField>::powf)
    }
    fn atan2(self, x: Self) -> Self {
        self.zip(x, <f64 as RealField>::atan2)
    }
    fn min(self, other: Self) -> Self {
        self.zip(other, f64::min)
    }
    fn max(self, other: Self) -> Self {
        self.zip(other, f64::max)
    }
}

/// Four vectors as one vector of lanes: lane `k` of entry `i` is `v[k][i]`.
pub fn pack<const N: usize>(v: [&SVector<f64, N>; 4]) -> SVector<F64x4, N> {
    SVector::from_data(nalgebra::ArrayStorage([core::array::from_fn(|i| {
        F64x4([v[0][i], v[1][i], v[2][i], v[3][i]])
    })]))
}

/// Lane `k` of a vector of lanes.
pub fn unpack<const N: usize>(v: &SVector<F64x4, N>, k: usize) -> SVector<f64, N> {
    SVector::from_fn(|i, _| v[i].0[k])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lanes_compute_what_f64_computes() {
        let a = F64x4([1.5, -2.0, 0.0, 1e300]);
        let b = F64x4([0.25, 3.0, -0.0, 1e10]);
        for (k, (x, y)) in a.0.iter().zip(b.0).enumerate() {
            assert_eq!((a + b).0[k], x + y);
            assert_eq!((a - b).0[k], x - y);
            assert_eq!((a * b).0[k], x * y);
            assert_eq!((a / b).0[k].to_bits(), (x / y).to_bits());
            assert_eq!((-a).0[k].to_bits(), (-x).to_bits());
        }
        let x = F64x4([0.3, -1.9, 1e-9, 2.5e6]);
        let (s, c) = x.sincos();
        for k in 0..4 {
            assert_eq!(
                (s.0[k], c.0[k]),
                crate::model::trig::sincos(x.0[k]),
                "lane {k}: the scalar path's bits"
            );
        }
    }
}
