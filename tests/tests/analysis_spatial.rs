//! Design measures of spatial legs (`leg_models::analysis` with a 3-D foot, vertical `z`)
//! against independent computations, on every spatial leg without naming it:
//!
//! - `Λ⁻¹` with the motors free and locked against the dense null-space method
//!   (`J_f Z (Zᵀ M Z)⁻¹ Zᵀ J_fᵀ`, `Z` a basis of `ker J` from an SVD);
//! - `J_θ` against central differences of poses assembled with one motor moved;
//! - `κ(J_θ)` and the foot's rank against nalgebra's SVD;
//! - every force-polytope vertex held at rest by the motors within their limits, three of
//!   them at a limit (virtual work on the closures' null space); its volume against the
//!   parallelepiped's closed form with three motors;
//! - the speed zonotope's volume and the vertical speed against three-motor closed forms;
//! - `ξ` against the leg with its body written out as three more coordinates (the
//!   momentum Jacobian from central differences of the potential energy under unit
//!   gravity);
//! - legs whose motors do not span the foot are refused with their structure's reason.
//!
//! And the 3-D sets themselves on slabs that no leg gives: a polytope of four to eight
//! slabs against Monte Carlo, a repeated slab, the zonotope's reach with four motors
//! against a two-variable linear program, and the Jacobi singular values against SVD.

use leg_models::analysis::polytope::{
    force_polytope, slab_polytope, speed_zonotope_volume, zonotope_reach,
};
use leg_models::analysis::workspace::{
    workspace, workspace_volume, GridOptions, NodeState, SlicePlane,
};
use leg_models::analysis::{
    extreme_singular_values, foot_inverse_inertia, holding_torque, impact_mitigation,
    motor_kinematics, point_measures, AnalysisError, Body, BodyCoupling, Inapplicable, LegFrame,
    MotorLimits,
};
use leg_models::assembly::{assemble_holding, project_position, Tolerance};
use leg_models::nalgebra::{DMatrix, SMatrix, SVector, Vector3};
use leg_models::{LegDynamics, LegModel, Parameters};
use leg_tests::{not_applicable, Rng};

fn home<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
) -> SVector<f64, NQ>
where
    L: LegDynamics<NQ, NC, NU>,
{
    let mut q = SVector::from(L::HOME);
    project_position::<L, f64, NQ, NC, NU>(p, &mut q, &Tolerance::default())
        .unwrap_or_else(|e| panic!("{}: home does not assemble: {e}", L::NAME));
    q
}

fn limits<const NU: usize>() -> MotorLimits<f64, NU> {
    MotorLimits {
        torque: SVector::from_fn(|k, _| 20.0 * (1.0 + 0.25 * k as f64)),
        speed: SVector::from_fn(|k, _| 10.0 * (1.0 + 0.1 * k as f64)),
    }
}

/// A basis of the null space of `a` (its right singular vectors of singular values under
/// `1e-9` of the largest), from nalgebra's SVD.
fn null_space(a: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.ncols();
    if a.nrows() == 0 {
        return DMatrix::identity(n, n);
    }
    // Square it up with zero rows so that V is n × n.
    let mut square = DMatrix::<f64>::zeros(n.max(a.nrows()), n);
    square.view_mut((0, 0), (a.nrows(), n)).copy_from(a);
    let svd = square.svd(false, true);
    let v_t = svd.v_t.unwrap();
    let top = svd.singular_values.max();
    let cols: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&i| svd.singular_values[i] <= 1e-9 * top.max(1e-300))
        .collect();
    DMatrix::from_fn(n, cols.len(), |r, c| v_t[(cols[c], r)])
}

/// `A C Aᵀ` with `C = Z (Zᵀ M Z)⁻¹ Zᵀ`, `Z` a basis of the motions that keep `J q̇ = 0`
/// with the joints in `locked` at rest: the dense null-space method.
fn dense_delassus(
    m: &DMatrix<f64>,
    j: &DMatrix<f64>,
    a: &DMatrix<f64>,
    locked: &[bool],
) -> DMatrix<f64> {
    let n = m.ncols();
    let rows = j.nrows() + locked.iter().filter(|&&l| l).count();
    let mut c = DMatrix::<f64>::zeros(rows, n);
    c.view_mut((0, 0), (j.nrows(), n)).copy_from(j);
    let mut r = j.nrows();
    for (k, &l) in locked.iter().enumerate() {
        if l {
            c[(r, k)] = 1.0;
            r += 1;
        }
    }
    let z = null_space(&c);
    let reduced = z.transpose() * m * &z;
    let inv = reduced.try_inverse().expect("Zᵀ M Z regular");
    a * &z * inv * z.transpose() * a.transpose()
}

fn dense<const R: usize, const C: usize>(x: &SMatrix<f64, R, C>) -> DMatrix<f64> {
    DMatrix::from_fn(R, C, |r, c| x[(r, c)])
}

/// Central differences of the foot over poses assembled with motor `k` moved by `±h`
/// (the other motors and the held joints fixed): a column of `J_θ`.
fn motor_column<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    k: usize,
) -> Vector3<f64>
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let h = 1e-6;
    let held: [bool; NQ] = core::array::from_fn(|j| frame.held[j] || L::ACTUATED.contains(&j));
    let tight = Tolerance::default();
    let moved = |s: f64| {
        let mut x = *q;
        x[L::ACTUATED[k]] += s * h;
        assemble_holding::<L, f64, NQ, NC, NU>(p, &mut x, &held, &tight).unwrap();
        L::foot_position(&x, p)
    };
    (moved(1.0) - moved(-1.0)) / (2.0 * h)
}

