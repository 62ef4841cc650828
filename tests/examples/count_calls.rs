//! Calls one hot path of one model a given number of times, for instruction counting
//! under callgrind: the difference between two call counts, divided by the difference,
//! is the cost of one call (`cargo xtask bench --instructions`, and the budgets
//! `cargo xtask test` checks).
//!
//! `count_calls MODEL PATH CALLS`, PATH one of `empty`, `fused`, `forward_dynamics`,
//! `batch_fused`, `batch_forward_dynamics` (four states per call, `F64x4` lanes),
//! `set_parameter` (parameter 0 set, prepared again where `prepare` reads it), `derivatives` (forward
//! dynamics and its derivatives), `finite_differences` (the same by forward differences of
//! forward dynamics), on a leg with contacts `contact_stance` (forward dynamics with every
//! contact sticking where it is) and `contact_slide` (every contact sliding: in 3-D its
//! friction along its slip velocity), on a floating robot `robot_forward_dynamics` and
//! `robot_stance`, `robot_stance_step`, `robot_free_step` (`run_robot`) and, with the `peers` feature, `casadi_fused`,
//! `casadi_forward_dynamics`,
//! `casadi_closed_fused`, `casadi_closed_forward_dynamics`, `casadi_closed_derivatives`.
//!
//! Every contender runs in the same loop (`measure`) and does only its own work per call:
//! its inputs are prepared once before the loop (the state, the parameters — as the
//! vector CasADi reads, as the `Params` ours reads — and CasADi's argument and result
//! pointer arrays), CasADi writes into buffers allocated before the loop, ours returns its
//! fixed-size outputs by value, and nothing can be hoisted out of the loop (`black_box`
//! on ours' inputs; CasADi's call is opaque). `empty` is the loop alone, the harness's
//! own cost per call, which `cargo xtask bench` subtracts and shows.

use std::hint::black_box;

use leg_models::dynamics::contact::{
    forward_dynamics_with_contacts, spec_friction, ContactMode, Ground, Modes,
};
use leg_models::dynamics::derivatives::forward_dynamics_derivatives;
use leg_models::dynamics::forward_dynamics;
use leg_models::nalgebra::SVector;
use leg_models::{ContactModel, LegDynamics, Parameters};

/// The measured loop, the same for every contender: `call` once per iteration, its result
/// kept so that nothing is dropped as unused.
#[inline(never)]
fn measure(n: usize, mut call: impl FnMut() -> f64) -> f64 {
    let mut acc = 0.0;
    for _ in 0..n {
        acc += black_box(call());
    }
    acc
}

