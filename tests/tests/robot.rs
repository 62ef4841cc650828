//! Floating robots (`generated::for_each_floating_model!`, `leg_models::robot`): the body's
//! pose on its free joint, against laws the code does not use.
//!
//! - In zero gravity, with motors pushing the joints, the robot's linear momentum and its
//!   angular momentum about the world's origin stay what they were (nothing outside acts);
//!   with gravity, the linear momentum grows by `m g t` exactly;
//! - passive and undamped, the energy in the world (with the body's height) stays;
//! - the chart moved to the body every step gives the trajectory of one chart held
//!   fixed for the whole run (where it stays away from its singularity), the latter
//!   turned into the world by rotation matrices written in the test;
//! - the quaternion stays unit, `q̇_quat = ½ q ⊗ (0, ω)` and `v̇` against differences of
//!   the pose and velocity over a step each way, at two sizes combined (Richardson);
//! - every run steps at the robot's own time scale (`time_step`).
//! - standing on coplanar feet (forces equal to the spec masses' weight) and landing on
//!   them (the impulses' energy identity, the momentum balance);
//! - where home is not a pose the least torques hold (Cassie's unloaded springs), standing
//!   where `robot::standing::standing_pose` puts it, and still there;
//! - balanced by the QP and pushed: every foot's force, from the simulator, inside its
//!   friction cone (two points of one rigid foot split as deep in their cones as any
//!   split goes), and back where it stood.

use leg_models::nalgebra::{SVector, UnitQuaternion, Vector3};
use leg_models::robot::balance::{cone_reading, judged_forces};
use leg_models::robot::standing::assembled_home;
use leg_models::robot::{self, RobotState};
use leg_models::simulate::State;
use leg_models::simulate::{step as fixed_step, StepOptions};
use leg_models::LegDynamics;
use leg_tests::standing::{spec_mass, standing_start, with_gravity, Stance};
use leg_tests::Rng;

/// A tumbling start: the body off the origin, turned, moving and spinning; the joints at
/// home (assembled), with rates that keep the closures.
fn tumbling<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    seed: u64,
) -> RobotState<f64, NQ>
where
    L: LegDynamics<NQ, NC, NU>,
{
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let mut rng = Rng::new(seed);
    let q = assembled_home::<L, NQ, NC, NU>(p).unwrap_or_else(|e| panic!("{}: {e}", L::NAME));
    let orientation = UnitQuaternion::from_euler_angles(0.3, -0.2, 0.7);
    let mut s = RobotState::at_rest(Vector3::new(0.4, -0.3, 1.2), orientation, q);
    // Closing the loops may have moved the body too (a home off its closures by a little,
    // as an imported one is): fold that into the pose so the chart is centred on it.
    s.recentre(f);
    // The body tumbles; the joints move gently (a light leg driven hard reaches its
    // loops' singularities within a fraction of a second, which is not what is tested).
    for k in 0..NQ {
        let size = if (f..f + 6).contains(&k) { 1.0 } else { 0.3 };
        s.v[k] = rng.range(-size, size);
    }
    leg_models::assembly::project_velocity::<L, f64, NQ, NC, NU>(p, &s.q, &mut s.v).unwrap();
    s
}

/// Motor torques that move the joints back and forth about home without driving them far:
/// a critically damped pull to home at 10 rad/s and a push of 2 rad/s² at 3 rad/s, each
/// scaled by the joint's own inertia. Internal forces only.
fn excitation<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: L::Params<f64>,
) -> impl FnMut(f64, &State<f64, NQ>) -> SVector<f64, NU>
where
    L: LegDynamics<NQ, NC, NU>,
{
    move |t: f64, s: &State<f64, NQ>| {
        let m = L::mass_matrix(&s.q, &p);
        SVector::<f64, NU>::from_fn(|i, _| {
            let a = L::ACTUATED[i];
            let pull = -100.0 * (s.q[a] - L::HOME[a]) - 20.0 * s.qd[a];
            m[(a, a)] * (pull + 2.0 * (3.0 * t + i as f64).sin())
        })
    }
}

/// The robot's own time scale: the largest RK4 step, of 2 ms halved until it is, whose
/// local error on the passive tumbling motion is below 1e-6 of the state's size. The
/// error of one step of `dt` is estimated by step doubling: one step against two half
/// steps differ by `Δ`, and as RK4's local error falls 32-fold per halving the step's
/// own error is `Δ · 32/31`. Light links with damping (Cassie's achilles rods, whose spin
/// about their own axis has almost no inertia) have fast modes and ask for a shorter
/// step than a light open chain; the tests below take their steps from this.
fn time_step<L, const NQ: usize, const NC: usize, const NU: usize>(p: &L::Params<f64>) -> f64
where
    L: LegDynamics<NQ, NC, NU>,
{
    let name = L::NAME;
    let start = tumbling::<L, NQ, NC, NU>(p, 30);
    let mut passive = |_: f64, _: &State<f64, NQ>| SVector::<f64, NU>::zeros();
    let scale = start.v.amax().max(start.position.norm()).max(1.0);
    let mut dt = 2e-3;
    let mut report = Vec::new();
    for _ in 0..8 {
        let mut whole = start;
        let one = robot::step::<L, f64, NQ, NC, NU>(
            p,
            &mut whole,
            0.0,
            &mut passive,
            &StepOptions::rk4(dt),
        );
        let mut halves = start;
        let h = dt / 2.0;
        let two = (0..2).try_for_each(|i| {
            robot::step::<L, f64, NQ, NC, NU>(
                p,
                &mut halves,
                i as f64 * h,
                &mut passive,
                &StepOptions::rk4(h),
            )
            .map(|_| ())
        });
        // A step that fails (a blow-up) is too long as well.
        let error = if one.is_ok() && two.is_ok() {
            ((whole.v - halves.v).amax())
                .max((whole.q - halves.q).amax())
                .max((whole.position - halves.position).amax())
                .max(whole.orientation.angle_to(&halves.orientation))
                * (32.0 / 31.0)
        } else {
            f64::INFINITY
        };
        report.push(format!("{:.4} ms: {:.1e}", dt * 1e3, error / scale));
        if error.is_finite() && error < 1e-6 * scale {
            eprintln!(
                "{name}: time step {:.4} ms (RK4 local errors {})",
                dt * 1e3,
                report.join(", ")
            );
            return dt;
        }
        dt /= 2.0;
    }
    panic!(
        "{name}: no RK4 step down to {} s keeps the local error small: {}",
        dt * 2.0,
        report.join(", ")
    );
}

/// The largest drift of the linear and angular momentum over `duration` at step `dt`, and
/// the quaternion's largest distance from the unit sphere.
fn momentum_drift<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    dt: f64,
    duration: f64,
) -> (f64, f64, f64, RobotState<f64, NQ>)
where
    L: LegDynamics<NQ, NC, NU>,
{
    let name = L::NAME;
    let mut s = tumbling::<L, NQ, NC, NU>(p, 31);
    let (lin0, ang0) = robot::momentum::<L, f64, NQ, NC, NU>(p, &s).unwrap();
    let mut motors = excitation::<L, NQ, NC, NU>(*p);
    let opts = StepOptions::rk4(dt);
    let (mut lin_err, mut ang_err, mut unit_err) = (0.0f64, 0.0f64, 0.0f64);
    let steps = (duration / dt).round() as usize;
    for i in 0..steps {
        robot::step::<L, f64, NQ, NC, NU>(p, &mut s, i as f64 * dt, &mut motors, &opts)
            .unwrap_or_else(|e| panic!("{name}: step {i}: {e}"));
        let (lin, ang) = robot::momentum::<L, f64, NQ, NC, NU>(p, &s).unwrap();
        lin_err = lin_err.max((lin - lin0).norm() / lin0.norm().max(1.0));
        ang_err = ang_err.max((ang - ang0).norm() / ang0.norm().max(1.0));
        unit_err = unit_err.max((s.orientation.into_inner().norm() - 1.0).abs());
    }
    (lin_err, ang_err, unit_err, s)
}

/// Momentum is a law of the equations, not of RK4 (it is not linear in the state): the
/// drift is the integrator's, falling as `dt⁴`, or at rounding already.
fn momentum_is_kept<L, const NQ: usize, const NC: usize, const NU: usize>()
where
    L: LegDynamics<NQ, NC, NU>,
{
    let name = L::NAME;
    let p = with_gravity::<L, NQ, NC, NU>([0.0, 0.0, 0.0], true);
    // 1 s, or 500 of the robot's steps but at least 62.5 ms where its time scale is short
    // (the laws hold over any span; a debug build takes milliseconds per step of a
    // 32-coordinate robot).
    let dt = time_step::<L, NQ, NC, NU>(&p);
    let duration = (500.0 * dt).clamp(0.0625, 1.0);
    let (lin1, ang1, unit1, s) = momentum_drift::<L, NQ, NC, NU>(&p, dt, duration);
    let (lin2, ang2, unit2, _) = momentum_drift::<L, NQ, NC, NU>(&p, dt / 2.0, duration);
    // The joints turned: the run is not trivially still.
    let home = SVector::<f64, NQ>::from_column_slice(&L::HOME);
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let moved = (f + 6..NQ)
        .map(|k| (s.q[k] - home[k]).abs())
        .fold(0.0, f64::max);
    assert!(moved > 0.01, "{name}: the joints hardly moved ({moved})");
    eprintln!(
        "{name}: {duration} s in zero gravity, motors on (joints moved {moved:.3} rad at most), relative drift of P and L: {lin1:.1e}, {ang1:.1e} at dt {:.3} ms; {lin2:.1e}, {ang2:.1e} at half of it; quaternion norm off by {:.1e}",
        dt * 1e3,
        unit1.max(unit2)
    );
    let fourth_order = |a: f64, b: f64| b < 1e-12 || (b < 1e-7 && a / b > 10.0);
    assert!(
        fourth_order(lin1, lin2),
        "{name}: linear momentum drifts {lin1:e} then {lin2:e}"
    );
    assert!(
        fourth_order(ang1, ang2),
        "{name}: angular momentum drifts {ang1:e} then {ang2:e}"
    );
    assert!(
        unit1.max(unit2) < 1e-14,
        "{name}: the quaternion left the unit sphere"
    );
}

