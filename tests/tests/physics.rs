//! Validation of every generated model's terms, independent of CasADi: each derived
//! term is checked against finite differences of lower-order generated terms (the
//! energies, the closure residual, the foot position), at many random states.
//! New geometries are covered automatically through `generated::for_each_model!`.

use leg_models::nalgebra::{SMatrix, SVector};
use leg_models::{ContactModel, JointKind, LegDynamics, LegModel, Parameters};
use leg_tests::Rng;

const STATES: usize = 200;

fn random_state<const NQ: usize>(rng: &mut Rng) -> (SVector<f64, NQ>, SVector<f64, NQ>) {
    let q = SVector::from_fn(|_, _| rng.range(-std::f64::consts::PI, std::f64::consts::PI));
    let qd = SVector::from_fn(|_, _| rng.range(-3.0, 3.0));
    (q, qd)
}

/// Odd-numbered samples use randomized parameters: every length, offset and centre of
/// mass moved (so terms that vanish at the spec's values, such as a zero `com_y`, are
/// exercised) and every mass, inertia, rotor inertia, gear ratio and damping scaled and
/// kept positive; gravity tilted (so terms that vanish with `gravity_x = 0` are too).
fn sample_params<P: Parameters<f64> + Default>(rng: &mut Rng, sample: usize) -> P {
    let mut p = P::default();
    if sample.is_multiple_of(2) {
        return p;
    }
    for (i, name) in P::NAMES.iter().enumerate() {
        let v = p.get(i).expect("listed parameter");
        let positive = ["mass", "inertia", "gear_ratio", "damping", "stiffness"]
            .iter()
            .any(|s| name.ends_with(s));
        let new = if name.starts_with("gravity") {
            v + rng.range(-2.0, 2.0)
        } else if positive {
            v * rng.range(0.8, 1.2) + rng.range(0.0, 0.02)
        } else {
            v + rng.range(-0.05, 0.05)
        };
        assert!(p.set(i, new));
    }
    assert!(p.get(P::NAMES.len()).is_none() && !p.set(P::NAMES.len(), 0.0));
    p
}

fn unit<const NQ: usize>(i: usize) -> SVector<f64, NQ> {
    SVector::from_fn(|r, _| if r == i { 1.0 } else { 0.0 })
}

/// `|a − b| ≤ tol · (1 + max|b|)`, entry by entry, with a message naming the term.
fn assert_close<const R: usize, const C: usize>(
    what: &str,
    a: &SMatrix<f64, R, C>,
    b: &SMatrix<f64, R, C>,
    tol: f64,
) {
    let scale = 1.0 + b.amax();
    let err = (a - b).amax();
    assert!(
        err <= tol * scale,
        "{what}: error {err:.3e} > {tol:.1e} × {scale:.3e}\n got {a}\n expected {b}"
    );
}

fn lagrangian<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    p: &L::Params<f64>,
) -> f64 {
    L::kinetic_energy(q, qd, p) - L::potential_energy(q, p)
}

/// `∂L/∂q̇` by central differences; exact up to rounding since `L` is quadratic in `q̇`.
fn momentum<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    p: &L::Params<f64>,
) -> SVector<f64, NQ> {
    let h = 1e-3;
    SVector::from_fn(|i, _| {
        let e = unit::<NQ>(i) * h;
        (lagrangian::<L, NQ, NC, NU>(q, &(qd + e), p)
            - lagrangian::<L, NQ, NC, NU>(q, &(qd - e), p))
            / (2.0 * h)
    })
}

pub fn check_mass_matrix<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let mut rng = Rng::new(1);
    for sample in 0..STATES {
        let p: L::Params<f64> = sample_params(&mut rng, sample);
        let (q, qd) = random_state::<NQ>(&mut rng);
        let m = L::mass_matrix(&q, &p);
        assert_close("M − Mᵀ", &m, &m.transpose(), 1e-14);
        let chol = m.cholesky();
        assert!(
            chol.is_some(),
            "{}: M not positive definite at q = {q}",
            L::NAME
        );
        // M as the Hessian of the generated kinetic energy in q̇ (exact for a quadratic).
        let h = 1e-2;
        let t = |v: SVector<f64, NQ>| L::kinetic_energy(&q, &v, &p);
        let fd = SMatrix::<f64, NQ, NQ>::from_fn(|i, j| {
            let (ei, ej) = (unit::<NQ>(i) * h, unit::<NQ>(j) * h);
            (t(qd + ei + ej) - t(qd + ei - ej) - t(qd - ei + ej) + t(qd - ei - ej)) / (4.0 * h * h)
        });
        assert_close(&format!("{}: M vs ∂²T/∂q̇²", L::NAME), &m, &fd, 1e-9);
        let t_quad = 0.5 * qd.dot(&(m * qd));
        let t_gen = L::kinetic_energy(&q, &qd, &p);
        assert!(
            (t_quad - t_gen).abs() <= 1e-12 * (1.0 + t_gen.abs()),
            "{}: T ≠ ½ q̇ᵀMq̇",
            L::NAME
        );
    }
}

