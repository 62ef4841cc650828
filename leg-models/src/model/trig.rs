//! Sine and cosine of one angle with one argument reduction: the generated code's one
//! trigonometric call per revolute joint ([`crate::Real::sincos`]).
//!
//! `f64::sin_cos` is `(sin, cos)`: two libm calls, each reducing the argument again
//! (about 125 instructions per pair here, callgrind). This is musl's `sincos` (FreeBSD's
//! kernels `__sin` and `__cos`, and the medium case of `__rem_pio2`, exact to 118 or 151
//! bits as needed): one reduction modulo π/2 and both kernel polynomials, evaluated side
//! by side (about 70 instructions); within an ulp of libm (tested). Arguments larger
//! than about 1.6e6 rad (far beyond any joint angle) and non-finite ones go to
//! `f64::sin` and `f64::cos`.
#![allow(clippy::excessive_precision, clippy::unreadable_literal)]

use nalgebra::ComplexField;

const S1: f64 = -1.66666666666666324348e-01;
const S2: f64 = 8.33333333332248946124e-03;
const S3: f64 = -1.98412698298579493134e-04;
const S4: f64 = 2.75573137070700676789e-06;
const S5: f64 = -2.50507602534068634195e-08;
const S6: f64 = 1.58969099521155010221e-10;

const C1: f64 = 4.16666666666666019037e-02;
const C2: f64 = -1.38888888888741095749e-03;
const C3: f64 = 2.48015872894767294178e-05;
const C4: f64 = -2.75573143513906633035e-07;
const C5: f64 = 2.08757232129817482790e-09;
const C6: f64 = -1.13596475577881948265e-11;

/// `(sin(x + y), cos(x + y))` on [−π/4, π/4], `y` the tail of the reduced argument:
/// musl's `__sin` and `__cos` with their operations in musl's order (the same bits), the
/// two polynomials' like-shaped halves evaluated side by side, which the compiler pairs
/// into SIMD lanes.
#[inline(always)]
fn kernels(x: f64, y: f64) -> (f64, f64) {
    let z = x * x;
    let w = z * z;
    // sin: r = S2 + z(S3 + z S4) + z w (S5 + z S6); cos: r = z(C1 + z(C2 + z C3)) + w²(C4 + z(C5 + z C6)).
    let a = [S2 + z * (S3 + z * S4), C1 + z * (C2 + z * C3)];
    let b = [S5 + z * S6, C4 + z * (C5 + z * C6)];
    let r = a[0] + z * w * b[0];
    let rc = z * a[1] + w * w * b[1];
    let v = z * x;
    let sin = x - ((z * (0.5 * y - v * r) - y) - v * S1);
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    let cos = w + (((1.0 - w) - hz) + (z * rc - x * y));
    (sin, cos)
}

/// 2²⁰ π/2, beyond which the reduction needs more of π's bits (libm takes over).
const FAR: f64 = 1.6470993291652855e6;
const TOINT: f64 = 1.5 / f64::EPSILON;
const INVPIO2: f64 = core::f64::consts::FRAC_2_PI; // musl's invpio2, the same bits
const PIO2_1: f64 = 1.57079632673412561417e+00;
const PIO2_1T: f64 = 6.07710050650619224932e-11;
const PIO2_2: f64 = 6.07710050630396597660e-11;
const PIO2_2T: f64 = 2.02226624879595063154e-21;
const PIO2_3: f64 = 2.02226624871116645580e-21;
const PIO2_3T: f64 = 8.47842766036889956997e-32;

/// Below these fractions of |x|, the reduced argument has cancelled enough bits for a
/// second (118 bits) and a third (151 bits, every double) round (musl: exponents 16 and
/// 49 apart; these magnitudes refine at least as often).
const SECOND: f64 = 1.0 / 32768.0;
const THIRD: f64 = 1.0 / 281474976710656.0;