fn falls_with_gravity<L, const NQ: usize, const NC: usize, const NU: usize>()
where
    L: LegDynamics<NQ, NC, NU>,
{
    let name = L::NAME;
    // Gravity along a slant: nothing about the code's axes is special.
    let g = Vector3::new(1.5, -2.0, -9.0);
    let p = with_gravity::<L, NQ, NC, NU>([g[0], g[1], g[2]], false);
    let mut s = tumbling::<L, NQ, NC, NU>(&p, 32);
    let (lin0, _) = robot::momentum::<L, f64, NQ, NC, NU>(&p, &s).unwrap();
    let (k0, v0) = robot::energies::<L, f64, NQ, NC, NU>(&p, &s).unwrap();
    let mass = spec_mass::<L, NQ, NC, NU>(&p);
    let mut passive = |_: f64, _: &State<f64, NQ>| SVector::<f64, NU>::zeros();
    let dt = time_step::<L, NQ, NC, NU>(&p) / 2.0;
    let opts = StepOptions::rk4(dt);
    let mut energy_err = 0.0f64;
    let steps = 500usize;
    let duration = steps as f64 * dt;
    for i in 0..steps {
        robot::step::<L, f64, NQ, NC, NU>(&p, &mut s, i as f64 * dt, &mut passive, &opts)
            .unwrap_or_else(|e| panic!("{name}: step {i}: {e}"));
        let (k, v) = robot::energies::<L, f64, NQ, NC, NU>(&p, &s).unwrap();
        energy_err = energy_err.max((k + v - k0 - v0).abs());
    }
    let (lin, _) = robot::momentum::<L, f64, NQ, NC, NU>(&p, &s).unwrap();
    let expected = lin0 + g * (mass * duration);
    let scale = (k0.abs() + v0.abs()).max(1.0);
    eprintln!(
        "{name}: {duration} s falling: |P − (P₀ + m g t)| {:.1e} (m {mass:.4} kg), energy off by {energy_err:.1e} J of {scale:.2}",
        (lin - expected).norm()
    );
    assert!(
        (lin - expected).norm() < 1e-9 * expected.norm(),
        "{name}: P {lin} not P₀ + m g t = {expected}"
    );
    assert!(
        energy_err < 1e-8 * scale,
        "{name}: energy moved by {energy_err:e} J"
    );
}

/// The recentred run against one chart held at the start's centre: the same motion in
/// two charts, so the same world pose and velocity at the end.
fn recentring_matches_a_fixed_chart<L, const NQ: usize, const NC: usize, const NU: usize>()
where
    L: LegDynamics<NQ, NC, NU>,
{
    let name = L::NAME;
    let p = with_gravity::<L, NQ, NC, NU>([0.3, 0.5, -9.81], true);
    let start = tumbling::<L, NQ, NC, NU>(&p, 33);
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let mut motors = excitation::<L, NQ, NC, NU>(p);
    // Half the robot's step, for 0.3 s, or 1200 steps but at least 75 ms where its time
    // scale is short: long enough to turn (the start spins at up to 1 rad/s an axis).
    let dt = time_step::<L, NQ, NC, NU>(&p) / 2.0;
    let opts = StepOptions::rk4(dt);
    let duration = (1200.0 * dt).clamp(0.075, 0.3);
    let steps = (duration / dt).round() as usize;
    let mut moving = start;
    for i in 0..steps {
        robot::step::<L, f64, NQ, NC, NU>(&p, &mut moving, i as f64 * dt, &mut motors, &opts)
            .unwrap();
    }
    let chart = robot::chart_params::<L, f64, NQ, NC, NU>(&p, &start.orientation).unwrap();
    let mut fixed = State {
        q: start.q,
        qd: start.v,
    };
    for i in 0..steps {
        fixed_step::<L, f64, NQ, NC, NU>(&chart, &mut fixed, i as f64 * dt, &mut motors, &opts)
            .unwrap();
    }
    let turned_by = (f + 3..f + 6).map(|k| fixed.q[k].abs()).fold(0.0, f64::max);
    // At least 0.3 rad/s on some axis over the run (0.09 rad in 0.3 s).
    assert!(
        turned_by > 0.3 * duration,
        "{name}: the body hardly turned in the fixed chart ({turned_by} rad)"
    );
    // The fixed chart's pose and velocities in the world, by rotation matrices written
    // here: p = p₀ + R₀ δ, R = R₀ R_x(α) R_y(β) R_z(γ); ṗ = R₀ δ̇, and the angles' rates
    // turned into the world one axis at a time.
    use leg_models::nalgebra::Rotation3;
    let c = |k: usize| fixed.q[f + k];
    let rate = |k: usize| fixed.qd[f + k];
    let (rx, ry, rz) = (
        Rotation3::from_axis_angle(&Vector3::x_axis(), c(3)),
        Rotation3::from_axis_angle(&Vector3::y_axis(), c(4)),
        Rotation3::from_axis_angle(&Vector3::z_axis(), c(5)),
    );
    let r0 = start.orientation.to_rotation_matrix();
    let position = start.position + r0 * Vector3::new(c(0), c(1), c(2));
    let turned = r0 * rx * ry * rz;
    let velocity = r0 * Vector3::new(rate(0), rate(1), rate(2));
    let spin = r0
        * (Vector3::x() * rate(3)
            + rx * (Vector3::y() * rate(4))
            + rx * ry * (Vector3::z() * rate(5)));
    let r1 = moving.orientation.to_rotation_matrix();
    let lin = Vector3::new(moving.v[f], moving.v[f + 1], moving.v[f + 2]);
    let ang = Vector3::new(moving.v[f + 3], moving.v[f + 4], moving.v[f + 5]);
    let dp = (position - moving.position).norm();
    let dr = (turned.matrix() - r1.matrix()).amax();
    let joints = (f + 6..NQ)
        .map(|k| {
            (fixed.qd[k] - moving.v[k])
                .abs()
                .max((fixed.q[k] - moving.q[k]).abs())
        })
        .fold(0.0, f64::max);
    let dv = (velocity - r1 * lin)
        .norm()
        .max((spin - r1 * ang).norm())
        .max(joints);
    eprintln!("{name}: recentred every step vs one chart ({:.3} s, the body turned {turned_by:.3} rad): |Δp| {dp:.1e} m, angle {dr:.1e} rad, |Δv| {dv:.1e}", steps as f64 * dt);
    assert!(
        dp < 1e-9 && dr < 1e-9 && dv < 1e-8,
        "{name}: Δp {dp:e}, angle {dr:e}, Δv {dv:e}"
    );
}

/// `ṗ = R v_b` and `q̇_quat = ½ q ⊗ (0, ω)` against the pose's central differences in time.
fn pose_rate_is_the_pose_derivative<L, const NQ: usize, const NC: usize, const NU: usize>()
where
    L: LegDynamics<NQ, NC, NU>,
{
    let name = L::NAME;
    let p = with_gravity::<L, NQ, NC, NU>([0.0, 0.0, -9.81], true);
    let s = tumbling::<L, NQ, NC, NU>(&p, 34);
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let (pd, qd) = s.pose_rate(f);
    // Central differences over h and h/2, combined (Richardson) to cancel their h² error:
    // h is a two-hundredth of the robot's step (1e-5 s where that is 2 ms).
    let h = time_step::<L, NQ, NC, NU>(&p) / 200.0;
    let mut zero = |_: f64, _: &State<f64, NQ>| SVector::<f64, NU>::zeros();
    let mut moved = |h: f64| {
        let mut ahead = s;
        robot::step::<L, f64, NQ, NC, NU>(&p, &mut ahead, 0.0, &mut zero, &StepOptions::rk4(h))
            .unwrap();
        let mut behind = s;
        robot::step::<L, f64, NQ, NC, NU>(&p, &mut behind, 0.0, &mut zero, &StepOptions::rk4(-h))
            .unwrap();
        (ahead, behind)
    };
    let (ahead, behind) = moved(h);
    let (near_ahead, near_behind) = moved(h / 2.0);
    let difference = |a: &RobotState<f64, NQ>, b: &RobotState<f64, NQ>, h: f64| {
        (
            (a.position - b.position) / (2.0 * h),
            (a.orientation.into_inner() - b.orientation.into_inner()) / (2.0 * h),
        )
    };
    let (p_wide, q_wide) = difference(&ahead, &behind, h);
    let (p_near, q_near) = difference(&near_ahead, &near_behind, h / 2.0);
    let pd_fd = (p_near * 4.0 - p_wide) / 3.0;
    let qd_fd = (q_near * 4.0 - q_wide) / 3.0;
    let e_p = (pd - pd_fd).norm();
    let e_q = (qd - qd_fd).norm();
    assert!(
        e_p < 1e-8 * pd.norm().max(1.0),
        "{name}: ṗ {pd} vs differences {pd_fd}"
    );
    assert!(
        e_q < 1e-8 * qd.norm().max(1.0),
        "{name}: q̇ {qd} vs differences {qd_fd}"
    );
    // v̇ (Pinocchio's convention for a free flyer: the derivative of the body-frame
    // velocities) against the same differences of v.
    let a = robot::forward_dynamics_at::<L, f64, NQ, NC, NU>(&p, &s, &SVector::zeros()).unwrap();
    let vd = robot::velocity_derivative(f, &s.v, &a.qdd);
    let vd_fd = (4.0 * (near_ahead.v - near_behind.v) / h - (ahead.v - behind.v) / (2.0 * h)) / 3.0;
    let e_v = (vd - vd_fd).amax();
    assert!(
        e_v < 1e-6 * vd.amax().max(1.0),
        "{name}: v̇ off its differences by {e_v:e}"
    );
}

