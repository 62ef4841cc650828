//! Spatial legs (`LegModel<NQ, NC, NU, 3>`, `generated::for_each_spatial_model!`): their
//! generated terms against independent checks, on every spatial leg without naming it.
//!
//! - `G`, `J`, the foot Jacobian and `J̇ q̇` against central differences of `V`, `φ`, the
//!   foot and `J q̇`;
//! - `M` symmetric positive definite and `½ q̇ᵀ M q̇` equal to the kinetic energy;
//! - `C q̇ + G` consistent with `M` and `V`: a passive, undamped swing of the closed chain
//!   (the runtime's KKT forward dynamics, RK4) keeps its energy to the integrator's order;
//! - a structurally redundant closure row (a planar loop written as a 3-D point closure)
//!   is handled with no regularization: `J q̈ + J̇ q̇ = 0` to rounding.

use leg_models::assembly::{project_position, project_velocity, Tolerance};
use leg_models::dynamics::forward_dynamics;
use leg_models::nalgebra::{SMatrix, SVector};
use leg_models::{LegDynamics, LegModel};
use leg_tests::Rng;

fn central<const N: usize, const R: usize>(
    f: impl Fn(&SVector<f64, N>) -> SVector<f64, R>,
    q: &SVector<f64, N>,
) -> SMatrix<f64, R, N> {
    let h = 1e-6;
    let mut out = SMatrix::<f64, R, N>::zeros();
    for k in 0..N {
        let mut a = *q;
        let mut b = *q;
        a[k] += h;
        b[k] -= h;
        out.set_column(k, &((f(&a) - f(&b)) / (2.0 * h)));
    }
    out
}

fn rel(a: f64, scale: f64) -> f64 {
    a / scale.max(1e-300)
}

fn assembled<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    q: &mut SVector<f64, NQ>,
) where
    L: LegDynamics<NQ, NC, NU>,
{
    project_position::<L, f64, NQ, NC, NU>(p, q, &Tolerance::default())
        .unwrap_or_else(|e| panic!("{}: does not assemble: {e}", L::NAME));
}