fn run<L: LegDynamics<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    what: &str,
    n: usize,
) -> Option<f64> {
    let p = L::Params::<f64>::default();
    let u = SVector::<f64, NU>::from_element(0.1);
    let q = SVector::<f64, NQ>::from_fn(|i, _| L::HOME[i] + 1e-3);
    let qd = SVector::<f64, NQ>::from_fn(|i, _| 0.2 * i as f64 - 0.3);
    Some(match what {
        "empty" => measure(n, || black_box(0.0)),
        // Ours returns its outputs by value (a fixed-size struct on the stack: no
        // allocation); `black_box` of the inputs keeps the call in the loop.
        // `black_box` of the whole result: every output is computed, as the peers' are (an
        // opaque call), not only the entry the loop reads.
        "fused" => measure(n, || {
            black_box(L::dynamics_terms(
                black_box(&q),
                black_box(&qd),
                black_box(&p),
            ))
            .mass_matrix[(0, 0)]
        }),
        "forward_dynamics" => measure(n, || {
            black_box(forward_dynamics::<L, f64, NQ, NC, NU>(
                black_box(&p),
                black_box(&q),
                black_box(&qd),
                black_box(&u),
                None,
            ))
            .map_or(0.0, |a| a.qdd[0])
        }),
        "directional" => {
            let a = SVector::<f64, NQ>::from_element(0.3);
            let f = SVector::<f64, NC>::from_element(0.2);
            measure(n, || {
                black_box(L::dynamics_derivatives(
                    black_box(&q),
                    black_box(&qd),
                    black_box(&a),
                    black_box(&f),
                    black_box(&p),
                ))
                .dynamics_q[(0, 0)]
            })
        }
        "derivatives" => measure(n, || {
            black_box(forward_dynamics_derivatives::<L, f64, NQ, NC, NU>(
                black_box(&p),
                black_box(&q),
                black_box(&qd),
                black_box(&u),
                None,
            ))
            .map_or(0.0, |d| d.qdd_q[(0, 0)])
        }),
        // The same derivatives as a user without them gets them: forward differences of
        // forward dynamics, one call at the state and one per coordinate of q, q̇ and u
        // (2 NQ + NU + 1 calls), into matrices allocated before the loop.
        "finite_differences" => {
            let mut jac = vec![0.0; (NQ + NC) * (2 * NQ + NU)];
            measure(n, || {
                leg_tests::forward_difference_derivatives::<L, NQ, NC, NU>(
                    black_box(&p),
                    black_box(&q),
                    black_box(&qd),
                    black_box(&u),
                    1e-7,
                    &mut jac,
                );
                black_box(&jac)[0]
            })
        }
        // What a change of parameters costs: parameter 0 set, every prepared value computed
        // again where `prepare` reads it (the work the per-state functions no longer do; a
        // floating robot's parameter 0, gravity, enters none, so there it costs a write).
        "set_parameter" => {
            let mut changed = p;
            let value = p.get(0).unwrap_or(0.0);
            measure(n, || {
                black_box(&mut changed).set(0, black_box(value));
                black_box(&changed).get(0).unwrap_or(0.0)
            })
        }
        // Four states per call on `F64x4` lanes (`cargo xtask bench` divides by four).
        // (A leg whose closure repeats rows has no batched forward dynamics.)
        "batch_forward_dynamics" if L::REDUNDANT_ROWS > 0 => return None,
        "batch_fused" | "batch_forward_dynamics" => {
            use leg_models::simd::{pack, F64x4};
            let p4 = leg_models::dynamics::batch::broadcast::<L, NQ, NC, NU>(&p);
            let qs: Vec<SVector<f64, NQ>> = (0..4).map(|k| q.add_scalar(1e-3 * k as f64)).collect();
            let q4 = pack([&qs[0], &qs[1], &qs[2], &qs[3]]);
            let qd4 = pack([&qd; 4]);
            let u4 = SVector::<F64x4, NU>::from_element(F64x4::splat(0.1));
            if what == "batch_fused" {
                measure(n, || {
                    black_box(L::dynamics_terms(
                        black_box(&q4),
                        black_box(&qd4),
                        black_box(&p4),
                    ))
                    .mass_matrix[(0, 0)]
                        .lane(0)
                })
            } else {
                measure(n, || {
                    black_box(
                        leg_models::dynamics::batch::forward_dynamics::<L, NQ, NC, NU>(
                            black_box(&p4),
                            black_box(&q4),
                            black_box(&qd4),
                            black_box(&u4),
                        ),
                    )
                    .map_or(0.0, |a| a.qdd[0].lane(0))
                })
            }
        }
        #[cfg(feature = "peers")]
        peer if peer.starts_with("casadi_") => {
            use leg_tests::casadi::{functions, parameter_vector, Prepared};
            let pv = parameter_vector(&p);
            let peers = functions(L::NAME);
            let (pair, path) = match peer.strip_prefix("casadi_closed_") {
                Some(path) => (peers.closed, path),
                None => (peers.lagrange, &peer["casadi_".len()..]),
            };
            let (mut first, mut second, mut third, mut fourth) = (
                vec![0.0; NQ * NQ],
                vec![0.0; NQ],
                vec![0.0; NC * NQ],
                vec![0.0; NC],
            );
            let prepared = match path {
                "fused" => Prepared::new(
                    pair.terms,
                    &[q.as_slice(), qd.as_slice(), &pv],
                    &mut [&mut first, &mut second, &mut third, &mut fourth],
                ),
                // A spatial leg's C has the fused terms only (derive.py says why).
                "forward_dynamics" => Prepared::new(
                    pair.forward_dynamics?,
                    &[q.as_slice(), qd.as_slice(), u.as_slice(), &pv],
                    &mut [&mut first, &mut fourth],
                ),
                // CasADi's `jacobian` of its forward dynamics: q̈, F and their six
                // derivatives (the closed form's only).
                "derivatives" if peer == "casadi_closed_derivatives" => {
                    let sizes = [NQ, NC, NQ * NQ, NQ * NQ, NQ * NU, NC * NQ, NC * NQ, NC * NU];
                    let mut outs: Vec<Vec<f64>> = sizes.iter().map(|&k| vec![0.0; k]).collect();
                    first = std::mem::take(&mut outs[2]);
                    let [a, b, _, d, e, f, g, h] = &mut outs[..] else {
                        unreachable!()
                    };
                    let prepared = Prepared::new(
                        peers.derivatives?,
                        &[q.as_slice(), qd.as_slice(), u.as_slice(), &pv],
                        &mut [a, b, &mut first, d, e, f, g, h],
                    );
                    let out = first.as_ptr();
                    return Some(measure(n, || {
                        // SAFETY: as below; `outs` and `first` live until after the loop.
                        unsafe {
                            black_box(&prepared).call();
                            out.read()
                        }
                    }));
                }
                _ => return None,
            };
            let out = first.as_ptr();
            measure(n, || {
                // SAFETY: the buffers live until after the loop, are not reallocated and
                // have the functions' dense sizes; the output is read after the call.
                unsafe {
                    black_box(&prepared).call();
                    out.read()
                }
            })
        }
        _ => return None,
    })
}

