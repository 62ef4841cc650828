//! Batched forward dynamics on `F64x4` lanes against the scalar path, lane by lane, on
//! every leg: four assembled random states with random torques, the same to 1e-12
//! relative; every parameter broadcast; lanes with different parameters (a sweep); a broken lane flagged while the
//! others stay right; legs whose closure repeats rows refused with a typed error.

use leg_models::dynamics::batch::{broadcast, forward_dynamics as batch_fd, BatchError};
use leg_models::dynamics::forward_dynamics;
use leg_models::nalgebra::SVector;
use leg_models::simd::{pack, unpack, F64x4};
use leg_models::{LegModel, Parameters};
use leg_tests::{random_assembled_state, Rng};

fn close<const N: usize>(a: &SVector<f64, N>, b: &SVector<f64, N>, what: &str) -> f64 {
    let scale = b.amax().max(1e-9);
    let e = (a - b).amax() / scale;
    assert!(
        e <= 1e-12,
        "{what}: batched {a:?}, scalar {b:?} (relative {e:.1e})"
    );
    e
}

/// `broadcast` of parameters that all differ from the defaults it starts from: every
/// value in every lane, and the prepared quantities of those values (the terms that read
/// them, lane by lane, against the scalar terms).
fn broadcast_sets_every_parameter<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    rng: &mut Rng,
) where
    L: LegModel<NQ, NC, NU>,
{
    let names = <L::Params<f64> as Parameters<f64>>::NAMES;
    let changes: Vec<(usize, f64)> = (0..names.len())
        .map(|i| (i, p.get(i).unwrap() * (1.0 + 1e-3 * (i + 1) as f64) + 1e-4))
        .collect();
    let mut changed = *p;
    assert!(changed.set_many(&changes));
    let p4 = broadcast::<L, NQ, NC, NU>(&changed);
    for (i, name) in names.iter().enumerate() {
        assert_eq!(
            p4.get(i),
            Some(F64x4::splat(changed.get(i).unwrap())),
            "{}: parameter {name}",
            L::NAME
        );
    }
    let s = random_assembled_state::<L, NQ, NC, NU>(p, rng, 1.0);
    let (q4, qd4) = (pack([&s.q; 4]), pack([&s.qd; 4]));
    let gravity = L::gravity_forces(&q4, &p4);
    let energy = L::kinetic_energy(&q4, &qd4, &p4);
    let want_energy = L::kinetic_energy(&s.q, &s.qd, &changed);
    for k in 0..4 {
        close(
            &unpack(&gravity, k),
            &L::gravity_forces(&s.q, &changed),
            L::NAME,
        );
        assert!(
            (energy.0[k] - want_energy).abs() <= 1e-12 * want_energy.abs().max(1e-9),
            "{}: kinetic energy {} against {want_energy}",
            L::NAME,
            energy.0[k]
        );
    }
}

fn check<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>() {
    let p = L::Params::<f64>::default();
    let p4 = broadcast::<L, NQ, NC, NU>(&p);
    let zero = SVector::<F64x4, NU>::from_element(F64x4::splat(0.0));
    let mut rng = Rng::new(41);
    if L::REDUNDANT_ROWS > 0 {
        let q = SVector::<F64x4, NQ>::from_element(F64x4::splat(0.0));
        assert_eq!(
            batch_fd::<L, NQ, NC, NU>(&p4, &q, &q, &zero),
            Err(BatchError::RedundantRows)
        );
        return;
    }
    broadcast_sets_every_parameter::<L, NQ, NC, NU>(&p, &mut rng);
    let mut worst = 0.0f64;
    for _ in 0..25 {
        let states: Vec<_> = (0..4)
            .map(|_| random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 2.0))
            .collect();
        let torques: Vec<SVector<f64, NU>> = (0..4)
            .map(|_| SVector::from_fn(|_, _| rng.range(-1.0, 1.0)))
            .collect();
        let q = pack([&states[0].q, &states[1].q, &states[2].q, &states[3].q]);
        let qd = pack([&states[0].qd, &states[1].qd, &states[2].qd, &states[3].qd]);
        let u = pack([&torques[0], &torques[1], &torques[2], &torques[3]]);
        let got = batch_fd::<L, NQ, NC, NU>(&p4, &q, &qd, &u).unwrap();
        assert_eq!(got.ok, [true; 4], "{}", L::NAME);
        for k in 0..4 {
            let want = forward_dynamics::<L, f64, NQ, NC, NU>(
                &p,
                &states[k].q,
                &states[k].qd,
                &torques[k],
                None,
            )
            .unwrap();
            worst = worst.max(close(&unpack(&got.qdd, k), &want.qdd, L::NAME));
            if NC > 0 {
                close(&unpack(&got.forces, k), &want.forces, L::NAME);
            }
        }
    }
    // A parameter sweep: lane k's first nonzero mass scaled by 1 + k/10 (a massless
    // slider's would sweep nothing).
    let mass = (0..<L::Params<f64> as Parameters<f64>>::NAMES.len())
        .find(|&i| {
            <L::Params<f64> as Parameters<f64>>::NAMES[i].ends_with("_mass")
                && p.get(i).unwrap() > 0.0
        })
        .unwrap();
    let m = p.get(mass).unwrap();
    let mut swept = p4;
    swept.set(mass, F64x4([m, 1.1 * m, 1.2 * m, 1.3 * m]));
    let s = random_assembled_state::<L, NQ, NC, NU>(&p, &mut rng, 1.0);
    let q = pack([&s.q; 4]);
    let qd = pack([&s.qd; 4]);
    let got = batch_fd::<L, NQ, NC, NU>(&swept, &q, &qd, &zero).unwrap();
    for k in 0..4 {
        let mut pk = p;
        pk.set(mass, m * (1.0 + k as f64 / 10.0));
        let want =
            forward_dynamics::<L, f64, NQ, NC, NU>(&pk, &s.q, &s.qd, &SVector::zeros(), None)
                .unwrap();
        close(&unpack(&got.qdd, k), &want.qdd, "sweep");
    }
    // A NaN state in lane 2 fails lane 2 only, as the scalar path fails it.
    let broken = SVector::<f64, NQ>::from_element(f64::NAN);
    let q = pack([&s.q, &s.q, &broken, &s.q]);
    let got = batch_fd::<L, NQ, NC, NU>(&p4, &q, &qd, &zero).unwrap();
    assert!(
        forward_dynamics::<L, f64, NQ, NC, NU>(&p, &broken, &s.qd, &SVector::zeros(), None)
            .is_err()
    );
    assert_eq!(got.ok, [true, true, false, true], "{}", L::NAME);
    eprintln!(
        "{}: batched q̈ within {worst:.1e} of the scalar path",
        L::NAME
    );
}

macro_rules! batch {
    ($module:ident, $ty:path, $nq:literal, $nc:literal, $nu:literal, $nk:literal) => {
        #[test]
        fn $module() {
            check::<$ty, $nq, $nc, $nu>();
        }
    };
}

generated::for_each_model!(batch);
