//! Calls each model's fused `dynamics_terms` (f64) a given number of times, for
//! instruction counting under callgrind: the difference between two iteration counts,
//! divided by the difference of the counts, is the cost of one call.
//!
//! ```text
//! cargo build --release -p leg-tests --example fused_terms
//! valgrind --tool=callgrind --callgrind-out-file=/dev/null target/release/examples/fused_terms minitaur 0
//! valgrind --tool=callgrind --callgrind-out-file=/dev/null target/release/examples/fused_terms minitaur 10000
//! ```
//! (`scripts/instruction-counts.sh` does this for every model.)

use std::hint::black_box;

use leg_models::nalgebra::SVector;
use leg_models::LegModel;

fn run<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    n: usize,
) -> f64 {
    let p = L::Params::<f64>::default();
    let mut acc = 0.0;
    for k in 0..n {
        let q = SVector::<f64, NQ>::from_fn(|i, _| 0.1 * (i + 1) as f64 + 1e-6 * k as f64);
        let qd = SVector::<f64, NQ>::from_fn(|i, _| 0.2 * i as f64 - 0.3);
        if std::env::var_os("FD").is_some() {
            let u = SVector::<f64, NU>::from_element(0.1);
            let a = leg_models::dynamics::forward_dynamics::<L, f64, NQ, NC, NU>(
                black_box(&p),
                black_box(&q),
                black_box(&qd),
                black_box(&u),
                None,
            );
            acc += black_box(a).map_or(0.0, |a| a.qdd[0]);
        } else {
            let t = L::dynamics_terms(black_box(&q), black_box(&qd), black_box(&p));
            acc += black_box(t).mass_matrix[(0, 0)];
        }
    }
    acc
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(model), Some(n)) = (
        args.first(),
        args.get(1).and_then(|n| n.parse::<usize>().ok()),
    ) else {
        eprintln!("usage: fused_terms MODEL ITERATIONS");
        std::process::exit(2);
    };
    let mut found = None;
    macro_rules! dispatch {
        ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal) => {
            if model == stringify!($module) {
                found = Some(run::<$ty, $nq, $nc, $nu>(n));
            }
        };
    }
    generated::for_each_model!(dispatch);
    match found {
        Some(acc) => println!("{acc}"),
        None => {
            eprintln!("unknown model `{model}`");
            std::process::exit(2);
        }
    }
}
