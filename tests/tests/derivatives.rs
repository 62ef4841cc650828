//! The derivatives of the dynamics (DESIGN.md §3.2) against central finite differences of
//! the functions they differentiate, on every generated leg: the generated directional
//! terms at random states, forward dynamics (with and without Baumgarte terms, with held
//! and sliding contacts) at 100 random regular assembled states, the reduction to the
//! motor angles, one RK4 and one semi-implicit Euler step in joint coordinates and on the
//! constraint manifold; and against a second formulation (the null-space form's `∂q̈/∂u
//! = G Ã⁻¹`; CasADi's own `jacobian` of its forward dynamics in `peers`).

use leg_models::control::linearize::{linearize_step, ManifoldChart};
use leg_models::control::{
    actuated_reduction, actuated_reduction_null_space, null_space, reduction_derivatives,
};
use leg_models::dynamics::contact::{
    forward_dynamics_with_contacts, spec_friction, ContactMode, Ground, Modes,
};
use leg_models::dynamics::derivatives::{
    contact_dynamics_derivatives, forward_dynamics_derivatives,
};
use leg_models::dynamics::structure::{Actuation, Structure};
use leg_models::dynamics::{forward_dynamics, Baumgarte};
use leg_models::nalgebra::{SMatrix, SVector};
use leg_models::simulate::{step, Method, State, StepOptions};
use leg_models::{ContactModel, LegModel};
use leg_tests::{random_assembled_state, Rng};

const STATES: usize = 100;
/// The differences' step (rad, m, rad/s, N·m): with Richardson extrapolation the
/// truncation error is `h⁴`-small, the rounding `ε |f| / h`.
const H: f64 = 1e-4;
/// Largest error accepted, relative to the largest entry of the derivative.
const REL: f64 = 1e-6;
/// Accelerations and forces are linear in the torques (for fixed contact modes), so a
/// step of 1 N·m has no truncation error and the least rounding.
const U_STEP: f64 = 1.0;

fn unit<const N: usize>(i: usize) -> SVector<f64, N> {
    SVector::from_fn(|r, _| if r == i { 1.0 } else { 0.0 })
}

/// A derivative to compare with, and the rounding noise it carries.
struct Want<const R: usize, const C: usize> {
    d: SMatrix<f64, R, C>,
    /// Of a central difference: `ε max|f| / h` (the rounding of `f`, divided by the step).
    noise: f64,
}

fn exact<const R: usize, const C: usize>(d: SMatrix<f64, R, C>) -> Want<R, C> {
    Want { d, noise: 0.0 }
}

/// Central differences of `f` along each coordinate of `x`, column by column, with
/// Richardson extrapolation: `(4 D(h/2) − D(h)) / 3` cancels the `h²` error of the
/// central difference `D`, leaving `h⁴` truncation and `ε |f| / h` rounding.
fn central<const N: usize, const R: usize>(
    x: &SVector<f64, N>,
    h: f64,
    mut f: impl FnMut(&SVector<f64, N>) -> SVector<f64, R>,
) -> Want<R, N> {
    let mut d = SMatrix::<f64, R, N>::zeros();
    let (mut size, mut spread) = (0.0f64, 0.0f64);
    for i in 0..N {
        let mut diff = |h: f64| {
            let (plus, minus) = (f(&(x + unit::<N>(i) * h)), f(&(x - unit::<N>(i) * h)));
            size = size.max(plus.amax()).max(minus.amax());
            (plus - minus) / (2.0 * h)
        };
        let (coarse, fine) = (diff(h), diff(h / 2.0));
        // What the extrapolation changed bounds the error left (a posteriori): it also
        // shows the rounding of an ill-conditioned solve, which `ε |f| / h` does not.
        spread = spread.max((fine - coarse).amax());
        d.set_column(i, &((fine * 4.0 - coarse) / 3.0));
    }
    Want {
        d,
        noise: (32.0 * f64::EPSILON * size / h).max(spread),
    }
}

/// Whether a difference is precise enough to check against: its noise at most a tenth of
/// what it measures (or of 1e-3 for a derivative that vanishes).
fn checkable<const R: usize, const C: usize>(want: &Want<R, C>) -> bool {
    want.noise <= 0.1 * want.d.amax().max(1e-3)
}