pub fn check_bias_forces<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let mut rng = Rng::new(2);
    let eps = 1e-5;
    for sample in 0..STATES {
        let p: L::Params<f64> = sample_params(&mut rng, sample);
        let (q, qd) = random_state::<NQ>(&mut rng);
        // Lagrange: N = (∂²L/∂q̇∂q) q̇ − ∂L/∂q, all by differences of the energies.
        let dp_dq_qd = (momentum::<L, NQ, NC, NU>(&(q + qd * eps), &qd, &p)
            - momentum::<L, NQ, NC, NU>(&(q - qd * eps), &qd, &p))
            / (2.0 * eps);
        let dl_dq = SVector::<f64, NQ>::from_fn(|i, _| {
            let e = unit::<NQ>(i) * eps;
            (lagrangian::<L, NQ, NC, NU>(&(q + e), &qd, &p)
                - lagrangian::<L, NQ, NC, NU>(&(q - e), &qd, &p))
                / (2.0 * eps)
        });
        let n = L::bias_forces(&q, &qd, &p);
        assert_close(
            &format!("{}: N vs Lagrange's equations", L::NAME),
            &n,
            &(dp_dq_qd - dl_dq),
            1e-6,
        );
        // G = ∂V/∂q and N(q, 0) = G.
        let dv_dq = SVector::<f64, NQ>::from_fn(|i, _| {
            let e = unit::<NQ>(i) * eps;
            (L::potential_energy(&(q + e), &p) - L::potential_energy(&(q - e), &p)) / (2.0 * eps)
        });
        let g = L::gravity_forces(&q, &p);
        assert_close(&format!("{}: G vs ∂V/∂q", L::NAME), &g, &dv_dq, 1e-7);
        assert_close(
            &format!("{}: N(q, 0) vs G", L::NAME),
            &L::bias_forces(&q, &SVector::zeros(), &p),
            &g,
            1e-13,
        );
    }
}

pub fn check_constraint_terms<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let mut rng = Rng::new(3);
    let (h, eps) = (1e-6, 1e-4);
    for sample in 0..STATES {
        let p: L::Params<f64> = sample_params(&mut rng, sample);
        let (q, qd) = random_state::<NQ>(&mut rng);
        let phi = |q: SVector<f64, NQ>| L::closure_residual(&q, &p);
        let fd = SMatrix::<f64, NC, NQ>::from_fn(|r, i| {
            let e = unit::<NQ>(i) * h;
            (phi(q + e)[r] - phi(q - e)[r]) / (2.0 * h)
        });
        assert_close(
            &format!("{}: J vs ∂φ/∂q", L::NAME),
            &L::constraint_jacobian(&q, &p),
            &fd,
            1e-7,
        );
        // J̇ q̇ = d²/dt² φ(q + t q̇) at t = 0: a second difference of φ in time.
        let second = (phi(q + qd * eps) - phi(q) * 2.0 + phi(q - qd * eps)) / (eps * eps);
        assert_close(
            &format!("{}: J̇q̇ vs d²φ/dt²", L::NAME),
            &L::constraint_bias(&q, &qd, &p),
            &second,
            1e-5,
        );
        // The closure points: column 2k minus column 2k + 1 is closure k's residual.
        let pts = L::closure_points(&q, &p);
        let from_points = SVector::<f64, NC>::from_fn(|r, _| {
            pts[(r % 2, r - r % 2)] - pts[(r % 2, r - r % 2 + 1)]
        });
        assert_close(
            &format!("{}: closure points vs φ", L::NAME),
            &from_points,
            &phi(q),
            1e-13,
        );
    }
}

