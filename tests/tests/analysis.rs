//! Design measures (`leg_models::analysis`) against something independent: the five-bar's
//! analytic workspace, statics through the KKT solve with the foot pinned, impulses
//! through the impact solve, the assembly's own singularity test, and a floating body
//! written as a spec. Every leg runs every measure, or is refused for a reason its
//! structure gives.

use leg_models::analysis::workspace::{
    follow, workspace, GridOptions, NodeState, Workspace, FOLD_FLOOR, GRID_FLOOR,
};
use leg_models::analysis::{
    foot_inverse_inertia, force_polygon, impact_mitigation, motor_kinematics, point_measures,
    AnalysisError, Body, BodyCoupling, LegFrame, MotorLimits,
};
use leg_models::assembly::{
    consistent_velocity, foot_inverse_holding, project_position, AssemblyError, Tolerance,
};
use leg_models::dynamics::actuation;
use leg_models::dynamics::contact::{solve_structured, ContactRows};
use leg_models::linalg::Cholesky;
use leg_models::nalgebra::{Matrix2, SMatrix, SVector, Vector2};
use leg_models::{LegDynamics, LegModel, Parameters};
use leg_tests::{not_applicable, Rng};

/// The spec's home pose on its closures.
fn home<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
) -> SVector<f64, NQ> {
    let mut q = SVector::from(L::HOME);
    project_position::<L, f64, NQ, NC, NU>(p, &mut q, &Tolerance::default()).unwrap();
    q
}

fn limits<const NU: usize>(torque: f64, speed: f64) -> MotorLimits<f64, NU> {
    MotorLimits {
        torque: SVector::from_fn(|k, _| torque * (1.0 + 0.25 * k as f64)),
        speed: SVector::from_fn(|k, _| speed * (1.0 + 0.1 * k as f64)),
    }
}

/// The size of `J_f M⁻¹ J_fᵀ` (1/kg): what rounding in an inverse inertia is relative to
/// (a pinned foot's is zero).
fn inverse_inertia_scale<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
) -> f64 {
    let m = L::mass_matrix(q, p);
    let jf = L::foot_jacobian(q, p);
    let mut y = jf.transpose();
    Cholesky::new(&m).unwrap().solve_mut(&mut y);
    (jf * y).amax()
}

/// Up to four pairs of rows held at zero velocity: the foot (pair 0) and unit rows of
/// the held joints (two per pair), as a contact solve takes them.
const NK: usize = 8;

fn pinned_rows<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    extra_locked: &[bool; NQ],
) -> ContactRows<f64, NQ, NK> {
    let jf = L::foot_jacobian(q, p);
    let mut c = SMatrix::<f64, NK, NQ>::zeros();
    let mut held = [false; NK];
    c.set_row(0, &jf.row(0));
    c.set_row(1, &jf.row(1));
    (held[0], held[1]) = (true, true);
    let mut r = 2;
    for j in 0..NQ {
        if frame.held[j] || extra_locked[j] {
            assert!(
                r < NK,
                "{}: too many held joints for the test's rows",
                L::NAME
            );
            c[(r, j)] = 1.0;
            held[r] = true;
            r += 1;
        }
    }
    ContactRows {
        c,
        w: c,
        slide: SVector::zeros(),
        held,
    }
}

/// Poses to check at: home and up to `n` reached nodes of a coarse grid.
fn sample_poses<const NQ: usize, const NU: usize>(
    ws: &Workspace<NQ, NU>,
    start: &SVector<f64, NQ>,
    n: usize,
    rng: &mut Rng,
) -> Vec<SVector<f64, NQ>> {
    let reached: Vec<usize> = (0..ws.states.len())
        .filter(|&i| matches!(ws.measures[i], Some(Ok(_))))
        .collect();
    let mut out = vec![*start];
    for _ in 0..n.min(reached.len()) {
        out.push(ws.poses[reached[(rng.unit() * reached.len() as f64) as usize]]);
    }
    out
}

fn grid<const NU: usize>(nodes: usize) -> GridOptions<NU> {
    GridOptions {
        nodes,
        window: None,
        plane: None,
        motor_range: None,
        limits: limits(2.0, 20.0),
    }
}

/// The leg's spec parameters, its frame, its home pose and a grid of `nodes` a side over
/// its workspace; `None` (recorded as not applicable to `check`) where the grid does not
/// apply to the leg.
#[allow(clippy::type_complexity)]
fn leg_grid<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    check: &str,
    nodes: usize,
) -> Option<(
    L::Params<f64>,
    LegFrame<NQ>,
    SVector<f64, NQ>,
    Workspace<NQ, NU>,
)> {
    let frame = LegFrame::of::<L, NC, NU>();
    if let Err(why) = frame.foot_polygons() {
        not_applicable(L::NAME, check, &why);
        return None;
    }
    let p = L::Params::<f64>::default();
    let start = home::<L, NQ, NC, NU>(&p);
    let ws = workspace::<L, NQ, NC, NU, 2, NC>(&p, &start, &frame, &grid::<NU>(nodes)).unwrap();
    Some((p, frame, start, ws))
}

/// Every measure on every leg: computed where the leg's structure allows it (finite,
/// with a workspace of positive area), refused with the structure's reason elsewhere.
pub fn check_every_measure<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let p = L::Params::<f64>::default();
    let frame = LegFrame::of::<L, NC, NU>();
    let q = home::<L, NQ, NC, NU>(&p);
    let lim = limits::<NU>(2.0, 20.0);
    // The inverse inertia applies to every leg whose mass matrix is regular.
    let inv = foot_inverse_inertia::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame, false).unwrap();
    assert!(inv.iter().all(|x| x.is_finite()), "{}", L::NAME);
    // Positive semi-definite, to rounding on the scale of J_f M⁻¹ J_fᵀ.
    let scale = inverse_inertia_scale::<L, NQ, NC, NU>(&p, &q);
    let eig = inv.symmetric_eigenvalues();
    assert!(eig.min() >= -1e-12 * scale, "{}: {eig:?}", L::NAME);
    let point = point_measures::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame, &lim);
    let ws = workspace::<L, NQ, NC, NU, 2, NC>(&p, &q, &frame, &grid::<NU>(40));
    match frame.foot_polygons() {
        Ok(()) => {
            let m = point.unwrap_or_else(|e| panic!("{}: {e}", L::NAME));
            assert!(m.condition >= 1.0 && m.condition.is_finite(), "{}", L::NAME);
            assert!(m.effective_mass > 0.0 && m.vertical_speed > 0.0);
            let ws = ws.unwrap_or_else(|e| panic!("{}: {e}", L::NAME));
            assert!(ws.area > 0.0 && ws.area.is_finite(), "{}", L::NAME);
            assert!(
                ws.states
                    .iter()
                    .filter(|&&s| s == NodeState::Reached)
                    .count()
                    > 20
            );
        }
        Err(why) => {
            not_applicable(L::NAME, "foot polygons and workspace", &why);
            assert_eq!(
                ws.err(),
                Some(AnalysisError::NotApplicable(why)),
                "{}",
                L::NAME
            );
            // Motor coordinates still exist on a one-motor linkage: its point measures do.
            match frame.motor_coordinates() {
                Ok(()) => {
                    let m = point.unwrap_or_else(|e| panic!("{}: {e}", L::NAME));
                    assert_eq!(m.vertical_force, None, "{}", L::NAME);
                }
                Err(why) => assert_eq!(point.err(), Some(AnalysisError::NotApplicable(why))),
            }
        }
    }
}