/// The error of `got` against `want`, relative to `want`'s largest entry (with an
/// absolute floor for derivatives that vanish, and less the difference's own rounding
/// noise); asserts it is at most `tol`.
fn check<const R: usize, const C: usize>(
    what: &str,
    got: &SMatrix<f64, R, C>,
    want: &Want<R, C>,
    tol: f64,
) -> f64 {
    let scale = want.d.amax().max(1e-6);
    // A difference whose own noise is a tenth of what it measures checks nothing: refused,
    // so that the allowance below cannot make the check vacuous.
    assert!(
        checkable(want),
        "{what}: the finite difference is too noisy to check against ({:.1e} of {scale:.1e})",
        want.noise
    );
    let err = ((got - want.d).amax() - want.noise).max(0.0) / scale;
    assert!(
        err <= tol,
        "{what}: relative error {err:.2e} > {tol:.0e} (noise {:.1e})\n got {got}\n want {}",
        want.noise,
        want.d
    );
    err
}

/// Directions along the constraint manifold at an assembled `q` (the null space of `J`),
/// and the curve `s ↦ P(q + s t)` (`P` the least-squares projection onto `φ = 0`) whose
/// central differences give a derivative along `t`: the projection's correction is even
/// in `s`, so it cancels. A leg closed redundantly is differentiated only along these:
/// off the manifold its closure rows are no longer dependent, and its dynamics are not a
/// smooth function of `q` there.
fn manifold_directions<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
) -> Vec<SVector<f64, NQ>> {
    let j = L::constraint_jacobian(q, p);
    let dj =
        leg_models::nalgebra::DMatrix::from_fn(NQ, NQ, |r, c| if r < NC { j[(r, c)] } else { 0.0 });
    let svd = dj.transpose().svd(true, false);
    let u = svd.u.expect("computed");
    let top = svd.singular_values.max();
    (0..NQ)
        .filter(|&k| svd.singular_values[k] <= 1e-9 * top)
        .map(|k| SVector::from_fn(|r, _| u[(r, k)]))
        .collect()
}

fn on_manifold<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    t: &SVector<f64, NQ>,
    s: f64,
) -> SVector<f64, NQ> {
    let mut x = q + t * s;
    leg_models::assembly::project_position::<L, f64, NQ, NC, NU>(p, &mut x, &Default::default())
        .expect("projects");
    x
}

/// `got`'s q-derivative against central differences of `f`: along every coordinate, or on
/// a leg closed redundantly along the manifold ([`manifold_directions`]).
fn check_q<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const R: usize,
>(
    what: &str,
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    got: &SMatrix<f64, R, NQ>,
    f: impl Fn(&SVector<f64, NQ>) -> SVector<f64, R>,
    tol: f64,
) -> f64 {
    if L::REDUNDANT_ROWS == 0 {
        return check(what, got, &central(q, H, f), tol);
    }
    let mut worst = 0.0f64;
    for t in manifold_directions::<L, NQ, NC, NU>(p, q) {
        let want = central(&SVector::<f64, 1>::zeros(), H, |s| {
            f(&on_manifold::<L, NQ, NC, NU>(p, q, &t, s[0]))
        });
        worst = worst.max(check(
            &format!("{what} along the manifold"),
            &(got * t),
            &want,
            tol,
        ));
    }
    worst
}