/// The foot's inverse inertia of the leg on a body of mass `body` that translates in
/// space, written out: coordinates `(x_b, q)`, `M_aug = [m_t I, P; Pᵀ, M]` with the
/// momentum Jacobian `P = Σ mᵢ ∂cᵢ/∂q` from central differences of `V` under unit
/// gravity, the closures `[0 J]`, the foot `[I J_f]`.
fn body_delassus<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    body: f64,
    leg_mass: f64,
    locked: &[bool],
) -> DMatrix<f64>
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let names = L::Params::<f64>::NAMES;
    let index = |n: &str| names.iter().position(|x| *x == n).unwrap();
    let g = [index("gravity_x"), index("gravity_y"), index("gravity_z")];
    let mut pm = DMatrix::<f64>::zeros(3, NQ);
    for axis in 0..3 {
        let mut unit = *p;
        for (a, &i) in g.iter().enumerate() {
            unit.set(i, if a == axis { 1.0 } else { 0.0 });
        }
        // V = −Σ m g·c, so ∂V/∂q = −P_axis with g along the axis; springs cancel in the
        // difference with gravity off.
        let mut off = *p;
        for &i in &g {
            off.set(i, 0.0);
        }
        let h = 1e-6;
        for k in 0..NQ {
            let dv = |params: &L::Params<f64>| {
                let (mut a, mut b) = (*q, *q);
                a[k] += h;
                b[k] -= h;
                (L::potential_energy(&a, params) - L::potential_energy(&b, params)) / (2.0 * h)
            };
            pm[(axis, k)] = dv(&off) - dv(&unit);
        }
    }
    let n = NQ + 3;
    let total = body + leg_mass;
    let mut m = DMatrix::<f64>::zeros(n, n);
    for i in 0..3 {
        m[(i, i)] = total;
    }
    m.view_mut((0, 3), (3, NQ)).copy_from(&pm);
    m.view_mut((3, 0), (NQ, 3)).copy_from(&pm.transpose());
    m.view_mut((3, 3), (NQ, NQ))
        .copy_from(&dense(&L::mass_matrix(q, p)));
    let mut j = DMatrix::<f64>::zeros(NC, n);
    j.view_mut((0, 3), (NC, NQ))
        .copy_from(&dense(&L::constraint_jacobian(q, p)));
    let mut a = DMatrix::<f64>::zeros(3, n);
    for i in 0..3 {
        a[(i, i)] = 1.0;
    }
    a.view_mut((0, 3), (3, NQ))
        .copy_from(&dense(&L::foot_jacobian(q, p)));
    let mut lock = vec![false; 3];
    lock.extend_from_slice(locked);
    dense_delassus(&m, &j, &a, &lock)
}