/// Force capacity against statics: the foot pinned to the ground (and the body held),
/// the motors at the torques of a polygon vertex, the KKT solve keeps the leg at rest and
/// the ground's force on the foot is minus the vertex. With two motors the vertex torques
/// are the limits themselves.
pub fn check_force_polygon<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let Some((p, frame, start, ws)) =
        leg_grid::<L, NQ, NC, NU>("force polygon against statics", 30)
    else {
        return;
    };
    let mut rng = Rng::new(7);
    let torque = limits::<NU>(2.0, 1.0).torque;
    let mut checked = 0;
    for q in sample_poses(&ws, &start, 6, &mut rng) {
        let Ok(kin) = motor_kinematics::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame) else {
            continue;
        };
        let poly = force_polygon::<L, f64, NQ, NC, NU>(&p, &q, &kin, &torque);
        assert!(poly.vertices().len() >= 4, "{}: {:?}", L::NAME, poly);
        let m = L::mass_matrix(&q, &p);
        let chol = Cholesky::new(&m).unwrap();
        let j = L::constraint_jacobian(&q, &p);
        let rows = pinned_rows::<L, NQ, NC, NU>(&p, &q, &frame, &[false; NQ]);
        let gravity = L::gravity_forces(&q, &p);
        let scale = poly.vertices().iter().map(|v| v.amax()).fold(0.0, f64::max);
        for f in poly.vertices() {
            let u = leg_models::analysis::holding_torque::<L, f64, NQ, NC, NU, 2>(&p, &q, &kin)
                + kin.foot_jacobian.transpose() * f;
            let at_limit = (0..NU)
                .filter(|&k| (u[k].abs() - torque[k]).abs() <= 1e-9 * torque[k])
                .count();
            assert!(
                at_limit >= 2,
                "{}: vertex {f:?} with torques {u:?}",
                L::NAME
            );
            assert!((0..NU).all(|k| u[k].abs() <= torque[k] * (1.0 + 1e-9)));
            if NU == 2 {
                // The limits themselves, not torques derived from the polygon.
                let limit = SVector::<f64, NU>::from_fn(|k, _| torque[k].copysign(u[k]));
                assert!((u - limit).amax() <= 1e-9 * torque.amax());
            }
            let tau = actuation::<L, f64, NQ, NC, NU>(&u) - gravity;
            let sol = solve_structured(
                &chol,
                &j,
                &SVector::zeros(),
                L::REDUNDANT_ROWS,
                &rows,
                &SVector::zeros(),
                &tau,
            )
            .unwrap();
            assert!(
                sol.x.amax() < 1e-7 * (1.0 + tau.amax() / m.amax()),
                "{}: the pinned leg moves: {:?}",
                L::NAME,
                sol.x
            );
            // The ground's force on the leg is −f.
            let ground = Vector2::new(sol.contact[0], sol.contact[1]);
            assert!(
                (ground + f).amax() <= 1e-8 * scale,
                "{}: KKT force {ground:?}, polygon vertex {f:?}",
                L::NAME
            );
        }
        // The largest downward push is on the polygon's boundary, straight down.
        if let Some(fv) = leg_models::analysis::vertical_force(
            &kin.foot_jacobian,
            &leg_models::analysis::holding_torque::<L, f64, NQ, NC, NU, 2>(&p, &q, &kin),
            &torque,
        ) {
            let u = leg_models::analysis::holding_torque::<L, f64, NQ, NC, NU, 2>(&p, &q, &kin)
                + kin.foot_jacobian.transpose() * Vector2::new(0.0, -fv);
            let worst = (0..NU).map(|k| u[k].abs() / torque[k]).fold(0.0, f64::max);
            assert!((worst - 1.0).abs() < 1e-9, "{}: {worst}", L::NAME);
        }
        checked += 1;
    }
    assert!(checked >= 2, "{}", L::NAME);
}

