//! Contact, impacts and hybrid simulation (DESIGN.md §3.1), on every leg with contacts:
//! the structured solve against a dense solve of the whole KKT system, the impact map's
//! identities, and drops whose events and energies are checked against free fall and
//! energy conservation.

use leg_models::dynamics::contact::{
    forward_dynamics_with_contacts, impact_map, spec_friction, ContactMode, Ground, ImpactError,
    Modes,
};
use leg_models::nalgebra::{DMatrix, DVector, SMatrix, SVector};
use leg_models::simulate::hybrid::{EventKind, HybridError, HybridSimulator, HybridState};
use leg_models::simulate::State;
use leg_models::{ContactModel, LegDynamics, Parameters};
use leg_tests::{not_applicable, Rng};

const STATES: usize = 100;

fn random_state<const NQ: usize>(rng: &mut Rng) -> (SVector<f64, NQ>, SVector<f64, NQ>) {
    let q = SVector::from_fn(|_, _| rng.range(-1.5, 1.5));
    let qd = SVector::from_fn(|_, _| rng.range(-2.0, 2.0));
    (q, qd)
}

/// Random modes: each contact in flight, sticking or sliding either way.
fn random_modes<const NK: usize>(rng: &mut Rng) -> Modes<NK> {
    let mut m = Modes::<NK>::flight();
    for k in 0..NK / 2 {
        let mode = match (rng.range(0.0, 4.0)) as usize {
            0 => ContactMode::Flight,
            1 => ContactMode::Stick,
            2 => ContactMode::Slide { forward: true },
            _ => ContactMode::Slide { forward: false },
        };
        m.set(k, mode);
    }
    m
}

/// The whole system as one dense matrix, solved by LU: unknowns `(x, F, λ over the held
/// rows)`, with the sliding contacts' friction written into the force columns.
#[allow(clippy::too_many_arguments)]
fn dense_solve<const NQ: usize, const NC: usize, const NK: usize>(
    m: &SMatrix<f64, NQ, NQ>,
    j: &SMatrix<f64, NC, NQ>,
    r_j: &SVector<f64, NC>,
    jc: &SMatrix<f64, NK, NQ>,
    r_c_base: &SVector<f64, NK>,
    ground: &Ground<f64>,
    modes: &Modes<NK>,
    mu: &SVector<f64, NK>,
    tau: &SVector<f64, NQ>,
) -> Option<(DVector<f64>, Vec<usize>)> {
    let (t, n) = (ground.tangent(), ground.normal);
    // Ground rows written out directly from J_c: t·J_c and n·J_c of each contact.
    let row = |k: usize, dir: &SVector<f64, 2>| -> DVector<f64> {
        DVector::from_fn(NQ, |c, _| {
            dir[0] * jc[(2 * k, c)] + dir[1] * jc[(2 * k + 1, c)]
        })
    };
    let rhs_row =
        |k: usize, dir: &SVector<f64, 2>| dir[0] * r_c_base[2 * k] + dir[1] * r_c_base[2 * k + 1];
    let mut cons: Vec<(DVector<f64>, DVector<f64>, f64)> = Vec::new(); // (C row, W row, rhs)
    let mut held = Vec::new();
    for k in 0..NK / 2 {
        match modes.get(k) {
            ContactMode::Flight => {}
            ContactMode::Stick => {
                cons.push((row(k, &t), row(k, &t), rhs_row(k, &t)));
                cons.push((row(k, &n), row(k, &n), rhs_row(k, &n)));
                held.extend([2 * k, 2 * k + 1]);
            }
            ContactMode::Slide { forward } => {
                let s = if forward { 1.0 } else { -1.0 };
                let w = row(k, &n) - row(k, &t) * (mu[2 * k] * s);
                cons.push((row(k, &n), w, rhs_row(k, &n)));
                held.push(2 * k + 1);
            }
        }
    }
    let size = NQ + NC + cons.len();
    let mut a = DMatrix::<f64>::zeros(size, size);
    let mut b = DVector::<f64>::zeros(size);
    for r in 0..NQ {
        for c in 0..NQ {
            a[(r, c)] = m[(r, c)];
        }
        b[r] = tau[r];
    }
    for i in 0..NC {
        for c in 0..NQ {
            a[(NQ + i, c)] = j[(i, c)];
            a[(c, NQ + i)] = -j[(i, c)];
        }
        b[NQ + i] = r_j[i];
    }
    for (i, (crow, wrow, rhs)) in cons.iter().enumerate() {
        for c in 0..NQ {
            a[(NQ + NC + i, c)] = crow[c];
            a[(c, NQ + NC + i)] = -wrow[c];
        }
        b[NQ + NC + i] = *rhs;
    }
    a.lu().solve(&b).map(|x| (x, held))
}