pub fn check_foot_terms<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let mut rng = Rng::new(4);
    let (h, eps) = (1e-6, 1e-4);
    for sample in 0..STATES {
        let p: L::Params<f64> = sample_params(&mut rng, sample);
        let (q, qd) = random_state::<NQ>(&mut rng);
        let foot = |q: SVector<f64, NQ>| L::foot_position(&q, &p);
        let fd = SMatrix::<f64, 2, NQ>::from_fn(|r, i| {
            let e = unit::<NQ>(i) * h;
            (foot(q + e)[r] - foot(q - e)[r]) / (2.0 * h)
        });
        assert_close(
            &format!("{}: J_f vs ∂foot/∂q", L::NAME),
            &L::foot_jacobian(&q, &p),
            &fd,
            1e-7,
        );
        let second = (foot(q + qd * eps) - foot(q) * 2.0 + foot(q - qd * eps)) / (eps * eps);
        assert_close(
            &format!("{}: J̇_f q̇ vs d²foot/dt²", L::NAME),
            &L::foot_bias(&q, &qd, &p),
            &second,
            1e-5,
        );
    }
}

pub fn check_fused_terms<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let mut rng = Rng::new(5);
    for sample in 0..STATES {
        let p: L::Params<f64> = sample_params(&mut rng, sample);
        let (q, qd) = random_state::<NQ>(&mut rng);
        let t = L::dynamics_terms(&q, &qd, &p);
        assert_close("fused M", &t.mass_matrix, &L::mass_matrix(&q, &p), 1e-13);
        assert_close(
            "fused N",
            &t.bias_forces,
            &L::bias_forces(&q, &qd, &p),
            1e-13,
        );
        assert_close(
            "fused J",
            &t.constraint_jacobian,
            &L::constraint_jacobian(&q, &p),
            1e-13,
        );
        assert_close(
            "fused J̇q̇",
            &t.constraint_bias,
            &L::constraint_bias(&q, &qd, &p),
            1e-13,
        );
    }
}

pub fn check_f32_matches_f64<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let p64 = L::Params::<f64>::default();
    let p32 = L::Params::<f32>::default();
    let mut rng = Rng::new(6);
    for _ in 0..STATES {
        let (q, qd) = random_state::<NQ>(&mut rng);
        let (q32, qd32) = (q.cast::<f32>(), qd.cast::<f32>());
        let a = L::dynamics_terms(&q32, &qd32, &p32);
        let b = L::dynamics_terms(&q, &qd, &p64);
        let tol = 1e-4;
        assert_close("f32 M", &a.mass_matrix.cast::<f64>(), &b.mass_matrix, tol);
        assert_close("f32 N", &a.bias_forces.cast::<f64>(), &b.bias_forces, tol);
        assert_close(
            "f32 J",
            &a.constraint_jacobian.cast::<f64>(),
            &b.constraint_jacobian,
            tol,
        );
        assert_close(
            "f32 J̇q̇",
            &a.constraint_bias.cast::<f64>(),
            &b.constraint_bias,
            tol,
        );
        let f = L::foot_position(&q32, &p32).cast::<f64>();
        assert_close("f32 foot", &f, &L::foot_position(&q, &p64), tol);
    }
}

pub fn check_damping<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>() {
    // Randomized parameters: the built-in specs set no damping, so at their values every
    // coefficient is zero and nothing would be checked.
    let mut rng = Rng::new(7);
    let p: L::Params<f64> = sample_params(&mut rng, 1);
    let names = <L::Params<f64> as Parameters<f64>>::NAMES;
    let (_, qd) = random_state::<NQ>(&mut rng);
    let d = L::damping_forces(&qd, &p);
    for (i, joint) in L::JOINT_NAMES.iter().enumerate() {
        let k = names
            .iter()
            .position(|n| *n == format!("{joint}_damping"))
            .expect("a damping parameter per joint");
        let coefficient = p.get(k).unwrap();
        assert!(
            coefficient > 0.0,
            "the randomized damping of {joint} is positive"
        );
        assert_eq!(
            d[i],
            coefficient * qd[i],
            "{}: D q̇ of joint {joint}",
            L::NAME
        );
    }
}

