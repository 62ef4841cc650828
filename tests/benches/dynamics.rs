//! Benchmarks of every generated model beside CasADi's own C code of the same
//! derivation: the generated terms, the fused terms, forward dynamics, the actuated
//! reduction, a control step and a simulation step, in f64 (and f32 for the fused terms
//! and forward dynamics); a floating robot's through `leg_models::robot`. `cargo xtask
//! bench` runs them and prints the table.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use leg_models::assembly::project_velocity;
use leg_models::control::reference::Sinusoid;
use leg_models::control::{actuated_reduction, Gains, JointFeedbackLinearization};
use leg_models::dynamics::contact::Ground;
use leg_models::dynamics::forward_dynamics;
use leg_models::nalgebra::{SVector, UnitQuaternion, Vector3};
use leg_models::robot::{self, RobotState};
use leg_models::simulate::hybrid::{HybridSimulator, HybridState};
use leg_models::simulate::{step, Method, State, StepOptions, TorqueSource};
use leg_models::ContactModel;
use leg_tests::casadi;
use leg_tests::passive_release_state;

fn bench_model<
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>(
    c: &mut Criterion,
) {
    let p = L::Params::<f64>::default();
    let p32 = L::Params::<f32>::default();
    let q = passive_release_state::<L, NQ, NC, NU>(&p).q;
    let mut qd = SVector::<f64, NQ>::from_fn(|i, _| 0.3 + 0.1 * i as f64);
    project_velocity::<L, f64, NQ, NC, NU>(&p, &q, &mut qd).unwrap();
    let u = SVector::<f64, NU>::from_fn(|k, _| 0.05 * (k as f64 + 1.0));
    let (q32, qd32, u32) = (q.cast::<f32>(), qd.cast::<f32>(), u.cast::<f32>());
    let pv = casadi::parameter_vector(&p);
    let peers = casadi::functions(L::NAME);

    let mut g = c.benchmark_group(L::NAME);
    g.warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_millis(1200))
        .sample_size(40);
    // The harness alone: what every measurement below includes besides its contender.
    g.bench_function("empty", |bch| {
        bch.iter(|| black_box((black_box(&q), black_box(&qd), black_box(&p))))
    });
    g.bench_function("fused-ours", |bch| {
        bch.iter(|| L::dynamics_terms(black_box(&q), black_box(&qd), black_box(&p)))
    });
    g.bench_function("fused-ours-f32", |bch| {
        bch.iter(|| L::dynamics_terms(black_box(&q32), black_box(&qd32), black_box(&p32)))
    });

    // Each peer computes the same numbers, and is measured as a CasADi user calls it: the
    // parameter vector and the argument and result pointer arrays prepared once, outputs
    // preallocated.
    let ours = L::dynamics_terms(&q, &qd, &p);
    let acc = forward_dynamics::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None).unwrap();
    let close = |a: &[f64], b: &[f64], tol: f64| {
        a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= tol * (1.0 + y.abs()))
    };
    for (form, pair) in [("casadi", peers.lagrange), ("casadi-closed", peers.closed)] {
        let (mut m, mut n, mut j, mut b) = (
            vec![0.0; NQ * NQ],
            vec![0.0; NQ],
            vec![0.0; NC * NQ],
            vec![0.0; NC],
        );
        let terms = casadi::Prepared::new(
            pair.terms,
            &[q.as_slice(), qd.as_slice(), &pv],
            &mut [&mut m, &mut n, &mut j, &mut b],
        );
        // SAFETY: the buffers outlive `terms` and have the function's dense sizes.
        assert_eq!(unsafe { terms.call() }, 0);
        assert!(
            close(&m, ours.mass_matrix.as_slice(), 1e-12)
                && close(&n, ours.bias_forces.as_slice(), 1e-12)
                && close(&j, ours.constraint_jacobian.as_slice(), 1e-12)
                && close(&b, ours.constraint_bias.as_slice(), 1e-12),
            "{}: {form}'s terms differ from ours",
            L::NAME
        );
        g.bench_function(format!("fused-{form}"), |bch| {
            // SAFETY: as above.
            bch.iter(|| unsafe { black_box(&terms).call() })
        });
        let (mut qdd, mut f) = (vec![0.0; NQ], vec![0.0; NC]);
        let fd = casadi::Prepared::new(
            pair.forward_dynamics
                .expect("a planar leg has CasADi's forward dynamics"),
            &[q.as_slice(), qd.as_slice(), u.as_slice(), &pv],
            &mut [&mut qdd, &mut f],
        );
        // SAFETY: as above.
        assert_eq!(unsafe { fd.call() }, 0);
        assert!(
            close(&qdd, acc.qdd.as_slice(), 1e-8) && close(&f, acc.forces.as_slice(), 1e-8),
            "{}: {form}'s forward dynamics differ from ours",
            L::NAME
        );
        g.bench_function(format!("fd-{form}"), |bch| {
            // SAFETY: as above.
            bch.iter(|| unsafe { black_box(&fd).call() })
        });
    }
    // Forward dynamics and its derivatives: ours (generated directional terms, one
    // factorization), forward differences of ours, and CasADi's `jacobian` of its
    // closed-form forward dynamics, checked equal first.
    let derivatives =
        leg_models::dynamics::derivatives::forward_dynamics_derivatives::<L, f64, NQ, NC, NU>(
            &p, &q, &qd, &u, None,
        )
        .unwrap();
    {
        let sizes = [NQ, NC, NQ * NQ, NQ * NQ, NQ * NU, NC * NQ, NC * NQ, NC * NU];
        let mut outs: Vec<Vec<f64>> = sizes.iter().map(|&k| vec![0.0; k]).collect();
        let mut refs: Vec<&mut Vec<f64>> = outs.iter_mut().collect();
        let jac = casadi::Prepared::new(
            peers
                .derivatives
                .expect("a planar leg has CasADi's derivatives"),
            &[q.as_slice(), qd.as_slice(), u.as_slice(), &pv],
            &mut refs,
        );
        // SAFETY: as above.
        assert_eq!(unsafe { jac.call() }, 0);
        let d = &derivatives;
        let qdd_ok = close(&outs[2], d.qdd_q.as_slice(), 1e-7)
            && close(&outs[3], d.qdd_qd.as_slice(), 1e-7)
            && close(&outs[4], d.qdd_u.as_slice(), 1e-7);
        assert!(qdd_ok, "{}: CasADi's jacobian differs from ours", L::NAME);
        g.bench_function("deriv-casadi-closed", |bch| {
            // SAFETY: as above.
            bch.iter(|| unsafe { black_box(&jac).call() })
        });
    }
    g.bench_function("deriv-ours", |bch| {
        bch.iter(|| {
            leg_models::dynamics::derivatives::forward_dynamics_derivatives::<L, f64, NQ, NC, NU>(
                black_box(&p),
                black_box(&q),
                black_box(&qd),
                black_box(&u),
                None,
            )
        })
    });
    let mut jac = vec![0.0; (NQ + NC) * (2 * NQ + NU)];
    g.bench_function("deriv-finite-differences", |bch| {
        bch.iter(|| {
            leg_tests::forward_difference_derivatives::<L, NQ, NC, NU>(
                black_box(&p),
                black_box(&q),
                black_box(&qd),
                black_box(&u),
                1e-7,
                &mut jac,
            )
        })
    });
    g.bench_function("fd-ours", |bch| {
        bch.iter(|| {
            forward_dynamics::<L, f64, NQ, NC, NU>(
                black_box(&p),
                black_box(&q),
                black_box(&qd),
                black_box(&u),
                None,
            )
        })
    });
    g.bench_function("fd-ours-f32", |bch| {
        bch.iter(|| {
            forward_dynamics::<L, f32, NQ, NC, NU>(
                black_box(&p32),
                black_box(&q32),
                black_box(&qd32),
                black_box(&u32),
                None,
            )
        })
    });
    // Four states per call on `F64x4` lanes (the table divides by four); legs whose closure
    // repeats rows have no batched forward dynamics.
    {
        use leg_models::simd::pack;
        let p4 = leg_models::dynamics::batch::broadcast::<L, NQ, NC, NU>(&p);
        let q4 = pack([&q; 4]);
        let qd4 = pack([&qd; 4]);
        let u4 = pack([&u; 4]);
        g.bench_function("fused-batch", |bch| {
            bch.iter(|| L::dynamics_terms(black_box(&q4), black_box(&qd4), black_box(&p4)))
        });
        if L::REDUNDANT_ROWS == 0 {
            g.bench_function("fd-batch", |bch| {
                bch.iter(|| {
                    leg_models::dynamics::batch::forward_dynamics::<L, NQ, NC, NU>(
                        black_box(&p4),
                        black_box(&q4),
                        black_box(&qd4),
                        black_box(&u4),
                    )
                })
            });
        }
    }
    g.bench_function("mass_matrix-ours", |bch| {
        bch.iter(|| L::mass_matrix(black_box(&q), black_box(&p)))
    });
    g.bench_function("bias_forces-ours", |bch| {
        bch.iter(|| L::bias_forces(black_box(&q), black_box(&qd), black_box(&p)))
    });
    g.bench_function("constraint_jacobian-ours", |bch| {
        bch.iter(|| L::constraint_jacobian(black_box(&q), black_box(&p)))
    });
    g.bench_function("constraint_bias-ours", |bch| {
        bch.iter(|| L::constraint_bias(black_box(&q), black_box(&qd), black_box(&p)))
    });
    g.bench_function("foot_jacobian-ours", |bch| {
        bch.iter(|| L::foot_jacobian(black_box(&q), black_box(&p)))
    });
    g.bench_function("kinetic_energy-ours", |bch| {
        bch.iter(|| L::kinetic_energy(black_box(&q), black_box(&qd), black_box(&p)))
    });
    g.bench_function("reduction-ours", |bch| {
        bch.iter(|| {
            let t = L::dynamics_terms(black_box(&q), black_box(&qd), &p);
            actuated_reduction::<L, f64, NQ, NC, NU>(&p, &t, &qd)
        })
    });
    let theta = SVector::<f64, NU>::from_fn(|k, _| q[L::ACTUATED[k]]);
    let reference = Sinusoid {
        offset: theta,
        amplitude: SVector::from_element(0.1),
        frequency: SVector::from_element(1.0),
        phase: SVector::zeros(),
    };
    let state = State { q, qd };
    // Joint-space control, on every leg whose motors do not over-determine it.
    if let Ok(mut controller) = JointFeedbackLinearization::<L, f64, _, NQ, NC, NU>::new(
        p,
        Gains::critically_damped(100.0),
        reference,
    ) {
        g.bench_function("control-ours", |bch| {
            bch.iter(|| controller.torque(black_box(0.1), black_box(&state)))
        });
    }
    let opts = StepOptions::rk4(1e-3);
    g.bench_function("step-ours", |bch| {
        bch.iter(|| {
            let mut s = black_box(state);
            let mut hold = |_: f64, _: &State<f64, NQ>| u;
            step::<L, f64, NQ, NC, NU>(&p, &mut s, 0.0, &mut hold, &opts).map(|_| s)
        })
    });
    // A hybrid step (RK4 with the contact rows in the solve, guards, projection onto every
    // active constraint) beside the swing-leg step: in stance (the home pose's contacts on
    // the ground, sticking) and in flight (5 cm up), neither with an event in the step.
    if NK > 0 {
        let sim = HybridSimulator::<L, f64, NQ, NC, NU, NK>::new(p, 1e-3);
        let zero = SVector::<f64, NU>::zeros();
        let mut hold = |_: f64, _: &HybridState<f64, NQ, NK>| zero;
        let rest = State {
            q,
            qd: SVector::zeros(),
        };
        // Flight: the home pose lifted 5 cm along the body's height (the prismatic joint
        // that raises the contacts most).
        let lift = leg_models::control::hop::height_joint::<L, f64, NQ, NC, NU, NK>(&p, &q);
        let mut up = rest;
        if let Some(i) = lift {
            up.q[i] += 0.05;
        }
        // Stance: every contact held where it is, projected onto the ground.
        let mut stance = HybridState::flight(rest);
        let coords = leg_models::dynamics::contact::Ground::<f64>::of::<L, NQ, NC, NU, NK>()
            .coordinates(&L::contact_positions(&q, &p));
        for k in 0..NK / 2 {
            stance
                .modes
                .set(k, leg_models::dynamics::contact::ContactMode::Stick);
            stance.anchors[2 * k] = coords[2 * k];
        }
        let stance = sim.project(&mut stance).map(|_| stance);
        for (name, start) in [
            ("hybrid-step-stance", stance),
            ("hybrid-step-flight", Ok(HybridState::flight(up))),
        ] {
            let Ok(start) = start else {
                eprintln!("{}: {name} not measured (no such state from home)", L::NAME);
                continue;
            };
            // Measured only where the step has no event: the cost of a plain step.
            let mut probe = start;
            match sim.step(&mut probe, 0.0, &mut hold) {
                Ok(e) if e.is_empty() => {}
                other => {
                    eprintln!(
                        "{}: {name} not measured (the step has events or fails: {other:?})",
                        L::NAME
                    );
                    continue;
                }
            }
            g.bench_function(name, |bch| {
                bch.iter(|| {
                    let mut hs = black_box(start);
                    sim.step(&mut hs, 0.0, &mut hold).map(|e| (hs, e.len()))
                })
            });
        }
    }
    g.finish();
}