fn check_leg<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>()
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let name = L::NAME;
    let p = L::Params::<f64>::default();
    let frame = LegFrame::of::<L, NC, NU>();
    let q0 = home::<L, NQ, NC, NU>(&p);
    let lim = limits::<NU>();
    let mut rng = Rng::new(42);
    let actuated: Vec<bool> = (0..NQ).map(|j| L::ACTUATED.contains(&j)).collect();
    let held: Vec<bool> = frame.held.to_vec();
    let mut poses = vec![q0];
    for _ in 0..3 {
        let mut q = q0;
        for k in 0..NQ {
            q[k] += 0.05 * rng.range(-1.0, 1.0);
        }
        if project_position::<L, f64, NQ, NC, NU>(&p, &mut q, &Tolerance::default()).is_ok() {
            poses.push(q);
        }
    }
    for (trial, q) in poses.iter().enumerate() {
        let what = format!("{name} pose {trial}");
        // The foot's inverse inertia applies to every leg (motor coordinates or not).
        let m = dense(&L::mass_matrix(q, &p));
        let j = dense(&L::constraint_jacobian(q, &p));
        let jf = dense(&L::foot_jacobian(q, &p));
        for locked in [false, true] {
            let ours = foot_inverse_inertia::<L, f64, NQ, NC, NU, 3, NP>(&p, q, &frame, locked)
                .unwrap_or_else(|e| panic!("{what}: Λ⁻¹: {e}"));
            let lock: Vec<bool> = (0..NQ)
                .map(|c| held[c] || (locked && actuated[c]))
                .collect();
            let theirs = dense_delassus(&m, &j, &jf, &lock);
            // Relative to the open chain's J_f M⁻¹ J_fᵀ: a fully actuated leg's locked Λ⁻¹
            // is zero, rounding on that scale.
            let open = dense_delassus(&m, &DMatrix::zeros(0, NQ), &jf, &vec![false; NQ]);
            let e = (dense(&ours) - &theirs).amax() / open.amax();
            assert!(
                e < 1e-9,
                "{what}: Λ⁻¹ (locked {locked}): {e:e}\n{ours}\n{theirs}"
            );
        }
        // ξ against the body written out (ten times the leg's mass).
        let coupling = BodyCoupling::new::<L, f64, NQ, NC, NU>(&p).expect("masses and gravity");
        // The leg's mass from its links' `<link>_mass`, each link once (a ball joint's three
        // coordinates `rod.x`, `rod.y`, `rod.z` move one link).
        let names = L::Params::<f64>::NAMES;
        let mut links: Vec<&str> = L::JOINT_NAMES
            .iter()
            .map(|j| j.split('.').next().unwrap())
            .collect();
        links.dedup();
        let leg_mass: f64 = links
            .iter()
            .map(|l| {
                let i = names
                    .iter()
                    .position(|n| *n == format!("{l}_mass"))
                    .unwrap();
                p.get(i).unwrap()
            })
            .sum();
        assert!(
            (coupling.leg_mass - leg_mass).abs() < 1e-12 * leg_mass,
            "{what}"
        );
        let body = Body::Translating {
            mass: 10.0 * coupling.leg_mass,
        };
        let xi =
            impact_mitigation::<L, f64, NQ, NC, NU, 3, NP>(&p, q, &frame, &body, Some(&coupling));
        match xi {
            Ok(xi) => {
                let mb = 10.0 * coupling.leg_mass;
                let free = body_delassus::<L, NQ, NC, NU, NP>(&p, q, mb, leg_mass, &held);
                let lock: Vec<bool> = (0..NQ).map(|c| held[c] || actuated[c]).collect();
                let locked = body_delassus::<L, NQ, NC, NU, NP>(&p, q, mb, leg_mass, &lock);
                let theirs = (free.clone() - locked).determinant() / free.determinant();
                assert!(
                    (xi - theirs).abs() < 1e-6 * theirs.abs().max(1e-3),
                    "{what}: ξ {xi} against the body written out {theirs}"
                );
                assert!((-1e-12..=1.0 + 1e-12).contains(&xi), "{what}: ξ {xi}");
            }
            Err(e) => {
                // Only a foot the closures hold to the body is refused.
                assert_eq!(
                    e,
                    AnalysisError::NotApplicable(Inapplicable::FootHeld),
                    "{what}"
                );
                not_applicable(name, "impact mitigation (3-D)", &e);
            }
        }
        let point = point_measures::<L, f64, NQ, NC, NU, 3, NP>(&p, q, &frame, &lim);
        let Err(why) = frame.foot_spans(3) else {
            let pm = point.unwrap_or_else(|e| panic!("{what}: {e}"));
            check_motor_measures::<L, NQ, NC, NU, NP>(&p, q, &frame, &lim, &pm, &what);
            if trial == 0 {
                check_slices::<L, NQ, NC, NU, NP>(&p, q, &frame, &lim);
            }
            continue;
        };
        if trial == 0 {
            not_applicable(
                name,
                "force and speed polytopes, workspace slices (3-D)",
                &why,
            );
            let options = grid::<NU>(8, None, &lim);
            assert_eq!(
                workspace::<L, NQ, NC, NU, 3, NP>(&p, q, &frame, &options).err(),
                Some(AnalysisError::NotApplicable(why)),
                "{what}"
            );
        }
        match frame.motor_coordinates() {
            Ok(()) => {
                // Fewer motors than the foot's coordinates: no polytopes, no κ.
                let pm = point.unwrap_or_else(|e| panic!("{what}: {e}"));
                assert_eq!(pm.vertical_force, None, "{what}");
                assert!(pm.condition.is_infinite(), "{what}");
                assert_eq!(pm.foot_rank, 0.0, "{what}");
                assert!(matches!(
                    why,
                    Inapplicable::FootOnACurve | Inapplicable::FootOnASurface
                ));
            }
            Err(structure) => {
                assert_eq!(why, structure, "{what}");
                assert_eq!(
                    point.err(),
                    Some(AnalysisError::NotApplicable(structure)),
                    "{what}"
                );
            }
        }
    }
}

fn grid<const NU: usize>(
    nodes: usize,
    plane: Option<SlicePlane>,
    lim: &MotorLimits<f64, NU>,
) -> GridOptions<NU> {
    GridOptions {
        nodes,
        window: None,
        plane,
        motor_range: None,
        limits: *lim,
    }
}

/// The workspace in the sagittal and the frontal slice through the stance foot: each
/// reached node's pose is on the closures with its foot on the node's point in the
/// plane, and the stance node is reached.
fn check_slices<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    lim: &MotorLimits<f64, NU>,
) where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let name = L::NAME;
    let stance = L::foot_position(q, p);
    for (plane, normal) in [
        (SlicePlane::SAGITTAL, Vector3::y()),
        (SlicePlane::FRONTAL, Vector3::x()),
    ] {
        let ws = workspace::<L, NQ, NC, NU, 3, NP>(p, q, frame, &grid::<NU>(24, Some(plane), lim))
            .unwrap_or_else(|e| panic!("{name}: slice {plane:?}: {e}"));
        let reached: Vec<usize> = (0..ws.states.len())
            .filter(|&i| ws.states[i] == NodeState::Reached)
            .collect();
        assert!(
            reached.len() > 20,
            "{name}: {} nodes reached",
            reached.len()
        );
        assert!(ws.area > 0.0 && ws.area.is_finite());
        // The node nearest the stance foot is reached.
        let at = ws.grid_coordinates(&stance);
        let (ix, iy) = (
            ((at[0] - ws.origin[0]) / ws.step).round() as usize,
            ((at[1] - ws.origin[1]) / ws.step).round() as usize,
        );
        assert_eq!(ws.states[iy * ws.nodes + ix], NodeState::Reached, "{name}");
        let size = leg_models::assembly::leg_size::<L, f64, NQ, NC, NU>(p, q);
        for &i in &reached {
            let pose = &ws.poses[i];
            let foot = L::foot_position(pose, p);
            let node = ws.node(i % ws.nodes, i / ws.nodes);
            // On the plane through the stance foot, at the node's coordinates.
            assert!(
                (foot - stance).dot(&normal).abs() < 1e-9 * size,
                "{name}: node {i} off the slice"
            );
            let along = [
                foot.dot(&Vector3::from(plane.axes[0])),
                foot.dot(&Vector3::from(plane.axes[1])),
            ];
            assert!(
                (along[0] - node[0]).abs() < 1e-9 * size
                    && (along[1] - node[1]).abs() < 1e-9 * size,
                "{name}: node {i} at {along:?}, not {node:?}"
            );
            assert!(
                L::closure_residual(pose, p).amax() < 1e-9 * size,
                "{name}: node {i} open"
            );
        }
    }
}