/// The robot at home on a ground through its contact points (their plane), holding still
/// with the least torques that do: it stays at rest for a second, and the ground forces
/// add up to its weight, the spec's masses times gravity.
fn stands_still_on_its_feet<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    let name = L::NAME;
    let Some(Stance {
        params: p,
        start: mut s,
        ground,
        modes,
        mu,
    }) = standing_start::<L, NQ, NC, NU, NK>("standing")
    else {
        return;
    };
    let size = L::leg_size(&s.q, &p);
    let (u, left) =
        robot::holding_torques::<L, f64, NQ, NC, NU, NK>(&p, &s, &modes, &ground, &mu).unwrap();
    // Every contact pushes on the ground at the pose (held contacts are bilateral in the
    // solve, so a pose found by the torques alone could pull on a heel). The cones are
    // not asked of the least torques: they squeeze the quadruped's feet sideways out of
    // theirs (the balance QP is what keeps forces in them); printed.
    let at_start =
        robot::stance_dynamics::<L, f64, NQ, NC, NU, NK>(&p, &s, &u, &modes, &ground, &mu).unwrap();
    let forces =
        judged_forces::<L, NQ, NC, NU, NK>(&p, &s, &at_start, &modes, &ground, &mu).unwrap();
    let mut cone = 0.0f64;
    for k in 0..NK / 3 {
        let c = cone_reading(&forces, &ground, &mu, k);
        assert!(
            c.normal > 0.0,
            "{name}: contact {k} pulls at the standing pose: {:.3} N",
            c.normal
        );
        cone = cone.max(c.ratio);
    }
    eprintln!("{name}: at the standing pose the least holding torques' forces reach {cone:.3} of a friction cone (a rigid foot's split the deepest)");
    // The weight from the spec's masses, not from the dynamics.
    let mass = spec_mass::<L, NQ, NC, NU>(&p);
    let weight = Vector3::new(0.0, 0.0, -9.81) * mass;
    let start = s;
    // The same stance written in a chart off its centre (at rest, so only the pose moves
    // into the chart): the step reports the same forces in the world.
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let (delta, angles) = (
        Vector3::new(0.01, 0.02, -0.01),
        Vector3::new(0.05, -0.04, 0.03),
    );
    let mut off = start;
    off.orientation = start.orientation * robot::ball_rotation(&angles).inverse();
    off.position = start.position - off.orientation.transform_vector(&delta);
    for k in 0..3 {
        off.q[f + k] = delta[k];
        off.q[f + 3 + k] = angles[k];
    }
    let (mut a, mut b) = (start, off);
    let at_centre =
        robot::stance_step::<L, f64, NQ, NC, NU, NK>(&p, &mut a, &u, &modes, &ground, &mu, 1e-3)
            .unwrap();
    let off_centre =
        robot::stance_step::<L, f64, NQ, NC, NU, NK>(&p, &mut b, &u, &modes, &ground, &mu, 1e-3)
            .unwrap();
    let d = (at_centre.world_forces - off_centre.world_forces).amax();
    assert!(
        d < 1e-9 * weight.norm(),
        "{name}: off the chart's centre the forces turn by {d:e} N"
    );
    let (mut moved, mut force_err) = (0.0f64, 0.0f64);
    // Held torques alone leave the stance's free motions (two on a quadruped) at an
    // unstable balance that rounding tips over (the legs buckle under the weight); a
    // joint PD about the pose keeps them, and adds nothing at the pose. Its stiffness is
    // the robot's weight times its size per radian, its damping that over 10 rad/s.
    let stiffness = weight.norm() * size;
    let damping = stiffness / 10.0;
    for _ in 0..1000 {
        let pd = SVector::<f64, NU>::from_fn(|i, _| {
            let a = L::ACTUATED[i];
            -stiffness * (s.q[a] - start.q[a]) - damping * s.v[a]
        });
        let stance = robot::stance_step::<L, f64, NQ, NC, NU, NK>(
            &p,
            &mut s,
            &(u + pd),
            &modes,
            &ground,
            &mu,
            1e-3,
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        let total = (0..NK / 3).fold(Vector3::zeros(), |a, k| {
            a + Vector3::new(
                stance.world_forces[3 * k],
                stance.world_forces[3 * k + 1],
                stance.world_forces[3 * k + 2],
            )
        });
        force_err = force_err.max((total + weight).norm());
        moved = moved
            .max((s.position - start.position).norm())
            .max(s.v.amax());
    }
    let angle = s.orientation.angle_to(&start.orientation);
    eprintln!(
        "{name}: 1 s standing on {} feet, holding torques {:.3e} N m at most (|q̈| {left:.1e} left): moved {moved:.1e} (m, m/s), turned {angle:.1e} rad; ground forces minus the weight ({:.4} N): {force_err:.1e} N",
        NK / 3,
        u.amax(),
        weight.norm()
    );
    // Still to 1e-10, or to ten times what the |q̈| the torques leave (rounding: Cassie's
    // light rods and cranks take 1e-10 rad/s² of it) moves in 1 s.
    let still = 1e-10f64.max(10.0 * left);
    assert!(
        moved < still && angle < still,
        "{name}: moved {moved:e}, turned {angle:e} (allowed {still:e})"
    );
    assert!(
        force_err < 1e-10 * weight.norm(),
        "{name}: ground forces off the weight by {force_err:e} N"
    );
}

/// The stance step by semi-implicit Euler (`pushed_stance_step_by`, MuJoCo's default
/// integrator's kind) is first order: pushed sideways from where the robot stands, its
/// state after 20 ms is off RK4's at 0.125 ms by half as much when its own step halves
/// (the ratio of the errors at 0.5 ms and 0.25 ms within 1.6–2.4), and its projections
/// keep the closures to 1e-12 of the robot's size. (At 1 ms Cassie's fast modes, its
/// light rods' spin under their damping, take Euler near its stability limit: 2.2 mm off
/// where 0.5 ms is 4 µm off.)
fn euler_stance_step_is_first_order<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::simulate::Method;
    let name = L::NAME;
    let Some(Stance {
        params: p,
        start,
        ground,
        modes,
        mu,
    }) = standing_start::<L, NQ, NC, NU, NK>("euler stance step")
    else {
        return;
    };
    if free_on_its_feet::<L, NQ, NC, NU, NK>(&p, &start) == 0 {
        leg_tests::not_applicable(
            name,
            "euler stance step",
            &"its held feet and closures hold every coordinate: nothing moves to integrate",
        );
        return;
    }
    let (u, _) =
        robot::holding_torques::<L, f64, NQ, NC, NU, NK>(&p, &start, &modes, &ground, &mu).unwrap();
    let push = ground.normal.cross(&Vector3::x()).normalize()
        * 0.05
        * 9.81
        * spec_mass::<L, NQ, NC, NU>(&p);
    let size = L::leg_size(&start.q, &p);
    let mut residual = 0.0f64;
    let mut run = |method: Method, dt: f64| {
        let mut s = start;
        let steps = (0.02 / dt).round() as usize;
        for i in 0..steps {
            robot::pushed_stance_step_by::<L, f64, NQ, NC, NU, NK>(
                method, &p, &mut s, &u, &push, &modes, &ground, &mu, dt,
            )
            .unwrap_or_else(|e| panic!("{name}: {method:?} step {i} at {dt} s: {e}"));
            if NC > 0 {
                residual = residual.max(L::closure_residual(&s.q, &p).amax());
            }
        }
        s
    };
    let reference = run(Method::Rk4, 1.25e-4);
    let off = |s: &RobotState<f64, NQ>| {
        (s.position - reference.position)
            .amax()
            .max((s.q - reference.q).amax() * size)
    };
    let (coarse, fine) = (
        off(&run(Method::SemiImplicitEuler, 5e-4)),
        off(&run(Method::SemiImplicitEuler, 2.5e-4)),
    );
    eprintln!("{name}: semi-implicit Euler stance steps pushed 20 ms, off RK4 at 0.125 ms by {coarse:.2e} m at 0.5 ms and {fine:.2e} m at 0.25 ms (ratio {:.2}); closures {residual:.1e}", coarse / fine);
    assert!(
        (1.6..=2.4).contains(&(coarse / fine)),
        "{name}: Euler's error {coarse:e} at 0.5 ms, {fine:e} at 0.25 ms: not first order"
    );
    assert!(
        residual <= 1e-12 * size.max(1.0),
        "{name}: the closures open by {residual:e}"
    );
}

/// Dropped flat onto every foot at once, 1 m/s into the ground and 0.2 m/s along it, the
/// motors free: every foot takes a normal impulse that pushes, every foot's velocity
/// into the ground is zero after it (a sticking one's along it too), the impulses add
/// up to the change of the robot's momentum, and the energy lost is the impulses' energy
/// identity to rounding: `T⁻ − T⁺ = ½ Δq̇ᵀ M Δq̇ − Σ v_k⁺ · Λ_k` (the last term, Coulomb's
/// friction work on the feet that slide, is zero for those that stick).
fn lands_flat_on_every_foot<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::dynamics::contact::ContactMode;
    let name = L::NAME;
    let Some(Stance {
        params: p,
        start: mut s,
        ground,
        mut modes,
        mu,
    }) = standing_start::<L, NQ, NC, NU, NK>("landing")
    else {
        return;
    };
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    // Down along the ground's normal and along the ground, as a rigid body: the body's
    // velocity in its own frame, the joints still.
    let along = ground.normal.cross(&Vector3::x()).normalize();
    let velocity = s
        .orientation
        .inverse_transform_vector(&(-ground.normal + along * 0.2));
    for k in 0..3 {
        s.v[f + k] = velocity[k];
    }
    let before = s;
    let (lin0, _) = robot::momentum::<L, f64, NQ, NC, NU>(&p, &s).unwrap();
    let (impact, world) =
        robot::impact::<L, f64, NQ, NC, NU, NK>(&p, &mut s, &mut modes, &ground, &mu)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    let chart = robot::chart_params::<L, f64, NQ, NC, NU>(&p, &s.orientation).unwrap();
    let m = L::mass_matrix(&s.q, &chart);
    let dv = before.v - s.v;
    let (k0, _) = robot::energies::<L, f64, NQ, NC, NU>(&p, &before).unwrap();
    let (k1, _) = robot::energies::<L, f64, NQ, NC, NU>(&p, &s).unwrap();
    let (lin1, _) = robot::momentum::<L, f64, NQ, NC, NU>(&p, &s).unwrap();
    // Each foot's velocity after it and its impulse, in the world.
    let rates = L::contact_jacobian(&s.q, &chart) * s.v;
    let foot = |v: &SVector<f64, NK>, k: usize| Vector3::new(v[3 * k], v[3 * k + 1], v[3 * k + 2]);
    let (mut work, mut total, mut into, mut stuck_speed) = (0.0, Vector3::zeros(), 0.0f64, 0.0f64);
    let mut sliding = 0;
    for k in 0..NK / 3 {
        let v = s.orientation.transform_vector(&foot(&rates, k));
        work += v.dot(&foot(&world, k));
        total += foot(&world, k);
        into = into.max(v.dot(&ground.normal).abs());
        match modes.get(k) {
            ContactMode::Stick => stuck_speed = stuck_speed.max(v.norm()),
            _ => sliding += 1,
        }
    }
    let identity = 0.5 * dv.dot(&(m * dv)) - work;
    // The closures' rates after it (the identity holds only if they are zero).
    let closure_rate = (L::constraint_jacobian(&s.q, &chart) * s.v).amax();
    eprintln!("{name}: landing: closures' rates after it {closure_rate:.1e}");
    let pushes = (0..NK / 3)
        .map(|k| impact.impulses[3 * k + 2])
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "{name}: flat landing on {} feet ({sliding} sliding after it): energy lost {:.6} J of {k0:.6} J; the identity ½ Δq̇ᵀ M Δq̇ − Σ v⁺·Λ off it by {:.1e} J; impulses minus Δ momentum {:.1e} N s; feet's speed into the ground after {into:.1e} m/s; smallest normal impulse {pushes:.4} N s",
        NK / 3,
        impact.energy_lost,
        (impact.energy_lost - identity).abs(),
        (total - (lin1 - lin0)).norm()
    );
    assert!(pushes > 0.0, "{name}: a foot takes no push ({pushes} N s)");
    assert!(
        (k0 - k1 - impact.energy_lost).abs() < 1e-12 * k0,
        "{name}: energy_lost is not T⁻ − T⁺"
    );
    // Rounding through solves with M, whose condition on a robot of light legs under a
    // heavy body is 1e6 or more.
    assert!(
        (impact.energy_lost - identity).abs() < 1e-10 * k0,
        "{name}: energy identity off by {:e}",
        impact.energy_lost - identity
    );
    assert!(
        impact.energy_lost > 0.0,
        "{name}: the landing gained energy"
    );
    assert!(
        (total - (lin1 - lin0)).norm() < 1e-12 * lin0.norm(),
        "{name}: impulses are not the change of momentum"
    );
    assert!(into < 1e-12 && stuck_speed < 1e-12, "{name}: a foot still moves into the ground ({into:e}) or a stuck one along it ({stuck_speed:e})");
}