/// A spatial leg: the fused terms beside CasADi's C of the Lagrange form and of the closed
/// form (checked equal first), forward dynamics, and a simulation step.
fn bench_spatial<L, const NQ: usize, const NC: usize, const NU: usize>(c: &mut Criterion)
where
    L: leg_models::LegDynamics<NQ, NC, NU>,
{
    let p = L::Params::<f64>::default();
    let q = passive_release_state::<L, NQ, NC, NU>(&p).q;
    let mut qd = SVector::<f64, NQ>::from_fn(|i, _| 0.3 + 0.1 * i as f64);
    project_velocity::<L, f64, NQ, NC, NU>(&p, &q, &mut qd).unwrap();
    let u = SVector::<f64, NU>::from_fn(|k, _| 0.05 * (k as f64 + 1.0));
    let pv = casadi::parameter_vector(&p);
    let peers = casadi::functions(L::NAME);
    let mut g = c.benchmark_group(L::NAME);
    g.warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_millis(1200))
        .sample_size(40);
    g.bench_function("empty", |bch| {
        bch.iter(|| black_box((black_box(&q), black_box(&qd), black_box(&p))))
    });
    g.bench_function("fused-ours", |bch| {
        bch.iter(|| L::dynamics_terms(black_box(&q), black_box(&qd), black_box(&p)))
    });
    let ours = L::dynamics_terms(&q, &qd, &p);
    let close = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= 1e-12 * (1.0 + y.abs()))
    };
    for (form, pair) in [("casadi", peers.lagrange), ("casadi-closed", peers.closed)] {
        let (mut m, mut n, mut j, mut b) = (
            vec![0.0; NQ * NQ],
            vec![0.0; NQ],
            vec![0.0; NC * NQ],
            vec![0.0; NC],
        );
        let terms = casadi::Prepared::new(
            pair.terms,
            &[q.as_slice(), qd.as_slice(), &pv],
            &mut [&mut m, &mut n, &mut j, &mut b],
        );
        // SAFETY: the buffers outlive `terms` and have the function's dense sizes.
        assert_eq!(unsafe { terms.call() }, 0);
        assert!(
            close(&m, ours.mass_matrix.as_slice())
                && close(&n, ours.bias_forces.as_slice())
                && close(&j, ours.constraint_jacobian.as_slice())
                && close(&b, ours.constraint_bias.as_slice()),
            "{}: {form}'s terms differ from ours",
            L::NAME
        );
        g.bench_function(format!("fused-{form}"), |bch| {
            // SAFETY: as above.
            bch.iter(|| unsafe { black_box(&terms).call() })
        });
    }
    g.bench_function("fd-ours", |bch| {
        bch.iter(|| {
            forward_dynamics::<L, f64, NQ, NC, NU>(
                black_box(&p),
                black_box(&q),
                black_box(&qd),
                black_box(&u),
                None,
            )
        })
    });
    let opts = StepOptions::rk4(1e-3);
    g.bench_function("step-ours", |bch| {
        bch.iter(|| {
            let mut s = black_box(State { q, qd });
            let mut hold = |_: f64, _: &State<f64, NQ>| u;
            step::<L, f64, NQ, NC, NU>(&p, &mut s, 0.0, &mut hold, &opts).map(|_| s)
        })
    });
    g.finish();
}