/// The generated directional terms against differences of the generated terms they
/// differentiate, at random (unassembled) states and random accelerations and forces.
fn generated_terms<
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>() {
    let p = L::Params::<f64>::default();
    let mut rng = Rng::new(12);
    let mut worst = 0.0f64;
    for _ in 0..STATES {
        let q = SVector::<f64, NQ>::from_fn(|_, _| rng.range(-3.0, 3.0));
        let qd = SVector::<f64, NQ>::from_fn(|_, _| rng.range(-3.0, 3.0));
        let a = SVector::<f64, NQ>::from_fn(|_, _| rng.range(-10.0, 10.0));
        let f = SVector::<f64, NC>::from_fn(|_, _| rng.range(-10.0, 10.0));
        let lam = SVector::<f64, NK>::from_fn(|_, _| rng.range(-10.0, 10.0));
        let name = L::NAME;
        let dma = L::mass_matrix_derivative(&q, &a, &p);
        worst = worst.max(check(
            &format!("{name} ∂(M a)/∂q"),
            &dma,
            &central(&q, H, |x| L::mass_matrix(x, &p) * a),
            REL,
        ));
        let (dn_q, dn_qd) = L::bias_forces_derivatives(&q, &qd, &p);
        check(
            &format!("{name} ∂N/∂q"),
            &dn_q,
            &central(&q, H, |x| L::bias_forces(x, &qd, &p)),
            REL,
        );
        check(
            &format!("{name} ∂N/∂q̇"),
            &dn_qd,
            &central(&qd, H, |x| L::bias_forces(&q, x, &p)),
            REL,
        );
        let c = L::constraint_derivatives(&q, &qd, &a, &f, &p);
        if NC > 0 {
            check(
                &format!("{name} ∂(Jᵀ f)/∂q"),
                &c.force_q,
                &central(&q, H, |x| L::constraint_jacobian(x, &p).transpose() * f),
                REL,
            );
            check(
                &format!("{name} ∂(J a)/∂q"),
                &c.jacobian_q,
                &central(&q, H, |x| L::constraint_jacobian(x, &p) * a),
                REL,
            );
            check(
                &format!("{name} ∂(J̇ q̇)/∂q"),
                &c.bias_q,
                &central(&q, H, |x| L::constraint_bias(x, &qd, &p)),
                REL,
            );
            // J̇ = d/ds J(q + s q̇) at s = 0, column by column.
            for k in 0..NQ {
                let dj = central(&SVector::<f64, 1>::zeros(), H, |s| {
                    L::constraint_jacobian(&(q + qd * s[0]), &p)
                        .column(k)
                        .into_owned()
                });
                check(
                    &format!("{name} J̇ column {k}"),
                    &c.jacobian_rate.column(k).into_owned(),
                    &Want {
                        d: dj.d.column(0).into_owned(),
                        noise: dj.noise,
                    },
                    REL,
                );
            }
        }
        if NK > 0 {
            let k = L::contact_derivatives(&q, &qd, &a, &lam, &p);
            check(
                &format!("{name} ∂(J_cᵀ λ)/∂q"),
                &k.force_q,
                &central(&q, H, |x| L::contact_jacobian(x, &p).transpose() * lam),
                REL,
            );
            check(
                &format!("{name} ∂(J_c a)/∂q"),
                &k.jacobian_q,
                &central(&q, H, |x| L::contact_jacobian(x, &p) * a),
                REL,
            );
            check(
                &format!("{name} ∂(J̇_c q̇)/∂q"),
                &k.bias_q,
                &central(&q, H, |x| L::contact_bias(x, &qd, &p)),
                REL,
            );
            check(
                &format!("{name} J̇_c q̇"),
                &(k.jacobian_rate * qd),
                &exact(L::contact_bias(&q, &qd, &p)),
                1e-12,
            );
        }
        // The fused function is the sum of the separate terms (and D).
        let fused = L::dynamics_derivatives(&q, &qd, &a, &f, &p);
        check(
            &format!("{name} fused ∂/∂q"),
            &fused.dynamics_q,
            &exact(dma + dn_q - c.force_q),
            1e-12,
        );
        check(
            &format!("{name} fused ∂/∂q̇"),
            &fused.dynamics_qd,
            &exact(dn_qd + central(&qd, H, |x| L::damping_forces(x, &p)).d),
            1e-9,
        );
        check(
            &format!("{name} fused ∂(J a + J̇ q̇)/∂q"),
            &fused.constraint_q,
            &exact(c.jacobian_q + c.bias_q),
            1e-12,
        );
    }
    eprintln!(
        "{}: generated terms, worst ∂(M a)/∂q error {worst:.1e}",
        L::NAME
    );
}

