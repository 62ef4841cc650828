//! The floating robots standing on their feet under the balance QP
//! (`leg_models::robot::balance`), pushed on the
//! body's origin for 0.1 s along the ground (sideways, then forwards): the largest push
//! each survives (no foot's force leaves its friction cone, and the body is back within
//! 1 mm and 1 mrad after 2 s, a rigid foot's load split between its points as deep in
//! their cones as any split goes), found by bisection. A robot whose home it cannot hold
//! still stands where `standing_pose` puts it; robots that cannot stand this way (fewer
//! than three contact points) are said not applicable, with why. Where the legs carry
//! springs (Cassie), the controller holds them rigid in its model and servos the motors
//! (its defaults); the same pushes planned with the springs as they are follow.
//!
//! `cargo run --release -p leg-tests --example balance`

use leg_models::nalgebra::Vector3;
use leg_models::robot::balance::BalanceGains;
use leg_models::ContactModel;
use leg_tests::standing::{largest_push, push_run, spec_mass, standing_start, Holding, Stance};

// 1 ms: finer than the quadruped's own step (2 ms, `time_step` in tests/tests/robot.rs).
const DT: f64 = 1e-3;
const PUSH_TIME: f64 = 0.1;
const DURATION: f64 = 2.0;

fn report<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>()
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let Some(Stance {
        params: p,
        start,
        ground,
        modes,
        mu,
    }) = standing_start::<L, NQ, NC, NU, NK>("balance example")
    else {
        return;
    };
    let weight = spec_mass::<L, NQ, NC, NU>(&p) * 9.81;
    println!("{}: weight {weight:.3} N, {} feet", L::NAME, NK / 3);
    let t0 = std::time::Instant::now();
    let still = push_run::<L, NQ, NC, NU, NK>(
        &p,
        &start,
        &ground,
        Holding::Balance(BalanceGains::default()),
        Vector3::zeros(),
        0.0,
        1.0,
        DT,
    );
    println!(
        "  balance QP, 1 s unpushed: {:?}; end {:.1e} m {:.1e} rad; {:.1} iterations a tick; {:.1} µs a tick (QP and step)",
        still.failed,
        still.end.0,
        still.end.1,
        still.mean_iterations,
        t0.elapsed().as_secs_f64() * 1e6 / 1000.0
    );
    // One command and one step alone, at the standing state (median of 9 batches).
    {
        use leg_models::robot::balance::{BalanceController, BalanceTarget};
        let mut c = BalanceController::<NQ, NC, NU, NK>::new(
            BalanceTarget::holding(&start),
            BalanceGains::default(),
            None,
        );
        let u = c
            .command::<L>(&p, &start, &modes, &ground, &mu)
            .unwrap()
            .torques;
        let median = |f: &mut dyn FnMut()| {
            let mut t: Vec<f64> = (0..9)
                .map(|_| {
                    let t0 = std::time::Instant::now();
                    for _ in 0..200 {
                        f();
                    }
                    t0.elapsed().as_secs_f64() * 1e6 / 200.0
                })
                .collect();
            t.sort_by(f64::total_cmp);
            t[4]
        };
        let command = median(&mut || {
            std::hint::black_box(c.command::<L>(&p, &start, &modes, &ground, &mu).unwrap());
        });
        let step = median(&mut || {
            let mut s = start;
            std::hint::black_box(
                leg_models::robot::stance_step::<L, f64, NQ, NC, NU, NK>(
                    &p, &mut s, &u, &modes, &ground, &mu, DT,
                )
                .unwrap(),
            );
        });
        println!("  one QP command {command:.1} µs, one RK4 stance step {step:.1} µs (medians)");
    }
    // The standing test's holding (least torques, joint PD), unpushed: its feet's forces
    // against their cones.
    let pd = push_run::<L, NQ, NC, NU, NK>(
        &p,
        &start,
        &ground,
        Holding::JointPd,
        Vector3::zeros(),
        0.0,
        1.0,
        DT,
    );
    println!(
        "  joint PD on the least holding torques, 1 s unpushed: {:?}; largest |λ_t|/(μ λ_n) {:.2}",
        pd.failed, pd.worst_friction
    );
    println!(
        "  balance QP, 1 s unpushed: largest |λ_t|/(μ λ_n) {:.3}, least normal force {:.3} N",
        still.worst_friction, still.least_normal
    );
    // Sideways and forwards along the ground, in the body's frame turned onto it.
    let side = ground
        .normal
        .cross(&start.orientation.transform_vector(&Vector3::x()))
        .normalize();
    let forward = side.cross(&ground.normal);
    let mut plans = vec![("balance QP", BalanceGains::default())];
    if !L::SPRINGS.is_empty() {
        plans.push((
            "balance QP, springs as they are",
            BalanceGains {
                rigid_springs: false,
                ..BalanceGains::default()
            },
        ));
        plans.push((
            "balance QP, springs rigid, no servo",
            BalanceGains {
                servo_stiffness: 0.0,
                ..BalanceGains::default()
            },
        ));
    }
    for (plan, gains) in plans {
        for (name, d) in [
            ("sideways", side),
            ("forwards", forward),
            ("backwards", -forward),
        ] {
            let (lo, hi, why) = largest_push::<L, NQ, NC, NU, NK>(
                &p,
                &start,
                &ground,
                Holding::Balance(gains),
                d,
                PUSH_TIME,
                DURATION,
                DT,
                6,
            );
            println!(
                "  {plan}, pushed {name} for {PUSH_TIME} s: survives {lo:.2} N ({:.2} of its weight); fails at {hi:.2} N: {why}",
                lo / weight
            );
        }
    }
}

macro_rules! each {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
        report::<$ty, $nq, $nc, $nu, $nk>();
    };
}

fn main() {
    generated::for_each_floating_model!(each);
}
