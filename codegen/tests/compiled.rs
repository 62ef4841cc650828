//! The emitted fixtures (`compiled/programs.rs`, kept fresh by `emit.rs`) compile for
//! `f32` and `f64` and compute what `std`'s math computes.
#![allow(
    clippy::approx_constant,
    clippy::excessive_precision,
    clippy::let_and_return
)]

use nalgebra::{RealField, SMatrix, SVector};

pub trait Real: RealField + Copy {
    fn lit(v: f64) -> Self;
    /// What `leg_models::Real::sincos` computes, here from `std`.
    fn sincos(self) -> (Self, Self) {
        self.sin_cos()
    }
}
impl Real for f64 {
    fn lit(v: f64) -> Self {
        v
    }
}
impl Real for f32 {
    fn lit(v: f64) -> Self {
        v as f32
    }
}

/// The emitted functions' bound: here this test's `Real`.
pub use Real as Arithmetic;

pub struct FixtureParams<T> {
    pub mass: T,
    pub length: T,
    pub unused: T,
}

#[path = "compiled/programs.rs"]
mod programs;

#[test]
fn unary_ops() {
    let x: f64 = 0.5;
    let y = programs::unary(&SVector::<f64, 1>::new(x));
    let expected = [
        -x,
        x * x,
        2.0 * x,
        1.0 / x,
        x.sqrt(),
        x.sin(),
        x.cos(),
        x.tan(),
        x.asin(),
        x.acos(),
        x.atan(),
        x.sinh(),
        x.cosh(),
        x.tanh(),
        x.exp(),
        x.ln(),
        x.abs(),
    ];
    for (i, e) in expected.iter().enumerate() {
        assert_eq!(y[i], *e, "entry {i}");
    }
    let y32 = programs::unary(&SVector::<f32, 1>::new(0.5));
    for (i, e) in expected.iter().enumerate() {
        assert!(
            (f64::from(y32[i]) - e).abs() < 1e-6 * (1.0 + e.abs()),
            "f32 entry {i}"
        );
    }
}

#[test]
fn binary_ops() {
    let (a, b): (f64, f64) = (0.7, 1.9);
    let y = programs::binary(&SVector::<f64, 2>::new(a, b));
    let expected = [
        a + b,
        a - b,
        a * b,
        a / b,
        a.powf(b),
        a.atan2(b),
        a.min(b),
        a.max(b),
    ];
    for (i, e) in expected.iter().enumerate() {
        assert_eq!(y[i], *e, "entry {i}");
    }
}

#[test]
fn constants_are_exact() {
    let c = programs::constants(&SVector::<f64, 1>::new(3.0));
    let expected = [
        0.1,
        -2.5e-8,
        1e300,
        5e-324,
        1.0 / 3.0,
        -0.0,
        f64::MAX,
        0.1 * 3.0,
    ];
    for (i, e) in expected.iter().enumerate() {
        assert_eq!(c[i].to_bits(), e.to_bits(), "entry {i}: {} vs {e}", c[i]);
    }
}

#[test]
fn struct_inputs_and_scalars() {
    let p = FixtureParams {
        mass: 2.0,
        length: 3.0,
        unused: f64::NAN,
    };
    let q = SVector::<f64, 3>::new(f64::NAN, 5.0, f64::NAN);
    let e = programs::struct_input(&q, &SVector::from_element(f64::NAN), &p);
    assert_eq!(e, 30.0);
    let _ = p.unused;
}

#[test]
fn shapes_are_column_major() {
    let (s, v, m, no_rows, no_cols) = programs::shapes(&SVector::<f64, 2>::new(2.0, 3.0));
    assert_eq!(s, 5.0);
    assert_eq!(v, SVector::<f64, 2>::new(2.0, 3.0));
    assert_eq!(m, SMatrix::<f64, 2, 3>::new(2.0, 5.0, 6.0, 3.0, 0.0, 2.0));
    assert_eq!(no_rows.shape(), (0, 3));
    assert_eq!(no_cols.shape(), (2, 0));
}

#[test]
fn dead_code_is_gone_but_the_result_stays() {
    assert_eq!(
        programs::dead_code(&SVector::<f64, 2>::new(0.3, 9.0)),
        0.3f64.cos()
    );
}