/// Forward dynamics' derivatives against central differences of forward dynamics, at
/// 100 random regular assembled states with random torques; every other state with
/// Baumgarte terms.
fn forward_dynamics_fd<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() -> f64 {
    let p = L::Params::<f64>::default();
    let mut rng = Rng::new(7);
    let mut worst = 0.0f64;
    for i in 0..STATES {
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 2.0);
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-2.0, 2.0));
        let baumgarte = (i % 2 == 1).then_some(Baumgarte {
            alpha: 10.0,
            beta: 10.0,
        });
        let d = forward_dynamics_derivatives::<L, f64, NQ, NC, NU>(&p, &s.q, &s.qd, &u, baumgarte)
            .expect("a regular state");
        let fd = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, u: &SVector<f64, NU>| {
            forward_dynamics::<L, f64, NQ, NC, NU>(&p, q, qd, u, baumgarte).expect("regular")
        };
        let plain = fd(&s.q, &s.qd, &u);
        assert_eq!(d.acceleration, plain, "{}: the same solution", L::NAME);
        let name = L::NAME;
        if L::REDUNDANT_ROWS == 0 {
            worst = worst.max(check(
                &format!("{name} ∂q̈/∂q"),
                &d.qdd_q,
                &central(&s.q, H, |x| fd(x, &s.qd, &u).qdd),
                REL,
            ));
        } else {
            // Along the manifold, with q̇ kept consistent (J q̇ = 0) so that the redundant
            // rows stay consistent: d/ds q̈(q(s), q̇(s)) = ∂q̈/∂q q' + ∂q̈/∂q̇ q̇'.
            let rate = |x: &SVector<f64, NQ>| {
                let mut v = s.qd;
                leg_models::assembly::project_velocity::<L, f64, NQ, NC, NU>(&p, x, &mut v)
                    .expect("projects");
                v
            };
            for t in manifold_directions::<L, NQ, NC, NU>(&p, &s.q) {
                let curve = |x: &SVector<f64, 1>| on_manifold::<L, NQ, NC, NU>(&p, &s.q, &t, x[0]);
                let zero = SVector::<f64, 1>::zeros();
                let (dq, dqd) = (
                    central(&zero, H, curve).d,
                    central(&zero, H, |x| rate(&curve(x))).d,
                );
                let want = central(&zero, H, |x| {
                    let q = curve(x);
                    fd(&q, &rate(&q), &u).qdd
                });
                worst = worst.max(check(
                    &format!("{name} ∂q̈/∂q along the manifold"),
                    &(d.qdd_q * dq + d.qdd_qd * dqd),
                    &want,
                    REL,
                ));
            }
        }
        worst = worst.max(check(
            &format!("{name} ∂q̈/∂q̇"),
            &d.qdd_qd,
            &central(&s.qd, H, |x| fd(&s.q, x, &u).qdd),
            REL,
        ));
        worst = worst.max(check(
            &format!("{name} ∂q̈/∂u"),
            &d.qdd_u,
            &central(&u, U_STEP, |x| fd(&s.q, &s.qd, x).qdd),
            REL,
        ));
        // A leg closed redundantly has many force solutions; the pivots pick one, and
        // which rows they leave out may change within a step: its forces are not a
        // differentiable function there, its accelerations are.
        if L::REDUNDANT_ROWS == 0 && NC > 0 {
            worst = worst.max(check(
                &format!("{name} ∂F/∂q"),
                &d.forces_q,
                &central(&s.q, H, |x| fd(x, &s.qd, &u).forces),
                REL,
            ));
            worst = worst.max(check(
                &format!("{name} ∂F/∂q̇"),
                &d.forces_qd,
                &central(&s.qd, H, |x| fd(&s.q, x, &u).forces),
                REL,
            ));
            worst = worst.max(check(
                &format!("{name} ∂F/∂u"),
                &d.forces_u,
                &central(&u, U_STEP, |x| fd(&s.q, &s.qd, x).forces),
                REL,
            ));
        }
        // The null-space form: q̈ = G θ̈ + c, Ã θ̈ = b̃ + u, so ∂q̈/∂u = G Ã⁻¹.
        if Structure::of::<L, NQ, NC, NU>().actuation() == Actuation::Full {
            let terms = L::dynamics_terms(&s.q, &s.qd, &p);
            let ns = null_space::<L, f64, NQ, NC, NU>(
                &terms.constraint_jacobian,
                &terms.constraint_bias,
            )
            .expect("regular");
            let red = actuated_reduction_null_space::<L, f64, NQ, NC, NU>(&p, &terms, &s.qd)
                .expect("regular");
            let inv = red.a_tilde.try_inverse().expect("Ã invertible");
            check(
                &format!("{name} ∂q̈/∂u null-space"),
                &d.qdd_u,
                &exact(ns.g * inv),
                1e-9,
            );
        }
    }
    worst
}