fn check_against_dense<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    if NK == 0 {
        not_applicable(
            L::NAME,
            "contact dynamics",
            &"the leg has no contact points",
        );
        return;
    }
    let p = L::Params::<f64>::default();
    let ground = Ground::of::<L, NQ, NC, NU, NK>();
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, 2>();
    let mut rng = Rng::new(21);
    let mut compared = 0;
    for _ in 0..STATES {
        let (q, qd) = random_state::<NQ>(&mut rng);
        let u = SVector::<f64, NU>::from_fn(|_, _| rng.range(-3.0, 3.0));
        let modes = random_modes::<NK>(&mut rng);
        let ours = forward_dynamics_with_contacts::<L, f64, NQ, NC, NU, NK, 2>(
            &p,
            &q,
            &qd,
            &u,
            &modes,
            &SVector::zeros(),
            &ground,
            &mu,
            None,
        );
        let terms = L::dynamics_terms(&q, &qd, &p);
        let mut tau = terms.bias_forces * -1.0 - L::damping_forces(&qd, &p);
        for (k, &a) in L::ACTUATED.iter().enumerate() {
            tau[a] += u[k];
        }
        let dense = dense_solve(
            &terms.mass_matrix,
            &terms.constraint_jacobian,
            &-terms.constraint_bias,
            &L::contact_jacobian(&q, &p),
            &-L::contact_bias(&q, &qd, &p),
            &ground,
            &modes,
            &mu,
            &tau,
        );
        let (Ok(ours), Some((x, held))) = (ours, dense) else {
            continue; // singular here (both formulations are free to refuse)
        };
        let scale = 1.0 + x.amax();
        for r in 0..NQ {
            assert!(
                (ours.x[r] - x[r]).abs() < 1e-8 * scale,
                "{}: q̈[{r}] {} vs dense {} ({:?})",
                L::NAME,
                ours.x[r],
                x[r],
                modes
            );
        }
        for (i, &r) in held.iter().enumerate() {
            let dense_force = x[NQ + NC + i];
            assert!(
                (ours.contact[r] - dense_force).abs() < 1e-8 * scale,
                "{}: contact force row {r}: {} vs dense {dense_force}",
                L::NAME,
                ours.contact[r]
            );
        }
        // Friction of a sliding contact: λ_t = −μ s λ_n, opposing the slip.
        for k in 0..NK / 2 {
            if let ContactMode::Slide { forward } = modes.get(k) {
                let s = if forward { 1.0 } else { -1.0 };
                let (lt, ln) = (ours.contact[2 * k], ours.contact[2 * k + 1]);
                assert!((lt + mu[2 * k] * s * ln).abs() < 1e-12 * (1.0 + ln.abs()));
            }
            if modes.get(k) == ContactMode::Flight {
                assert_eq!((ours.contact[2 * k], ours.contact[2 * k + 1]), (0.0, 0.0));
            }
        }
        compared += 1;
    }
    assert!(
        compared > STATES / 2,
        "{}: only {compared} states compared",
        L::NAME
    );
}