/// Contact terms against differences of the generated contact positions.
pub fn check_contact_terms<
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>() {
    assert_eq!(
        L::CONTACT_NAMES.len() * 2,
        NK,
        "{}: two rows per contact",
        L::NAME
    );
    assert_eq!(L::CONTACT_FRICTION.len() * 2, NK);
    let n = L::GROUND_NORMAL;
    assert!((n[0].hypot(n[1]) - 1.0).abs() < 1e-15, "unit ground normal");
    let mut rng = Rng::new(9);
    let (h, eps) = (1e-6, 1e-4);
    for sample in 0..STATES {
        let p: L::Params<f64> = sample_params(&mut rng, sample);
        let (q, qd) = random_state::<NQ>(&mut rng);
        let x = |q: SVector<f64, NQ>| L::contact_positions(&q, &p);
        let fd = SMatrix::<f64, NK, NQ>::from_fn(|r, i| {
            let e = unit::<NQ>(i) * h;
            (x(q + e)[r] - x(q - e)[r]) / (2.0 * h)
        });
        assert_close(
            &format!("{}: J_c vs ∂x_c/∂q", L::NAME),
            &L::contact_jacobian(&q, &p),
            &fd,
            1e-7,
        );
        let second = (x(q + qd * eps) - x(q) * 2.0 + x(q - qd * eps)) / (eps * eps);
        assert_close(
            &format!("{}: J̇_c q̇ vs d²x_c/dt²", L::NAME),
            &L::contact_bias(&q, &qd, &p),
            &second,
            1e-5,
        );
    }
}

/// What each joint kind does to the points beyond it, from the generated joint positions
/// and link tips alone: a prismatic joint translates every point it moves by the same
/// vector, of the length it slides; a revolute joint keeps every point it moves at its
/// distance from the joint (a rotation about it) and leaves its own joint point in place.
pub fn check_joint_kinds<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let mut rng = Rng::new(10);
    let h = 1e-3;
    for sample in 0..STATES / 4 {
        let p: L::Params<f64> = sample_params(&mut rng, sample);
        let (q, _) = random_state::<NQ>(&mut rng);
        let points = |q: &SVector<f64, NQ>| {
            let (j, t) = (L::joint_positions(q, &p), L::link_tips(q, &p));
            (0..NQ).flat_map(move |i| [j.column(i).into_owned(), t.column(i).into_owned()])
        };
        for i in 0..NQ {
            let moved = q + unit::<NQ>(i) * h;
            let pivot = L::joint_positions(&q, &p).column(i).into_owned();
            let mut shift: Option<SVector<f64, 2>> = None;
            for (a, b) in points(&q).zip(points(&moved)) {
                let d = b - a;
                if d.norm() < 1e-14 {
                    continue;
                }
                match L::JOINT_KINDS[i] {
                    JointKind::Prismatic => {
                        assert!(
                            (d.norm() - h).abs() < 1e-12,
                            "{}: slide of joint {i}",
                            L::NAME
                        );
                        let s = *shift.get_or_insert(d);
                        assert!((d - s).norm() < 1e-12, "{}: joint {i} translates", L::NAME);
                    }
                    JointKind::Revolute => {
                        let (ra, rb) = ((a - pivot).norm(), (b - pivot).norm());
                        assert!((ra - rb).abs() < 1e-12, "{}: joint {i} rotates", L::NAME);
                    }
                }
            }
            // PARENTS: a joint moves only its own link and the links hung below it.
            let (j0, t0) = (L::joint_positions(&q, &p), L::link_tips(&q, &p));
            let (j1, t1) = (L::joint_positions(&moved, &p), L::link_tips(&moved, &p));
            for k in 0..NQ {
                let mut below = k == i;
                let mut a = L::PARENTS[k];
                while let Some(up) = a {
                    below |= up == i;
                    a = L::PARENTS[up];
                }
                if !below {
                    assert!(
                        (j1.column(k) - j0.column(k)).norm() < 1e-14
                            && (t1.column(k) - t0.column(k)).norm() < 1e-14,
                        "{}: joint {i} moves link {k}, which PARENTS does not hang below it",
                        L::NAME
                    );
                }
            }
            let pivot_after = L::joint_positions(&moved, &p).column(i).into_owned();
            if L::JOINT_KINDS[i] == JointKind::Revolute {
                assert!(
                    (pivot_after - pivot).norm() < 1e-14,
                    "{}: pivot {i} stays",
                    L::NAME
                );
            }
        }
    }
}