/// The foot's inverse inertia against an impulse: the leg strikes with its foot pinned
/// on impact (the plastic impact solve, foot rows held); the foot's velocity change is
/// `Λ⁻¹ P` for the impulse `P` the ground gives. With the motors locked, the same with
/// their joints held; and a leg whose rotors are a billion times heavier has the locked
/// leg's inertia.
pub fn check_foot_inertia<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let frame = LegFrame::of::<L, NC, NU>();
    let p = L::Params::<f64>::default();
    let q = home::<L, NQ, NC, NU>(&p);
    let mut rng = Rng::new(11);
    let actuated: [bool; NQ] = core::array::from_fn(|c| L::ACTUATED.contains(&c));
    for locked in [false, true] {
        let inv =
            foot_inverse_inertia::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame, locked).unwrap();
        let extra = if locked { actuated } else { [false; NQ] };
        // A pre-impact velocity on the closures, the held joints at rest.
        let mut qd = SVector::<f64, NQ>::from_fn(|_, _| rng.range(-1.0, 1.0));
        for j in 0..NQ {
            if frame.held[j] || extra[j] {
                qd[j] = 0.0;
            }
        }
        let mut rows_free = pinned_rows::<L, NQ, NC, NU>(&p, &q, &frame, &extra);
        (rows_free.held[0], rows_free.held[1]) = (false, false);
        rows_free.w.row_mut(0).fill(0.0);
        rows_free.w.row_mut(1).fill(0.0);
        let m = L::mass_matrix(&q, &p);
        let chol = Cholesky::new(&m).unwrap();
        let j = L::constraint_jacobian(&q, &p);
        // Project the random rates onto the closures and held rows (a velocity impact
        // with the foot free).
        let pre = solve_structured(
            &chol,
            &j,
            &SVector::zeros(),
            L::REDUNDANT_ROWS,
            &rows_free,
            &SVector::zeros(),
            &(m * qd),
        )
        .unwrap()
        .x;
        let rows = pinned_rows::<L, NQ, NC, NU>(&p, &q, &frame, &extra);
        let sol = match solve_structured(
            &chol,
            &j,
            &SVector::zeros(),
            L::REDUNDANT_ROWS,
            &rows,
            &SVector::zeros(),
            &(m * pre),
        ) {
            Ok(s) => s,
            // A foot that cannot move (locked, or a one-motor linkage's line) makes the
            // pinned rows repeat: nothing to strike with.
            Err(_) => {
                let scale = inverse_inertia_scale::<L, NQ, NC, NU>(&p, &q);
                assert!(
                    inv.symmetric_eigenvalues().min() < 1e-9 * scale,
                    "{}",
                    L::NAME
                );
                continue;
            }
        };
        let v_before = L::foot_jacobian(&q, &p) * pre;
        let impulse = Vector2::new(sol.contact[0], sol.contact[1]);
        let dv = inv * impulse;
        assert!(
            (dv + v_before).amax() <= 1e-9 * (1.0 + v_before.amax()),
            "{} (locked {locked}): Λ⁻¹P = {dv:?}, foot velocity before {v_before:?}",
            L::NAME
        );
    }
    // Locking a motor is the limit of an infinitely heavy rotor: reflected inertias 1e7
    // times the mass matrix's largest entry.
    let mut heavy = p;
    let mut any = false;
    let index = |name: String| L::Params::<f64>::NAMES.iter().position(|n| *n == name);
    let biggest = L::mass_matrix(&q, &p).amax();
    for &a in &L::ACTUATED {
        let link = L::JOINT_NAMES[a];
        let (Some(i), Some(g)) = (
            index(format!("{link}_rotor_inertia")),
            index(format!("{link}_gear_ratio")),
        ) else {
            continue;
        };
        let gear = p.get(g).unwrap();
        heavy.set(i, 1e7 * biggest / (gear * gear));
        any = true;
    }
    assert!(any, "{}: no rotor inertia parameter", L::NAME);
    let locked = foot_inverse_inertia::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame, true).unwrap();
    let nearly =
        foot_inverse_inertia::<L, f64, NQ, NC, NU, 2, NC>(&heavy, &q, &frame, false).unwrap();
    let free = foot_inverse_inertia::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame, false).unwrap();
    assert!(
        (locked - nearly).amax()
            <= 1e-5
                * free
                    .amax()
                    .max(1e-6 * inverse_inertia_scale::<L, NQ, NC, NU>(&p, &q)),
        "{}: locked {locked:?}, rotors ×1e9 {nearly:?}",
        L::NAME
    );
}

/// The foot's rank measure at nodes across the workspace against nalgebra: the ratio of
/// the singular values of `J_f N`, `N` an orthonormal basis of the null space of the
/// closures with the held joints at rest (right singular vectors of that stack, not from
/// `G`), its sign that of `det [J; J_f]` over the free joints where that is square. It
/// does not vanish at a passive singularity: across each sign change of the passive rank
/// measure it keeps its sign.
pub fn check_foot_rank<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    use nalgebra::DMatrix;
    let Some((p, frame, start, ws)) = leg_grid::<L, NQ, NC, NU>("foot rank", 40) else {
        return;
    };
    let held: Vec<usize> = (0..NQ).filter(|&c| frame.held[c]).collect();
    let square = NU == 2 && L::REDUNDANT_ROWS == 0 && NC + 2 + held.len() == NQ;
    let mut checked = 0;
    let mut convention = None;
    for (i, m) in ws.measures.iter().enumerate() {
        let Some(Ok(m)) = m else { continue };
        if i % 7 != 0 {
            continue;
        }
        let q = &ws.poses[i];
        let j = L::constraint_jacobian(q, &p);
        let jf = L::foot_jacobian(q, &p);
        let mut a = DMatrix::<f64>::zeros(NC + held.len(), NQ);
        for r in 0..NC {
            for c in 0..NQ {
                a[(r, c)] = j[(r, c)];
            }
        }
        for (r, &c) in held.iter().enumerate() {
            a[(NC + r, c)] = 1.0;
        }
        // The right singular vectors of A (zero rows added to make it square, so that
        // the SVD is full) with the NU smallest singular values span the motions.
        let mut square_a = DMatrix::<f64>::zeros(NQ.max(a.nrows()), NQ);
        square_a.rows_mut(0, a.nrows()).copy_from(&a);
        let svd = square_a.svd(false, true);
        let v_t = svd.v_t.unwrap();
        let mut order: Vec<usize> = (0..NQ).collect();
        order.sort_by(|&x, &y| svd.singular_values[x].total_cmp(&svd.singular_values[y]));
        let mut null = DMatrix::<f64>::zeros(NQ, NU);
        for (k, &o) in order.iter().take(NU).enumerate() {
            null.set_column(k, &v_t.row(o).transpose());
        }
        assert!((&a * &null).amax() < 1e-9, "{}: null space", L::NAME);
        let jf_d = DMatrix::from_fn(2, NQ, |r, c| jf[(r, c)]);
        let sv = (jf_d * &null).svd(false, false).singular_values;
        let (hi, lo) = (sv.max(), sv.min());
        let expected = if NU < 2 { 0.0 } else { lo / hi };
        assert!(
            (m.foot_rank.abs() - expected).abs() < 1e-8,
            "{}: foot rank {} against {expected} at node {i}",
            L::NAME,
            m.foot_rank
        );
        if square {
            let mut k = DMatrix::<f64>::zeros(NQ, NQ);
            for c in 0..NQ {
                if frame.held[c] {
                    continue;
                }
                for r in 0..NC {
                    k[(r, c)] = j[(r, c)];
                }
                k[(NC, c)] = jf[(0, c)];
                k[(NC + 1, c)] = jf[(1, c)];
            }
            for (r, &c) in held.iter().enumerate() {
                k[(NC + 2 + r, c)] = 1.0;
            }
            // The sign is det K's up to one sign for the leg (the joints' order).
            let det = k.determinant();
            if det.abs() > 1e-9 {
                let agree = (m.foot_rank > 0.0) == (det > 0.0);
                assert_eq!(
                    *convention.get_or_insert(agree),
                    agree,
                    "{}: node {i}",
                    L::NAME
                );
            }
        }
        checked += 1;
    }
    assert!(checked > 0, "{}", L::NAME);
    // Across a passive singularity the foot keeps both directions: no sign change. Where
    // the two kinds meet (a parallelogram's straight leg) both vanish: a crossing whose
    // foot rank is small must then be at the workspace's edge, within two cells of a node
    // the branch does not reach.
    let at_home = leg_models::analysis::foot_rank::<L, f64, NQ, NC, NU, 2>(
        &frame,
        &motor_kinematics::<L, f64, NQ, NC, NU, 2, NC>(&p, &start, &frame).unwrap(),
    )
    .abs();
    let n = ws.nodes;
    let near_edge = |i: usize| {
        let (x, y) = ((i % n) as isize, (i / n) as isize);
        (-2..=2).any(|dy| {
            (-2..=2).any(|dx| {
                let (u, v) = (x + dx, y + dy);
                u < 0
                    || v < 0
                    || u >= n as isize
                    || v >= n as isize
                    || ws.states[v as usize * n + u as usize] != NodeState::Reached
            })
        })
    };
    let mut crossings = 0;
    for i in 0..n * n {
        for k in [i + 1, i + n] {
            if k >= n * n || (k == i + 1 && (i + 1) % n == 0) || !ws.joined(i, k) {
                continue;
            }
            let (Some(Ok(a)), Some(Ok(b))) = (&ws.measures[i], &ws.measures[k]) else {
                continue;
            };
            if !ws.passive_signed || (ws.passive_rank[i] > 0.0) == (ws.passive_rank[k] > 0.0) {
                continue;
            }
            if a.foot_rank.abs().min(b.foot_rank.abs()) <= 0.1 * at_home {
                assert!(
                    near_edge(i) || near_edge(k),
                    "{}: the foot rank is small at a passive crossing inside the workspace, {:?}",
                    L::NAME,
                    ws.node(i % n, i / n)
                );
            } else {
                assert_eq!(
                    a.foot_rank > 0.0,
                    b.foot_rank > 0.0,
                    "{}: the foot rank changes sign across a passive singularity: {} {} at {:?} {:?}, passive {} {}",
                    L::NAME,
                    a.foot_rank,
                    b.foot_rank,
                    ws.node(i % n, i / n),
                    ws.node(k % n, k / n),
                    ws.passive_rank[i],
                    ws.passive_rank[k]
                );
                crossings += 1;
            }
        }
    }
    println!(
        "{}: foot rank checked at {checked} nodes, {crossings} passive crossings",
        L::NAME
    );
}