/// The measures in motor coordinates of a leg whose motors span the foot.
fn check_motor_measures<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    lim: &MotorLimits<f64, NU>,
    pm: &leg_models::analysis::PointMeasures<f64, NQ, NU, 3>,
    what: &str,
) where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let kin = motor_kinematics::<L, f64, NQ, NC, NU, 3, NP>(p, q, frame).unwrap();
    // J_θ against poses assembled with a motor moved.
    for k in 0..NU {
        let fd = motor_column::<L, NQ, NC, NU, NP>(p, q, frame, k);
        let e = (kin.foot_jacobian.column(k) - fd).amax() / kin.foot_jacobian.amax();
        assert!(e < 1e-6, "{what}: J_θ column {k}: {e:e}");
    }
    // κ and the foot's rank against nalgebra's SVD.
    let sv = dense(&kin.foot_jacobian).svd(false, false).singular_values;
    let kappa = sv.max() / sv.min();
    assert!(
        (pm.condition - kappa).abs() < 1e-9 * kappa,
        "{what}: κ {} against SVD {kappa}",
        pm.condition
    );
    // The foot's rank: σ_min/σ_max of J_f on an orthonormal basis of span G (QR).
    let g = dense(&kin.g);
    let basis = g.clone().qr().q();
    let sv = (dense(&kin.joint_foot_jacobian) * basis)
        .svd(false, false)
        .singular_values;
    let ratio = sv.min() / sv.max();
    assert!(
        (pm.foot_rank.abs() - ratio).abs() < 1e-9,
        "{what}: foot rank {} against SVD {ratio}",
        pm.foot_rank
    );
    assert!(
        pm.effective_mass > 0.0 && pm.effective_mass.is_finite(),
        "{what}"
    );
    let inv_z = pm.inverse_inertia[(2, 2)];
    assert!((pm.effective_mass * inv_z - 1.0).abs() < 1e-12, "{what}");
    // Far from a singularity the passive rank measure is not rounding, structurally
    // redundant rows or not (their pivots counted, a loop at home measured 1e-9): between
    // σ_min / σ_max of the passive columns and its square root (the pivots' estimate).
    let mut jp = dense(&L::constraint_jacobian(q, p));
    for &a in L::ACTUATED.iter() {
        jp.column_mut(a).fill(0.0);
    }
    let sv = jp.svd(false, false).singular_values;
    let mut sv: Vec<f64> = sv
        .iter()
        .copied()
        .filter(|&x| x > 1e-9 * sv.max())
        .collect();
    sv.sort_by(f64::total_cmp);
    let ratio = sv[0] / sv[sv.len() - 1];
    let rank = pm.passive_rank.abs();
    assert!(
        rank > 0.1 * ratio && rank < 10.0 * ratio.sqrt(),
        "{what}: passive rank {rank:e} against σ_min/σ_max {ratio:e}"
    );

    // The force polytope: each vertex is a foot force the motors hold at rest within their
    // limits, three of them (at least) at a limit. Virtual work: the joint torques
    // B u − G − J_fᵀ f do no work on any motion the closures allow.
    let poly = force_polytope::<L, f64, NQ, NC, NU>(p, q, &kin, &lim.torque);
    assert!(
        poly.vertices().len() >= 8,
        "{what}: {} vertices",
        poly.vertices().len()
    );
    let hold = holding_torque::<L, f64, NQ, NC, NU, 3>(p, q, &kin);
    let grav = dense(&L::gravity_forces(q, p));
    let j = dense(&L::constraint_jacobian(q, p));
    let mut c = DMatrix::<f64>::zeros(NC + NQ, NQ);
    c.view_mut((0, 0), (NC, NQ)).copy_from(&j);
    for (r, &h) in frame.held.iter().enumerate() {
        if h {
            c[(NC + r, r)] = 1.0;
        }
    }
    let z = null_space(&c);
    let jf = dense(&L::foot_jacobian(q, p));
    for f in poly.vertices() {
        let u = hold + kin.foot_jacobian.transpose() * f;
        let at_limit = (0..NU)
            .filter(|&k| (u[k].abs() - lim.torque[k]).abs() <= 1e-9 * lim.torque[k])
            .count();
        assert!(
            at_limit >= 3,
            "{what}: vertex {f:?} has {at_limit} motors at a limit"
        );
        assert!(
            (0..NU).all(|k| u[k].abs() <= lim.torque[k] * (1.0 + 1e-9)),
            "{what}: vertex {f:?} beyond a limit: {u:?}"
        );
        let mut tau =
            -grav.clone() - jf.transpose() * DMatrix::from_column_slice(3, 1, f.as_slice());
        for (k, &a) in L::ACTUATED.iter().enumerate() {
            tau[a] += u[k];
        }
        let work = (z.transpose() * &tau).amax();
        assert!(
            work < 1e-8 * (tau.amax() + lim.torque.amax()),
            "{what}: vertex {f:?} not at rest: {work:e}"
        );
    }
    let det = kin.foot_jacobian.determinant_if_square();
    if let Some(det) = det {
        // Three motors: a parallelepiped, volume Π 2τ_k / |det J_θ|.
        let closed: f64 = lim.torque.iter().map(|t| 2.0 * t).product::<f64>() / det.abs();
        assert!(
            (poly.volume() - closed).abs() < 1e-9 * closed,
            "{what}: force polytope volume {} against {closed}",
            poly.volume()
        );
        let zono = speed_zonotope_volume(&kin.foot_jacobian, &lim.speed);
        let closed: f64 = 8.0 * lim.speed.iter().product::<f64>() * det.abs();
        assert!(
            (zono - closed).abs() < 1e-9 * closed,
            "{what}: zonotope {zono} against {closed}"
        );
        // Vertical speed: θ̇ = v J_θ⁻¹ e_z, the first motor to reach its limit bounds v.
        let inv = kin.foot_jacobian.foot_jacobian_square_inverse();
        let closed = (0..NU)
            .map(|k| lim.speed[k] / inv[k].abs())
            .fold(f64::INFINITY, f64::min);
        assert!(
            (pm.vertical_speed - closed).abs() < 1e-9 * closed,
            "{what}: vertical speed {} against {closed}",
            pm.vertical_speed
        );
    }
    // The downward push `f = (0, 0, −F)`: held at rest within the limits, a motor at its
    // limit (so no larger push is held).
    if let Some(push) = pm.vertical_force.filter(|f| f.is_finite()) {
        let f = Vector3::new(0.0, 0.0, -push);
        let u = hold + kin.foot_jacobian.transpose() * f;
        assert!(
            (0..NU).all(|k| u[k].abs() <= lim.torque[k] * (1.0 + 1e-9)),
            "{what}: push {push} beyond a limit: {u:?}"
        );
        assert!(
            (0..NU).any(|k| (u[k].abs() - lim.torque[k]).abs() <= 1e-9 * lim.torque[k]),
            "{what}: push {push} leaves every motor below its limit: {u:?}"
        );
        let mut tau =
            -grav.clone() - jf.transpose() * DMatrix::from_column_slice(3, 1, f.as_slice());
        for (k, &a) in L::ACTUATED.iter().enumerate() {
            tau[a] += u[k];
        }
        assert!(
            (z.transpose() * &tau).amax() < 1e-8 * (tau.amax() + lim.torque.amax()),
            "{what}: push not at rest"
        );
    }
}