/// With contacts held (the first sticking, the second, if any, sliding), against
/// differences of forward dynamics with the same modes.
fn contact_fd<
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>() -> f64 {
    if NK == 0 {
        return 0.0;
    }
    let p = L::Params::<f64>::default();
    let (ground, mu) = (
        Ground::of::<L, NQ, NC, NU, NK>(),
        spec_friction::<L, f64, NQ, NC, NU, NK, 2>(),
    );
    let mut modes = Modes::<NK>::flight();
    modes.set(0, ContactMode::Stick);
    if NK >= 4 {
        modes.set(1, ContactMode::Slide { forward: true });
    }
    let mut rng = Rng::new(9);
    let (mut worst, mut tried) = (0.0f64, 0);
    let (mut checked, mut noisy) = (0, 0);
    while checked < STATES && tried < 40 * STATES {
        tried += 1;
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 2.0);
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-2.0, 2.0));
        let anchors = ground.coordinates(&L::contact_positions(&s.q, &p));
        let baumgarte = (checked % 2 == 1).then_some(Baumgarte {
            alpha: 5.0,
            beta: 5.0,
        });
        let solve = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, u: &SVector<f64, NU>| {
            forward_dynamics_with_contacts::<L, f64, NQ, NC, NU, NK, 2>(
                &p, q, qd, u, &modes, &anchors, &ground, &mu, baumgarte,
            )
        };
        // Held contacts may repeat the closures at some poses: those are not regular.
        let Ok(d) = contact_dynamics_derivatives::<L, f64, NQ, NC, NU, NK, 2>(
            &p, &s.q, &s.qd, &u, &modes, &anchors, &ground, &mu, baumgarte, None,
        ) else {
            continue;
        };
        let regular = |x: &SVector<f64, NQ>| {
            (0..NQ).all(|i| {
                solve(&(x + unit::<NQ>(i) * H), &s.qd, &u).is_ok()
                    && solve(&(x - unit::<NQ>(i) * H), &s.qd, &u).is_ok()
            })
        };
        if !regular(&s.q) {
            continue;
        }
        let sol = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, u: &SVector<f64, NU>| {
            solve(q, qd, u).unwrap()
        };
        assert_eq!(d.solution, sol(&s.q, &s.qd, &u));
        let name = L::NAME;
        let (dq, dqd) = (
            central(&s.q, H, |x| sol(x, &s.qd, &u).x),
            central(&s.qd, H, |x| sol(&s.q, x, &u).x),
        );
        // A held contact can make the stance system nearly singular (a foot under a body
        // that can barely move): there the differences are noise, and the state is left
        // out (counted) instead of passing a check that cannot fail.
        if !(checkable(&dq) && checkable(&dqd)) {
            noisy += 1;
            continue;
        }
        for (what, got, want) in [("∂q̈/∂q", d.qdd_q, dq), ("∂q̈/∂q̇", d.qdd_qd, dqd)] {
            worst = worst.max(check(&format!("{name} stance {what}"), &got, &want, REL));
        }
        worst = worst.max(check(
            &format!("{name} stance ∂q̈/∂u"),
            &d.qdd_u,
            &central(&u, U_STEP, |x| sol(&s.q, &s.qd, x).x),
            REL,
        ));
        worst = worst.max(check(
            &format!("{name} stance ∂λ/∂q"),
            &d.contact_q,
            &central(&s.q, H, |x| sol(x, &s.qd, &u).contact),
            REL,
        ));
        worst = worst.max(check(
            &format!("{name} stance ∂λ/∂q̇"),
            &d.contact_qd,
            &central(&s.qd, H, |x| sol(&s.q, x, &u).contact),
            REL,
        ));
        worst = worst.max(check(
            &format!("{name} stance ∂λ/∂u"),
            &d.contact_u,
            &central(&u, U_STEP, |x| sol(&s.q, &s.qd, x).contact),
            REL,
        ));
        checked += 1;
    }
    assert!(
        checked >= STATES / 2 && noisy <= checked / 4,
        "{}: {checked} regular stance states checked, {noisy} too ill-conditioned to difference",
        L::NAME
    );
    worst
}