/// The contact paths of leg `L` (`ND` rows per contact): forward dynamics with every
/// contact held where it is, or sliding; `None` for another path, or where the state
/// does not allow the path (a slide with no slip velocity).
fn run_contact<
    L: ContactModel<NQ, NC, NU, NK, ND>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    what: &str,
    n: usize,
) -> Option<f64> {
    if NK == 0 {
        return None;
    }
    let p = L::Params::<f64>::default();
    let u = SVector::<f64, NU>::from_element(0.1);
    let q = SVector::<f64, NQ>::from_fn(|i, _| L::HOME[i] + 1e-3);
    let qd = SVector::<f64, NQ>::from_fn(|i, _| 0.2 * i as f64 - 0.3);
    let ground = Ground::<f64, ND>::of::<L, NQ, NC, NU, NK>();
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, ND>();
    let anchors = ground.coordinates(&L::contact_positions(&q, &p));
    let mode = match what {
        "contact_stance" => ContactMode::Stick,
        "contact_slide" => ContactMode::Slide { forward: true },
        _ => return None,
    };
    let mut modes = Modes::<NK, ND>::flight();
    for k in 0..NK / ND {
        modes.set(k, mode);
    }
    let call = || {
        forward_dynamics_with_contacts::<L, f64, NQ, NC, NU, NK, ND>(
            black_box(&p),
            black_box(&q),
            black_box(&qd),
            black_box(&u),
            black_box(&modes),
            black_box(&anchors),
            &ground,
            &mu,
            None,
        )
    };
    // Measured only where the path solves: its error path is not what a budget guards.
    call().ok()?;
    Some(measure(n, || call().map_or(0.0, |s| s.x[0])))
}