fn check_leg<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>()
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let name = L::NAME;
    // The dimension the runtime decides by (foot control needs as many motors) is the
    // points' own.
    assert_eq!(L::DIMENSION, 3, "{name}: LegDynamics::DIMENSION");
    let p = L::Params::<f64>::default();
    let mut rng = Rng::new(30);
    // Each rod's length |a − b| at every assembled state (the same, whatever the pose).
    let mut rods: Vec<Vec<f64>> = vec![Vec::new(); L::DISTANCE_CLOSURES.len()];
    for trial in 0..5 {
        // Random poses near home, put on the closures; random velocities.
        let mut q = SVector::<f64, NQ>::from(L::HOME);
        for k in 0..NQ {
            q[k] += 0.1 * rng.range(-1.0, 1.0);
        }
        assembled::<L, NQ, NC, NU>(&p, &mut q);
        let mut qd = SVector::<f64, NQ>::from_fn(|_, _| rng.range(-2.0, 2.0));
        project_velocity::<L, f64, NQ, NC, NU>(&p, &q, &mut qd).unwrap();

        let points = L::closure_points(&q, &p);
        for (r, &k) in L::DISTANCE_CLOSURES.iter().enumerate() {
            rods[r].push((points.column(2 * k) - points.column(2 * k + 1)).norm());
        }
        let g = L::gravity_forces(&q, &p);
        let g_fd = central(|x| SVector::<f64, 1>::new(L::potential_energy(x, &p)), &q).transpose();
        let e = rel((g - g_fd).amax(), g.amax());
        assert!(e < 1e-7, "{name} #{trial}: G vs ∂V/∂q: {e:e}");

        let j = L::constraint_jacobian(&q, &p);
        let j_fd = central(|x| L::closure_residual(x, &p), &q);
        let e = rel((j - j_fd).amax(), j.amax());
        assert!(e < 1e-7, "{name} #{trial}: J vs ∂φ/∂q: {e:e}");

        let jf = L::foot_jacobian(&q, &p);
        let jf_fd = central(|x| L::foot_position(x, &p), &q);
        let e = rel((jf - jf_fd).amax(), jf.amax());
        assert!(e < 1e-7, "{name} #{trial}: J_f vs ∂foot/∂q: {e:e}");

        let b = L::constraint_bias(&q, &qd, &p);
        let b_fd = central(|x| L::constraint_jacobian(x, &p) * qd, &q) * qd;
        let e = rel(
            (b - b_fd).amax(),
            b.amax().max(j.amax() * qd.norm_squared()),
        );
        assert!(e < 1e-6, "{name} #{trial}: J̇ q̇ vs ∂(J q̇)/∂q q̇: {e:e}");

        let m = L::mass_matrix(&q, &p);
        let e = rel((m - m.transpose()).amax(), m.amax());
        assert!(e < 1e-14, "{name} #{trial}: M not symmetric: {e:e}");
        assert!(
            m.cholesky().is_some(),
            "{name} #{trial}: M not positive definite"
        );
        let t = L::kinetic_energy(&q, &qd, &p);
        let e = rel((t - 0.5 * qd.dot(&(m * qd))).abs(), t);
        assert!(e < 1e-12, "{name} #{trial}: T vs ½ q̇ᵀ M q̇: {e:e}");

        // The KKT solve on every row, the redundant ones included, unregularized.
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-0.5, 0.5));
        let acc = forward_dynamics::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None)
            .unwrap_or_else(|e| panic!("{name} #{trial}: forward dynamics: {e}"));
        let closure = (j * acc.qdd + b).amax();
        // Rounding is relative to the terms summed, |J| |q̈|: J q̈ itself can be small
        // where q̈ lies mostly in J's null space (the achilles rod's fast free spin).
        let scale = (j.abs() * acc.qdd.abs()).amax().max(b.amax());
        assert!(
            rel(closure, scale) < 1e-10,
            "{name} #{trial}: J q̈ + J̇ q̇ = {closure:e} (scale {scale:e})"
        );
    }
    // The rods' lengths are the parameters `<closure>_distance`, in closure order.
    let names = <L::Params<f64> as leg_models::Parameters<f64>>::NAMES;
    let lengths: Vec<f64> = names
        .iter()
        .enumerate()
        .filter(|(_, n)| n.ends_with("_distance"))
        .map(|(i, _)| leg_models::Parameters::get(&p, i).unwrap())
        .collect();
    assert_eq!(lengths.len(), rods.len(), "{name}: a parameter per rod");
    for (r, measured) in rods.iter().enumerate() {
        for &x in measured {
            assert!(
                (x - lengths[r]).abs() < 1e-12 * lengths[r],
                "{name}: rod {} is {x} m at an assembled state, its parameter {} m",
                L::DISTANCE_CLOSURES[r],
                lengths[r]
            );
        }
    }
}