/// A floating robot as a user calls it (`leg_models::robot`), beside Pinocchio's free
/// flyer (`cargo xtask bench --pinocchio cassie minitaur_quadruped`): the fused terms in
/// the chart; forward dynamics at a state (`forward_dynamics_at`, the chart centred on the
/// body, then `velocity_derivative`: the body's v̇, what Pinocchio returns) and, with
/// contact points, the stance with every one held (`stance_dynamics`, v̇ too). The state
/// (`leg_tests::robot_scene`): `passive_release_state`'s joints, the body level at the
/// origin, rates `0.3 + 0.1 i` put on the closures and the held contacts. The xtask's
/// state for Pinocchio is the same pose and rates, projected in another order (the body
/// re-centred after the projection there, before it here), so not to the bit the same;
/// the cost of our call does not depend on the state.
fn bench_floating<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    c: &mut Criterion,
) where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let leg_tests::RobotScene {
        params: p,
        free: f,
        state: s,
        ground,
        modes,
        friction: mu,
        torques: u,
    } = leg_tests::robot_scene::<L, NQ, NC, NU, NK>()
        .unwrap_or_else(|e| panic!("{}: the robot's scene: {e}", L::NAME));
    let mut g = c.benchmark_group(L::NAME);
    g.warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_millis(1200))
        .sample_size(40);
    g.bench_function("empty", |bch| {
        bch.iter(|| black_box((black_box(&s), black_box(&u), black_box(&p))))
    });
    g.bench_function("fused-ours", |bch| {
        bch.iter(|| L::dynamics_terms(black_box(&s.q), black_box(&s.v), black_box(&p)))
    });
    g.bench_function("fd-ours", |bch| {
        bch.iter(|| {
            let s = black_box(&s);
            robot::forward_dynamics_at::<L, f64, NQ, NC, NU>(black_box(&p), s, black_box(&u))
                .map(|a| (robot::velocity_derivative(f, &s.v, &a.qdd), a.forces))
        })
    });
    let stance = |s: &RobotState<f64, NQ>| {
        robot::stance_dynamics::<L, f64, NQ, NC, NU, NK>(
            black_box(&p),
            s,
            black_box(&u),
            &modes,
            &ground,
            &mu,
        )
        .map(|st| {
            (
                robot::velocity_derivative(f, &s.v, &st.solution.x),
                st.world_forces,
            )
        })
    };
    // Measured only where the stance solves: its error path is not what is compared.
    if NK > 0 && stance(&s).is_ok() {
        g.bench_function("stance-ours", |bch| bch.iter(|| stance(black_box(&s))));
        // One stance step at 0.5 ms (MuJoCo Menagerie's Cassie's time step), every
        // contact held, the closures projected after it: RK4 and semi-implicit Euler.
        for (id, method) in [
            ("step-ours", Method::Rk4),
            ("step-ours-euler", Method::SemiImplicitEuler),
        ] {
            let step = |s: &RobotState<f64, NQ>| {
                let mut s = *s;
                robot::pushed_stance_step_by::<L, f64, NQ, NC, NU, NK>(
                    method,
                    black_box(&p),
                    &mut s,
                    black_box(&u),
                    &Vector3::zeros(),
                    &modes,
                    &ground,
                    &mu,
                    5e-4,
                )
                .map(|st| (s, st.world_forces))
            };
            if step(&s).is_ok() {
                g.bench_function(id, |bch| bch.iter(|| step(black_box(&s))));
            }
        }
        // One step with every foot free (`robot::time_stepping`): the contact modes from
        // one complementarity solve, the problem allocated once outside the loop, on the
        // ground through the lowest foot (count_calls' `robot_free_step`).
        let under = leg_tests::ground_under::<L, NQ, NC, NU, NK>(
            &leg_tests::robot_scene::<L, NQ, NC, NU, NK>().expect("the scene above"),
        );
        let mut problem = robot::time_stepping::FootContacts::of::<L, NQ, NC, NU, NK>();
        let mut free_step = |s: &RobotState<f64, NQ>| {
            let mut s = *s;
            robot::time_stepping::contact_step::<L, f64, NQ, NC, NU, NK>(
                &mut problem,
                black_box(&p),
                &mut s,
                black_box(&u),
                &Vector3::zeros(),
                &under,
                &mu,
                5e-4,
            )
            .map(|st| (s, st.world_forces))
        };
        if free_step(&s).is_ok() {
            g.bench_function("step-ours-free", |bch| {
                bch.iter(|| free_step(black_box(&s)))
            });
        }
    }
    if let Some(replay) = Replay::<NQ, NU>::read(L::NAME) {
        bench_second::<L, NQ, NC, NU, NK>(&mut g, &replay);
    }
    g.finish();
}