/// `SPRINGS` names the right joints and parameters: turning one spring's stiffness to
/// zero takes exactly `k (q_a − q_b − rest)` off `G` on `a` and puts it back on `b`.
pub fn check_springs<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>() {
    let names = <L::Params<f64> as Parameters<f64>>::NAMES;
    let mut rng = Rng::new(12);
    for spring in L::SPRINGS {
        assert_eq!(
            names[spring.stiffness],
            format!("{}_stiffness", spring.name)
        );
        assert_eq!(names[spring.rest], format!("{}_rest", spring.name));
        for sample in 0..STATES / 10 {
            let p: L::Params<f64> = sample_params(&mut rng, sample);
            let (q, _) = random_state::<NQ>(&mut rng);
            let mut without = p;
            assert!(without.set(spring.stiffness, 0.0));
            let k = p.get(spring.stiffness).unwrap();
            let stretch =
                q[spring.a] - spring.b.map_or(0.0, |b| q[b]) - p.get(spring.rest).unwrap();
            let mut expected = SVector::<f64, NQ>::zeros();
            expected[spring.a] += k * stretch;
            if let Some(b) = spring.b {
                expected[b] -= k * stretch;
            }
            let d = L::gravity_forces(&q, &p) - L::gravity_forces(&q, &without);
            assert!(
                (d - expected).amax() <= 1e-9 * (1.0 + expected.amax()),
                "{}: spring {}: {d} against {expected}",
                L::NAME,
                spring.name
            );
        }
    }
}