fn check_impact_identities<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    if NK == 0 {
        not_applicable(L::NAME, "impact map", &"the leg has no contact points");
        return;
    }
    let p = L::Params::<f64>::default();
    let ground = Ground::of::<L, NQ, NC, NU, NK>();
    let mut rng = Rng::new(22);
    let (mut sticking, mut sliding, mut pulling) = (0, 0, 0);
    let mut worst_identity: f64 = 0.0;
    for i in 0..STATES {
        let (q, mut qd) = random_state::<NQ>(&mut rng);
        // Every contact held; half the cases with friction high enough to stick.
        let mut modes = Modes::<NK>::flight();
        for k in 0..NK / 2 {
            modes.set(k, ContactMode::Stick);
        }
        let mu = SVector::<f64, NK>::from_element(if i % 2 == 0 { 1e6 } else { 0.3 });
        // Drive the contacts into the ground so that the impulses push.
        let c = ground.rows(&L::contact_jacobian(&q, &p));
        for k in 0..NK / 2 {
            qd -= c.row(2 * k + 1).transpose() * rng.range(0.5, 2.0);
        }
        // A contact that would pull leaves the impact (as the simulator's touchdown does).
        let mut outcome = None;
        for _ in 0..=NK / 2 {
            let mut trial = modes;
            match impact_map::<L, f64, NQ, NC, NU, NK, 2>(&p, &q, &qd, &mut trial, &ground, &mu) {
                Ok(imp) => {
                    outcome = Some((modes, trial, imp));
                    break;
                }
                Err(ImpactError::Pulling { contact, .. }) => {
                    pulling += 1;
                    modes.set(contact, ContactMode::Flight);
                }
                Err(e) => panic!("{}: impact failed: {e}", L::NAME),
            }
        }
        let Some((before, after, imp)) = outcome else {
            continue;
        };
        let modes = after;
        let m = L::mass_matrix(&q, &p);
        let j = L::constraint_jacobian(&q, &p);
        let scale = 1.0 + qd.amax();
        assert!(
            (j * imp.qd_plus).amax() < 1e-10 * scale,
            "{}: J q̇⁺ = 0",
            L::NAME
        );
        let cv = c * imp.qd_plus;
        for k in 0..NK / 2 {
            if modes.get(k) == ContactMode::Flight {
                assert_eq!(imp.impulses[2 * k + 1], 0.0);
                continue;
            }
            assert!(
                cv[2 * k + 1].abs() < 1e-10 * scale,
                "{}: normal velocity after impact",
                L::NAME
            );
            assert!(imp.impulses[2 * k + 1] >= 0.0, "{}: Λ_n ≥ 0", L::NAME);
            let (lt, ln) = (imp.impulses[2 * k], imp.impulses[2 * k + 1]);
            assert!(
                lt.abs() <= mu[2 * k] * ln * (1.0 + 1e-12) + 1e-12,
                "{}: in the cone",
                L::NAME
            );
            if modes.get(k) == ContactMode::Stick {
                assert!(cv[2 * k].abs() < 1e-10 * scale, "{}: J_c q̇⁺ = 0", L::NAME);
            }
        }
        // Momentum balance M (q̇⁺ − q̇⁻) = Jᵀ Λ + Σ (t Λ_t + n Λ_n)·J_c, checked from the
        // impulses the map reports.
        let jc = L::contact_jacobian(&q, &p);
        let mut base_impulse = SVector::<f64, NK>::zeros();
        let (t, n) = (ground.tangent(), ground.normal);
        for k in 0..NK / 2 {
            let (lt, ln) = (imp.impulses[2 * k], imp.impulses[2 * k + 1]);
            base_impulse[2 * k] = t[0] * lt + n[0] * ln;
            base_impulse[2 * k + 1] = t[1] * lt + n[1] * ln;
        }
        let dq = imp.qd_plus - qd;
        let balance = m * dq - j.transpose() * imp.closure_impulses - jc.transpose() * base_impulse;
        assert!(
            balance.amax() < 1e-9 * (1.0 + (m * qd).amax()),
            "{}: momentum balance {balance}",
            L::NAME
        );
        let held_any = (0..NK / 2).any(|k| modes.get(k).on_ground());
        if !held_any {
            continue; // every contact left the impact: nothing happened
        }
        if modes == before {
            // A plastic sticking impact loses exactly ½ Δq̇ᵀ M Δq̇.
            let expected = 0.5 * dq.dot(&(m * dq));
            worst_identity = worst_identity.max((imp.energy_lost - expected).abs() / expected);
            assert!(
                (imp.energy_lost - expected).abs() <= 1e-12 * expected.max(1e-300),
                "{}: energy lost {} vs ½ΔᵀMΔ {expected}",
                L::NAME,
                imp.energy_lost
            );
            sticking += 1;
        } else {
            // Sliding: the slip after runs against the friction impulse; and unless the
            // impulse reversed the slip, energy is lost.
            let mut reversed = false;
            let cv_before = c * qd;
            for k in 0..NK / 2 {
                if let ContactMode::Slide { forward } = modes.get(k) {
                    let s = if forward { 1.0 } else { -1.0 };
                    assert!(
                        cv[2 * k] * s >= -1e-10 * scale,
                        "{}: slip direction",
                        L::NAME
                    );
                    assert!(
                        imp.impulses[2 * k] * s <= 1e-12,
                        "{}: friction opposes slip",
                        L::NAME
                    );
                    reversed |= cv_before[2 * k] * s < 0.0;
                }
            }
            if !reversed {
                assert!(
                    imp.energy_lost >= -1e-12,
                    "{}: a sliding impact loses energy",
                    L::NAME
                );
            }
            sliding += 1;
        }
    }
    eprintln!(
        "{}: {sticking} sticking impacts (energy identity off by at most {worst_identity:.1e} relative), {sliding} sliding, {pulling} contacts left the impact",
        L::NAME
    );
    assert!(
        sticking > 10,
        "{}: {sticking} sticking impacts, {sliding} sliding, {pulling} pulling",
        L::NAME
    );
    assert!(sliding > 0, "{}: {sliding} sliding impacts", L::NAME);
}