/// A floating robot as a user calls it (`leg_models::robot`), at the state the criterion
/// benchmark uses: `robot_forward_dynamics` (`forward_dynamics_at`: the chart centred on
/// the body, gravity rotated into it, then the body's v̇) and `robot_stance`
/// (`stance_dynamics` with every contact held, v̇ too), `robot_stance_step` (one
/// semi-implicit Euler step of that stance at 0.5 ms, its projections included) and
/// `robot_free_step` (one step at 0.5 ms with every foot free, `time_stepping`: its
/// complementarity solve included, the problem allocated once before the loop).
fn run_robot<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    what: &str,
    n: usize,
) -> Option<f64>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::robot;
    if !matches!(
        what,
        "robot_forward_dynamics" | "robot_stance" | "robot_stance_step" | "robot_free_step"
    ) || (what != "robot_forward_dynamics" && NK == 0)
    {
        return None;
    }
    // The criterion benchmark's scene.
    let leg_tests::RobotScene {
        params: p,
        free: f,
        state: s,
        ground,
        modes,
        friction: mu,
        torques: u,
    } = leg_tests::robot_scene::<L, NQ, NC, NU, NK>().ok()?;
    if what == "robot_forward_dynamics" {
        let call = || {
            robot::forward_dynamics_at::<L, f64, NQ, NC, NU>(
                black_box(&p),
                black_box(&s),
                black_box(&u),
            )
            .map(|a| robot::velocity_derivative(f, &s.v, &a.qdd))
        };
        call().ok()?;
        return Some(measure(n, || call().map_or(0.0, |a| a[0])));
    }
    if what == "robot_stance_step" {
        // One semi-implicit Euler stance step at 0.5 ms (`bench --mujoco`'s step), the
        // projections after it included.
        let call = || {
            let mut s = black_box(s);
            robot::pushed_stance_step_by::<L, f64, NQ, NC, NU, NK>(
                leg_models::simulate::Method::SemiImplicitEuler,
                black_box(&p),
                &mut s,
                black_box(&u),
                &leg_models::nalgebra::Vector3::zeros(),
                &modes,
                &ground,
                &mu,
                5e-4,
            )
            .map(|_| s)
        };
        call().ok()?;
        return Some(measure(n, || call().map_or(0.0, |s| s.v[0])));
    }
    if what == "robot_free_step" {
        // The ground where the lowest foot is, so that the step's solve has a contact to
        // hold and none to push out of the ground.
        let scene = leg_tests::robot_scene::<L, NQ, NC, NU, NK>().ok()?;
        let ground = leg_tests::ground_under::<L, NQ, NC, NU, NK>(&scene);
        let mut problem = robot::time_stepping::FootContacts::of::<L, NQ, NC, NU, NK>();
        let mut call = || {
            let mut s = black_box(s);
            robot::time_stepping::contact_step::<L, f64, NQ, NC, NU, NK>(
                &mut problem,
                black_box(&p),
                &mut s,
                black_box(&u),
                &leg_models::nalgebra::Vector3::zeros(),
                &ground,
                &mu,
                5e-4,
            )
            .map(|_| s)
        };
        call().ok()?;
        return Some(measure(n, || call().map_or(0.0, |s| s.v[0])));
    }
    let call = || {
        robot::stance_dynamics::<L, f64, NQ, NC, NU, NK>(
            black_box(&p),
            black_box(&s),
            black_box(&u),
            &modes,
            &ground,
            &mu,
        )
        .map(|st| robot::velocity_derivative(f, &s.v, &st.solution.x))
    };
    // Measured only where the stance solves: its error path is not what a budget guards.
    call().ok()?;
    Some(measure(n, || call().map_or(0.0, |a| a[0])))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(model), Some(what), Some(n)) = (
        args.first(),
        args.get(1),
        args.get(2).and_then(|n| n.parse::<usize>().ok()),
    ) else {
        eprintln!("usage: count_calls MODEL PATH CALLS");
        std::process::exit(2);
    };
    let mut found = None;
    macro_rules! dispatch {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
            if model == stringify!($module) {
                found = run::<$ty, $nq, $nc, $nu>(what, n)
                    .or_else(|| run_contact::<$ty, $nq, $nc, $nu, $nk, 2>(what, n));
            }
        };
    }
    generated::for_each_model!(dispatch);
    // Spatial legs (their foot has three coordinates): the same paths.
    macro_rules! dispatch_spatial {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            if model == stringify!($module) {
                found = run::<$ty, $nq, $nc, $nu>(what, n)
                    .or_else(|| run_contact::<$ty, $nq, $nc, $nu, $nk, 3>(what, n));
            }
        };
    }
    generated::for_each_spatial_model!(dispatch_spatial);
    // Floating robots: their terms in the body's chart, the same paths, and the robot's
    // own calls.
    macro_rules! dispatch_floating {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $np:literal, $nk:literal) => {
            if model == stringify!($module) {
                found = run::<$ty, $nq, $nc, $nu>(what, n)
                    .or_else(|| run_contact::<$ty, $nq, $nc, $nu, $nk, 3>(what, n))
                    .or_else(|| run_robot::<$ty, $nq, $nc, $nu, $nk>(what, n));
            }
        };
    }
    generated::for_each_floating_model!(dispatch_floating);
    match found {
        Some(acc) => println!("{acc}"),
        None => {
            eprintln!("unknown model `{model}` or path `{what}`");
            std::process::exit(2);
        }
    }
}