/// How many motions the held contacts and the closures leave the robot at `s`: `NQ` less
/// the rank of the contact rows and the closure rows stacked (singular values above 1e-9
/// of the largest). None where the feet hold every coordinate (three point feet under
/// one-motor legs): the body cannot move, so there is nothing for a balance controller
/// to steer, and a push is carried by the feet alone.
fn free_on_its_feet<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
    s: &RobotState<f64, NQ>,
) -> usize
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    let chart = robot::chart_params::<L, f64, NQ, NC, NU>(p, &s.orientation).unwrap();
    let c = L::contact_jacobian(&s.q, &chart);
    let j = L::constraint_jacobian(&s.q, &chart);
    let rows = leg_models::nalgebra::DMatrix::<f64>::from_fn(NK + NC, NQ, |r, k| {
        if r < NK {
            c[(r, k)]
        } else {
            j[(r - NK, k)]
        }
    });
    let sv = rows.svd(false, false).singular_values;
    let top = sv.amax();
    NQ - sv.iter().filter(|&&x| x > 1e-9 * top).count()
}

/// Balanced by the QP (`robot::balance`) on its feet at 1 ms steps: unpushed for 0.25 s,
/// the ground forces the simulator applies add up to the weight from the spec's masses
/// and every foot's stays well inside its friction cone (the least holding torques of
/// the standing test load the feet sideways, outside their cones: printed beside it);
/// pushed forwards on the body at 5 % of its weight for 0.1 s, it stays on its feet
/// (every force in its cone, every step) and is back within 1 mm and 1 mrad after 1.25 s;
/// pushed at three times its weight, the run fails, and says which foot slipped or
/// lifted (or that no torques keep the feet in their cones). Where the legs carry
/// springs, the default (the springs rigid in the controller's model, a motor servo)
/// is what holds: planned with the springs as they are, the same push fails.
fn balances_and_recovers_from_a_push<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::robot::balance::{BalanceController, BalanceGains, BalanceTarget};
    use leg_tests::standing::{push_run, Holding};
    let name = L::NAME;
    let Some(Stance {
        params: p,
        start,
        ground,
        modes,
        mu,
    }) = standing_start::<L, NQ, NC, NU, NK>("balance")
    else {
        return;
    };
    if free_on_its_feet::<L, NQ, NC, NU, NK>(&p, &start) == 0 {
        leg_tests::not_applicable(
            name,
            "balance",
            &"its held feet and closures hold every coordinate: there is no motion to balance",
        );
        return;
    }
    let weight = spec_mass::<L, NQ, NC, NU>(&p) * 9.81;
    // Unpushed: the weight on the feet, inside the cones.
    let mut control = BalanceController::<NQ, NC, NU, NK>::new(
        BalanceTarget::holding(&start),
        BalanceGains::default(),
        None,
    );
    let (mut s, mut force_err, mut ratio) = (start, 0.0f64, 0.0f64);
    for _ in 0..250 {
        let cmd = control
            .command::<L>(&p, &s, &modes, &ground, &mu)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let before = s;
        let stance = robot::stance_step::<L, f64, NQ, NC, NU, NK>(
            &p,
            &mut s,
            &cmd.torques,
            &modes,
            &ground,
            &mu,
            1e-3,
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        let forces =
            judged_forces::<L, NQ, NC, NU, NK>(&p, &before, &stance, &modes, &ground, &mu).unwrap();
        let mut total = Vector3::zeros();
        for k in 0..NK / 3 {
            let c = cone_reading(&forces, &ground, &mu, k);
            total += c.force;
            assert!(c.normal > 0.0, "{name}: foot {k} pulls ({:e} N)", c.normal);
            ratio = ratio.max(c.ratio);
        }
        force_err = force_err.max((total - Vector3::new(0.0, 0.0, weight)).norm());
    }
    let moved = (s.position - start.position).norm();
    let held = push_run::<L, NQ, NC, NU, NK>(
        &p,
        &start,
        &ground,
        Holding::JointPd,
        Vector3::zeros(),
        0.0,
        0.01,
        1e-3,
    );
    eprintln!(
        "{name}: balanced 0.25 s: ground forces minus the weight ({weight:.3} N) {force_err:.1e} N, moved {moved:.1e} m, largest |λ_t|/(μ λ_n) {ratio:.3} (the least holding torques: {:.2})",
        held.worst_friction
    );
    // The body's accelerations are its task's, so the forces balance the weight to the
    // size of those: the small tangential-force weight moves its equilibrium by
    // hundredths of a micrometre, which it settles to.
    assert!(
        force_err < 1e-4 * weight,
        "{name}: forces off the weight by {force_err:e} N"
    );
    assert!(
        ratio < 0.5,
        "{name}: a foot's force is near its cone's edge ({ratio})"
    );
    assert!(moved < 1e-6, "{name}: moved {moved:e} m unpushed");
    let side = ground
        .normal
        .cross(&start.orientation.transform_vector(&Vector3::x()))
        .normalize();
    let forward = side.cross(&ground.normal);
    // 5 % of the weight: Cassie's largest forward push is 10 %, the quadruped's 54 %.
    let push = forward * (0.05 * weight);
    let pushed = push_run::<L, NQ, NC, NU, NK>(
        &p,
        &start,
        &ground,
        Holding::Balance(BalanceGains::default()),
        push,
        0.1,
        1.25,
        1e-3,
    );
    eprintln!(
        "{name}: pushed forwards at 0.05 of its weight for 0.1 s: {:?}; went {:.2e} m; largest |λ_t|/(μ λ_n) {:.3}, least normal force {:.3} N; after 1.25 s {:.1e} m, {:.1e} rad, |v| {:.1e}; {:.1} QP iterations a tick",
        pushed.failed, pushed.excursion, pushed.worst_friction, pushed.least_normal, pushed.end.0, pushed.end.1, pushed.end.2, pushed.mean_iterations
    );
    assert!(pushed.failed.is_none(), "{name}: {:?}", pushed.failed);
    assert!(
        pushed.excursion > 1e-5,
        "{name}: the push did not move the body"
    );
    let shoved = push_run::<L, NQ, NC, NU, NK>(
        &p,
        &start,
        &ground,
        Holding::Balance(BalanceGains::default()),
        side * (3.0 * weight),
        0.1,
        0.1,
        1e-3,
    );
    let why = shoved.failed.map(|(_, w)| w).unwrap_or_default();
    assert!(
        why.contains("friction cone") || why.contains("pulls") || why.contains("PrimalInfeasible"),
        "{name}: a push of three times the weight did not unseat it ({why:?})"
    );
    // Where the legs carry springs, the controller's model holds them rigid and a motor
    // servo damps their modes; planned with the springs as they are, the same push
    // unseats the robot (the QP's answer to the springs' modes pushes a foot out of
    // its cone).
    if !L::SPRINGS.is_empty() {
        let compliant = BalanceGains {
            rigid_springs: false,
            ..BalanceGains::default()
        };
        let run = push_run::<L, NQ, NC, NU, NK>(
            &p,
            &start,
            &ground,
            Holding::Balance(compliant),
            push,
            0.1,
            0.25,
            1e-3,
        );
        eprintln!(
            "{name}: planned with its springs as they are, the same push: {:?}",
            run.failed
        );
        // A foot out of its cone or pulling during the run, not the end's settling test.
        let why = run.failed.map(|(_, w)| w).unwrap_or_default();
        assert!(
            why.contains("friction cone")
                || why.contains("pulls")
                || why.contains("PrimalInfeasible"),
            "{name}: the springs as they are held the push too ({why:?})"
        );
    }
}

/// The QP's constraints, made to bind: on a ground whose friction is just above the
/// least the stance needs, every planned force is inside its cone and one is on its
/// edge (planned in the controller's model: the robot's where its legs carry no springs
/// or they are planned as they are, and then the forces the step applies; bad servo
/// gains are refused); with torque limits below the torques it picks unlimited, every torque is within
/// its limit and one is at it. The forces its command reports (its stance) are the ones the stance step applies,
/// and bad limits are refused with the motor named.
fn balance_constraints_bind<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::dynamics::contact::Modes;
    use leg_models::robot::balance::{BalanceController, BalanceGains, BalanceTarget};
    let name = L::NAME;
    let Some(Stance {
        params: p,
        start,
        ground,
        modes,
        mu,
    }) = standing_start::<L, NQ, NC, NU, NK>("balance constraints")
    else {
        return;
    };
    if free_on_its_feet::<L, NQ, NC, NU, NK>(&p, &start) == 0 {
        leg_tests::not_applicable(
            name,
            "balance constraints",
            &"its held feet and closures hold every coordinate: its torques set its ground forces alone, with no internal forces to shift",
        );
        return;
    }
    // A state off the target, so the tasks ask for something.
    let mut s = start;
    s.position += ground.normal.cross(&Vector3::x()).normalize() * 2e-3;
    let new = |limit| {
        BalanceController::<NQ, NC, NU, NK>::new(
            BalanceTarget::holding(&start),
            BalanceGains::default(),
            limit,
        )
    };
    let ratios = |w: &SVector<f64, NK>, mu: &SVector<f64, NK>| {
        (0..NK / 3)
            .map(|k| cone_reading(w, &ground, mu, k).ratio)
            .fold(0.0f64, f64::max)
    };
    let free = new(None)
        .command::<L>(&p, &s, &modes, &ground, &mu)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    // The planned forces are the step's.
    let mut stepped = s;
    let stance = robot::stance_step::<L, f64, NQ, NC, NU, NK>(
        &p,
        &mut stepped,
        &free.torques,
        &modes,
        &ground,
        &mu,
        1e-3,
    )
    .unwrap();
    let d = (stance.world_forces - free.stance.world_forces).amax();
    assert!(
        d < 1e-12 * free.stance.world_forces.amax(),
        "{name}: planned and applied forces differ by {d:e} N"
    );
    // Friction scaled so the unconstrained forces' worst foot would need 1.5 times it:
    // the cone binds.
    // The QP plans the forces in its model: the robot's own where the legs carry no
    // springs or they are planned as they are (then the forces the step applies, rebuilt
    // from the affine maps against a direct solve), the rigid-spring model's where they
    // are held rigid.
    let planned = (free.planned_forces - free.stance.world_forces).amax();
    eprintln!("{name}: balance: planned forces off the applied by {planned:.2e} N");
    let as_they_are = if L::SPRINGS.is_empty() {
        free
    } else {
        BalanceController::<NQ, NC, NU, NK>::new(
            BalanceTarget::holding(&start),
            BalanceGains {
                rigid_springs: false,
                ..BalanceGains::default()
            },
            None,
        )
        .command::<L>(&p, &s, &modes, &ground, &mu)
        .unwrap_or_else(|e| panic!("{name}: springs as they are: {e}"))
    };
    let off = (as_they_are.planned_forces - as_they_are.stance.world_forces).amax();
    assert!(
        off < 1e-12 * as_they_are.stance.world_forces.amax(),
        "{name}: planned forces differ from the applied by {off:e} N"
    );
    // Bad servo gains, named.
    let e = BalanceController::<NQ, NC, NU, NK>::new(
        BalanceTarget::holding(&start),
        BalanceGains {
            servo_damping: f64::NAN,
            ..BalanceGains::default()
        },
        None,
    )
    .command::<L>(&p, &s, &modes, &ground, &mu)
    .unwrap_err()
    .to_string();
    assert!(e.contains("servo_damping"), "{name}: {e}");
    let need = ratios(&free.planned_forces, &mu);
    let low = mu * (need / 1.5);
    let tight = new(None)
        .command::<L>(&p, &s, &modes, &ground, &low)
        .unwrap_or_else(|e| panic!("{name}: low friction: {e}"));
    let r = ratios(&tight.planned_forces, &low);
    eprintln!("{name}: balance: unconstrained forces need μ ratio {need:.4}; on 1/1.5 of that the worst foot is at {r:.6} of its cone");
    assert!(
        r <= 1.0 + 1e-6 && r > 0.99,
        "{name}: on low friction the worst foot is at {r} of its cone"
    );
    // One limit for every motor, 0.95 of the largest torque picked unlimited (the others
    // take up the load): every torque within, one at it.
    let limit = SVector::<f64, NU>::from_element(0.95 * free.torques.amax());
    let limited = new(Some(limit))
        .command::<L>(&p, &s, &modes, &ground, &mu)
        .unwrap_or_else(|e| panic!("{name}: limited: {e}"));
    let over = (0..NU)
        .map(|i| limited.torques[i].abs() / limit[i])
        .fold(0.0f64, f64::max);
    assert!(
        over <= 1.0 + 1e-6 && over > 0.99,
        "{name}: the torques reach {over} of their limits"
    );
    // Bad limits, named.
    let mut bad = limit;
    bad[NU - 1] = f64::INFINITY;
    let e = new(Some(bad))
        .command::<L>(&p, &s, &modes, &ground, &mu)
        .unwrap_err()
        .to_string();
    assert!(e.contains(&format!("motor {}", NU - 1)), "{name}: {e}");
    // A controller whose limits are switched on after set-up sets itself up again.
    let mut c = new(None);
    c.command::<L>(&p, &s, &modes, &ground, &mu).unwrap();
    c.torque_limit = Some(limit);
    let again = c
        .command::<L>(&p, &s, &modes, &ground, &mu)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    assert!(
        (again.torques - limited.torques).amax() < 1e-6 * limit.amax(),
        "{name}: the limits switched on give other torques"
    );
    // No contact held: nothing to balance on.
    let e = c
        .command::<L>(&p, &s, &Modes::<NK, 3>::flight(), &ground, &mu)
        .unwrap_err();
    assert!(e.to_string().contains("no contact is held"), "{name}: {e}");
}