/// The first round: `(x·2/π + 1.5·2⁵², n, r, w)` with `x − n π/2 ≈ r − w` (Rust rounds
/// to nearest, so musl's corrections for directed rounding are left out).
#[inline(always)]
fn first_round(x: f64) -> (f64, f64, f64, f64) {
    let shifted = x * INVPIO2 + TOINT;
    let fnum = shifted - TOINT;
    (shifted, fnum, x - fnum * PIO2_1, fnum * PIO2_1T)
}

/// A further round with the next part `p` of π/2 and its tail `pt`: `(r, w, r − w)`.
#[inline(always)]
fn refine(r: f64, fnum: f64, p: f64, pt: f64) -> (f64, f64, f64) {
    let w = fnum * p;
    let next = r - w;
    let w = fnum * pt - ((r - next) - w);
    (next, w, next - w)
}

/// `x − n π/2` as a head and a tail, and `n`, for |x| < 2²⁰ π/2 (musl's `__rem_pio2`).
#[inline(always)]
fn rem_pio2(x: f64) -> (i32, f64, f64) {
    let (_, fnum, r1, w1) = first_round(x);
    let (mut r, mut w, mut y0) = (r1, w1, r1 - w1);
    let ax = x.abs();
    if y0.abs() < ax * SECOND {
        (r, w, y0) = refine(r, fnum, PIO2_2, PIO2_2T);
        if y0.abs() < ax * THIRD {
            (r, w, y0) = refine(r, fnum, PIO2_3, PIO2_3T);
        }
    }
    (fnum as i32, y0, (r - y0) - w)
}