macro_rules! contact_tests {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        mod $module {
            #[test]
            fn structured_solve_matches_a_dense_kkt_solve() {
                super::check_against_dense::<$ty, $nq, $nc, $nu, $nk>();
            }
            #[test]
            fn impact_map_meets_its_identities() {
                super::check_impact_identities::<$ty, $nq, $nc, $nu, $nk>();
            }
        }
    };
}

generated::for_each_model!(contact_tests);

fn param<P: Parameters<f64>>(p: &P, name: &str) -> f64 {
    let i = P::NAMES.iter().position(|n| *n == name).unwrap();
    p.get(i).unwrap()
}

/// Minitaur's leg on its rail, released at rest above the ground with the motors off:
/// in uniform gravity the whole leg falls rigidly (the rail pushes sideways only), so the
/// toe touches down at `t = √(2 h / g)` exactly; the impact takes the energy the map
/// reports, and in between energy is kept.
#[test]
fn minitaur_hopper_drop_touches_down_at_the_free_fall_time() {
    use generated::minitaur_hopper::{Params, NC, NK, NQ, NU};
    use generated::MinitaurHopper as L;
    let p = Params::<f64>::default();
    let sim = HybridSimulator::<L, f64, NQ, NC, NU, NK>::new(p, 1e-3);
    let mut q = SVector::<f64, NQ>::from(L::HOME);
    leg_models::assembly::project_position::<L, f64, NQ, NC, NU>(&p, &mut q, &Default::default())
        .unwrap();
    let drop = 0.1;
    q[0] += drop;
    let start = sim
        .start(
            State {
                q,
                qd: SVector::zeros(),
            },
            &SVector::zeros(),
        )
        .unwrap();
    assert_eq!(start.modes.get(0), ContactMode::Flight);
    let h = L::contact_positions(&q, &p)[1];
    let g = -param(&p, "gravity_y");
    let expected = (2.0 * h / g).sqrt();
    let steps = ((expected + 0.01) / 1e-3) as usize;
    let mut zero = |_: f64, _: &HybridState<f64, NQ, NK>| SVector::<f64, NU>::zeros();
    let record = sim.run(start, steps, &mut zero).unwrap();
    let touchdown = record
        .events
        .iter()
        .find(|e| e.kind == EventKind::Touchdown)
        .expect("the toe lands");
    let error = (touchdown.t - expected).abs();
    eprintln!(
        "touchdown at {} s, free fall {expected} s: error {error:.2e} s",
        touchdown.t
    );
    assert!(
        error < 1e-9,
        "touchdown at {} s, free fall says {expected} s (error {error:.2e})",
        touchdown.t
    );
    // Energy: kept in flight, less the impact's loss at touchdown.
    let e0 = record.samples[0].energy;
    let before: Vec<_> = record
        .samples
        .iter()
        .filter(|s| s.t < touchdown.t)
        .collect();
    for s in &before {
        assert!(
            (s.energy - e0).abs() < 1e-6 * e0.abs().max(1.0),
            "flight energy drifts"
        );
    }
    assert!(touchdown.energy_lost > 0.0 && touchdown.impulse[1] > 0.0);
}