/// The environment variable naming the folder of `legs sim ROBOT` runs (`ROBOT/trajectory.csv`)
/// that `second-ours` replays (`cargo xtask bench --mujoco` sets it).
const REPLAY_DIR: &str = "LEG_BENCH_REPLAY";

/// A run of `legs sim ROBOT` (the balance QP closing the loop, the push on the body): the
/// state it started from, each step's torques and push, and each step's start.
struct Replay<const NQ: usize, const NU: usize> {
    dt: f64,
    starts: Vec<RobotState<f64, NQ>>,
    torques: Vec<SVector<f64, NU>>,
    pushes: Vec<Vector3<f64>>,
}

impl<const NQ: usize, const NU: usize> Replay<NQ, NU> {
    /// `$LEG_BENCH_REPLAY/NAME/trajectory.csv`; `None` where the variable is not set.
    /// Panics on a file that is not `sim`'s (the bench is not to run on half a replay).
    fn read(name: &str) -> Option<Self> {
        let dir = std::env::var_os(REPLAY_DIR)?;
        let path = std::path::Path::new(&dir).join(name).join("trajectory.csv");
        // A robot `sim` cannot run (fewer than three contact points) has no replay.
        if !path.exists() {
            return None;
        }
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
        let columns = |prefix: &str| -> Vec<usize> {
            (0..header.len())
                .filter(|&i| header[i].starts_with(prefix))
                .collect()
        };
        let one = |name: &str| {
            header
                .iter()
                .position(|h| *h == name)
                .unwrap_or_else(|| panic!("{}: no column {name}", path.display()))
        };
        let (q, v, u) = (columns("q_"), columns("v_"), columns("u_"));
        assert!(
            q.len() == NQ && v.len() == NQ && u.len() == NU,
            "{}: {} q, {} v and {} u columns, the model has {NQ} coordinates and {NU} motors",
            path.display(),
            q.len(),
            v.len(),
            u.len()
        );
        let pose = [
            "body_x", "body_y", "body_z", "body_qw", "body_qx", "body_qy", "body_qz",
        ]
        .map(one);
        let push = ["push_x", "push_y", "push_z"].map(one);
        let time = one("t");
        let (mut starts, mut torques, mut pushes, mut times) = (vec![], vec![], vec![], vec![]);
        for line in lines {
            let row: Vec<f64> = line
                .split(',')
                .map(|x| x.parse().unwrap_or(f64::NAN))
                .collect();
            let at = |i: &usize| row[*i];
            let [x, y, z, w, i, j, k] = pose.map(|c| row[c]);
            starts.push(RobotState {
                position: Vector3::new(x, y, z),
                orientation: UnitQuaternion::new_normalize(leg_models::nalgebra::Quaternion::new(
                    w, i, j, k,
                )),
                q: SVector::from_iterator(q.iter().map(at)),
                v: SVector::from_iterator(v.iter().map(at)),
            });
            torques.push(SVector::from_iterator(u.iter().map(at)));
            pushes.push(Vector3::from_iterator(push.iter().map(at)));
            times.push(row[time]);
        }
        assert!(times.len() >= 2, "{}: fewer than two rows", path.display());
        Some(Replay {
            dt: times[1] - times[0],
            starts,
            torques,
            pushes,
        })
    }
}