/// `(largest |E(t) − E(0)|, peak kinetic energy, largest |V|, the loop's gap at the end)`
/// of an undamped, unforced swing from home over 0.5 s, plain RK4 at `dt`.
fn energy_swing<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    dt: f64,
) -> (f64, f64, f64, f64)
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let name = L::NAME;
    let mut p = L::Params::<f64>::default();
    // Undamped: every damping parameter zero.
    for (i, n) in <L::Params<f64> as leg_models::Parameters<f64>>::NAMES
        .iter()
        .enumerate()
    {
        if n.ends_with("_damping") {
            leg_models::Parameters::set(&mut p, i, 0.0);
        }
    }
    let mut q = SVector::<f64, NQ>::from(L::HOME);
    assembled::<L, NQ, NC, NU>(&p, &mut q);
    let mut qd = SVector::<f64, NQ>::zeros();
    let u = SVector::<f64, NU>::zeros();
    let energy = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>| {
        L::kinetic_energy(q, qd, &p) + L::potential_energy(q, &p)
    };
    let e0 = energy(&q, &qd);
    let f = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>| {
        forward_dynamics::<L, f64, NQ, NC, NU>(&p, q, qd, &u, None)
            .unwrap_or_else(|e| panic!("{name}: forward dynamics: {e}"))
            .qdd
    };
    let mut peak_kinetic: f64 = 0.0;
    let mut largest_potential = L::potential_energy(&q, &p).abs();
    let mut drift: f64 = 0.0;
    for _ in 0..(0.5 / dt).round() as usize {
        let k1 = (qd, f(&q, &qd));
        let k2 = (
            qd + k1.1 * (dt / 2.0),
            f(&(q + k1.0 * (dt / 2.0)), &(qd + k1.1 * (dt / 2.0))),
        );
        let k3 = (
            qd + k2.1 * (dt / 2.0),
            f(&(q + k2.0 * (dt / 2.0)), &(qd + k2.1 * (dt / 2.0))),
        );
        let k4 = (qd + k3.1 * dt, f(&(q + k3.0 * dt), &(qd + k3.1 * dt)));
        q += (k1.0 + k2.0 * 2.0 + k3.0 * 2.0 + k4.0) * (dt / 6.0);
        qd += (k1.1 + k2.1 * 2.0 + k3.1 * 2.0 + k4.1) * (dt / 6.0);
        peak_kinetic = peak_kinetic.max(L::kinetic_energy(&q, &qd, &p));
        largest_potential = largest_potential.max(L::potential_energy(&q, &p).abs());
        drift = drift.max((energy(&q, &qd) - e0).abs());
    }
    // Plain RK4, no projection: the loop drifts open at the integrator's order only.
    let gap = L::closure_residual(&q, &p).amax();
    assert!(gap < 1e-6, "{name}: the loop opened {gap:e} m");
    (drift, peak_kinetic, largest_potential, gap)
}

/// Energy is kept to the integrator's order: small, and more than 4 times smaller at half the step (a
/// wrong `C q̇` or `G` leaves an error that does not shrink with the step), unless it is
/// rounding alone (below 1e-10 of the peak kinetic plus the largest potential energy).
fn energy_kept<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>()
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let name = L::NAME;
    let (coarse, peak, _, coarse_gap) = energy_swing::<L, NQ, NC, NU, NP>(2e-4);
    let (fine, _, potential, fine_gap) = energy_swing::<L, NQ, NC, NU, NP>(1e-4);
    // A wrong J̇ q̇ opens the loop whatever the step; RK4's own drift shrinks with it (the
    // stiff springs of cassie_leg's shin and heel leave 1.6e-7 m at 0.2 ms).
    assert!(
        fine_gap < 1e-9 || coarse_gap > 4.0 * fine_gap,
        "{name}: the loop's drift does not shrink with the step ({coarse_gap:e} m at 0.2 ms, {fine_gap:e} m at 0.1 ms)"
    );
    eprintln!("{name}: loop drift {coarse_gap:e} m at 0.2 ms, {fine_gap:e} m at 0.1 ms; energy {coarse:e} J, {fine:e} J");
    assert!(peak > 1e-3, "{name}: the swing did not move ({peak:e} J)");
    assert!(
        fine < 1e-6 * peak,
        "{name}: energy drifted {fine:e} J over 0.5 s (peak kinetic {peak:e} J)"
    );
    // Where RK4's error is below rounding (a block falling at constant acceleration, where
    // it is exact), rounding is all that is left, and it does not shrink with the step.
    // Rounding scales with the energies summed, the potential one included: a leg hanging
    // 0.3 m below its base (the user trial's, `ankle_rod_leg`) carries 0.6 J of it, and
    // its 2.7e-12 J at 0.1 ms is 4.5e-12 of that.
    let rounding = 1e-10 * (peak + potential);
    assert!(
        fine < rounding || coarse > 4.0 * fine,
        "{name}: the energy error does not shrink with the step ({coarse:e} J at 0.2 ms, {fine:e} J at 0.1 ms)"
    );
}