/// The reduction's inverse dynamics `u = Ã v − b̃` against differences of the reduction.
fn reduction_fd<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>() {
    if Structure::of::<L, NQ, NC, NU>().joint_space().is_err() {
        return;
    }
    let p = L::Params::<f64>::default();
    let mut rng = Rng::new(5);
    for _ in 0..STATES {
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 2.0);
        let v = SVector::<f64, NU>::from_fn(|_, _| rng.range(-5.0, 5.0));
        let d = reduction_derivatives::<L, f64, NQ, NC, NU>(&p, &s.q, &s.qd, &v).expect("regular");
        let torque = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>| {
            let terms = L::dynamics_terms(q, qd, &p);
            let r = actuated_reduction::<L, f64, NQ, NC, NU>(&p, &terms, qd).expect("regular");
            r.a_tilde * v - r.b_tilde
        };
        check(
            &format!("{} ∂u/∂q of the reduction", L::NAME),
            &d.torque_q,
            &central(&s.q, H, |x| torque(x, &s.qd)),
            REL,
        );
        check(
            &format!("{} ∂u/∂q̇ of the reduction", L::NAME),
            &d.torque_qd,
            &central(&s.qd, H, |x| torque(&s.q, x)),
            REL,
        );
    }
}

/// One step's linearization against differences of the step, in joint coordinates.
fn step_fd<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>() -> f64 {
    let p = L::Params::<f64>::default();
    let mut rng = Rng::new(3);
    let mut worst = 0.0f64;
    for i in 0..8 {
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 2.0);
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-2.0, 2.0));
        let mut opts = StepOptions::rk4(2e-3);
        // Without the projection: the step's own linearization (exact).
        opts.project = false;
        if i % 2 == 1 {
            opts.method = Method::SemiImplicitEuler;
        }
        let run = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, u: &SVector<f64, NU>| {
            let mut x = State { q: *q, qd: *qd };
            let mut held = |_: f64, _: &State<f64, NQ>| *u;
            step::<L, f64, NQ, NC, NU>(&p, &mut x, 0.0, &mut held, &opts).expect("regular");
            x
        };
        let (next, jac) = linearize_step::<L, f64, NQ, NC, NU>(&p, &s, &u, &opts).expect("regular");
        assert_eq!(next, run(&s.q, &s.qd, &u));
        let name = format!("{} {:?}", L::NAME, opts.method);
        worst = worst.max(check_q::<L, NQ, NC, NU, NQ>(
            &format!("{name} ∂q⁺/∂q"),
            &p,
            &s.q,
            &jac.q_q,
            |x| run(x, &s.qd, &u).q,
            REL,
        ));
        worst = worst.max(check_q::<L, NQ, NC, NU, NQ>(
            &format!("{name} ∂q̇⁺/∂q"),
            &p,
            &s.q,
            &jac.qd_q,
            |x| run(x, &s.qd, &u).qd,
            REL,
        ));
        for (what, got, want) in [
            (
                "∂q⁺/∂q̇",
                jac.q_qd,
                central(&s.qd, H, |x| run(&s.q, x, &u).q),
            ),
            (
                "∂q̇⁺/∂q̇",
                jac.qd_qd,
                central(&s.qd, H, |x| run(&s.q, x, &u).qd),
            ),
        ] {
            worst = worst.max(check(&format!("{name} {what}"), &got, &want, REL));
        }
        worst = worst.max(check(
            &format!("{name} ∂q̇⁺/∂u"),
            &jac.qd_u,
            &central(&u, U_STEP, |x| run(&s.q, &s.qd, x).qd),
            REL,
        ));
        worst = worst.max(check(
            &format!("{name} ∂q⁺/∂u"),
            &jac.q_u,
            &central(&u, U_STEP, |x| run(&s.q, &s.qd, x).q),
            REL,
        ));
    }
    worst
}