/// Issue 29, class 10: a start 0.1 m into the ground began the record 0.1 m higher, with
/// no event and no error. It is refused, naming the contact and the depth; a toe on the
/// ground (to rounding) starts in stance where it is.
#[test]
fn a_start_under_the_ground_is_refused() {
    use generated::minitaur_hopper::{Params, NC, NK, NQ, NU};
    use generated::MinitaurHopper as L;
    let p = Params::<f64>::default();
    let sim = HybridSimulator::<L, f64, NQ, NC, NU, NK>::new(p, 1e-3);
    let mut home = SVector::<f64, NQ>::from(L::HOME);
    leg_models::assembly::project_position::<L, f64, NQ, NC, NU>(
        &p,
        &mut home,
        &Default::default(),
    )
    .unwrap();
    let toe = L::contact_positions(&home, &p)[1];
    let at = |shift: f64| {
        let mut q = home;
        q[0] += shift - toe; // the rail's height: the toe at `shift` above the ground
        State {
            q,
            qd: SVector::zeros(),
        }
    };
    for depth in [0.1, 1e-3, 1e-6] {
        match sim.start(at(-depth), &SVector::zeros()) {
            Err(e @ HybridError::StartsUnderGround { contact, depth: d }) => {
                assert_eq!(contact, "toe_contact");
                assert!((d - depth).abs() < 1e-12, "{d} for {depth}");
                assert!(e.to_string().contains("under the ground"), "{e}");
            }
            other => panic!("{depth} m under: {other:?}"),
        }
    }
    let on = at(0.0);
    let start = sim.start(on, &SVector::zeros()).unwrap();
    assert_eq!(start.modes.get(0), ContactMode::Stick);
    assert!(
        (start.state.q - on.q).amax() < 1e-9,
        "moved: {}",
        start.state.q - on.q
    );
}

/// A conservative motor law `u = −k_p (θ − θ₀)` (a spring on each motor, no damping):
/// its potential `½ k_p |θ − θ₀|²` joins `T + V`, so energy is kept between events.
#[allow(clippy::type_complexity)]
fn motor_spring<const NQ: usize, const NU: usize, const NK: usize>(
    actuated: [usize; NU],
    theta0: SVector<f64, NU>,
    kp: f64,
) -> (
    impl FnMut(f64, &HybridState<f64, NQ, NK>) -> SVector<f64, NU>,
    impl Fn(&State<f64, NQ>) -> f64,
) {
    let law = move |_: f64, s: &HybridState<f64, NQ, NK>| {
        SVector::<f64, NU>::from_fn(|k, _| -kp * (s.state.q[actuated[k]] - theta0[k]))
    };
    let potential = move |s: &State<f64, NQ>| {
        (0..NU)
            .map(|k| 0.5 * kp * (s.q[actuated[k]] - theta0[k]).powi(2))
            .sum::<f64>()
    };
    (law, potential)
}

/// Drops a leg from `lift` above its home pose with motor springs and checks the record:
/// energy (with the motors' potential) kept between events to 1e-6, each touchdown's loss
/// equal to the energy's jump, residuals at every sample within `1e-12 m`.
fn drop_test<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    lift: usize,
    height: f64,
    seconds: f64,
    kp: f64,
) -> leg_models::simulate::hybrid::HybridRecord<f64, NQ, NC, NU, NK>
where
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
{
    // Without damping, so that energy is kept between events.
    let mut p = L::Params::<f64>::default();
    for (i, name) in <L::Params<f64> as Parameters<f64>>::NAMES
        .iter()
        .enumerate()
    {
        if name.ends_with("_damping") {
            p.set(i, 0.0);
        }
    }
    let mut sim = HybridSimulator::<L, f64, NQ, NC, NU, NK>::new(p, 1e-3);
    // The motor springs act continuously, so that they keep energy.
    sim.options.control = leg_models::simulate::ControlUpdate::PerStage;
    let mut q = SVector::<f64, NQ>::from(L::HOME);
    leg_models::assembly::project_position::<L, f64, NQ, NC, NU>(&p, &mut q, &Default::default())
        .unwrap();
    q[lift] += height;
    let theta0 = SVector::<f64, NU>::from_fn(|k, _| q[L::ACTUATED[k]]);
    let (mut law, potential) = motor_spring::<NQ, NU, NK>(L::ACTUATED, theta0, kp);
    let start = sim
        .start(
            State {
                q,
                qd: SVector::zeros(),
            },
            &SVector::zeros(),
        )
        .unwrap();
    let steps = (seconds / 1e-3) as usize;
    let record = match sim.run(start, steps, &mut law) {
        Ok(r) => r,
        Err(stopped) => panic!("{}: {stopped}; events {:?}", L::NAME, stopped.record.events),
    };
    let total = |s: &leg_models::simulate::hybrid::HybridSample<f64, NQ, NC, NU, NK>| {
        s.energy + potential(&s.state.state)
    };
    let scale = record
        .samples
        .iter()
        .map(|s| total(s).abs())
        .fold(1.0, f64::max);
    for pair in record.samples.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        let between: Vec<_> = record
            .events
            .iter()
            .filter(|e| e.t > a.t && e.t <= b.t)
            .collect();
        let lost: f64 = between.iter().map(|e| e.energy_lost).sum();
        let sliding = [a, b].iter().any(|s| {
            (0..NK / 2).any(|k| matches!(s.state.modes.get(k), ContactMode::Slide { .. }))
        });
        if !sliding {
            let drift = (total(b) + lost - total(a)).abs();
            assert!(
                drift < 1e-6 * scale,
                "{}: energy at t = {}: drift {drift:.3e} (events {between:?})",
                L::NAME,
                b.t
            );
        }
        assert!(
            b.closure_residual <= 1e-12,
            "{}: closure residual {}",
            L::NAME,
            b.closure_residual
        );
        assert!(
            b.contact_residual <= 1e-12,
            "{}: contact residual {}",
            L::NAME,
            b.contact_residual
        );
    }
    record
}