/// `robot::feet_on_a_plane` from home: the contact points' heights along the body's `z`,
/// read off the contact positions, are equal; the closures are closed; the body's six
/// coordinates did not move; the joints moved little (a robot whose feet are flat at
/// home is left where it was; the quadruped's toes are on one plane at home, but one
/// tilted from the body's `z`).
fn puts_its_feet_on_a_plane<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    let name = L::NAME;
    if NK < 6 {
        leg_tests::not_applicable(name, "feet on a plane", &"fewer than two contact points");
        return;
    }
    let p = with_gravity::<L, NQ, NC, NU>([0.0, 0.0, -9.81], true);
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let home = assembled_home::<L, NQ, NC, NU>(&p).unwrap_or_else(|e| panic!("{}: {e}", L::NAME));
    let tol = leg_models::assembly::Tolerance::default();
    let heights = |q: &SVector<f64, NQ>| {
        let x = L::contact_positions(q, &p);
        (0..NK / 3).map(|k| x[3 * k + 2]).collect::<Vec<_>>()
    };
    let spread = |h: &[f64]| {
        h.iter().cloned().fold(f64::MIN, f64::max) - h.iter().cloned().fold(f64::MAX, f64::min)
    };
    let before = spread(&heights(&home));
    let mut q = home;
    robot::feet_on_a_plane::<L, f64, NQ, NC, NU, NK>(&p, &mut q, &Vector3::z(), &tol)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let size = L::leg_size(&q, &p);
    let after = spread(&heights(&q));
    let closure = L::closure_residual(&q, &p).amax();
    // (Closing the loops from home may have moved the chart's six a little already.)
    let body = (0..6)
        .map(|k| (q[f + k] - home[f + k]).abs())
        .fold(0.0, f64::max);
    let moved = (q - home).amax();
    eprintln!("{name}: feet on a plane: heights spread {before:.3e} m at home, {after:.1e} m after; closures {closure:.1e} m; joints moved {moved:.3e} rad at most");
    assert!(
        after <= 1e-12 * size,
        "{name}: heights still spread by {after:e} m"
    );
    assert!(
        closure <= 1e-12 * size,
        "{name}: closures open by {closure:e} m"
    );
    assert!(body == 0.0, "{name}: the body moved ({body:e})");
    if before <= tol.relative_residual * size {
        assert!(moved <= 1e-12, "{name}: flat at home, yet moved {moved:e}");
    } else {
        assert!(
            moved < 0.5,
            "{name}: moved {moved} rad to put its feet flat"
        );
    }
}

/// The centre of mass (`robot::centre_of_mass`, from the potential energy) moves with the
/// linear momentum (`robot::momentum`, from the mass matrix): `m ċ = P` at a moving state,
/// `ċ` by central differences along the rates, the chart held (Cassie's springs, whose
/// energy is in the potential too, are left out by the difference from no gravity).
fn centre_of_mass_moves_with_the_momentum<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    let name = L::NAME;
    let p = with_gravity::<L, NQ, NC, NU>([0.0, 0.0, -9.81], true);
    let s = tumbling::<L, NQ, NC, NU>(&p, 3);
    let chart = robot::chart_params::<L, f64, NQ, NC, NU>(&p, &s.orientation).unwrap();
    let com =
        |q: &SVector<f64, NQ>| robot::centre_of_mass::<L, f64, NQ, NC, NU>(&chart, q).unwrap();
    let h = 1e-6;
    let rate = (com(&(s.q + s.v * h)) - com(&(s.q - s.v * h))) / (2.0 * h);
    let mass = spec_mass::<L, NQ, NC, NU>(&p);
    let (linear, _) = robot::momentum::<L, f64, NQ, NC, NU>(&p, &s).unwrap();
    let from_com = s.orientation.transform_vector(&(rate * mass));
    let e = (from_com - linear).norm();
    eprintln!("{name}: m ċ against P: {e:.1e} N s of {:.3}", linear.norm());
    assert!(
        e < 1e-7 * linear.norm().max(mass),
        "{name}: m ċ off P by {e:e}"
    );
}

/// Two held contacts on one rigid foot share the load along their distance equally (the
/// least of the stance solve's solutions, the split being no row's to say): its feet put
/// flat, at rest, with the motors off, the toe's and heel's forces along the line from one
/// to the other are equal. And the rates projected onto the held contacts and closures
/// (`project_held_velocity`) move no held contact and lose energy as an M-orthogonal
/// projection does: `T⁻ − T⁺ = ½ Δq̇ᵀ M Δq̇`.
fn held_rows_split_and_project<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::dynamics::contact::{project_held_velocity, spec_friction, Ground, Modes};
    let name = L::NAME;
    if NK < 6 {
        leg_tests::not_applicable(name, "held rows", &"fewer than two contact points");
        return;
    }
    let p = with_gravity::<L, NQ, NC, NU>([0.0, 0.0, -9.81], true);
    let mut q = assembled_home::<L, NQ, NC, NU>(&p).unwrap_or_else(|e| panic!("{}: {e}", L::NAME));
    let tol = leg_models::assembly::Tolerance::default();
    robot::feet_on_a_plane::<L, f64, NQ, NC, NU, NK>(&p, &mut q, &Vector3::z(), &tol).unwrap();
    let x = L::contact_positions(&q, &p);
    let at = |k: usize| Vector3::new(x[3 * k], x[3 * k + 1], x[3 * k + 2]);
    let ground = Ground {
        normal: Vector3::z(),
        offset: at(0).z,
    };
    let modes = Modes::<NK, 3>::stick();
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, 3>();
    let s = RobotState::at_rest(Vector3::zeros(), UnitQuaternion::identity(), q);
    let size = L::leg_size(&q, &p);
    // Pairs of contacts on one rigid body: their distance's rate is zero whatever the
    // rates (checked on random rates), so their rows repeat each other.
    let c = L::contact_jacobian(&q, &p);
    let mut rng = Rng::new(11);
    let rates = SVector::<f64, NQ>::from_fn(|_, _| rng.range(-1.0, 1.0));
    let v = c * rates;
    let mut pairs = Vec::new();
    for a in 0..NK / 3 {
        for b in a + 1..NK / 3 {
            let d = at(b) - at(a);
            let dv = Vector3::new(
                v[3 * b] - v[3 * a],
                v[3 * b + 1] - v[3 * a + 1],
                v[3 * b + 2] - v[3 * a + 2],
            );
            if d.dot(&dv).abs() < 1e-12 * d.norm() * v.amax() {
                pairs.push((a, b, d.normalize()));
            }
        }
    }
    if pairs.is_empty() {
        leg_tests::not_applicable(
            name,
            "held rows' split",
            &"no two contacts on one rigid body",
        );
    } else {
        let stance = robot::stance_dynamics::<L, f64, NQ, NC, NU, NK>(
            &p,
            &s,
            &SVector::zeros(),
            &modes,
            &ground,
            &mu,
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        let w = stance.world_forces;
        let force = |k: usize| Vector3::new(w[3 * k], w[3 * k + 1], w[3 * k + 2]);
        for &(a, b, d) in &pairs {
            let (fa, fb) = (force(a).dot(&d), force(b).dot(&d));
            eprintln!("{name}: contacts {a} and {b} on one body: along their line {fa:.6} N and {fb:.6} N");
            assert!(
                (fa - fb).abs() < 1e-9 * w.amax(),
                "{name}: contacts {a}, {b} split {fa} / {fb}"
            );
        }
        // The forces that move nothing: as many directions as pairs, and they span each
        // pair's equal and opposite forces along its line (the test's geometry, not the
        // Jacobians').
        let internal = leg_models::robot::balance::internal_forces::<L, NQ, NC, NU, NK>(
            &p, &s, &modes, &ground,
        )
        .unwrap();
        assert_eq!(internal.ncols(), pairs.len(), "{name}: internal forces");
        let frame = robot::ground_in_chart(&ground, &s.position, &s.orientation).frame();
        for &(a, b, d) in &pairs {
            // In the chart ground's frame (the chart is the world here).
            let along = frame * d;
            let mut e = leg_models::nalgebra::DVector::<f64>::zeros(NK);
            for i in 0..3 {
                e[3 * a + i] = along[i];
                e[3 * b + i] = -along[i];
            }
            // To rounding over the gap between the null space and the least other
            // singular value of [Cᵀ Jᵀ] (Cassie's light rods: 3e-9).
            let off = (&e - &internal * (internal.transpose() * &e)).amax();
            assert!(
                off < 1e-7,
                "{name}: contacts {a} and {b} pushing apart along their line are {off:e} off the internal forces"
            );
        }
        // The deepest split against a scan of every pair's split on a grid (±the largest
        // force, 201 steps a pair): the cone program's margin is the scan's best or better.
        let forces = stance.solution.contact;
        let (_, margin) =
            leg_models::robot::balance::deepest_split(&forces, &internal, &modes, &mu).unwrap();
        let margin_of = |l: &SVector<f64, NK>| {
            (0..NK / 3).fold(f64::INFINITY, |m, k| {
                m.min(mu[3 * k + 2] * l[3 * k + 2] - l[3 * k].hypot(l[3 * k + 1]))
            })
        };
        let (span, steps) = (w.amax(), 200);
        let mut best = f64::NEG_INFINITY;
        let mut z = vec![0usize; internal.ncols()];
        'scan: loop {
            let mut trial = forces;
            for (c, &i) in z.iter().enumerate() {
                let zc = span * (2.0 * i as f64 / steps as f64 - 1.0);
                for r in 0..NK {
                    trial[r] += internal[(r, c)] * zc;
                }
            }
            best = best.max(margin_of(&trial));
            for i in z.iter_mut() {
                *i += 1;
                if *i <= steps {
                    continue 'scan;
                }
                *i = 0;
            }
            break;
        }
        eprintln!("{name}: deepest split: margin {margin:.6} N (a scan's best {best:.6} N; the least split's {:.6} N)", margin_of(&forces));
        assert!(
            margin >= best - 1e-6 * span,
            "{name}: the cone program's margin {margin} is below a scan's {best}"
        );
    }
    // The projection.
    let mut moving = rates;
    leg_models::assembly::project_velocity::<L, f64, NQ, NC, NU>(&p, &q, &mut moving).unwrap();
    let before = moving;
    project_held_velocity::<L, f64, NQ, NC, NU, NK, 3>(&p, &q, &mut moving, &modes, &ground)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let m = L::mass_matrix(&q, &p);
    let held = (c * moving).amax();
    let closure = (L::constraint_jacobian(&q, &p) * moving).amax();
    let dv = before - moving;
    let lost = 0.5 * before.dot(&(m * before)) - 0.5 * moving.dot(&(m * moving));
    let identity = 0.5 * dv.dot(&(m * dv));
    eprintln!("{name}: held rates projected: contacts {held:.1e}, closures {closure:.1e}; energy lost {lost:.6} J, ½ Δq̇ᵀ M Δq̇ off it by {:.1e} J", (lost - identity).abs());
    let scale = before.amax() * size;
    assert!(
        held < 1e-12 * scale && closure < 1e-12 * scale,
        "{name}: held {held:e}, closures {closure:e}"
    );
    assert!(
        (lost - identity).abs() < 1e-10 * lost,
        "{name}: not M-orthogonal: {lost} vs {identity}"
    );
}