/// The linearization in a chart of the manifold against differences through the chart:
/// lift perturbed coordinates onto the constraints, step (without the projection), read
/// the coordinates back.
fn manifold_fd<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const M: usize,
    const NX: usize,
>() -> f64 {
    let p = L::Params::<f64>::default();
    let mut rng = Rng::new(4);
    let mut worst = 0.0f64;
    let mut opts = StepOptions::rk4(2e-3);
    opts.project = false;
    let tol = leg_models::assembly::Tolerance::default();
    for _ in 0..6 {
        let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 2.0);
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-2.0, 2.0));
        let chart = ManifoldChart::<f64, NQ, M>::new::<L, NC, NU>(&p, &s.q).expect("regular");
        let lin = chart
            .linearize_step::<L, NC, NU, NX>(&p, &s, &u, &opts)
            .expect("regular");
        let (theta, rate) = chart.coordinates_of(&s);
        let x0 = SVector::<f64, NX>::from_fn(|k, _| if k < M { theta[k] } else { rate[k - M] });
        let through = |x: &SVector<f64, NX>, u: &SVector<f64, NU>| {
            let th = SVector::<f64, M>::from_fn(|k, _| x[k]);
            let rt = SVector::<f64, M>::from_fn(|k, _| x[M + k]);
            let mut state = chart.lift::<L, NC, NU>(&p, &th, &rt, &tol).expect("lifts");
            let mut held = |_: f64, _: &State<f64, NQ>| *u;
            step::<L, f64, NQ, NC, NU>(&p, &mut state, 0.0, &mut held, &opts).expect("steps");
            let (a, b) = chart.coordinates_of(&state);
            SVector::<f64, NX>::from_fn(|k, _| if k < M { a[k] } else { b[k - M] })
        };
        // The lift is exact (assembled to ~1e-13 of the leg's size): a larger step keeps
        // its rounding small against the difference.
        let h = 1e-4;
        worst = worst.max(check(
            &format!("{} manifold A", L::NAME),
            &lin.a,
            &central(&x0, h, |x| through(x, &u)),
            REL,
        ));
        worst = worst.max(check(
            &format!("{} manifold B", L::NAME),
            &lin.b,
            &central(&u, h, |v| through(&x0, v)),
            REL,
        ));
    }
    worst
}