/// `(sin x, cos x)` with one argument reduction.
#[inline]
pub fn sincos(x: f64) -> (f64, f64) {
    let ax = x.abs();
    if ax <= core::f64::consts::FRAC_PI_4 {
        return kernels(x, 0.0);
    }
    if ax.is_nan() || ax >= FAR {
        return (ComplexField::sin(x), ComplexField::cos(x));
    }
    let (n, y0, y1) = rem_pio2(x);
    let (s, c) = kernels(y0, y1);
    match n & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// [`sincos`] of four lanes without branches, bit for bit: every reduction round is
/// computed and the one the scalar path would use is selected, quadrants by bit masks;
/// lanes out of the reduction's range go to libm (a branch taken only for them).
#[inline(always)]
pub fn sincos_lanes(x: [f64; 4]) -> ([f64; 4], [f64; 4]) {
    let mut s = [0.0; 4];
    let mut c = [0.0; 4];
    let mut far = false;
    for k in 0..4 {
        let x = x[k];
        let ax = x.abs();
        far |= ax.is_nan() || ax >= FAR;
        let (shifted, fnum, r1, w1) = first_round(x);
        let y1 = r1 - w1;
        let (r2, w2, y2) = refine(r1, fnum, PIO2_2, PIO2_2T);
        let (r3, w3, y3) = refine(r2, fnum, PIO2_3, PIO2_3T);
        // The scalar path's choice of round.
        let second = y1.abs() < ax * SECOND;
        let third = second && y2.abs() < ax * THIRD;
        let (r, w, y0) = if third {
            (r3, w3, y3)
        } else if second {
            (r2, w2, y2)
        } else {
            (r1, w1, y1)
        };
        let tail = (r - y0) - w;
        let (ks, kc) = kernels(y0, tail);
        // n mod 4 from the low bits of the shifted sum (1.5·2⁵² + n).
        let n = shifted.to_bits() & 3;
        let swap = n & 1 == 1;
        let (mut sk, mut ck) = if swap { (kc, ks) } else { (ks, kc) };
        let flip_sin = (n & 2) << 62;
        let flip_cos = ((n + 1) & 2) << 62;
        sk = f64::from_bits(sk.to_bits() ^ flip_sin);
        ck = f64::from_bits(ck.to_bits() ^ flip_cos);
        s[k] = sk;
        c[k] = ck;
    }
    if far {
        for k in 0..4 {
            if x[k].is_nan() || x[k].abs() >= FAR {
                (s[k], c[k]) = (ComplexField::sin(x[k]), ComplexField::cos(x[k]));
            }
        }
    }
    (s, c)
}

#[cfg(test)]
mod tests {
    use super::{sincos, sincos_lanes};

    /// Distance in ulps between two doubles of the same sign (or both near zero).
    fn ulps(a: f64, b: f64) -> f64 {
        if a == b {
            return 0.0;
        }
        let scale = a.abs().max(b.abs());
        // One ulp of the larger magnitude; below 1e-300 compare absolutely.
        let ulp = if scale > 1e-300 {
            f64::EPSILON * f64::powi(2.0, scale.log2().floor() as i32)
        } else {
            f64::MIN_POSITIVE
        };
        (a - b).abs() / ulp
    }

    /// Within an ulp of the platform's libm, which is itself within an ulp of the exact
    /// value, at angles of every size a joint takes and near multiples of π/2, where the
    /// reduction cancels.
    #[test]
    fn agrees_with_libm() {
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut worst = 0.0f64;
        let mut check = |x: f64| {
            let (s, c) = sincos(x);
            let e = ulps(s, x.sin()).max(ulps(c, x.cos()));
            assert!(
                e <= 2.0,
                "sincos({x:e}) = ({s:e}, {c:e}), libm ({:e}, {:e})",
                x.sin(),
                x.cos()
            );
            worst = worst.max(e);
        };
        for scale in [
            1e-300, 1e-8, 1e-3, 0.7, 1.0, 3.0, 10.0, 100.0, 1e4, 1e6, 1e7, 1e20,
        ] {
            for _ in 0..20_000 {
                check((2.0 * next() - 1.0) * scale);
            }
        }
        for k in -2000..2000 {
            let x = k as f64 * core::f64::consts::FRAC_PI_2;
            for d in [-2.0, -1.0, 0.0, 1.0, 2.0] {
                check(x + d * f64::EPSILON * x.abs().max(1.0));
            }
        }
        for x in [
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            5e-324,
            core::f64::consts::FRAC_PI_4,
        ] {
            check(x);
        }
        eprintln!("sincos: worst {worst:.2} ulp from libm");
        assert!(worst <= 2.0);
    }

    /// The lanes give the scalar path's bits, reduction rounds and quadrants included.
    #[test]
    fn lanes_match_the_scalar_path() {
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut xs: Vec<f64> = Vec::new();
        for scale in [1e-9, 0.5, 1.0, 4.0, 100.0, 1e5, 1e7] {
            xs.extend((0..4000).map(|_| (2.0 * next() - 1.0) * scale));
        }
        for k in -300..300 {
            let x = k as f64 * core::f64::consts::FRAC_PI_2;
            xs.extend([x, x + x.abs() * f64::EPSILON, x - x.abs() * f64::EPSILON]);
        }
        xs.extend([0.0, -0.0, f64::NAN, f64::INFINITY, -1e300]);
        while !xs.len().is_multiple_of(4) {
            xs.push(1.0);
        }
        for chunk in xs.chunks(4) {
            let x = [chunk[0], chunk[1], chunk[2], chunk[3]];
            let (s, c) = sincos_lanes(x);
            for k in 0..4 {
                let (ss, cc) = sincos(x[k]);
                assert_eq!(
                    (s[k].to_bits(), c[k].to_bits()),
                    (ss.to_bits(), cc.to_bits()),
                    "lane of {:e}",
                    x[k]
                );
            }
        }
    }

    #[test]
    fn signed_zero_and_non_finite() {
        assert_eq!(sincos(-0.0).0.to_bits(), (-0.0f64).to_bits());
        assert_eq!(sincos(0.0), (0.0, 1.0));
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let (s, c) = sincos(x);
            assert!(s.is_nan() && c.is_nan());
        }
    }
}