/// Every leg's assembly branches at its home motor angles: the home pose first, each
/// other one closed with the motors and the body's joints where home has them and no two
/// the same pose (modulo a turn); a leg whose motors do not determine it has only home.
pub fn check_assembly_branches<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    use leg_models::analysis::workspace::assembly_modes;
    let p = L::Params::<f64>::default();
    let frame = LegFrame::of::<L, NC, NU>();
    let start = home::<L, NQ, NC, NU>(&p);
    let modes = assembly_modes::<L, NQ, NC, NU>(&p, &start, &frame, 64);
    assert_eq!(modes[0], start, "{}", L::NAME);
    if frame.motor_coordinates().is_err() {
        assert_eq!(modes.len(), 1, "{}", L::NAME);
        return;
    }
    let turn = std::f64::consts::TAU;
    for (b, q) in modes.iter().enumerate() {
        assert!(
            L::closure_residual(q, &p).amax() < 1e-9,
            "{}: branch {b}",
            L::NAME
        );
        for c in 0..NQ {
            if frame.held[c] || L::ACTUATED.contains(&c) {
                assert_eq!(q[c], start[c], "{}: branch {b}, joint {c}", L::NAME);
            }
        }
        for other in &modes[..b] {
            let apart = (0..NQ).any(|c| {
                let d = q[c] - other[c];
                (d - turn * (d / turn).round()).abs() > 1e-6
            });
            assert!(apart, "{}: branch {b} twice", L::NAME);
        }
    }
    println!("{}: {} assembly branches", L::NAME, modes.len());
}