macro_rules! validate {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        mod $module {
            type Model = $ty;
            #[test]
            fn mass_matrix_is_spd_and_the_hessian_of_kinetic_energy() {
                super::check_mass_matrix::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn bias_forces_satisfy_lagranges_equations() {
                super::check_bias_forces::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn constraint_jacobian_and_bias_match_differences_of_phi() {
                super::check_constraint_terms::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn foot_jacobian_and_bias_match_differences_of_foot() {
                super::check_foot_terms::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn fused_terms_match_separate_terms() {
                super::check_fused_terms::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn f32_matches_f64() {
                super::check_f32_matches_f64::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn damping_is_diagonal_and_linear() {
                super::check_damping::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn contact_jacobian_and_bias_match_differences_of_positions() {
                super::check_contact_terms::<Model, $nq, $nc, $nu, $nk>();
            }
            #[test]
            fn joints_translate_or_rotate_what_they_move() {
                super::check_joint_kinds::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn springs_name_their_joints_and_parameters() {
                super::check_springs::<Model, $nq, $nc, $nu>();
            }
        }
    };
}

generated::for_each_model!(validate);

/// The open chain against the textbook closed form of a two-link arm's `M` and `G`,
/// with the parameters read from the generated `Params` (the spec's values).
#[test]
fn two_link_matches_the_textbook_closed_form() {
    use generated::two_link::Params;
    use generated::TwoLink;
    let p = Params::<f64>::default();
    let (m1, m2, i1, i2) = (
        p.upper_arm_mass,
        p.forearm_mass,
        p.upper_arm_inertia,
        p.forearm_inertia,
    );
    let (l1, c1, c2) = (p.upper_arm_length_x, p.upper_arm_com_x, p.forearm_com_x);
    let g = -p.gravity_y;
    let mut rng = Rng::new(8);
    for _ in 0..STATES {
        let (q, qd) = random_state::<2>(&mut rng);
        let (cq2, sq2) = (q[1].cos(), q[1].sin());
        let m11 = i1 + i2 + m1 * c1 * c1 + m2 * (l1 * l1 + c2 * c2 + 2.0 * l1 * c2 * cq2);
        let m12 = i2 + m2 * (c2 * c2 + l1 * c2 * cq2);
        let m22 = i2 + m2 * c2 * c2;
        let m = SMatrix::<f64, 2, 2>::new(m11, m12, m12, m22);
        assert_close("two_link M", &TwoLink::mass_matrix(&q, &p), &m, 1e-13);
        let gv = SVector::<f64, 2>::new(
            (m1 * c1 + m2 * l1) * g * q[0].cos() + m2 * c2 * g * (q[0] + q[1]).cos(),
            m2 * c2 * g * (q[0] + q[1]).cos(),
        );
        assert_close("two_link G", &TwoLink::gravity_forces(&q, &p), &gv, 1e-13);
        // Coriolis and centrifugal terms: h = m2 l1 c2 sin q2.
        let h = m2 * l1 * c2 * sq2;
        let c = SVector::<f64, 2>::new(
            -h * (2.0 * qd[0] * qd[1] + qd[1] * qd[1]),
            h * qd[0] * qd[0],
        );
        assert_close(
            "two_link N",
            &TwoLink::bias_forces(&q, &qd, &p),
            &(c + gv),
            1e-12,
        );
        let foot = SVector::<f64, 2>::new(
            l1 * q[0].cos() + p.forearm_length_x * (q[0] + q[1]).cos(),
            l1 * q[0].sin() + p.forearm_length_x * (q[0] + q[1]).sin(),
        );
        assert_close(
            "two_link foot",
            &TwoLink::foot_position(&q, &p),
            &foot,
            1e-14,
        );
    }
}

/// A symmetric five-bar in a symmetric pose has its foot on the symmetry axis and
/// zero closure residual when the angles close the loop (law of cosines).
#[test]
fn minitaur_closes_at_the_law_of_cosines_pose() {
    use generated::minitaur::Params;
    use generated::Minitaur;
    let p = Params::<f64>::default();
    let (l1, l2) = (p.upper_a_length_x, p.lower_a_length_x);
    // Foot straight below the hip at depth d: upper links at ±alpha from the vertical.
    let d: f64 = 0.22;
    let alpha = ((l1 * l1 + d * d - l2 * l2) / (2.0 * l1 * d)).acos();
    let beta = ((l1 * l1 + l2 * l2 - d * d) / (2.0 * l1 * l2)).acos();
    let down = -std::f64::consts::FRAC_PI_2;
    let q = SVector::<f64, 4>::new(
        down + alpha,
        -(std::f64::consts::PI - beta),
        down - alpha,
        std::f64::consts::PI - beta,
    );
    let phi = Minitaur::closure_residual(&q, &p);
    assert!(phi.amax() < 1e-15, "residual {phi}");
    let foot = Minitaur::foot_position(&q, &p);
    assert!(
        (foot[0]).abs() < 1e-15 && (foot[1] + d).abs() < 1e-15,
        "foot {foot}"
    );
}

/// Springs against their formula: with gravity off, the potential energy of
/// `raibert_hopper` is `½ k (q_shin − rest)² + ½ k (q_thigh − q_torso − rest)²`, and the
/// generalized forces `G` are its gradient, written out by hand.
#[test]
fn raibert_hopper_springs_follow_their_formula() {
    use generated::raibert_hopper::{ParamValues, Params};
    use generated::RaibertHopper;
    let p = Params::new(ParamValues::<f64> {
        gravity_x: 0.0,
        gravity_y: 0.0,
        ..Default::default()
    });
    let mut rng = Rng::new(11);
    for _ in 0..STATES {
        let (q, _) = random_state::<5>(&mut rng);
        let leg = q[4] - p.leg_spring_rest;
        let hip = q[3] - q[2] - p.hip_spring_rest;
        let v = 0.5 * p.leg_spring_stiffness * leg * leg + 0.5 * p.hip_spring_stiffness * hip * hip;
        let got = RaibertHopper::potential_energy(&q, &p);
        assert!((got - v).abs() <= 1e-12 * (1.0 + v), "V {got} vs {v}");
        let (kl, kh) = (p.leg_spring_stiffness, p.hip_spring_stiffness);
        let g = SVector::<f64, 5>::new(0.0, 0.0, -kh * hip, kh * hip, kl * leg);
        assert_close(
            "spring G",
            &RaibertHopper::gravity_forces(&q, &p),
            &g,
            1e-12,
        );
    }
}

/// On the rail, `minitaur_hopper` is `minitaur` carried by its body: the same closure
/// and foot relative to the body, the toe contact at the closure point, and the body's
/// weight in `G` of the rail joint.
#[test]
fn minitaur_hopper_is_minitaur_on_a_rail() {
    use generated::{Minitaur, MinitaurHopper};
    let (p, ph) = (
        generated::minitaur::Params::<f64>::default(),
        generated::minitaur_hopper::Params::<f64>::default(),
    );
    let mut rng = Rng::new(12);
    for _ in 0..STATES {
        let (q, _) = random_state::<4>(&mut rng);
        let y = rng.range(-1.0, 1.0);
        let qh = SVector::<f64, 5>::new(y, q[0], q[1], q[2], q[3]);
        let lift = SVector::<f64, 2>::new(0.0, y);
        assert_close(
            "closure",
            &MinitaurHopper::closure_residual(&qh, &ph),
            &Minitaur::closure_residual(&q, &p),
            1e-14,
        );
        assert_close(
            "foot",
            &MinitaurHopper::foot_position(&qh, &ph),
            &(Minitaur::foot_position(&q, &p) + lift),
            1e-14,
        );
        let toe = MinitaurHopper::contact_positions(&qh, &ph);
        assert_close("toe", &toe, &MinitaurHopper::foot_position(&qh, &ph), 0.0);
        let m: f64 = ["body", "upper_a", "lower_a", "upper_b", "lower_b"]
            .iter()
            .map(|l| {
                let names = <generated::minitaur_hopper::Params<f64> as Parameters<f64>>::NAMES;
                let i = names
                    .iter()
                    .position(|n| *n == format!("{l}_mass"))
                    .unwrap();
                ph.get(i).unwrap()
            })
            .sum();
        let g = MinitaurHopper::gravity_forces(&qh, &ph)[0];
        assert!(
            (g - m * 9.81).abs() < 1e-12,
            "rail G {g} vs weight {}",
            m * 9.81
        );
    }
}

/// Parameters changed at run time (`Parameters::set`, which prepares the parameter-only
/// quantities again) give the terms that CasADi's C computes from the raw parameter
/// vector, which has no prepared values: a stale prepared value would show here. Two
/// peers: the same closed form (to 1e-12), and the notes' Lagrange form (`M`, `N` by
/// differentiating `L` written on absolute positions, `J = ∂φ/∂q`: a derivation
/// independent of ours, to 1e-10). Every parameter is changed, one state per change.
#[cfg(feature = "peers")]
fn check_prepared_parameters_follow_set<
    L: LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    use leg_tests::casadi;
    let peers = casadi::functions(L::NAME);
    let mut rng = Rng::new(29);
    let mut p = L::Params::<f64>::default();
    for (i, (peer, form, tol)) in
        (0..<L::Params<f64> as Parameters<f64>>::NAMES.len()).flat_map(|i| {
            [
                (i, (peers.closed, "closed form", 1e-12)),
                (i, (peers.lagrange, "Lagrange form", 1e-10)),
            ]
        })
    {
        if form == "closed form" {
            let value = p.get(i).unwrap();
            assert!(p.set(i, value * rng.range(0.8, 1.25) + rng.range(-0.01, 0.01)));
        }
        let (q, qd) = random_state::<NQ>(&mut rng);
        let ours = L::dynamics_terms(&q, &qd, &p);
        let raw = casadi::parameter_vector(&p);
        let (mut m, mut n, mut j, mut jd) = (
            vec![0.0; NQ * NQ],
            vec![0.0; NQ],
            vec![0.0; NC * NQ],
            vec![0.0; NC],
        );
        let call = casadi::Prepared::new(
            peer.terms,
            &[q.as_slice(), qd.as_slice(), &raw],
            &mut [&mut m, &mut n, &mut j, &mut jd],
        );
        // SAFETY: the buffers live to the end of this iteration and have the dense sizes.
        assert_eq!(unsafe { call.call() }, 0);
        let close = |a: &[f64], b: &[f64], what: &str| {
            let scale = b.iter().fold(1e-9f64, |s, x| s.max(x.abs()));
            for (x, y) in a.iter().zip(b) {
                assert!(
                    (x - y).abs() <= tol * scale,
                    "{}: {what} after setting {}: ours {x}, CasADi's C of the {form} {y}",
                    L::NAME,
                    <L::Params<f64> as Parameters<f64>>::NAMES[i]
                );
            }
        };
        close(ours.mass_matrix.as_slice(), &m, "M");
        close(ours.bias_forces.as_slice(), &n, "N");
        close(ours.constraint_jacobian.as_slice(), &j, "J");
        close(ours.constraint_bias.as_slice(), &jd, "J̇q̇");
    }
}

#[cfg(feature = "peers")]
macro_rules! prepared {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        mod $module {
            #[test]
            fn prepared_parameters_follow_set() {
                super::super::check_prepared_parameters_follow_set::<$ty, $nq, $nc, $nu>();
            }
        }
    };
}

#[cfg(feature = "peers")]
mod prepared_parameters {
    generated::for_each_model!(prepared);

    /// Spatial legs: the Lagrange peer differentiates positions and orientations composed
    /// in the base frame, ours are the recursions in link frames.
    macro_rules! prepared_spatial {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            prepared!($module, $ty, $nq, $nc, $nu, 0);
        };
    }
    generated::for_each_spatial_model!(prepared_spatial);
}