trait SquareFoot {
    fn determinant_if_square(&self) -> Option<f64>;
    /// The last column of `J_θ⁻¹` (the motor rates per unit vertical foot speed).
    fn foot_jacobian_square_inverse(&self) -> Vec<f64>;
}

impl<const NU: usize> SquareFoot for SMatrix<f64, 3, NU> {
    fn determinant_if_square(&self) -> Option<f64> {
        (NU == 3).then(|| dense(self).determinant())
    }
    fn foot_jacobian_square_inverse(&self) -> Vec<f64> {
        let inv = dense(self).try_inverse().unwrap();
        (0..NU).map(|k| inv[(k, 2)]).collect()
    }
}

macro_rules! spatial {
    ($name:ident, $ty:ty, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
        #[test]
        fn $name() {
            super::check_leg::<$ty, $nq, $nc, $nu, $np>();
        }
    };
}

mod every_spatial_leg {
    generated::for_each_spatial_model!(spatial);
}

/// The volume of `{f : lo ≤ Aᵀ f ≤ hi}` by Monte Carlo in the parallelepiped of three of
/// its slabs (which holds it; the smallest such), with its own random numbers.
fn monte_carlo<const NU: usize>(
    a: &SMatrix<f64, 3, NU>,
    lo: &SVector<f64, NU>,
    hi: &SVector<f64, NU>,
    rng: &mut Rng,
    samples: usize,
) -> f64 {
    let mut best: Option<([usize; 3], f64)> = None;
    for i in 0..NU {
        for j in i + 1..NU {
            for k in j + 1..NU {
                let b =
                    SMatrix::<f64, 3, 3>::from_columns(&[a.column(i), a.column(j), a.column(k)]);
                let det = b.determinant().abs();
                if det < 1e-6 {
                    continue;
                }
                let v = [i, j, k].iter().map(|&m| hi[m] - lo[m]).product::<f64>() / det;
                if best.is_none_or(|(_, w)| v < w) {
                    best = Some(([i, j, k], v));
                }
            }
        }
    }
    let (three, box_volume) = best.expect("three independent slabs");
    let b = SMatrix::<f64, 3, 3>::from_columns(&[
        a.column(three[0]),
        a.column(three[1]),
        a.column(three[2]),
    ]);
    let bt_inv = b.transpose().try_inverse().unwrap();
    let mut inside = 0;
    for _ in 0..samples {
        let s = Vector3::from_fn(|r, _| rng.range(lo[three[r]], hi[three[r]]));
        let f = bt_inv * s;
        if (0..NU).all(|m| {
            let v = a.column(m).dot(&f);
            v >= lo[m] && v <= hi[m]
        }) {
            inside += 1;
        }
    }
    box_volume * inside as f64 / samples as f64
}

fn random_slabs<const NU: usize>(
    rng: &mut Rng,
) -> (SMatrix<f64, 3, NU>, SVector<f64, NU>, SVector<f64, NU>) {
    let a = SMatrix::<f64, 3, NU>::from_fn(|_, _| rng.range(-1.0, 1.0));
    // Slabs about a common inner point, so that they meet.
    let centre = Vector3::new(
        rng.range(-0.2, 0.2),
        rng.range(-0.2, 0.2),
        rng.range(-0.2, 0.2),
    );
    let mid = a.transpose() * centre;
    let lo = SVector::<f64, NU>::from_fn(|k, _| mid[k] - rng.range(0.3, 1.0));
    let hi = SVector::<f64, NU>::from_fn(|k, _| mid[k] + rng.range(0.3, 1.0));
    (a, lo, hi)
}