/// Where the grid puts a passive singularity ("type II"), bisection between the two
/// nodes finds a pose where `assemble`'s velocity solve reports `Singular`; where it
/// puts the branch's end ("type I"), the foot Jacobian's smallest singular value goes
/// to zero.
pub fn check_singularities<
    L: LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>() {
    let Some((p, frame, start, ws)) = leg_grid::<L, NQ, NC, NU>("singularity curves", 60) else {
        return;
    };
    let n = ws.nodes;
    let tol = Tolerance::default();
    let foot_at = |a: [f64; 2], b: [f64; 2], t: f64| {
        Vector2::new(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
    };
    let home_kin = motor_kinematics::<L, f64, NQ, NC, NU, 2, NC>(&p, &start, &frame).unwrap();
    let mut passive_checked = 0;
    let mut drawn_checked = 0;
    let mut edges_checked = 0;
    for i in 0..n * n {
        for k in [i + 1, i + n] {
            if k >= n * n || (k == i + 1 && (i + 1) % n == 0) {
                continue;
            }
            let (a, b) = (ws.node(i % n, i / n), ws.node(k % n, k / n));
            match (ws.states[i], ws.states[k]) {
                (NodeState::Reached, NodeState::Reached)
                    if ws.passive_signed
                        && ws.joined(i, k)
                        && (ws.passive_rank[i] > 0.0) != (ws.passive_rank[k] > 0.0) =>
                {
                    // Marching squares draws a crossing in a square of four joined nodes.
                    let complete = |c: usize| {
                        c % n + 1 < n
                            && c + n + 1 < n * n
                            && [
                                (c, c + 1),
                                (c + 1, c + n + 1),
                                (c + n + 1, c + n),
                                (c + n, c),
                            ]
                            .iter()
                            .all(|&(x, y)| ws.joined(x, y))
                    };
                    let squares = if k == i + 1 {
                        [Some(i), i.checked_sub(n)]
                    } else {
                        [Some(i), (i % n > 0).then(|| i - 1)]
                    };
                    let on_square = squares.into_iter().flatten().any(complete);
                    // A few crossings of each kind: anywhere, and on drawn squares.
                    if passive_checked >= 4 && (drawn_checked >= 4 || !on_square) {
                        continue;
                    }
                    // Bisection on the sign of the passive rank measure, continuing the
                    // branch from node i.
                    let (mut lo, mut hi, mut q) = (0.0, 1.0, ws.poses[i]);
                    let sign = ws.passive_rank[i] > 0.0;
                    for _ in 0..60 {
                        let mid = 0.5 * (lo + hi);
                        let qm = foot_inverse_holding::<L, f64, NQ, NC, NU, 2, NC>(
                            &p,
                            &foot_at(a, b, mid),
                            &q,
                            &tol,
                            &frame.held,
                        )
                        .unwrap();
                        let r = leg_models::analysis::passive_rank_at::<L, f64, NQ, NC, NU>(
                            &p, &qm, &frame,
                        );
                        if (r > 0.0) == sign {
                            (lo, q) = (mid, qm);
                        } else {
                            hi = mid;
                        }
                    }
                    let theta_dot = SVector::<f64, NU>::from_element(1.0);
                    let r =
                        leg_models::analysis::passive_rank_at::<L, f64, NQ, NC, NU>(&p, &q, &frame);
                    assert!(r.abs() < 1e-6, "{}: rank {r} after bisection", L::NAME);
                    if !frame.has_body() {
                        assert_eq!(
                            consistent_velocity::<L, f64, NQ, NC, NU>(&p, &q, &theta_dot),
                            Err(AssemblyError::Singular),
                            "{}: at the curve",
                            L::NAME
                        );
                        assert!(consistent_velocity::<L, f64, NQ, NC, NU>(
                            &p,
                            &ws.poses[i],
                            &theta_dot
                        )
                        .is_ok());
                    }
                    assert_eq!(
                        motor_kinematics::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame).err(),
                        Some(AnalysisError::PassiveSingular)
                    );
                    if on_square {
                        // And the grid drew a curve through this edge.
                        let mid = foot_at(a, b, lo);
                        assert!(
                            ws.distance_to_singularity([mid[0], mid[1]]).unwrap() <= 0.5 * ws.step,
                            "{}",
                            L::NAME
                        );
                        drawn_checked += 1;
                    }
                    passive_checked += 1;
                }
                (NodeState::Reached, NodeState::BranchEnds) if edges_checked < 8 => {
                    // The last point along the edge the branch reaches from node i, with
                    // steps down to 1e-7 of the way: the grid's sixteenth stops short of a
                    // fold where a joint turns fast near it (cassie_planar's toe crank turns
                    // 0.2 rad over the last 0.3 mm, where σ_min is still 3e-3 of home's).
                    let (mut lo, mut hi, mut q) = (0.0, 1.0, ws.poses[i]);
                    let from = Vector2::new(a[0], a[1]);
                    for _ in 0..50 {
                        let mid = 0.5 * (lo + hi);
                        match follow::<L, NQ, NC, NU, 2, NC>(
                            &p,
                            &ws.poses[i],
                            &from,
                            &foot_at(a, b, mid),
                            &frame,
                            &tol,
                            FOLD_FLOOR,
                        ) {
                            Ok(qm) => (lo, q) = (mid, qm),
                            _ => hi = mid,
                        }
                    }
                    // q is within 2⁻⁵⁰ of a cell from where `follow` ends, which is within
                    // about 1e-7 of the way from the fold.

                    let interior = home_kin.foot_jacobian;
                    let (s_in_hi, s_in_lo) = leg_models::analysis::singular_values(&interior);
                    match motor_kinematics::<L, f64, NQ, NC, NU, 2, NC>(&p, &q, &frame) {
                        Ok(kin) => {
                            let rank = |kin| {
                                leg_models::analysis::foot_rank::<L, f64, NQ, NC, NU, 2>(
                                    &frame, kin,
                                )
                                .abs()
                            };
                            let (at_end, at_home) = (rank(&kin), rank(&home_kin));
                            assert!(
                                at_end < 1e-3 * at_home,
                                "{}: foot rank {at_end} at the branch's end, {at_home} at home",
                                L::NAME
                            );
                            let (_, s) = leg_models::analysis::singular_values(&kin.foot_jacobian);
                            // σ_min ∝ √(distance to the edge): 1e-4 of the home pose's at
                            // a distance below 1e-9 of the cell.
                            assert!(
                                s < 1e-3 * s_in_lo,
                                "{}: σ_min {s} at the branch's end, {s_in_lo} at home (σ_max {s_in_hi})",
                                L::NAME
                            );
                        }
                        // The branch can also end where the passive joints lose rank.
                        Err(AnalysisError::PassiveSingular) => {}
                        Err(e) => panic!("{}: {e}", L::NAME),
                    }
                    edges_checked += 1;
                }
                _ => {}
            }
        }
    }
    println!(
        "{}: {passive_checked} passive crossings ({drawn_checked} on a drawn curve), {edges_checked} branch ends checked",
        L::NAME
    );
    // Where the passive rank crosses zero inside squares of joined nodes, curves exist.
    if passive_checked > 0 && !ws.passive_curves.is_empty() {
        assert!(drawn_checked > 0, "{}", L::NAME);
    }
    if edges_checked == 0 && passive_checked == 0 {
        // No singularity in the grid (a sliding shin reaches everywhere but its hip):
        // then no node may be singular either.
        for m in ws.measures.iter().flatten() {
            assert!(m.is_ok(), "{}: {:?}", L::NAME, m);
        }
    }
}