macro_rules! derivative_checks {
    ($module:ident, $ty:ty, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        mod $module {
            use super::*;

            const M: usize = <$ty as leg_models::LegDynamics<$nq, $nc, $nu>>::MOBILITY;

            #[test]
            fn generated_directional_terms_match_finite_differences() {
                generated_terms::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn forward_dynamics_derivatives_match_finite_differences() {
                let worst = forward_dynamics_fd::<$ty, $nq, $nc, $nu>();
                let contact = contact_fd::<$ty, $nq, $nc, $nu, $nk>();
                eprintln!(
                    "{}: worst relative error {worst:.1e} (contacts {contact:.1e})",
                    stringify!($module)
                );
            }

            #[test]
            fn reduction_derivatives_match_finite_differences() {
                reduction_fd::<$ty, $nq, $nc, $nu>();
            }

            #[test]
            fn step_linearizations_match_finite_differences() {
                let joint = step_fd::<$ty, $nq, $nc, $nu>();
                let manifold = manifold_fd::<$ty, $nq, $nc, $nu, M, { 2 * M }>();
                eprintln!(
                    "{}: step {joint:.1e}, on the manifold {manifold:.1e}",
                    stringify!($module)
                );
            }
        }
    };
}

generated::for_each_model!(derivative_checks);

/// Against CasADi's own `jacobian` of its forward dynamics (the closed-form terms solved
/// by CasADi's `solve` and differentiated by its AD, compiled from the generated C): a
/// second formulation of every derivative, at 100 random regular states per leg.
#[cfg(feature = "peers")]
mod casadi_jacobian {
    use super::*;
    use leg_tests::casadi::{functions, parameter_vector, Prepared};

    fn compare<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>() {
        let p = L::Params::<f64>::default();
        let pv = parameter_vector(&p);
        let mut rng = Rng::new(31);
        let mut worst = 0.0f64;
        for _ in 0..STATES {
            let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 2.0);
            let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-2.0, 2.0));
            let d = forward_dynamics_derivatives::<L, f64, NQ, NC, NU>(&p, &s.q, &s.qd, &u, None)
                .expect("regular");
            let sizes = [NQ, NC, NQ * NQ, NQ * NQ, NQ * NU, NC * NQ, NC * NQ, NC * NU];
            let mut out: Vec<Vec<f64>> = sizes.iter().map(|&n| vec![f64::NAN; n]).collect();
            let (q, qd, uu) = (
                s.q.as_slice().to_vec(),
                s.qd.as_slice().to_vec(),
                u.as_slice().to_vec(),
            );
            {
                let mut refs: Vec<&mut Vec<f64>> = out.iter_mut().collect();
                let call = Prepared::new(
                    functions(L::NAME)
                        .derivatives
                        .expect("a planar leg has CasADi's derivatives"),
                    &[&q, &qd, &uu, &pv],
                    &mut refs,
                );
                // SAFETY: the buffers outlive the call and have the function's dense sizes.
                assert_eq!(unsafe { call.call() }, 0);
            }
            let name = L::NAME;
            let mat = |v: &Vec<f64>| SMatrix::<f64, NQ, NQ>::from_column_slice(v);
            for (what, ours, theirs) in [
                ("∂q̈/∂q", d.qdd_q, mat(&out[2])),
                ("∂q̈/∂q̇", d.qdd_qd, mat(&out[3])),
            ] {
                if L::REDUNDANT_ROWS > 0 {
                    // The two solves drop different rows, so they extend the dynamics
                    // differently off the manifold; along it they agree (to what q̇, held
                    // while q moves, leaves of the redundant rows' consistency).
                    for t in manifold_directions::<L, NQ, NC, NU>(&p, &s.q) {
                        worst = worst.max(check(
                            &format!("{name} CasADi {what} along the manifold"),
                            &(ours * t),
                            &exact(theirs * t),
                            1e-6,
                        ));
                    }
                    continue;
                }
                worst = worst.max(check(
                    &format!("{name} CasADi {what}"),
                    &ours,
                    &exact(theirs),
                    1e-8,
                ));
            }
            worst = worst.max(check(
                &format!("{name} CasADi ∂q̈/∂u"),
                &d.qdd_u,
                &exact(SMatrix::<f64, NQ, NU>::from_column_slice(&out[4])),
                1e-8,
            ));
            // CasADi solves the independent rows of a leg closed redundantly, ours pivots:
            // their forces are different solutions.
            if L::REDUNDANT_ROWS == 0 && NC > 0 {
                for (what, ours, k) in [("∂F/∂q", d.forces_q, 5), ("∂F/∂q̇", d.forces_qd, 6)]
                {
                    worst = worst.max(check(
                        &format!("{name} CasADi {what}"),
                        &ours,
                        &exact(SMatrix::<f64, NC, NQ>::from_column_slice(&out[k])),
                        1e-8,
                    ));
                }
                worst = worst.max(check(
                    &format!("{name} CasADi ∂F/∂u"),
                    &d.forces_u,
                    &exact(SMatrix::<f64, NC, NU>::from_column_slice(&out[7])),
                    1e-8,
                ));
            }
        }
        eprintln!(
            "{}: against CasADi's jacobian, worst relative difference {worst:.1e}",
            L::NAME
        );
    }

    macro_rules! each {
        ($module:ident, $ty:ty, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            #[test]
            fn $module() {
                compare::<$ty, $nq, $nc, $nu>();
            }
        };
    }

    generated::for_each_model!(each);
}