#[test]
fn minitaur_hopper_lands_and_stands_on_motor_springs() {
    use generated::minitaur_hopper::{NC, NK, NQ, NU};
    let record = drop_test::<generated::MinitaurHopper, NQ, NC, NU, NK>(0, 0.05, 1.0, 20.0);

    assert!(record.events.iter().any(|e| e.kind == EventKind::Touchdown));
}

#[test]
fn raibert_hopper_lands_on_a_slope() {
    use generated::raibert_hopper::{NC, NK, NQ, NU};
    let record = drop_test::<generated::RaibertHopper, NQ, NC, NU, NK>(1, 0.0, 1.0, 200.0);
    assert!(record.events.iter().any(|e| e.kind == EventKind::Touchdown));
}

/// Stance against an independent formulation: `minitaur_hopper` with its toe sticking
/// (contact rows) and `minitaur_pinned_toe`, the same leg with the toe closed to the base
/// (closure rows, other generated code), give the same accelerations, and the ground
/// force equals the pin's closure force, at assembled states under random torques.
#[test]
fn sticking_stance_equals_the_toe_pinned_by_a_closure() {
    use generated::{MinitaurHopper as H, MinitaurPinnedToe as P};
    let (ph, pp) = (
        generated::minitaur_hopper::Params::<f64>::default(),
        generated::minitaur_pinned_toe::Params::<f64>::default(),
    );
    let ground = Ground::of::<H, 5, 2, 2, 2>();
    let mu = spec_friction::<H, f64, 5, 2, 2, 2, 2>();
    let mut rng = Rng::new(23);
    let mut compared = 0;
    for _ in 0..STATES {
        let mut q = SVector::<f64, 5>::from(P::HOME);
        for k in 0..5 {
            q[k] += rng.range(-0.05, 0.05);
        }
        let tol = Default::default();
        if leg_models::assembly::project_position::<P, f64, 5, 4, 2>(&pp, &mut q, &tol).is_err() {
            continue;
        }
        let mut qd = SVector::<f64, 5>::from_fn(|_, _| rng.range(-1.0, 1.0));
        leg_models::assembly::project_velocity::<P, f64, 5, 4, 2>(&pp, &q, &mut qd).unwrap();
        let u = SVector::<f64, 2>::from_fn(|_, _| rng.range(-2.0, 2.0));
        let pinned =
            leg_models::dynamics::forward_dynamics::<P, f64, 5, 4, 2>(&pp, &q, &qd, &u, None)
                .unwrap();
        let mut modes = Modes::<2>::flight();
        modes.set(0, ContactMode::Stick);
        let anchors = ground.coordinates(&H::contact_positions(&q, &ph));
        assert!(anchors[1].abs() < 1e-12, "the pinned toe is on the ground");
        let stance = forward_dynamics_with_contacts::<H, f64, 5, 2, 2, 2, 2>(
            &ph, &q, &qd, &u, &modes, &anchors, &ground, &mu, None,
        )
        .unwrap();
        let scale = 1.0 + pinned.qdd.amax();
        assert!(
            (stance.x - pinned.qdd).amax() < 1e-9 * scale,
            "q̈ {} vs {}",
            stance.x,
            pinned.qdd
        );
        // Closure rows of the pinned leg: [toe (five-bar), ground_pin]; +F acts on the toe.
        let pin = SVector::<f64, 2>::new(pinned.forces[2], pinned.forces[3]);
        let force_scale = 1.0 + pin.amax();
        assert!(
            (stance.contact[0] - pin[0]).abs() < 1e-9 * force_scale,
            "λ_t {} vs {}",
            stance.contact[0],
            pin[0]
        );
        assert!(
            (stance.contact[1] - pin[1]).abs() < 1e-9 * force_scale,
            "λ_n {} vs {}",
            stance.contact[1],
            pin[1]
        );
        assert!((stance.closure[0] - pinned.forces[0]).abs() < 1e-9 * force_scale);
        compared += 1;
    }
    assert!(compared > STATES / 2, "{compared} states compared");
}