macro_rules! floating_robot_tests {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
        mod $module {
            #[test]
            fn momentum_is_kept_in_zero_gravity() {
                super::momentum_is_kept::<$ty, $nq, $nc, $nu>();
            }

            #[test]
            fn falls_with_momentum_and_energy_as_physics_says() {
                super::falls_with_gravity::<$ty, $nq, $nc, $nu>();
            }

            #[test]
            fn recentring_every_step_matches_one_fixed_chart() {
                super::recentring_matches_a_fixed_chart::<$ty, $nq, $nc, $nu>();
            }

            #[test]
            fn pose_rate_is_the_pose_derivative() {
                super::pose_rate_is_the_pose_derivative::<$ty, $nq, $nc, $nu>();
            }

            #[test]
            fn lands_flat_on_every_foot_at_once() {
                super::lands_flat_on_every_foot::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn balances_and_recovers_from_a_push() {
                super::balances_and_recovers_from_a_push::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn balance_constraints_bind() {
                super::balance_constraints_bind::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn puts_its_feet_on_a_plane() {
                super::puts_its_feet_on_a_plane::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn centre_of_mass_moves_with_the_momentum() {
                super::centre_of_mass_moves_with_the_momentum::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn held_rows_split_and_project() {
                super::held_rows_split_and_project::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn euler_stance_step_is_first_order() {
                super::euler_stance_step_is_first_order::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn stands_still_with_its_weight_on_its_feet() {
                super::stands_still_on_its_feet::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn free_feet_stand_as_held_feet_do() {
                super::free_feet_stand_as_held_feet_do::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn free_feet_land_flat() {
                super::free_feet_land_flat::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn free_feet_lift_off_and_slide() {
                super::free_feet_lift_off_and_slide::<$ty, $nq, $nc, $nu, $nk>();
            }

            #[test]
            fn free_feet_refuse_bad_input() {
                super::free_feet_refuse_bad_input::<$ty, $nq, $nc, $nu, $nk>();
            }
        }
    };
}

generated::for_each_floating_model!(floating_robot_tests);

#[test]
fn there_is_a_floating_robot() {
    let mut n = 0;
    macro_rules! count {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            n += 1;
        };
    }
    generated::for_each_floating_model!(count);
    assert!(n >= 1);
}

#[test]
fn a_fixed_base_is_not_a_robot() {
    use generated::cassie_leg::CassieLeg;
    let e = robot::free_joint::<CassieLeg, 13, 6, 5>().unwrap_err();
    assert!(e.to_string().contains("fixed base"), "{e}");
}

#[test]
fn feet_on_a_plane_refuses_no_direction_and_keeps_the_pose() {
    use generated::minitaur_quadruped::MinitaurQuadruped as R;
    use leg_models::assembly::AssemblyError;
    let p = <R as LegDynamics<22, 12, 8>>::Params::<f64>::default();
    let home = SVector::<f64, 22>::from_column_slice(&R::HOME);
    for up in [Vector3::zeros(), Vector3::new(f64::NAN, 0.0, 1.0)] {
        let mut q = home;
        let e =
            robot::feet_on_a_plane::<R, f64, 22, 12, 8, 12>(&p, &mut q, &up, &Default::default())
                .unwrap_err();
        assert_eq!(e, AssemblyError::NonFinite);
        assert_eq!(q, home, "a refused request moved the pose");
    }
}

#[test]
fn standing_pose_refuses_bad_input_and_a_fixed_base() {
    use generated::minitaur_quadruped::MinitaurQuadruped as R;
    use leg_models::dynamics::contact::{spec_friction, Ground, Modes};
    use leg_models::robot::standing::{standing_pose, StandingError};
    let p = with_gravity::<R, 22, 12, 8>([0.0, 0.0, -9.81], true);
    let start = robot::RobotState::at_rest(
        Vector3::zeros(),
        leg_models::nalgebra::UnitQuaternion::identity(),
        assembled_home::<R, 22, 12, 8>(&p).unwrap(),
    );
    let (modes, ground) = (Modes::<12, 3>::stick(), Ground::of::<R, 22, 12, 8, 12>());
    let mu = spec_friction::<R, f64, 22, 12, 8, 12, 3>();
    let mut nan = start;
    nan.q[7] = f64::NAN;
    for (s, w) in [(nan, 0.1), (start, 0.0), (start, f64::INFINITY)] {
        let e = standing_pose::<R, 22, 12, 8, 12>(&p, &s, &modes, &ground, &mu, w, 10).unwrap_err();
        assert_eq!(e, StandingError::NonFinite, "{e}");
    }
    // Nothing held, nothing to stand on.
    let e = standing_pose::<R, 22, 12, 8, 12>(&p, &start, &Modes::flight(), &ground, &mu, 0.1, 10)
        .unwrap_err();
    assert_eq!(e, StandingError::NoStance, "{e}");
    use generated::cassie_leg::CassieLeg;
    let leg = <CassieLeg as LegDynamics<13, 6, 5>>::Params::<f64>::default();
    let e = standing_pose::<CassieLeg, 13, 6, 5, 0>(
        &leg,
        &robot::RobotState::at_rest(
            Vector3::zeros(),
            leg_models::nalgebra::UnitQuaternion::identity(),
            SVector::from_column_slice(&CassieLeg::HOME),
        ),
        &Modes::stick(),
        &Ground::of::<CassieLeg, 13, 6, 5, 0>(),
        &spec_friction::<CassieLeg, f64, 13, 6, 5, 0, 3>(),
        0.1,
        10,
    )
    .unwrap_err();
    assert!(e.to_string().contains("fixed base"), "{e}");
}

#[test]
fn deepest_split_meets_a_hand_solution_and_refuses_bad_input() {
    use leg_models::dynamics::contact::Modes;
    use leg_models::nalgebra::DMatrix;
    use leg_models::robot::balance::{deepest_split, BalanceError};
    // Two points of one foot, rows (λ_t₁, λ_t₂, λ_n): 1.5 N and 0.5 N along t₁ on 1 N
    // each, μ = 1; they may push apart along t₁. By hand: the least margin
    // min(1 − |1.5 + z|, 1 − |0.5 − z|) is largest, 0, at z = −0.5: both (1, 0, 1).
    let forces = SVector::<f64, 6>::from_column_slice(&[1.5, 0.0, 1.0, 0.5, 0.0, 1.0]);
    let mu = SVector::<f64, 6>::from_element(1.0);
    let modes = Modes::<6, 3>::stick();
    let mut n = DMatrix::<f64>::zeros(6, 1);
    n[(0, 0)] = std::f64::consts::FRAC_1_SQRT_2;
    n[(3, 0)] = -std::f64::consts::FRAC_1_SQRT_2;
    let (split, margin) = deepest_split(&forces, &n, &modes, &mu).unwrap();
    let by_hand = SVector::<f64, 6>::from_column_slice(&[1.0, 0.0, 1.0, 1.0, 0.0, 1.0]);
    assert!(margin.abs() < 1e-7, "margin {margin}");
    assert!((split - by_hand).amax() < 1e-7, "split {split:?}");
    // Without the internal direction, the forces as they are: 1.5 N on 1 N, 0.5 outside.
    let (same, least) = deepest_split(&forces, &DMatrix::zeros(6, 0), &modes, &mu).unwrap();
    assert_eq!(same, forces);
    assert!((least + 0.5).abs() < 1e-15, "{least}");
    // Refused: the wrong rows, and a NaN.
    let e = deepest_split(&forces, &DMatrix::zeros(5, 1), &modes, &mu).unwrap_err();
    assert!(matches!(e, BalanceError::SplitInput { .. }), "{e}");
    let mut bad = forces;
    bad[2] = f64::NAN;
    let e = deepest_split(&bad, &n, &modes, &mu).unwrap_err();
    assert!(e.to_string().contains("not finite"), "{e}");
}

/// What one free-feet step (`robot::time_stepping::contact_step`) must satisfy, checked
/// from outside it, in the chart centred at the step's start, from the step's `v⁺` (its
/// `acceleration`), its impulses and its modes:
///
/// - complementarity per contact: `p_n ≥ 0`, `n·C v⁺ + φ/h ≥ 0`, one of them zero;
///   friction inside the 4-edge pyramid `|p_t₁| + |p_t₂| ≤ μ p_n`; a sticking contact's
///   velocity along the ground zero, a sliding one's friction on the pyramid's edge and
///   opposing its slip (`p_t · v_t = −γ μ p_n`), a contact in flight with no impulse;
/// - Newton: the free joint's translation rows of `M (v⁺ − v) + h (N − G)` at the step's
///   start, in the world, are `h (m g + push)` plus the feet's impulses in the world (the
///   weight from the spec's masses);
/// - the impulses' energy identity: `T(v⁺) − T(v*) = −½ Δᵀ M Δ − Σ p_n φ/h − Σ γ μ p_n`
///   with `Δ = v⁺ − v*` (`v*` the step's rates without the ground);
/// - the whole equations of motion, every row, from the model's terms: `M (v⁺ − v) − h
///   (B u + push − N − D v) − Jᵀ F − Cᵀ p = 0` (the step's closure and contact impulses),
///   and `J v⁺ = 0`; and maximum dissipation on the 4-edge pyramid: `±v_t,i + γ ≥ 0`
///   for each edge, `γ ≥ 0` (friction on the edge most against the slip).
///
/// Returns the largest violation of each, scaled: complementarity (with maximum
/// dissipation) in m/s and N s over the step's scale, Newton over the weight's impulse,
/// energy over the kinetic energy (or the weight's work over the step where that is
/// larger), the equations of motion over the largest of their terms.
#[allow(clippy::too_many_arguments)]
fn free_step_violations<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    p: &L::Params<f64>,
    before: &RobotState<f64, NQ>,
    step: &leg_models::robot::time_stepping::ContactStep<f64, NQ, NC, NK>,
    u: &SVector<f64, NU>,
    push: &Vector3<f64>,
    ground: &leg_models::dynamics::contact::Ground<f64, 3>,
    mu: &SVector<f64, NK>,
    dt: f64,
) -> [f64; 4]
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::dynamics::contact::ContactMode;
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let mut s0 = *before;
    s0.recentre(f);
    let chart = robot::chart_params::<L, f64, NQ, NC, NU>(p, &s0.orientation).unwrap();
    let local = robot::ground_in_chart(ground, &s0.position, &s0.orientation);
    let c = local.rows(&L::contact_jacobian(&s0.q, &chart));
    let heights = local.coordinates(&L::contact_positions(&s0.q, &chart));
    let v_plus = s0.v + step.acceleration * dt;
    let v_free = s0.v + step.free_acceleration * dt;
    let rates = c * v_plus;
    let mass = spec_mass::<L, NQ, NC, NU>(p);
    let weight_impulse = mass * 9.81 * dt;
    let speed_scale = v_plus.amax() * L::leg_size(&s0.q, p) + 9.81 * dt;
    let mut comp = 0.0f64;
    let mut slip_work = 0.0;
    let mut gap_work = 0.0;
    for k in 0..NK / 3 {
        let (pt1, pt2, pn) = (
            step.impulses[3 * k],
            step.impulses[3 * k + 1],
            step.impulses[3 * k + 2],
        );
        let (vt1, vt2) = (rates[3 * k], rates[3 * k + 1]);
        let wn = rates[3 * k + 2] + heights[3 * k + 2] / dt;
        let gamma = step.slip_speed[3 * k + 2];
        let m = mu[3 * k];
        let imp = |x: f64| x / weight_impulse;
        let vel = |x: f64| x / speed_scale;
        comp = comp
            .max(imp(-pn))
            .max(vel(-wn))
            .max(imp(pn).min(vel(wn)))
            .max(imp(pt1.abs() + pt2.abs() - m * pn));
        match step.modes.get(k) {
            ContactMode::Flight => {
                comp = comp.max(imp(step.impulses.fixed_rows::<3>(3 * k).amax()))
            }
            ContactMode::Stick => comp = comp.max(vel(vt1.abs().max(vt2.abs()))),
            ContactMode::Slide { .. } => {
                comp = comp
                    .max(imp((pt1.abs() + pt2.abs() - m * pn).abs()))
                    .max(imp(pt1 * vt1 + pt2 * vt2 + gamma * m * pn) / speed_scale)
            }
        }
        if step.modes.get(k) != ContactMode::Flight {
            // Maximum dissipation: no edge of the pyramid slides faster than γ.
            for d in [vt1, -vt1, vt2, -vt2] {
                comp = comp.max(vel(-(d + gamma)));
            }
            comp = comp.max(vel(-gamma));
        }
        slip_work += gamma * m * pn;
        gap_work += pn * heights[3 * k + 2] / dt;
    }
    // Newton for the step: the free joint's translation rows of `M (v⁺ − v) + h (N −
    // G)` (the momentum's change less the Coriolis terms over the step, at the step's
    // start pose), turned into the world, against the weight from the spec's masses, the
    // push and the feet's impulses in the world. (The momentum at the pose after the
    // step differs from it by O(h²): semi-implicit Euler keeps it only to its order.)
    let terms = L::dynamics_terms(&s0.q, &s0.v, &chart);
    let gravity_terms = L::dynamics_terms(&s0.q, &SVector::zeros(), &chart).bias_forces;
    let rows = terms.mass_matrix * (v_plus - s0.v) + (terms.bias_forces - gravity_terms) * dt;
    let lin = s0
        .orientation
        .transform_vector(&Vector3::new(rows[f], rows[f + 1], rows[f + 2]));
    let impulses = (0..NK / 3).fold(Vector3::zeros(), |a, k| {
        a + Vector3::new(
            step.world_forces[3 * k],
            step.world_forces[3 * k + 1],
            step.world_forces[3 * k + 2],
        ) * dt
    });
    let expected = (Vector3::new(0.0, 0.0, -9.81) * mass + push) * dt + impulses;
    let newton = (lin - expected).norm() / weight_impulse;
    let m = L::mass_matrix(&s0.q, &chart);
    let kinetic = |v: &SVector<f64, NQ>| 0.5 * v.dot(&(m * v));
    let delta = v_plus - v_free;
    let identity = -0.5 * delta.dot(&(m * delta)) - gap_work - slip_work;
    let energy_scale = kinetic(&v_plus)
        .max(kinetic(&v_free))
        .max(weight_impulse * 9.81 * dt)
        .max(weight_impulse * speed_scale);
    let energy = (kinetic(&v_plus) - kinetic(&v_free) - identity).abs() / energy_scale;
    // The equations of motion, every row, from the model's terms.
    let mut applied = leg_models::dynamics::actuation::<L, f64, NQ, NC, NU>(u);
    let on_body = s0.orientation.inverse_transform_vector(push);
    for k in 0..3 {
        applied[f + k] += on_body[k];
    }
    let j = L::constraint_jacobian(&s0.q, &chart);
    let parts = [
        terms.mass_matrix * (v_plus - s0.v),
        (applied - terms.bias_forces - L::damping_forces(&s0.v, &chart)) * dt,
        j.transpose() * step.closure,
        c.transpose() * step.impulses,
    ];
    let motion_scale = parts.iter().fold(weight_impulse, |a, x| a.max(x.amax()));
    let motion = ((parts[0] - parts[1] - parts[2] - parts[3]).amax() / motion_scale)
        .max((j * v_plus).amax() / speed_scale);
    [comp, newton, energy, motion]
}

/// The largest of each of [`free_step_violations`] over a run, and how many steps had
/// each contact mode (flight, stick, slide) summed over the contacts.
#[derive(Debug, Default)]
struct FreeRun {
    worst: [f64; 4],
    modes: [usize; 3],
    pivots: usize,
    warm: usize,
    steps: usize,
}

impl FreeRun {
    #[allow(clippy::too_many_arguments)]
    fn step<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
        &mut self,
        problem: &mut leg_models::robot::time_stepping::FootContacts<f64>,
        p: &L::Params<f64>,
        s: &mut RobotState<f64, NQ>,
        u: &SVector<f64, NU>,
        push: &Vector3<f64>,
        ground: &leg_models::dynamics::contact::Ground<f64, 3>,
        mu: &SVector<f64, NK>,
        dt: f64,
    ) -> leg_models::robot::time_stepping::ContactStep<f64, NQ, NC, NK>
    where
        L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
    {
        use leg_models::dynamics::contact::ContactMode;
        let before = *s;
        let step = robot::time_stepping::contact_step::<L, f64, NQ, NC, NU, NK>(
            problem, p, s, u, push, ground, mu, dt,
        )
        .unwrap_or_else(|e| panic!("{}: step {}: {e}", L::NAME, self.steps));
        let v =
            free_step_violations::<L, NQ, NC, NU, NK>(p, &before, &step, u, push, ground, mu, dt);
        for (worst, v) in self.worst.iter_mut().zip(v) {
            *worst = worst.max(v);
        }
        for k in 0..NK / 3 {
            self.modes[match step.modes.get(k) {
                ContactMode::Flight => 0,
                ContactMode::Stick => 1,
                ContactMode::Slide { .. } => 2,
            }] += 1;
        }
        self.pivots += step.pivots;
        self.warm += usize::from(step.warm);
        self.steps += 1;
        step
    }

    /// Every step complementary, Newton's and the energy identity to rounding.
    fn check(&self, name: &str, scene: &str) {
        let [comp, newton, energy, motion] = self.worst;
        eprintln!(
            "{name}: {scene}: {} steps, contact-steps in flight / stick / slide {:?}, {:.1} pivots a step, {} steps solved on the last step's basis; worst complementarity {comp:.1e}, Newton {newton:.1e}, energy identity {energy:.1e}, equations of motion {motion:.1e}",
            self.steps,
            self.modes,
            self.pivots as f64 / self.steps.max(1) as f64,
            self.warm
        );
        assert!(comp < 1e-8, "{name}: {scene}: not complementary ({comp:e})");
        assert!(
            newton < 1e-9,
            "{name}: {scene}: momentum off Newton ({newton:e})"
        );
        assert!(
            energy < 1e-8,
            "{name}: {scene}: energy identity off ({energy:e})"
        );
        assert!(
            motion < 1e-8,
            "{name}: {scene}: equations of motion off ({motion:e})"
        );
    }
}

/// Feet free (`robot::time_stepping`) under the balance QP: standing 0.25 s at 0.5 ms
/// steps, every foot sticks, the forces add up to the weight and the body stays put; the first step's rates
/// are those of the held-feet Euler stance step (the same physics by a KKT solve with
/// every contact held, not a complementarity solve), to rounding; and every step passes
/// [`free_step_violations`]. (At 1 ms, Cassie under the QP diverged within 24 steps of
/// this first-order step, as its held-feet Euler step nears its stability limit there.)
fn free_feet_stand_as_held_feet_do<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::robot::balance::{BalanceController, BalanceGains, BalanceTarget};
    use leg_models::robot::time_stepping::FootContacts;
    use leg_models::simulate::Method;
    let name = L::NAME;
    let Some(Stance {
        params: p,
        start,
        ground,
        modes,
        mu,
    }) = standing_start::<L, NQ, NC, NU, NK>("free feet standing")
    else {
        return;
    };
    if free_on_its_feet::<L, NQ, NC, NU, NK>(&p, &start) == 0 {
        leg_tests::not_applicable(
            name,
            "free feet standing",
            &"its held feet and closures hold every coordinate: there is no balance QP to stand under",
        );
        return;
    }
    let dt = 5e-4;
    let mass = spec_mass::<L, NQ, NC, NU>(&p);
    let mut control = BalanceController::<NQ, NC, NU, NK>::new(
        BalanceTarget::holding(&start),
        BalanceGains::default(),
        None,
    );
    let mut problem = FootContacts::of::<L, NQ, NC, NU, NK>();
    let mut run = FreeRun::default();
    let (mut s, mut force_err) = (start, 0.0f64);
    let zero = Vector3::zeros();
    for i in 0..500 {
        let cmd = control
            .command::<L>(&p, &s, &modes, &ground, &mu)
            .unwrap_or_else(|e| panic!("{name}: step {i}: {e}"));
        if i == 0 {
            let mut held = s;
            robot::pushed_stance_step_by::<L, f64, NQ, NC, NU, NK>(
                Method::SemiImplicitEuler,
                &p,
                &mut held,
                &cmd.torques,
                &zero,
                &modes,
                &ground,
                &mu,
                dt,
            )
            .unwrap();
            let mut free = s;
            run.step::<L, NQ, NC, NU, NK>(
                &mut problem,
                &p,
                &mut free,
                &cmd.torques,
                &zero,
                &ground,
                &mu,
                dt,
            );
            // Both recentred on where the body went: the same chart.
            let d = (free.v - held.v)
                .amax()
                .max((free.position - held.position).amax());
            eprintln!("{name}: free feet's first step off the held feet's Euler step by {d:.1e}");
            assert!(
                d < 1e-10,
                "{name}: the free-feet step is not the held stance's ({d:e})"
            );
            s = free;
            continue;
        }
        let step = run.step::<L, NQ, NC, NU, NK>(
            &mut problem,
            &p,
            &mut s,
            &cmd.torques,
            &zero,
            &ground,
            &mu,
            dt,
        );
        let total = (0..NK / 3).fold(Vector3::zeros(), |a, k| {
            a + Vector3::new(
                step.world_forces[3 * k],
                step.world_forces[3 * k + 1],
                step.world_forces[3 * k + 2],
            )
        });
        force_err = force_err.max((total - Vector3::new(0.0, 0.0, 9.81 * mass)).norm());
    }
    run.check(name, "standing under the balance QP, feet free");
    let moved = (s.position - start.position).norm();
    eprintln!("{name}: feet free, standing 0.25 s: forces off the weight by {force_err:.1e} N, moved {moved:.1e} m");
    assert_eq!(
        run.modes[0] + run.modes[2],
        0,
        "{name}: a foot lifted or slid standing"
    );
    assert!(
        force_err < 1e-4 * 9.81 * mass,
        "{name}: forces off the weight by {force_err:e} N"
    );
    assert!(moved < 1e-6, "{name}: moved {moved:e} m");
}

/// Feet free, dropped flat from 5 mm above the ground at 1 m/s down and 0.2 m/s along
/// it, motors limp: the feet fall freely (no impulse) until the step they would pass
/// through the ground, all of them land in that one step (they are on one plane and the
/// robot falls as one body), each pushes, and none sinks after it; every step passes
/// [`free_step_violations`] (Newton's law carries the touchdown's impulses, the energy
/// identity the plastic impact's loss).
fn free_feet_land_flat<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::dynamics::contact::ContactMode;
    use leg_models::robot::time_stepping::FootContacts;
    let name = L::NAME;
    let Some(Stance {
        params: p,
        start: mut s,
        ground,
        mu,
        ..
    }) = standing_start::<L, NQ, NC, NU, NK>("free feet landing")
    else {
        return;
    };
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let along = ground.normal.cross(&Vector3::x()).normalize();
    let velocity = s
        .orientation
        .inverse_transform_vector(&(-ground.normal + along * 0.2));
    for k in 0..3 {
        s.v[f + k] = velocity[k];
    }
    s.position += ground.normal * 5e-3;
    let dt = 1e-3;
    let mut problem = FootContacts::of::<L, NQ, NC, NU, NK>();
    let mut run = FreeRun::default();
    let zero = Vector3::zeros();
    let mut landed = None;
    for i in 0..20 {
        let step = run.step::<L, NQ, NC, NU, NK>(
            &mut problem,
            &p,
            &mut s,
            &SVector::zeros(),
            &zero,
            &ground,
            &mu,
            dt,
        );
        let touching = (0..NK / 3)
            .filter(|&k| step.modes.get(k) != ContactMode::Flight)
            .count();
        match landed {
            None if touching == 0 => {}
            None => {
                assert_eq!(
                    touching,
                    NK / 3,
                    "{name}: {touching} of {} feet landed at step {i}",
                    NK / 3
                );
                landed = Some(i);
            }
            Some(_) => {}
        }
    }
    let landed = landed.unwrap_or_else(|| panic!("{name}: never landed"));
    // 5 mm at 1 m/s or more (limp legs swing their feet down faster): not in the first
    // step, by the sixth.
    assert!((1..=5).contains(&landed), "{name}: landed at step {landed}");
    run.check(name, "dropped flat, feet free");
    let chart = robot::chart_params::<L, f64, NQ, NC, NU>(&p, &s.orientation).unwrap();
    let local = robot::ground_in_chart(&ground, &s.position, &s.orientation);
    let depth = local
        .coordinates(&L::contact_positions(&s.q, &chart))
        .iter()
        .skip(2)
        .step_by(3)
        .fold(0.0f64, |a, &h| a.max(-h));
    eprintln!("{name}: feet free, landed at step {landed}; deepest foot 15 ms later {depth:.1e} m");
    assert!(depth < 1e-4, "{name}: a foot sank {depth:e} m");
}

/// Feet free, thrown up from standing at 1 m/s along the ground's normal (the body and
/// its legs as one, motors limp): every foot leaves the ground in the first step (later
/// a limp leg may swing a foot back down: Cassie's springs, loaded where it stood,
/// unload); pushed sideways at a fifth of the weight on ice (μ =
/// 0.05, and the least holding torques and a joint PD, 0.1 s at 0.5 ms), the feet slide; every step passes
/// [`free_step_violations`].
fn free_feet_lift_off_and_slide<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::robot::time_stepping::FootContacts;
    let name = L::NAME;
    let Some(Stance {
        params: p,
        start,
        ground,
        modes,
        mu,
    }) = standing_start::<L, NQ, NC, NU, NK>("free feet lifting off and sliding")
    else {
        return;
    };
    let dt = 1e-3;
    let weight = spec_mass::<L, NQ, NC, NU>(&p) * 9.81;
    let mut problem = FootContacts::of::<L, NQ, NC, NU, NK>();
    let (u, _) =
        robot::holding_torques::<L, f64, NQ, NC, NU, NK>(&p, &start, &modes, &ground, &mu).unwrap();
    let f = robot::free_joint::<L, NQ, NC, NU>().unwrap();
    let up = start.orientation.inverse_transform_vector(&ground.normal);
    let mut run = FreeRun::default();
    let mut s = start;
    for k in 0..3 {
        s.v[f + k] = up[k];
    }
    for i in 0..20 {
        run.step::<L, NQ, NC, NU, NK>(
            &mut problem,
            &p,
            &mut s,
            &SVector::zeros(),
            &Vector3::zeros(),
            &ground,
            &mu,
            dt,
        );
        if i == 0 {
            assert_eq!(
                run.modes[0],
                NK / 3,
                "{name}: a foot stayed on the ground thrown up: {:?}",
                run.modes
            );
        }
    }
    run.check(name, "thrown up at 1 m/s, motors limp, feet free");
    let size = L::leg_size(&start.q, &p);
    let stiffness = weight * size;
    let damping = stiffness / 10.0;
    let ice = SVector::<f64, NK>::repeat(0.05);
    let side = ground.normal.cross(&Vector3::x()).normalize() * (0.2 * weight);
    // Half a millisecond: at 1 ms this first-order step under the joint PD diverges on
    // Cassie (its held-feet Euler step's stability limit, as standing).
    let dt = 5e-4;
    let mut run = FreeRun::default();
    let mut s = start;
    for _ in 0..200 {
        let pd = SVector::<f64, NU>::from_fn(|i, _| {
            let a = L::ACTUATED[i];
            -stiffness * (s.q[a] - start.q[a]) - damping * s.v[a]
        });
        run.step::<L, NQ, NC, NU, NK>(
            &mut problem,
            &p,
            &mut s,
            &(u + pd),
            &side,
            &ground,
            &ice,
            dt,
        );
    }
    run.check(
        name,
        "pushed sideways at 0.2 of its weight on ice (μ 0.05), feet free",
    );
    let slid = (s.position - start.position).dot(&side.normalize());
    eprintln!("{name}: on ice, slid {slid:.3e} m along the push in 0.1 s");
    assert!(
        run.modes[2] > 0,
        "{name}: no foot slid on ice: {:?}",
        run.modes
    );
    assert!(slid > 0.0, "{name}: did not go the push's way ({slid:e} m)");
}

/// A free-feet step refuses a bad step length (as the held-feet step does) and a
/// problem made for another robot, and leaves the state as it was.
fn free_feet_refuse_bad_input<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>()
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::robot::time_stepping::{contact_step, ContactStepError, FootContacts};
    let Some(Stance {
        params: p,
        start,
        ground,
        mu,
        ..
    }) = standing_start::<L, NQ, NC, NU, NK>("free feet bad input")
    else {
        return;
    };
    let mut problem = FootContacts::of::<L, NQ, NC, NU, NK>();
    let mut s = start;
    for dt in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
        // The held-feet step refuses it too, with either integrator.
        for method in [
            leg_models::simulate::Method::Rk4,
            leg_models::simulate::Method::SemiImplicitEuler,
        ] {
            let e = robot::pushed_stance_step_by::<L, f64, NQ, NC, NU, NK>(
                method,
                &p,
                &mut s,
                &SVector::zeros(),
                &Vector3::zeros(),
                &leg_models::dynamics::contact::Modes::stick(),
                &ground,
                &mu,
                dt,
            )
            .unwrap_err();
            assert!(matches!(e, robot::RobotStepError::TimeStep { .. }), "{e}");
        }
        let e = contact_step::<L, f64, NQ, NC, NU, NK>(
            &mut problem,
            &p,
            &mut s,
            &SVector::zeros(),
            &Vector3::zeros(),
            &ground,
            &mu,
            dt,
        )
        .unwrap_err();
        assert!(matches!(e, ContactStepError::TimeStep { .. }), "{e}");
        assert!(e.to_string().contains("time step"), "{e}");
    }
    let mut other = FootContacts::<f64>::new(NK / 3 + 1, 4).unwrap();
    let e = contact_step::<L, f64, NQ, NC, NU, NK>(
        &mut other,
        &p,
        &mut s,
        &SVector::zeros(),
        &Vector3::zeros(),
        &ground,
        &mu,
        1e-3,
    )
    .unwrap_err();
    assert!(e.to_string().contains("contacts"), "{e}");
    assert_eq!(s, start, "{}: a refused step moved the state", L::NAME);
    assert!(FootContacts::<f64>::new(2, 2).is_err());
}