/// A leg's ball joints (`BALL_JOINTS`): forward dynamics refuses their angles'
/// singularity by name, at `β = ±π/2` and within `√ε` of it, and solves a hundredth of a
/// radian away, where `M` is still positive definite. A leg without ball joints: nothing to
/// check, said by the return value.
fn ball_joint_singularity<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
) -> usize
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    use leg_models::dynamics::DynamicsError;
    let p = L::Params::<f64>::default();
    let home = SVector::<f64, NQ>::from(L::HOME);
    let (qd, u) = (SVector::<f64, NQ>::zeros(), SVector::<f64, NU>::zeros());
    for &b in L::BALL_JOINTS {
        for beta in [
            std::f64::consts::FRAC_PI_2,
            -std::f64::consts::FRAC_PI_2,
            std::f64::consts::FRAC_PI_2 - 1e-9,
        ] {
            let mut q = home;
            q[b + 1] = beta;
            match forward_dynamics::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None) {
                Err(DynamicsError::BallJointSingular { joint, cos_beta }) => {
                    assert_eq!(joint, b);
                    assert!(cos_beta.abs() < 1e-8);
                }
                other => panic!("{}: β = {beta}: {other:?}", L::NAME),
            }
        }
        let mut q = home;
        q[b + 1] = std::f64::consts::FRAC_PI_2 - 1e-2;
        assert!(L::mass_matrix(&q, &p).cholesky().is_some());
        assert!(forward_dynamics::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None).is_ok());
    }
    L::BALL_JOINTS.len()
}

/// A spatial leg through the runtime's `Leg` (the generated `Leg` alias): its home
/// assembles onto the closures, its forward dynamics is the free function's bit for bit,
/// and its recording simulator runs, the loops kept.
fn leg_wrapper<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>()
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let leg = leg_models::Leg::<L, f64, NQ, NC, NU>::default();
    let q = leg.assembled_home().expect("home assembles");
    assert!(leg.closure_residual(&q).amax() < 1e-12, "{}", L::NAME);
    let qd = SVector::<f64, NQ>::zeros();
    let u = SVector::<f64, NU>::from_element(0.1);
    let wrapped = leg.forward_dynamics(&q, &qd, &u).expect("forward dynamics");
    let free = forward_dynamics::<L, f64, NQ, NC, NU>(leg.params(), &q, &qd, &u, None).unwrap();
    assert_eq!(wrapped.qdd, free.qdd, "{}", L::NAME);
    let opts = leg_models::simulate::StepOptions::rk4(1e-3);
    let mut torques = leg.torque_source(|_t, _s| SVector::<f64, NU>::zeros());
    let run = leg
        .simulator(opts)
        .run(leg_models::simulate::State { q, qd }, 20, &mut torques)
        .expect("runs");
    assert_eq!(run.len(), 21);
    assert!(
        run.iter().all(|s| s.closure_residual < 1e-12),
        "{}",
        L::NAME
    );
}

