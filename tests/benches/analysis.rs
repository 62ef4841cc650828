//! The design measures' cost: one leg's 200 × 200 grid of foot positions (continuation
//! over the branch and every measure at every node), and the measures at one pose.
//! `cargo bench -p leg-tests --features peers --bench analysis`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use leg_models::analysis::workspace::{workspace, GridOptions};
use leg_models::analysis::{point_measures, LegFrame, MotorLimits};
use leg_models::assembly::{project_position, Tolerance};
use leg_models::nalgebra::SVector;
use leg_models::LegModel;

fn bench_leg<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    c: &mut Criterion,
) {
    let p = L::Params::<f64>::default();
    let mut q = SVector::from(L::HOME);
    project_position::<L, f64, NQ, NC, NU>(&p, &mut q, &Tolerance::default()).unwrap();
    let frame = LegFrame::of::<L, NC, NU>();
    let limits = MotorLimits {
        torque: SVector::from_element(1.0),
        speed: SVector::from_element(100.0),
    };
    let options = GridOptions {
        nodes: 200,
        window: None,
        plane: None,
        motor_range: None,
        limits,
    };
    let mut g = c.benchmark_group(format!("analysis/{}", L::NAME));
    g.warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(8))
        .sample_size(10);
    g.bench_function("grid-200", |b| {
        b.iter(|| workspace::<L, NQ, NC, NU, 2, NC>(black_box(&p), &q, &frame, &options).unwrap())
    });
    g.finish();
    let mut g = c.benchmark_group(format!("analysis/{}", L::NAME));
    g.warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1))
        .sample_size(40);
    g.bench_function("point", |b| {
        b.iter(|| {
            point_measures::<L, f64, NQ, NC, NU, 2, NC>(
                black_box(&p),
                black_box(&q),
                &frame,
                &limits,
            )
        })
    });
    g.finish();
}

fn benches(c: &mut Criterion) {
    bench_leg::<generated::Minitaur, 4, 2, 2>(c);
    bench_leg::<generated::Atrias, 4, 2, 2>(c);
    bench_leg::<generated::Digit, 4, 2, 2>(c);
}

criterion_group!(analysis, benches);
criterion_main!(analysis);