/// A simulated second (the replay's steps) of the standing, pushed robot, beside MuJoCo's
/// (`xtask/mujoco_step_bench.py`, the same torques and pushes): each step's recorded
/// torques and a motor servo about the recorded motion (the servo MuJoCo's run needs to
/// keep its robot on its feet open-loop; here it adds nothing to what was recorded, but its
/// work is done), every contact held, on the world's ground `z = 0` where `sim` stands
/// robots. RK4 (as `sim` steps) must end where the recorded run did, or the replay is not
/// the run and nothing is timed.
fn bench_second<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    g: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>,
    replay: &Replay<NQ, NU>,
) where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::dynamics::contact::{spec_friction, Modes};
    const KP: f64 = 200.0;
    const KD: f64 = 5.0;
    let p = L::Params::<f64>::default();
    let ground = Ground {
        normal: Vector3::z(),
        offset: 0.0,
    };
    let (modes, mu) = (
        Modes::<NK, 3>::stick(),
        spec_friction::<L, f64, NQ, NC, NU, NK, 3>(),
    );
    let second = |method: Method, every: &mut dyn FnMut(usize, &RobotState<f64, NQ>)| {
        let mut s = replay.starts[0];
        for i in 0..replay.starts.len() {
            let (recorded, mut u) = (&replay.starts[i], replay.torques[i]);
            for (k, &a) in L::ACTUATED.iter().enumerate() {
                u[k] += KP * (recorded.q[a] - s.q[a]) + KD * (recorded.v[a] - s.v[a]);
            }
            robot::pushed_stance_step_by::<L, f64, NQ, NC, NU, NK>(
                method,
                &p,
                &mut s,
                &u,
                &replay.pushes[i],
                &modes,
                &ground,
                &mu,
                replay.dt,
            )
            .unwrap_or_else(|e| panic!("{}: replayed step {i}: {e}", L::NAME));
            every(i, &s);
        }
        s
    };
    // Each step's end against the next row's start (the last step's end is not a row).
    let mut off = 0.0f64;
    second(Method::Rk4, &mut |i, s| {
        if let Some(next) = replay.starts.get(i + 1) {
            off = off.max((s.position - next.position).amax());
            off = off.max((s.q - next.q).amax());
        }
    });
    assert!(
        off <= 1e-9,
        "{}: the RK4 replay parts from the recorded run by {off:.1e} m: not the same run",
        L::NAME
    );
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(4));
    for (id, method) in [
        ("second-ours", Method::Rk4),
        ("second-ours-euler", Method::SemiImplicitEuler),
    ] {
        g.bench_function(id, |bch| {
            bch.iter(|| {
                second(black_box(method), &mut |_, s| {
                    black_box(s);
                })
            })
        });
    }
    // Every foot free (`robot::time_stepping`): each step finds every contact's mode, as
    // MuJoCo's finds its contacts and solves them, rather than holding the given ones.
    let mut problem = robot::time_stepping::FootContacts::of::<L, NQ, NC, NU, NK>();
    let free_second = |problem: &mut robot::time_stepping::FootContacts<f64>| {
        let mut s = replay.starts[0];
        let mut lifted = 0usize;
        for i in 0..replay.starts.len() {
            let (recorded, mut u) = (&replay.starts[i], replay.torques[i]);
            for (k, &a) in L::ACTUATED.iter().enumerate() {
                u[k] += KP * (recorded.q[a] - s.q[a]) + KD * (recorded.v[a] - s.v[a]);
            }
            let step = robot::time_stepping::contact_step::<L, f64, NQ, NC, NU, NK>(
                problem,
                &p,
                &mut s,
                &u,
                &replay.pushes[i],
                &ground,
                &mu,
                replay.dt,
            )
            .unwrap_or_else(|e| panic!("{}: replayed free-feet step {i}: {e}", L::NAME));
            lifted += (0..NK / 3)
                .filter(|&k| !step.modes.get(k).on_ground())
                .count();
            black_box(&s);
        }
        (s, lifted)
    };
    let (_, lifted) = free_second(&mut problem);
    eprintln!(
        "{}: the free-feet replay: {lifted} contact-steps off the ground",
        L::NAME
    );
    g.bench_function("second-ours-free", |bch| {
        bch.iter(|| free_second(&mut problem))
    });
}

fn benches(c: &mut Criterion) {
    macro_rules! each {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            bench_model::<$ty, $nq, $nc, $nu, $nk>(c);
        };
    }
    generated::for_each_model!(each);
    macro_rules! spatial {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            bench_spatial::<$ty, $nq, $nc, $nu>(c);
        };
    }
    generated::for_each_spatial_model!(spatial);
    macro_rules! floating {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            bench_floating::<$ty, $nq, $nc, $nu, $nk>(c);
        };
    }
    generated::for_each_floating_model!(floating);
}

criterion_group!(dynamics, benches);
criterion_main!(dynamics);