/// Lemke's method against enumeration: on random LCPs whose `M` is a P-matrix (a
/// positive definite symmetric part plus a skew part), which have exactly one solution,
/// every one of the `2ⁿ` complementary bases is tried by a dense LU and the one
/// feasible basis's solution must be Lemke's, to 1e-10; and Lemke's `w`, `z` satisfy
/// the conditions themselves.
#[test]
fn lemke_meets_enumeration_on_p_matrix_problems() {
    use leg_models::dynamics::lcp::Lemke;
    let mut rng = Rng::new(31);
    let mut pivots = 0;
    let mut problems = 0;
    for n in 1..=7usize {
        let mut lemke = Lemke::<f64>::new(n);
        for _ in 0..60 {
            let a = DMatrix::<f64>::from_fn(n, n, |_, _| rng.range(-1.0, 1.0));
            let skew = DMatrix::<f64>::from_fn(n, n, |_, _| rng.range(-1.0, 1.0));
            let m = a.transpose() * &a
                + DMatrix::<f64>::identity(n, n) * 0.05
                + (&skew - skew.transpose());
            let q = DVector::<f64>::from_fn(n, |_, _| rng.range(-1.0, 1.0));
            let flat: Vec<f64> = (0..n * n).map(|k| m[(k / n, k % n)]).collect();
            lemke.solve(&flat, q.as_slice()).unwrap();
            pivots += lemke.pivots;
            problems += 1;
            let z = DVector::from_column_slice(lemke.z());
            let w = DVector::from_column_slice(lemke.w());
            let mut found = Vec::new();
            for set in 0..(1usize << n) {
                let basic: Vec<usize> = (0..n).filter(|i| set >> i & 1 == 1).collect();
                let k = basic.len();
                let mut zb = DVector::<f64>::zeros(n);
                if k > 0 {
                    let mbb = DMatrix::from_fn(k, k, |r, c| m[(basic[r], basic[c])]);
                    let qb = DVector::from_fn(k, |r, _| -q[basic[r]]);
                    let Some(sol) = mbb.lu().solve(&qb) else {
                        continue;
                    };
                    for (r, &i) in basic.iter().enumerate() {
                        zb[i] = sol[r];
                    }
                }
                let wb = &m * &zb + &q;
                let feasible = (0..n).all(|i| {
                    if set >> i & 1 == 1 {
                        zb[i] >= -1e-12
                    } else {
                        wb[i] >= -1e-12
                    }
                });
                if feasible {
                    found.push(zb);
                }
            }
            assert!(!found.is_empty(), "n = {n}: no basis is feasible");
            for zb in &found {
                assert!(
                    (zb - &z).amax() < 1e-10,
                    "n = {n}: Lemke's z {z} is not the enumerated {zb}"
                );
            }
            assert!((&w - (&m * &z + &q)).amax() < 1e-12);
            for i in 0..n {
                assert!(z[i] >= 0.0 && w[i] >= -1e-12 && z[i] * w[i] == 0.0);
            }
        }
    }
    eprintln!(
        "Lemke on {problems} P-matrix problems of sizes 1..7: {:.2} pivots each on average, every one the enumerated solution",
        pivots as f64 / problems as f64
    );
}