fn check_polytopes<const NU: usize>(seed: u64) {
    let mut rng = Rng::new(seed);
    for trial in 0..4 {
        let (a, lo, hi) = random_slabs::<NU>(&mut rng);
        let ours = slab_polytope(&a, &lo, &hi);
        let theirs = monte_carlo(&a, &lo, &hi, &mut rng, 100_000);
        let e = (ours.volume() - theirs).abs() / theirs;
        assert!(
            e < 0.01,
            "{NU} slabs #{trial}: volume {} against Monte Carlo {theirs} ({e:.3})",
            ours.volume()
        );
        // Every vertex is in every slab and on three of their planes.
        for v in ours.vertices() {
            let on = (0..NU)
                .filter(|&m| {
                    let x = a.column(m).dot(v);
                    (x - lo[m]).abs() < 1e-9 || (x - hi[m]).abs() < 1e-9
                })
                .count();
            assert!(on >= 3, "{NU} slabs #{trial}: vertex on {on} planes");
        }
    }
}

#[test]
fn polytopes_of_four_to_eight_slabs_against_monte_carlo() {
    check_polytopes::<3>(1);
    check_polytopes::<4>(2);
    check_polytopes::<5>(3);
    check_polytopes::<6>(4);
    check_polytopes::<8>(5);
}