macro_rules! analysis {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        mod $module {
            type Model = $ty;
            #[test]
            fn every_measure_runs_or_says_why_not() {
                super::check_every_measure::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn force_polygon_matches_statics_with_the_foot_pinned() {
                super::check_force_polygon::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn foot_inertia_matches_an_impulse() {
                super::check_foot_inertia::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn foot_rank_is_the_mechanisms_not_the_motors() {
                super::check_foot_rank::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn assembly_branches_close_and_differ() {
                super::check_assembly_branches::<Model, $nq, $nc, $nu>();
            }
            #[test]
            fn singularity_curves_are_where_the_rank_is_lost() {
                super::check_singularities::<Model, $nq, $nc, $nu>();
            }
        }
    };
}

generated::for_each_model!(analysis);

/// The five-bar's workspace (both motors turning freely) is the intersection of the two
/// branches' annuli: `|l₁ − l₂| ≤ |p − hip| ≤ l₁ + l₂` for each. Every node farther than
/// two cells from that boundary is reached exactly when it is inside, and the area agrees.
fn five_bar_annuli<L: LegModel<4, 2, 2>>() {
    let p = L::Params::<f64>::default();
    let frame = LegFrame::of::<L, 2, 2>();
    let q = home::<L, 4, 2, 2>(&p);
    let joints = L::joint_positions(&q, &p);
    let tips = L::link_tips(&q, &p);
    let len = |j: usize| (tips.column(j) - joints.column(j)).norm();
    let (hip_a, hip_b) = (joints.column(0).into_owned(), joints.column(2).into_owned());
    let (a1, a2, b1, b2) = (len(0), len(1), len(2), len(3));
    assert!(
        (L::foot_position(&q, &p) - tips.column(1)).norm() < 1e-12,
        "the foot is the toe"
    );
    let ws = workspace::<L, 4, 2, 2, 2, 2>(&p, &q, &frame, &grid::<2>(100)).unwrap();
    // Signed distance inside the intersection of the annuli (positive inside).
    let inside = |x: Vector2<f64>| {
        let (ra, rb) = ((x - hip_a).norm(), (x - hip_b).norm());
        [
            ra - (a1 - a2).abs(),
            a1 + a2 - ra,
            rb - (b1 - b2).abs(),
            b1 + b2 - rb,
        ]
        .into_iter()
        .fold(f64::INFINITY, f64::min)
    };
    let mut checked = 0;
    let mut inside_count = 0usize;
    for iy in 0..ws.nodes {
        for ix in 0..ws.nodes {
            let x = ws.node(ix, iy);
            let d = inside(Vector2::new(x[0], x[1]));
            inside_count += (d > 0.0) as usize;
            if d.abs() <= 2.0 * ws.step {
                continue;
            }
            let reached = ws.states[iy * ws.nodes + ix] == NodeState::Reached;
            assert_eq!(reached, d > 0.0, "{}: node {x:?}, {d} m inside", L::NAME);
            checked += 1;
        }
    }
    assert!(checked > ws.nodes * ws.nodes / 2);
    let exact = inside_count as f64 * ws.step * ws.step;
    assert!(
        (ws.area - exact).abs() <= 0.03 * exact,
        "{}: area {} against {exact}",
        L::NAME,
        ws.area
    );
}

#[test]
fn five_bar_workspace_is_the_intersection_of_the_annuli() {
    five_bar_annuli::<generated::Minitaur>();
    five_bar_annuli::<generated::FiveBarOffset>();
    // Minitaur's coaxial hips: an annulus between 0.1 m and 0.3 m.
    let p = generated::minitaur::Params::<f64>::default();
    let frame = LegFrame::of::<generated::Minitaur, 2, 2>();
    let q = home::<generated::Minitaur, 4, 2, 2>(&p);
    let ws =
        workspace::<generated::Minitaur, 4, 2, 2, 2, 2>(&p, &q, &frame, &grid::<2>(100)).unwrap();
    let annulus = std::f64::consts::PI * (0.3f64.powi(2) - 0.1f64.powi(2));
    assert!((ws.area - annulus).abs() < 0.03 * annulus, "{}", ws.area);
}

/// `follow` ends at the fold, not short of it, where a joint turns fast near the fold:
/// `cassie_planar` (three motors moving a two-coordinate foot) at the edge of its reach
/// has its toe crank near its dead centre, turning about 0.2 rad over the last 0.3 mm.
/// Against a march of its own along the same edge (each step solved from the last, grown
/// by half after each that holds and halved otherwise, none turning a joint by more than
/// 0.02 rad, until a step of 1e-15 of the cell fails): with [`FOLD_FLOOR`], `follow`
/// reaches the edge's point 1e-6 of a cell before the march's last and not the one 1e-6
/// after it, and the foot's rank there is below 1e-4 of home's (σ_min ∝ √distance). With
/// the grid's floor, a sixteenth of the way, it stops short: up to 0.0074 of a cell
/// (0.27 mm; the foot's rank 9.3e-4 there, 0.34 at home).
#[test]
fn follow_ends_at_the_fold_where_a_joint_turns_fast() {
    type L = generated::CassiePlanar;
    let (p, frame, start, ws) = leg_grid::<L, 7, 4, 3>("follow to the fold", 60).unwrap();
    let tol = Tolerance::default();
    let n = ws.nodes;
    let rank = |q: &SVector<f64, 7>| {
        let kin = motor_kinematics::<L, f64, 7, 4, 3, 2, 4>(&p, q, &frame).unwrap();
        leg_models::analysis::foot_rank::<L, f64, 7, 4, 3, 2>(&frame, &kin).abs()
    };
    let at_home = rank(&start);
    let (mut checked, mut short) = (0, 0.0f64);
    for i in 0..n * n - 1 {
        let k = i + 1;
        if k % n == 0 || ws.states[i] != NodeState::Reached || ws.states[k] != NodeState::BranchEnds
        {
            continue;
        }
        let (a, b) = (ws.node(i % n, i / n), ws.node(k % n, k / n));
        let foot_at = |t: f64| Vector2::new(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
        // The march.
        let (mut q, mut t, mut h) = (ws.poses[i], 0.0, 1e-3);
        for _ in 0..10_000 {
            if h < 1e-15 {
                break;
            }
            match foot_inverse_holding::<L, f64, 7, 4, 3, 2, 4>(
                &p,
                &foot_at(t + h),
                &q,
                &tol,
                &frame.held,
            ) {
                Ok(next) if (next - q).amax() < 0.02 => (q, t, h) = (next, t + h, 1.5 * h),
                _ => h *= 0.5,
            }
        }
        assert!(h < 1e-15 && t < 1.0, "the march crosses the edge: t = {t}");
        let to = |s: f64, floor: f64| {
            follow::<L, 7, 4, 3, 2, 4>(
                &p,
                &ws.poses[i],
                &Vector2::new(a[0], a[1]),
                &foot_at(s),
                &frame,
                &tol,
                floor,
            )
        };
        let before = to(t - 1e-6, FOLD_FLOOR).unwrap_or_else(|e| {
            panic!(
                "edge {i}: follow stops before {} of the cell: {e}",
                t - 1e-6
            )
        });
        assert!(to(t + 1e-6, FOLD_FLOOR).is_err(), "edge {i}: past the fold");
        let r = rank(&before);
        assert!(
            r < 1e-4 * at_home,
            "edge {i}: foot rank {r}, {at_home} at home"
        );
        // The grid's floor: where it stops, by bisection.
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            match to(mid, GRID_FLOOR) {
                Ok(_) => lo = mid,
                _ => hi = mid,
            }
        }
        short = short.max(t - lo);
        checked += 1;
        if checked == 8 {
            break;
        }
    }
    assert_eq!(checked, 8);
    println!("with the grid's floor follow stops up to {short} of a cell short of the fold");
}

/// A motor range that leaves out the starting pose is named as such, not as a branch
/// that ends at once; a range around it limits the workspace to the motors' range.
#[test]
fn motor_ranges_refuse_a_start_outside_and_count_angles_modulo_a_turn() {
    type L = generated::Minitaur;
    let p = generated::minitaur::Params::<f64>::default();
    let frame = LegFrame::of::<L, 2, 2>();
    let q = home::<L, 4, 2, 2>(&p);
    let theta = [q[L::ACTUATED[0]], q[L::ACTUATED[1]]];
    let mut options = grid::<2>(30);
    options.motor_range = Some([(theta[0] + 0.1, theta[0] + 1.0), (-10.0, 10.0)]);
    let e = workspace::<L, 4, 2, 2, 2, 2>(&p, &q, &frame, &options).unwrap_err();
    assert_eq!(
        e,
        AnalysisError::StartOutOfRange {
            motor: 0,
            angle: theta[0],
            range: (theta[0] + 0.1, theta[0] + 1.0)
        }
    );
    assert!(e.to_string().contains("outside the motor range"), "{e}");
    options.motor_range = Some([
        (theta[0] - 0.3, theta[0] + 0.3),
        (theta[1] - 0.3, theta[1] + 0.3),
    ]);
    let ws = workspace::<L, 4, 2, 2, 2, 2>(&p, &q, &frame, &options).unwrap();
    let turn = std::f64::consts::TAU;
    for (state, pose) in ws.states.iter().zip(&ws.poses) {
        if *state == NodeState::Reached {
            for (k, &a) in L::ACTUATED.iter().enumerate() {
                let d = pose[a] - theta[k];
                assert!((d - turn * (d / turn).round()).abs() <= 0.3 + 1e-12);
            }
        }
    }
    // Just under a turn: the fronts that meet around the annulus's hole carry angles a
    // turn apart, the same poses; nodes reached with a motor's angle outside the range as
    // written but inside it modulo a turn are kept, and the nodes lost are those of the
    // 0.28 rad left out, not the half of the annulus past the seam.
    let range = [
        (theta[0] - 3.0, theta[0] + 3.0),
        (theta[1] - 3.0, theta[1] + 3.0),
    ];
    options.motor_range = Some(range);
    let almost = workspace::<L, 4, 2, 2, 2, 2>(&p, &q, &frame, &options).unwrap();
    let mut wrapped = 0;
    for (state, pose) in almost.states.iter().zip(&almost.poses) {
        if *state == NodeState::Reached {
            for (k, &a) in L::ACTUATED.iter().enumerate() {
                let (lo, hi) = range[k];
                assert!(lo + (pose[a] - lo).rem_euclid(turn) <= hi);
                wrapped += usize::from(pose[a] < lo || pose[a] > hi);
            }
        }
    }
    assert!(wrapped > 0, "no node needed the turn");
    options.motor_range = None;
    let free = workspace::<L, 4, 2, 2, 2, 2>(&p, &q, &frame, &options).unwrap();
    assert!(
        almost.area > 0.8 * free.area,
        "{} of {}",
        almost.area,
        free.area
    );
}

/// The assembly modes of a five-bar at its home motor angles: the two lower links' tips
/// meet where the circles about the two knees cross, twice; the other mode's foot is the
/// home foot reflected in the line through the knees. Each mode's workspace is found.
#[test]
fn a_five_bar_has_two_assembly_modes_mirrored_in_its_knees() {
    use leg_models::analysis::workspace::assembly_modes;
    fn check<L: LegModel<4, 2, 2>>() {
        let p = L::Params::<f64>::default();
        let frame = LegFrame::of::<L, 2, 2>();
        let q = home::<L, 4, 2, 2>(&p);
        let modes = assembly_modes::<L, 4, 2, 2>(&p, &q, &frame, 64);
        assert_eq!(modes.len(), 2, "{}: {modes:?}", L::NAME);
        assert_eq!(modes[0], q);
        let other = modes[1];
        for &a in L::ACTUATED.iter() {
            assert_eq!(other[a], q[a]);
        }
        assert!(L::closure_residual(&other, &p).amax() < 1e-10);
        // The knees: the lower links' joints.
        let joints = L::joint_positions(&q, &p);
        let (k1, k2) = (joints.column(1).into_owned(), joints.column(3).into_owned());
        let axis = (k2 - k1).normalize();
        let f = L::foot_position(&q, &p) - k1;
        let mirrored = k1 + 2.0 * f.dot(&axis) * axis - f;
        let foot = L::foot_position(&other, &p);
        assert!(
            (foot - mirrored).norm() < 1e-9,
            "{}: {foot} against {mirrored}",
            L::NAME
        );
        let ws = workspace::<L, 4, 2, 2, 2, 2>(&p, &other, &frame, &grid::<2>(40)).unwrap();
        assert!(ws.area > 0.0);
    }
    check::<generated::Minitaur>();
    check::<generated::FiveBarOffset>();
}

/// The impact mitigation factor of a leg on a translating body against the same leg
/// written with its body: `two_link` given `knee_runner`'s thigh and shin, on a body of
/// the runner's torso mass, and `knee_runner` with its torso's pitch inertia made huge.
#[test]
fn impact_mitigation_on_a_body_matches_a_leg_with_that_body() {
    use generated::{KneeRunner, TwoLink};
    let mut arm = generated::two_link::Params::<f64>::default();
    let mut runner = generated::knee_runner::Params::<f64>::default();
    let get = |name: &str| {
        let i = generated::knee_runner::Params::<f64>::NAMES
            .iter()
            .position(|n| *n == name)
            .unwrap_or_else(|| panic!("{name}"));
        runner.get(i).unwrap()
    };
    let names = generated::two_link::Params::<f64>::NAMES;
    for (mine, theirs) in [("upper_arm", "thigh"), ("forearm", "shin")] {
        for field in [
            "length_x",
            "length_y",
            "mass",
            "com_x",
            "com_y",
            "inertia",
            "rotor_inertia",
            "gear_ratio",
        ] {
            let i = names
                .iter()
                .position(|n| *n == format!("{mine}_{field}"))
                .unwrap();
            assert!(arm.set(i, get(&format!("{theirs}_{field}"))));
        }
    }
    let torso_mass = get("torso_mass");
    let pitch = generated::knee_runner::Params::<f64>::NAMES
        .iter()
        .position(|n| *n == "torso_inertia")
        .unwrap();
    runner.set(pitch, 1e8);
    let mut q_runner = SVector::from(KneeRunner::HOME);
    project_position::<KneeRunner, f64, 5, 0, 2>(&runner, &mut q_runner, &Tolerance::default())
        .unwrap();
    let q_arm = SVector::<f64, 2>::new(q_runner[3], q_runner[4]);
    let frame_runner = LegFrame::of::<KneeRunner, 0, 2>();
    assert!(frame_runner.has_body());
    let frame_arm = LegFrame::of::<TwoLink, 0, 2>();
    assert!(!frame_arm.has_body());
    let coupling = BodyCoupling::new::<TwoLink, f64, 2, 0, 2>(&arm).unwrap();
    let mut rng = Rng::new(3);
    for _ in 0..5 {
        let mut qr = q_runner;
        qr[3] += rng.range(-0.3, 0.3);
        qr[4] += rng.range(-0.3, 0.3);
        let qa = SVector::<f64, 2>::new(qr[3], qr[4]);
        let of_runner = impact_mitigation::<KneeRunner, f64, 5, 0, 2, 2, 0>(
            &runner,
            &qr,
            &frame_runner,
            &Body::Fixed,
            None,
        )
        .unwrap();
        let of_arm = impact_mitigation::<TwoLink, f64, 2, 0, 2, 2, 0>(
            &arm,
            &qa,
            &frame_arm,
            &Body::Translating { mass: torso_mass },
            Some(&coupling),
        )
        .unwrap();
        assert!(of_arm > 0.0 && of_arm < 1.0, "{of_arm}");
        assert!(
            (of_arm - of_runner).abs() < 1e-7,
            "arm on a body {of_arm}, runner {of_runner}"
        );
    }
    // On a fixed hip the locked leg is rigid: the factor needs a body.
    assert_eq!(
        impact_mitigation::<TwoLink, f64, 2, 0, 2, 2, 0>(
            &arm,
            &q_arm,
            &frame_arm,
            &Body::Fixed,
            None
        ),
        Err(AnalysisError::NotApplicable(
            leg_models::analysis::Inapplicable::RigidWhenLocked
        ))
    );
    // A toe pinned by a closure cannot move with the motors free: the reason names the
    // closures, not a motor count (it has two motors; issue 29 found "the leg has 1 motor").
    {
        use generated::MinitaurPinnedToe as P;
        let p = <P as leg_models::LegDynamics<5, 4, 2>>::Params::<f64>::default();
        let mut q = SVector::<f64, 5>::from(<P as leg_models::LegDynamics<5, 4, 2>>::HOME);
        project_position::<P, f64, 5, 4, 2>(&p, &mut q, &Tolerance::default()).unwrap();
        let frame = LegFrame::<5>::of::<P, 4, 2>();
        let e = impact_mitigation::<P, f64, 5, 4, 2, 2, 4>(&p, &q, &frame, &Body::Fixed, None)
            .unwrap_err();
        assert_eq!(
            e,
            AnalysisError::NotApplicable(leg_models::analysis::Inapplicable::FootHeld),
            "{e}"
        );
        assert!(!e.to_string().contains("1 motor"), "{e}");
    }
    // A heavier body mitigates more (the leg is a smaller share of what hits).
    let light = impact_mitigation::<TwoLink, f64, 2, 0, 2, 2, 0>(
        &arm,
        &q_arm,
        &frame_arm,
        &Body::Translating { mass: 1.0 },
        Some(&coupling),
    )
    .unwrap();
    let heavy = impact_mitigation::<TwoLink, f64, 2, 0, 2, 2, 0>(
        &arm,
        &q_arm,
        &frame_arm,
        &Body::Translating { mass: 100.0 },
        Some(&coupling),
    )
    .unwrap();
    assert!(light < heavy, "{light} {heavy}");
    // Issue 29: a body of 1e308 kg was refused with "the factor needs a body (give its
    // mass)". A body that heavy is the fixed base's limit, where a leg rigid when locked
    // mitigates fully: ξ → 1, approached monotonically by ever heavier bodies.
    let mut last = heavy;
    for mass in [1e4, 1e8, 1e16, 1e308] {
        let xi = impact_mitigation::<TwoLink, f64, 2, 0, 2, 2, 0>(
            &arm,
            &q_arm,
            &frame_arm,
            &Body::Translating { mass },
            Some(&coupling),
        )
        .unwrap();
        assert!(
            xi >= last && xi <= 1.0 + 1e-12,
            "{mass} kg: {xi} after {last}"
        );
        last = xi;
    }
    assert!((last - 1.0).abs() < 1e-9, "{last}");
    let _ = Matrix2::<f64>::identity();
}

/// A one-motor linkage's workspace is its foot's path: Klann's crank turns fully and the
/// path closes on itself (the branch comes back to the start after a turn), every point
/// on the closures at its motor angle; a leg with two motors is told to use the grid.
#[test]
fn a_crank_linkage_traces_a_closed_foot_path() {
    use generated::KlannLinkage;
    use leg_models::analysis::workspace::foot_path;
    let p = generated::klann_linkage::Params::<f64>::default();
    let frame = LegFrame::of::<KlannLinkage, 6, 1>();
    let q = home::<KlannLinkage, 7, 6, 1>(&p);
    let path = foot_path::<KlannLinkage, 7, 6, 1>(&p, &q, &frame, 120, None).unwrap();
    assert!(path.full_turn);
    assert_eq!(path.feet.len(), 121);
    let (first, last) = (path.feet[0], path.feet[120]);
    assert!(
        (first[0] - last[0]).hypot(first[1] - last[1]) < 1e-9,
        "{first:?} {last:?}"
    );
    // After a turn of the crank every joint is back, the crank one turn on.
    let turn = path.poses[120] - path.poses[0];
    let crank = KlannLinkage::ACTUATED[0];
    assert!(
        (turn[crank] - std::f64::consts::TAU).abs() < 1e-9,
        "{turn:?}"
    );
    for d in turn.iter() {
        let off = d - std::f64::consts::TAU * (d / std::f64::consts::TAU).round();
        assert!(off.abs() < 1e-9, "{turn:?}");
    }
    for (theta, q) in path.angles.iter().zip(&path.poses) {
        assert!(KlannLinkage::closure_residual(q, &p).amax() < 1e-12);
        assert_eq!(q[KlannLinkage::ACTUATED[0]], *theta);
    }
    // The path's length converges: four times the samples add less than 1 %.
    let fine = foot_path::<KlannLinkage, 7, 6, 1>(&p, &q, &frame, 480, None).unwrap();
    assert!(
        fine.length >= path.length && fine.length < 1.01 * path.length,
        "{} at 120 samples, {} at 480",
        path.length,
        fine.length
    );
    let minitaur = LegFrame::of::<generated::Minitaur, 2, 2>();
    let pm = generated::minitaur::Params::<f64>::default();
    let qm = home::<generated::Minitaur, 4, 2, 2>(&pm);
    assert!(matches!(
        foot_path::<generated::Minitaur, 4, 2, 2>(&pm, &qm, &minitaur, 60, None),
        Err(AnalysisError::NotApplicable(
            leg_models::analysis::Inapplicable::NotOneMotor { motors: 2 }
        ))
    ));
}