/// The KKT solve the leg's structure chooses (its mass matrix factored along the tree on a
/// body carrying legs, densely on one leg) against its definition and against the dense
/// solve, at states off home with rates and torques: `M q̈ − Jᵀ F = τ`, `J q̈ = r`
/// (forces compared as `Jᵀ F`, which redundant rows leave unique), and the derivatives'
/// own factorization of `K` solving `∂q̈/∂u` as the dense solve does column by column.
fn kkt_solve_meets_its_definition<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NP: usize,
>()
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    use leg_models::dynamics::derivatives::forward_dynamics_derivatives;
    use leg_models::dynamics::structure::{factors_along_the_tree, mass_factor_operations};
    use leg_models::dynamics::{actuation, solve_kkt};
    let name = L::NAME;
    let (dense_ops, tree_ops) = mass_factor_operations(&L::PARENTS);
    eprintln!(
        "{name}: mass matrix factored {} (multiply–adds dense {dense_ops}, along the tree {tree_ops:?})",
        if factors_along_the_tree(&L::PARENTS) { "along the tree" } else { "densely" }
    );
    let p = L::Params::<f64>::default();
    let mut rng = Rng::new(77);
    for trial in 0..5 {
        // On the closures with rates that keep them, where rows that repeat the others are
        // consistent with them.
        let mut q = SVector::<f64, NQ>::from_fn(|i, _| L::HOME[i] + 0.05 * rng.range(-1.0, 1.0));
        assembled::<L, NQ, NC, NU>(&p, &mut q);
        let mut qd = SVector::<f64, NQ>::from_fn(|_, _| rng.range(-1.0, 1.0));
        project_velocity::<L, f64, NQ, NC, NU>(&p, &q, &mut qd).unwrap();
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-1.0, 1.0));
        let terms = L::dynamics_terms(&q, &qd, &p);
        let (m, j) = (&terms.mass_matrix, &terms.constraint_jacobian);
        let tau =
            actuation::<L, f64, NQ, NC, NU>(&u) - terms.bias_forces - L::damping_forces(&qd, &p);
        let r = -terms.constraint_bias;
        let chosen = forward_dynamics::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None).unwrap();
        let dense = solve_kkt(m, j, &tau, &r, L::REDUNDANT_ROWS).unwrap();
        let scale = tau.amax() + m.amax() * chosen.qdd.amax();
        let e_dyn = (m * chosen.qdd - j.transpose() * chosen.forces - tau).amax();
        let e_rows = (j * chosen.qdd - r).amax();
        let e_qdd = (chosen.qdd - dense.qdd).amax();
        let e_f = (j.transpose() * (chosen.forces - dense.forces)).amax();
        assert!(
            e_dyn <= 1e-11 * scale,
            "{name} #{trial}: M q̈ − Jᵀ F − τ {e_dyn:e} of {scale:e}"
        );
        assert!(
            e_rows <= 1e-11 * (r.amax() + j.amax() * chosen.qdd.amax()),
            "{name} #{trial}: J q̈ − r {e_rows:e}"
        );
        assert!(
            e_qdd < 1e-10 * chosen.qdd.amax().max(1.0),
            "{name} #{trial}: q̈ off the dense solve's by {e_qdd:e}"
        );
        assert!(
            e_f <= 1e-10 * scale,
            "{name} #{trial}: Jᵀ F off the dense solve's by {e_f:e}"
        );
        let d = forward_dynamics_derivatives::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None).unwrap();
        assert!((d.acceleration.qdd - chosen.qdd).amax() < 1e-10 * chosen.qdd.amax().max(1.0));
        for k in 0..NU {
            let mut e = SVector::<f64, NU>::zeros();
            e[k] = 1.0;
            let column = solve_kkt(
                m,
                j,
                &actuation::<L, f64, NQ, NC, NU>(&e),
                &SVector::zeros(),
                L::REDUNDANT_ROWS,
            )
            .unwrap()
            .qdd;
            let e_u = (d.qdd_u.column(k) - column).amax();
            assert!(
                e_u < 1e-10 * column.amax().max(1e-300),
                "{name} #{trial}: ∂q̈/∂u{k} off the dense solve by {e_u:e}"
            );
        }
    }
}

macro_rules! spatial_leg_tests {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
        mod $module {

            #[test]
            fn terms_against_finite_differences_and_the_kkt_rows() {
                super::check_leg::<$ty, $nq, $nc, $nu, $np>();
            }

            #[test]
            fn passive_swing_keeps_its_energy() {
                super::energy_kept::<$ty, $nq, $nc, $nu, $np>();
            }

            #[test]
            fn kkt_solve_meets_its_definition() {
                super::kkt_solve_meets_its_definition::<$ty, $nq, $nc, $nu, $np>();
            }

            #[test]
            fn the_runtime_leg_takes_it() {
                super::leg_wrapper::<$ty, $nq, $nc, $nu, $np>();
            }
        }
    };
}