#[test]
fn a_repeated_slab_counts_its_faces_once() {
    // The unit box |f_i| ≤ 1 with its x slab given twice, once scaled by 2.
    let a = SMatrix::<f64, 3, 4>::new(1.0, 0.0, 0.0, 2.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    let lo = SVector::<f64, 4>::new(-1.0, -1.0, -1.0, -2.0);
    let hi = SVector::<f64, 4>::new(1.0, 1.0, 1.0, 2.0);
    let poly = slab_polytope(&a, &lo, &hi);
    assert_eq!(poly.vertices().len(), 8);
    assert!((poly.volume() - 8.0).abs() < 1e-12, "{}", poly.volume());
    // A cube with its corner cut within rounding and its z slab repeated scaled by 3: the
    // faces found on each slab's plane in the vertices' units, each counted once.
    let a = SMatrix::<f64, 3, 5>::new(
        1.0, 1.0, 0.0, 0.0, 0.0, //
        1.0, 0.0, 1.0, 0.0, 0.0, //
        1.0, 0.0, 0.0, 1.0, 3.0,
    );
    let slack = 9.0 * f64::EPSILON * 1e4;
    let lo = SVector::<f64, 5>::new(0.0, 0.0, 0.0, 0.0, 0.0);
    let hi = SVector::<f64, 5>::new(3.0 - 0.6 * slack, 1.0, 1.0, 1.0, 3.0);
    let poly = slab_polytope(&a, &lo, &hi);
    assert!((poly.volume() - 1.0).abs() < 1e-9, "{}", poly.volume());
    // Slabs that leave a direction free: unbounded.
    let flat = SMatrix::<f64, 3, 3>::new(1.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0);
    let poly = slab_polytope(&flat, &SVector::repeat(-1.0), &SVector::repeat(1.0));
    assert!(poly.volume().is_infinite());
    // Slabs that do not meet: empty.
    let a = SMatrix::<f64, 3, 4>::new(1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    let lo = SVector::<f64, 4>::new(-1.0, -1.0, -1.0, 2.0);
    let hi = SVector::<f64, 4>::new(1.0, 1.0, 1.0, 3.0);
    let poly = slab_polytope(&a, &lo, &hi);
    assert!(poly.vertices().is_empty() && poly.volume() == 0.0);
}

#[test]
fn zonotope_reach_with_four_motors_against_a_linear_program() {
    // max v subject to J θ̇ = v e_z, |θ̇_k| ≤ ω_k. With four motors θ̇ = v t + s n (J t = e_z,
    // n spanning ker J): for each v the feasible s form an interval; bisect on v.
    let mut rng = Rng::new(7);
    for trial in 0..20 {
        let j = SMatrix::<f64, 3, 4>::from_fn(|_, _| rng.range(-1.0, 1.0));
        let w = SVector::<f64, 4>::from_fn(|_, _| rng.range(0.5, 2.0));
        let ours = zonotope_reach(&j, &w, &Vector3::z());
        let jd = dense(&j);
        let t = jd.clone().pseudo_inverse(1e-12).unwrap()
            * DMatrix::from_column_slice(3, 1, &[0.0, 0.0, 1.0]);
        let n = null_space(&jd);
        assert_eq!(n.ncols(), 1);
        let feasible = |v: f64| {
            let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
            for k in 0..4 {
                let (a, b) = (v * t[k], n[(k, 0)]);
                if b.abs() < 1e-15 {
                    if a.abs() > w[k] {
                        return false;
                    }
                    continue;
                }
                let (x, y) = ((-w[k] - a) / b, (w[k] - a) / b);
                lo = lo.max(x.min(y));
                hi = hi.min(x.max(y));
            }
            lo <= hi
        };
        let (mut a, mut b) = (0.0, 1e3);
        for _ in 0..200 {
            let m = 0.5 * (a + b);
            if feasible(m) {
                a = m;
            } else {
                b = m;
            }
        }
        assert!(
            (ours - a).abs() < 1e-9 * a,
            "#{trial}: reach {ours} against the linear program {a}"
        );
        // Its volume: the zonotope is the polytope of its facets' slabs, one per pair of
        // generators g_i × g_j, bounded by ± Σ_k |n · g_k|.
        let g = |k: usize| j.column(k) * w[k];
        let mut normals = SMatrix::<f64, 3, 6>::zeros();
        let mut bound = SVector::<f64, 6>::zeros();
        let mut c = 0;
        for i in 0..4 {
            for k in i + 1..4 {
                let n = g(i).cross(&g(k));
                normals.set_column(c, &n);
                bound[c] = (0..4).map(|m| n.dot(&g(m)).abs()).sum();
                c += 1;
            }
        }
        let facets = slab_polytope(&normals, &(-bound), &bound).volume();
        let zono = speed_zonotope_volume(&j, &w);
        assert!(
            (zono - facets).abs() < 1e-9 * facets,
            "#{trial}: {zono} against {facets}"
        );
    }
}

#[test]
fn jacobi_singular_values_against_svd() {
    let mut rng = Rng::new(11);
    for trial in 0..200 {
        let mut a = SMatrix::<f64, 3, 4>::from_fn(|_, _| rng.range(-1.0, 1.0));
        if trial % 2 == 1 {
            // Nearly singular: the third row close to a mix of the first two.
            let mix = a.row(0) * 0.3 - a.row(1) * 0.7;
            let tiny = 10f64.powi(-(trial % 12) - 2);
            let noise = SMatrix::<f64, 1, 4>::from_fn(|_, _| tiny * rng.range(-1.0, 1.0));
            a.set_row(2, &(mix + noise));
        }
        let (hi, lo) = extreme_singular_values(&a);
        let sv = dense(&a).svd(false, false).singular_values;
        assert!((hi - sv.max()).abs() < 1e-13 * sv.max(), "#{trial}");
        // Jacobi keeps σ_min to relative accuracy; the SVD's own error is ε σ_max.
        assert!(
            (lo - sv.min()).abs() < 1e-13 * sv.max(),
            "#{trial}: σ_min {lo:e} against {:e}",
            sv.min()
        );
    }
    // Fewer columns than rows: σ_min = 0.
    let a = SMatrix::<f64, 3, 2>::new(1.0, 0.0, 0.0, 1.0, 1.0, 1.0);
    assert!(extreme_singular_values(&a).1 < 1e-15);
}

#[test]
fn revolute_knee_slices_against_their_closed_forms() {
    // The thigh (0.2 m) and shin (0.25 m) put the foot anywhere at 0.05 to 0.45 m from the
    // hip pitch joint in the pitch plane (the knee turns freely); that plane turns with the
    // abduction about x, 0.06 m off the x axis. In the frame turned by the abduction the foot
    // is (a, 0.06, c) with a² + c² in [0.05², 0.45²]: the foot at (x, y, z) has
    // x² + y² + z² − 0.06² in that range, with y² + z² ≥ 0.06².
    // - Sagittal slice y = y₀ (|y₀| > 0.06): x² + z² in [0.05² + 0.06² − y₀², 0.45² + 0.06² −
    //   y₀²], an annulus (a disc where the first is negative) of area
    //   π (0.45² − max(0.05², y₀² − 0.06²)): π (0.45² − 0.05²) for |y₀| up to 0.078 m.
    // - Frontal slice x = x₀: y² + z² − 0.06² in [0.05² − x₀², 0.45² − x₀²] and ≥ 0: an
    //   annulus of area π (0.45² − max(x₀², 0.05²)).
    type L = generated::revolute_knee_leg::RevoluteKneeLeg;
    let p = <L as LegDynamics<7, 5, 3>>::Params::<f64>::default();
    let q = home::<L, 7, 5, 3>(&p);
    let frame = LegFrame::of::<L, 5, 3>();
    let foot = <L as LegModel<7, 5, 3, 3, 2>>::foot_position(&q, &p);
    assert!(foot[1].abs() > 0.06, "stance y {}", foot[1]);
    let (r, big) = (0.05f64, 0.45f64);
    let lim = limits::<3>();
    // Other abductions move y₀ and the sagittal slice shrinks as the formula says.
    for abduction in [0.3, 0.6] {
        let mut q2 = q;
        q2[0] = abduction;
        project_position::<L, f64, 7, 5, 3>(&p, &mut q2, &Tolerance::default()).unwrap();
        let y0 = <L as LegModel<7, 5, 3, 3, 2>>::foot_position(&q2, &p)[1];
        let closed = std::f64::consts::PI * (big * big - (y0 * y0 - 0.0036).max(r * r));
        let ws =
            workspace::<L, 7, 5, 3, 3, 2>(&p, &q2, &frame, &grid::<3>(80, None, &lim)).unwrap();
        let e = (ws.area - closed).abs() / closed;
        assert!(
            e < 0.01,
            "abduction {abduction}: {} m² against {closed} m² ({e:.4})",
            ws.area
        );
    }
    for (plane, closed) in [
        (
            SlicePlane::SAGITTAL,
            std::f64::consts::PI * (big * big - (foot[1] * foot[1] - 0.0036).max(r * r)),
        ),
        (
            SlicePlane::FRONTAL,
            std::f64::consts::PI * (big * big - (foot[0] * foot[0]).max(r * r)),
        ),
    ] {
        let ws = workspace::<L, 7, 5, 3, 3, 2>(&p, &q, &frame, &grid::<3>(80, Some(plane), &lim))
            .unwrap();
        // Axes given longer are made unit: the same grid.
        let long = SlicePlane {
            axes: plane.axes.map(|a| a.map(|x| 2.0 * x)),
        };
        let same = workspace::<L, 7, 5, 3, 3, 2>(&p, &q, &frame, &grid::<3>(20, Some(long), &lim))
            .unwrap();
        let unit = workspace::<L, 7, 5, 3, 3, 2>(&p, &q, &frame, &grid::<3>(20, Some(plane), &lim))
            .unwrap();
        assert_eq!((same.area, same.origin), (unit.area, unit.origin));
        let e = (ws.area - closed).abs() / closed;
        assert!(
            e < 0.01,
            "{plane:?}: slice area {} m² against {closed} m² ({e:.4})",
            ws.area
        );
    }
}

#[test]
fn slices_are_refused_where_they_do_not_apply() {
    // A planar leg's workspace is its own plane.
    type P = generated::minitaur::Minitaur;
    let p = <P as LegDynamics<4, 2, 2>>::Params::<f64>::default();
    let q = home::<P, 4, 2, 2>(&p);
    let frame = LegFrame::of::<P, 2, 2>();
    let e = workspace::<P, 4, 2, 2, 2, 2>(
        &p,
        &q,
        &frame,
        &grid::<2>(8, Some(SlicePlane::SAGITTAL), &limits::<2>()),
    )
    .unwrap_err();
    assert_eq!(e, AnalysisError::NotApplicable(Inapplicable::PlanarSlice));
    // Axes that are not orthogonal, or not finite.
    assert!(SlicePlane::new([1.0, 0.0, 0.0], [1.0, 1.0, 0.0]).is_err());
    assert!(SlicePlane::new([f64::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]).is_err());
    assert!(SlicePlane::new([0.0; 3], [0.0, 1.0, 0.0]).is_err());
    let tilted = SlicePlane::new([1.0, 1.0, 0.0], [0.0, 0.0, 2.0]).unwrap();
    assert!((Vector3::from(tilted.axes[0]).norm() - 1.0).abs() < 1e-15);
    // A bad plane in the options is refused before any work.
    type S = generated::abducted_five_bar::AbductedFiveBar;
    let p = <S as LegDynamics<5, 3, 3>>::Params::<f64>::default();
    let q = home::<S, 5, 3, 3>(&p);
    let bad = SlicePlane {
        axes: [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
    };
    let e = workspace::<S, 5, 3, 3, 3, 2>(
        &p,
        &q,
        &LegFrame::of::<S, 3, 3>(),
        &grid::<3>(8, Some(bad), &limits::<3>()),
    )
    .unwrap_err();
    assert!(matches!(e, AnalysisError::Grid { .. }), "{e}");
}

#[test]
fn revolute_knee_volume_against_its_closed_form() {
    // The foot is (a, 0.06, c) in the frame the abduction turns, a² + c² in [0.05², 0.45²]:
    // in space, |p|² − 0.06² in that range with the distance from the x axis ρ ≥ 0.06.
    // With c² = ρ² − 0.06² (ρ dρ = c dc) the volume is 2π ∫∫ c dc da over the half annulus
    // c ≥ 0: 2π × its first moment about the diameter, (4π/3)(0.45³ − 0.05³).
    type L = generated::revolute_knee_leg::RevoluteKneeLeg;
    let p = <L as LegDynamics<7, 5, 3>>::Params::<f64>::default();
    let q = home::<L, 7, 5, 3>(&p);
    let frame = LegFrame::of::<L, 5, 3>();
    let closed = 4.0 * std::f64::consts::PI / 3.0 * (0.45f64.powi(3) - 0.05f64.powi(3));
    // A coarse grid (its cells 4.4 cm) for a debug build: 3.8 % off at 24 nodes a side,
    // 0.1 % at 32 (`cargo xtask analyze revolute_knee_leg --volume 32`).
    let v = workspace_volume::<L, 7, 5, 3, 2>(&p, &q, &frame, 24, None).unwrap();
    let e = (v.volume - closed).abs() / closed;
    assert!(
        e < 0.06,
        "volume {} m³ against {closed} m³ ({e:.4})",
        v.volume
    );
    assert_eq!(v.states.len(), 24 * 24 * 24);
    assert_eq!(
        v.reached,
        v.states
            .iter()
            .filter(|&&s| s == NodeState::Reached)
            .count()
    );
    // A motor range the start is outside of, and bad node counts, are refused.
    let e = workspace_volume::<L, 7, 5, 3, 2>(&p, &q, &frame, 1, None).unwrap_err();
    assert!(matches!(e, AnalysisError::Grid { .. }), "{e}");
    let e = workspace_volume::<L, 7, 5, 3, 2>(&p, &q, &frame, 101, None).unwrap_err();
    assert!(matches!(e, AnalysisError::Grid { .. }), "{e}");
    let away = [(q[0] + 0.5, q[0] + 1.0); 3];
    let e = workspace_volume::<L, 7, 5, 3, 2>(&p, &q, &frame, 8, Some(&away)).unwrap_err();
    assert!(matches!(e, AnalysisError::StartOutOfRange { .. }), "{e}");
    // A leg whose motors do not span its foot has no volume.
    type R = generated::rssr_linkage::RssrLinkage;
    let p = <R as LegDynamics<5, 3, 1>>::Params::<f64>::default();
    let q = home::<R, 5, 3, 1>(&p);
    let e =
        workspace_volume::<R, 5, 3, 1, 2>(&p, &q, &LegFrame::of::<R, 3, 1>(), 8, None).unwrap_err();
    assert!(matches!(e, AnalysisError::NotApplicable(_)), "{e}");
}
