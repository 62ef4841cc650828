//! Calls one hot path of one model a given number of times, for instruction counting
//! under callgrind: the difference between two call counts, divided by the difference,
//! is the cost of one call (`cargo xtask bench --instructions`, and the budgets
//! `cargo xtask test` checks).
//!
//! `count_calls MODEL fused|forward_dynamics|casadi_fused|casadi_forward_dynamics CALLS`
//! (the CasADi paths with the `peers` feature).

use std::hint::black_box;

use leg_models::dynamics::forward_dynamics;
use leg_models::nalgebra::SVector;
use leg_models::LegModel;

fn run<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    what: &str,
    n: usize,
) -> Option<f64> {
    let p = L::Params::<f64>::default();
    let u = SVector::<f64, NU>::from_element(0.1);
    let mut acc = 0.0;
    for k in 0..n {
        // Distinct states, so that nothing is hoisted out of the loop.
        let q = SVector::<f64, NQ>::from_fn(|i, _| L::HOME[i] + 1e-6 * k as f64);
        let qd = SVector::<f64, NQ>::from_fn(|i, _| 0.2 * i as f64 - 0.3);
        acc += match what {
            "fused" => {
                black_box(L::dynamics_terms(
                    black_box(&q),
                    black_box(&qd),
                    black_box(&p),
                ))
                .mass_matrix[(0, 0)]
            }
            "forward_dynamics" => black_box(forward_dynamics::<L, f64, NQ, NC, NU>(
                black_box(&p),
                black_box(&q),
                black_box(&qd),
                black_box(&u),
                None,
            ))
            .map_or(0.0, |a| a.qdd[0]),
            #[cfg(feature = "peers")]
            "casadi_fused" | "casadi_forward_dynamics" => {
                use leg_models::Parameters;
                let pv: Vec<f64> = (0..<L::Params<f64> as Parameters<f64>>::NAMES.len())
                    .map(|i| p.get(i).unwrap())
                    .collect();
                let (terms, fd) = leg_tests::casadi::functions(L::NAME);
                let mut out = vec![0.0; NQ * NQ + NQ + NC * NQ + NC];
                let (a, rest) = out.split_at_mut(NQ * NQ);
                let (b, rest) = rest.split_at_mut(NQ);
                let (c, d) = rest.split_at_mut(NC * NQ);
                if what == "casadi_fused" {
                    leg_tests::casadi::call(
                        terms,
                        &[black_box(q.as_slice()), qd.as_slice(), &pv],
                        &mut [a, b, c, d],
                    );
                } else {
                    leg_tests::casadi::call(
                        fd,
                        &[black_box(q.as_slice()), qd.as_slice(), u.as_slice(), &pv],
                        &mut [&mut a[..NQ], &mut c[..NC]],
                    );
                }
                black_box(&out)[0]
            }
            _ => return None,
        };
    }
    Some(acc)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(model), Some(what), Some(n)) = (
        args.first(),
        args.get(1),
        args.get(2).and_then(|n| n.parse::<usize>().ok()),
    ) else {
        eprintln!("usage: count_calls MODEL fused|forward_dynamics CALLS");
        std::process::exit(2);
    };
    let mut found = None;
    macro_rules! dispatch {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal) => {
            if model == stringify!($module) {
                found = run::<$ty, $nq, $nc, $nu>(what, n);
            }
        };
    }
    generated::for_each_model!(dispatch);
    match found {
        Some(acc) => println!("{acc}"),
        None => {
            eprintln!("unknown model `{model}` or path `{what}`");
            std::process::exit(2);
        }
    }
}