/// Degenerate problems of the kind contact gives (a positive semidefinite `M` of
/// repeated rows, as a rigid foot's toe and heel make, and `q` with zeros, as resting
/// contacts make): Lemke's solution satisfies the conditions, complementarity exactly.
#[test]
fn lemke_solves_degenerate_problems() {
    use leg_models::dynamics::lcp::Lemke;
    let mut rng = Rng::new(7);
    for n in [2usize, 4, 6, 9] {
        let mut lemke = Lemke::<f64>::new(n);
        for _ in 0..100 {
            // Rank about half: rows repeated.
            let half = DMatrix::<f64>::from_fn(n.div_ceil(2), n, |_, _| rng.range(-1.0, 1.0));
            let a = DMatrix::from_fn(n, n, |r, c| half[(r % half.nrows(), c)]);
            let m = a.transpose() * &a;
            // q in M's range plus a non-negative part, some entries zero: the problem then
            // has a solution (q = M z₀ + s with z₀, s ≥ 0).
            let z0 = DVector::<f64>::from_fn(n, |_, _| rng.range(0.0, 1.0).max(0.5) - 0.5);
            let s = DVector::<f64>::from_fn(n, |_, _| rng.range(0.0, 1.0).max(0.5) - 0.5);
            let q = -(&m * &z0) + s;
            let flat: Vec<f64> = (0..n * n).map(|k| m[(k / n, k % n)]).collect();
            lemke
                .solve(&flat, q.as_slice())
                .unwrap_or_else(|e| panic!("n = {n}: {e}"));
            let (z, w) = (lemke.z(), lemke.w());
            let scale = 1.0 + m.amax() + q.amax();
            for i in 0..n {
                assert!(z[i] >= 0.0, "n = {n}: z[{i}] = {}", z[i]);
                assert!(w[i] >= -1e-10 * scale, "n = {n}: w[{i}] = {}", w[i]);
                assert!(z[i] * w[i] == 0.0, "n = {n}: z w at {i}");
            }
            let residual =
                (DVector::from_column_slice(w) - (&m * DVector::from_column_slice(z) + &q)).amax();
            assert!(
                residual < 1e-12 * scale,
                "n = {n}: w off M z + q by {residual}"
            );
        }
    }
}

/// Warm starts: a problem solved again takes no pivot and gives the same solution; one
/// whose last basis is infeasible for it is solved by pivoting, and still matches
/// enumeration (`lemke_meets_enumeration_on_p_matrix_problems` runs with warm starts on,
/// each problem after another's basis); with warm starts off, every solve pivots.
#[test]
fn lemke_warm_starts_from_its_last_basis() {
    use leg_models::dynamics::lcp::Lemke;
    let mut lemke = Lemke::<f64>::new(3);
    // A P-matrix, and q with one negative entry.
    let m = [2.0, 1.0, 0.0, -1.0, 3.0, 1.0, 0.5, 0.0, 4.0];
    let q = [-1.0, 2.0, -3.0];
    lemke.solve(&m, &q).unwrap();
    let (first, pivots) = (lemke.z().to_vec(), lemke.pivots);
    assert!(pivots > 0 && !lemke.warm);
    lemke.solve(&m, &q).unwrap();
    assert!(lemke.warm && lemke.pivots == 0);
    assert_eq!(lemke.z(), first.as_slice());
    // Another q: the last basis (z₀, z₂ basic) gives z₀ < 0 there, so it pivots.
    let other = [1.0, -2.0, 3.0];
    lemke.solve(&m, &other).unwrap();
    assert!(!lemke.warm && lemke.pivots > 0);
    let (z, w) = (lemke.z(), lemke.w());
    for i in 0..3 {
        let wi = other[i] + (0..3).map(|j| m[3 * i + j] * z[j]).sum::<f64>();
        assert!((wi - w[i]).abs() < 1e-14 && w[i] >= 0.0 && z[i] >= 0.0 && w[i] * z[i] == 0.0);
    }
    lemke.warm_start = false;
    lemke.solve(&m, &other).unwrap();
    assert!(!lemke.warm && lemke.pivots > 0);
}

/// Bad input is refused by name: the wrong size, a NaN, and a problem with no solution
/// (`w = −z − 1` can never be non-negative), which Lemke's path ends on a ray.
#[test]
fn lemke_refuses_bad_input() {
    use leg_models::dynamics::lcp::{LcpError, Lemke};
    let mut lemke = Lemke::<f64>::new(2);
    assert_eq!(
        lemke.solve(&[1.0, 0.0, 0.0], &[1.0, 1.0]),
        Err(LcpError::Size {
            expected: 2,
            got: 3
        })
    );
    assert_eq!(
        lemke.solve(&[1.0, 0.0, 0.0, 1.0], &[1.0]),
        Err(LcpError::Size {
            expected: 2,
            got: 1
        })
    );
    assert_eq!(
        lemke.solve(&[1.0, 0.0, 0.0, f64::NAN], &[1.0, -1.0]),
        Err(LcpError::NonFinite)
    );
    let mut one = Lemke::<f64>::new(1);
    assert!(matches!(
        one.solve(&[-1.0], &[-1.0]),
        Err(LcpError::Ray { .. })
    ));
    // q ≥ 0: z = 0 without a pivot.
    one.solve(&[-1.0], &[2.0]).unwrap();
    assert_eq!((one.z()[0], one.w()[0], one.pivots), (0.0, 2.0, 0));
    let text = LcpError::Ray { pivots: 3 }.to_string();
    assert!(text.contains("ray") && text.contains('3'), "{text}");
}