generated::for_each_spatial_model!(spatial_leg_tests);
// A floating robot's terms in its body's chart are a spatial model's: the same checks
// (the free joint's six coordinates among the others).
generated::for_each_floating_model!(spatial_leg_tests);

/// The tree factorization is in use: at least one floating robot (a body carrying legs)
/// has its mass matrix factored along the tree, so `kkt_solve_meets_its_definition` checks
/// that path and not only the dense one.
#[test]
fn a_robot_factors_its_mass_matrix_along_the_tree() {
    let mut along = Vec::new();
    macro_rules! tree {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            if leg_models::dynamics::structure::factors_along_the_tree(
                &<$ty as LegDynamics<$nq, $nc, $nu>>::PARENTS,
            ) {
                along.push(stringify!($module));
            }
        };
    }
    generated::for_each_floating_model!(tree);
    assert!(
        !along.is_empty(),
        "no floating robot factors along the tree"
    );
    eprintln!("factored along the tree: {along:?}");
}

/// The ball-joint singularity on every spatial leg that has one; at least one does, so the
/// check cannot pass by finding none.
#[test]
fn ball_joints_refuse_their_singularity() {
    let mut balls = 0;
    macro_rules! each {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            balls += ball_joint_singularity::<$ty, $nq, $nc, $nu, $np>();
        };
    }
    generated::for_each_spatial_model!(each);
    assert!(balls >= 1, "no spatial leg has a ball joint");
}

#[test]
fn there_is_a_spatial_leg() {
    let mut n = 0;
    macro_rules! count {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            n += 1;
        };
    }
    generated::for_each_spatial_model!(count);
    assert!(n >= 1);
}

/// The ball joint's convention, against rotation matrices written here: the RSSR's
/// coupler tip is the crank's tip plus `R_x(θ) R_x(α) R_y(β) R_z(γ) (0.25, 0, 0)`, and the
/// rocker's tip its pivot plus `R_z(ψ) (0, 0.08, 0)` (the spec's lengths).
#[test]
fn ball_joint_angles_are_x_then_y_then_z() {
    use generated::rssr_linkage::RssrLinkage;
    use leg_models::nalgebra::{Matrix3, Vector3};
    let rot = |axis: usize, a: f64| {
        let (s, c) = a.sin_cos();
        let mut r = Matrix3::identity();
        let (i, j) = [(1, 2), (2, 0), (0, 1)][axis];
        r[(i, i)] = c;
        r[(j, j)] = c;
        r[(i, j)] = -s;
        r[(j, i)] = s;
        r
    };
    assert_eq!(
        RssrLinkage::JOINT_NAMES,
        ["crank", "coupler.x", "coupler.y", "coupler.z", "rocker"]
    );
    assert_eq!(RssrLinkage::BALL_JOINTS, &[1]);
    let p = <RssrLinkage as LegDynamics<5, 3, 1>>::Params::<f64>::default();
    let mut rng = Rng::new(7);
    for _ in 0..5 {
        let q = SVector::<f64, 5>::from_fn(|_, _| rng.range(-1.2, 1.2));
        let crank = rot(0, q[0]);
        let tip = crank * Vector3::new(0.0, 0.05, 0.0)
            + crank * rot(0, q[1]) * rot(1, q[2]) * rot(2, q[3]) * Vector3::new(0.25, 0.0, 0.0);
        let rocker = Vector3::new(0.25, 0.0, -0.06) + rot(2, q[4]) * Vector3::new(0.0, 0.08, 0.0);
        let points = RssrLinkage::closure_points(&q, &p);
        assert!((points.column(0) - tip).amax() < 1e-15, "{points} vs {tip}");
        assert!((points.column(1) - rocker).amax() < 1e-15);
    }
}
