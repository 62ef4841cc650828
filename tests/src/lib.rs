#![doc = include_str!("../../README.md")]
// The README is this crate's documentation, so its Rust examples run as doctests; so do
// those of the docs/ files, each the documentation of an empty module that only doctests
// see (`cfg(doctest)`: not part of the crate otherwise). A docs file with a ```rust
// block needs its module here.

// docs/rust-api.md
#[doc = include_str!("../../docs/rust-api.md")]
#[cfg(doctest)]
pub mod rust_api {}

// docs/comparing-designs.md
#[doc = include_str!("../../docs/comparing-designs.md")]
#[cfg(doctest)]
pub mod comparing_designs {}

// docs/spec-format.md (its one block is `rust,ignore`: a fragment of a user's crate)
#[doc = include_str!("../../docs/spec-format.md")]
#[cfg(doctest)]
pub mod spec_format {}

// Helpers shared by the workspace tests.

pub mod standing;

use std::path::{Path, PathBuf};

use leg_models::assembly::{project_position, project_velocity, Tolerance};
use leg_models::dynamics::forward_dynamics;
use leg_models::nalgebra::SVector;
use leg_models::simulate::State;
use leg_models::LegDynamics;

/// Records that a check does not apply to a leg, and why (a property of the leg: its
/// motors, mobility or closures). Printed with the test's output, and collected in
/// `target/not-applicable.txt`, which `cargo xtask test` shows at the end.
pub fn not_applicable(leg: &str, check: &str, why: &dyn std::fmt::Display) {
    use std::io::Write as _;
    let why = why.to_string();
    let why = why.strip_prefix("not applicable: ").unwrap_or(&why);
    let line = format!("{leg}: {check}: not applicable: {why}");
    println!("{line}");
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map_or_else(|| workspace_root().join("target"), PathBuf::from);
    let _ = std::fs::create_dir_all(&target);
    if let Ok(mut f) = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(target.join("not-applicable.txt"))
    {
        let _ = writeln!(f, "{line}");
    }
}

/// A small deterministic generator (xorshift64*), so that failures reproduce.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11;
        bits as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ lives in the workspace")
        .to_path_buf()
}

/// A random regular assembled state: random angles projected onto `φ = 0`, random rates
/// projected onto `J q̇ = 0`. States near a singularity are skipped: the dynamics must
/// solve and the passive joints must keep their rank (reciprocal condition of
/// `J_p J_pᵀ` above 1e-4), which also leaves out a five-bar's degenerate mode where both
/// branches coincide, and a ball joint's angles stay 0.2 rad from their chart's
/// singularity (`|cos β| > 0.2`: nearer, `M` in the angles' rates is near singular,
/// cond 3e12 on cassie_leg, and every solve loses digits with it). Singular
/// configurations have tests of their own.
pub fn random_assembled_state<
    L: LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    p: &L::Params<f64>,
    rng: &mut Rng,
    rate: f64,
) -> State<f64, NQ> {
    loop {
        let mut q = SVector::<f64, NQ>::from_fn(|_, _| {
            rng.range(-std::f64::consts::PI, std::f64::consts::PI)
        });
        let mut qd = SVector::<f64, NQ>::from_fn(|_, _| rng.range(-rate, rate));
        if project_position::<L, f64, NQ, NC, NU>(p, &mut q, &Tolerance::default()).is_err()
            || project_velocity::<L, f64, NQ, NC, NU>(p, &q, &mut qd).is_err()
        {
            continue;
        }
        if L::BALL_JOINTS.iter().all(|&b| q[b + 1].cos().abs() > 0.2)
            && forward_dynamics::<L, f64, NQ, NC, NU>(p, &q, &qd, &SVector::zeros(), None).is_ok()
            && passive_rcond::<L, NQ, NC, NU>(p, &q) > 1e-4
        {
            return State { q, qd };
        }
    }
}

/// The derivatives of forward dynamics as a user without them computes them: forward
/// differences, one call at the state and one per coordinate of `q`, `q̇` and `u`
/// (`2 NQ + NU + 1` calls), written into `jac` (column-major `(NQ + NC) × (2 NQ + NU)`:
/// `q̈` then `F`, by `q`, then `q̇`, then `u`). The benchmarks' baseline; `false` where a
/// call fails.
pub fn forward_difference_derivatives<
    L: LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    u: &SVector<f64, NU>,
    h: f64,
    jac: &mut [f64],
) -> bool {
    let fd = |q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, u: &SVector<f64, NU>| {
        forward_dynamics::<L, f64, NQ, NC, NU>(p, q, qd, u, None)
    };
    let Ok(base) = fd(q, qd, u) else {
        return false;
    };
    let rows = NQ + NC;
    let mut put = |col: usize, a: leg_models::dynamics::Acceleration<f64, NQ, NC>| {
        for r in 0..NQ {
            jac[col * rows + r] = (a.qdd[r] - base.qdd[r]) / h;
        }
        for r in 0..NC {
            jac[col * rows + NQ + r] = (a.forces[r] - base.forces[r]) / h;
        }
    };
    for i in 0..NQ {
        let mut x = *q;
        x[i] += h;
        let Ok(a) = fd(&x, qd, u) else { return false };
        put(i, a);
        let mut x = *qd;
        x[i] += h;
        let Ok(a) = fd(q, &x, u) else { return false };
        put(NQ + i, a);
    }
    for i in 0..NU {
        let mut x = *u;
        x[i] += h;
        let Ok(a) = fd(q, qd, &x) else { return false };
        put(2 * NQ + i, a);
    }
    true
}

/// The leg's home pose from its spec, assembled (every joint free), at rest: where the
/// drift figures release each leg.
pub fn passive_release_state<
    L: LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    p: &L::Params<f64>,
) -> State<f64, NQ> {
    let mut q = SVector::<f64, NQ>::from_column_slice(&L::HOME);
    project_position::<L, f64, NQ, NC, NU>(p, &mut q, &Tolerance::default())
        .expect("the home pose assembles");
    State {
        q,
        qd: SVector::zeros(),
    }
}

/// The scene a floating robot's calls are measured at, by the criterion benchmark and
/// by `count_calls` alike: the home pose on a body at the origin, a velocity of every
/// coordinate projected onto the closures and onto every contact held, and small
/// torques.
pub struct RobotScene<const NQ: usize, const NU: usize, const NK: usize, P> {
    pub params: P,
    /// The free joint's first coordinate.
    pub free: usize,
    pub state: leg_models::robot::RobotState<f64, NQ>,
    /// Any plane: a held contact's `q̈` does not depend on where the ground is.
    pub ground: leg_models::dynamics::contact::Ground<f64, 3>,
    /// Every contact held.
    pub modes: leg_models::dynamics::contact::Modes<NK, 3>,
    /// The spec's friction coefficients.
    pub friction: SVector<f64, NK>,
    pub torques: SVector<f64, NU>,
}

/// [`RobotScene`] of `L` at its default parameters, or why there is none (the model
/// does not float, or a velocity projection fails). Panics where the home pose does not
/// assemble ([`passive_release_state`]).
pub fn robot_scene<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
) -> Result<RobotScene<NQ, NU, NK, L::Params<f64>>, String>
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    use leg_models::dynamics::contact::{project_held_velocity, spec_friction, Ground, Modes};
    use leg_models::nalgebra::{UnitQuaternion, Vector3};
    use leg_models::robot::{self, RobotState};
    let params = L::Params::<f64>::default();
    let free = robot::free_joint::<L, NQ, NC, NU>().map_err(|e| e.to_string())?;
    let q = passive_release_state::<L, NQ, NC, NU>(&params).q;
    let mut state = RobotState::at_rest(Vector3::zeros(), UnitQuaternion::identity(), q);
    state.recentre(free);
    let mut v = SVector::<f64, NQ>::from_fn(|i, _| 0.3 + 0.1 * i as f64);
    project_velocity::<L, f64, NQ, NC, NU>(&params, &state.q, &mut v)
        .map_err(|e| format!("the closures' velocity projection: {e}"))?;
    let ground = Ground::<f64, 3>::of::<L, NQ, NC, NU, NK>();
    let modes = Modes::<NK, 3>::stick();
    if NK > 0 {
        project_held_velocity::<L, f64, NQ, NC, NU, NK, 3>(
            &params, &state.q, &mut v, &modes, &ground,
        )
        .map_err(|e| format!("the held contacts' velocity projection: {e}"))?;
    }
    state.v = v;
    Ok(RobotScene {
        params,
        free,
        state,
        ground,
        modes,
        friction: spec_friction::<L, f64, NQ, NC, NU, NK, 3>(),
        torques: SVector::from_fn(|k, _| 0.05 * (k as f64 + 1.0)),
    })
}

/// The scene's ground moved to touch its lowest contact point (the spec's normal, the
/// offset the least `n · x` of the contacts), for the steps in which the ground's place
/// matters (every foot free, `robot::time_stepping`): the lowest contact on it, the
/// others above it, none pushed out of it.
pub fn ground_under<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    scene: &RobotScene<NQ, NU, NK, L::Params<f64>>,
) -> leg_models::dynamics::contact::Ground<f64, 3>
where
    L: leg_models::ContactModel<NQ, NC, NU, NK, 3>,
{
    let x = L::contact_positions(&scene.state.q, &scene.params);
    let n = scene.ground.normal;
    let lowest = (0..NK / 3)
        .map(|k| n.dot(&x.fixed_rows::<3>(3 * k)))
        .fold(f64::INFINITY, f64::min);
    leg_models::dynamics::contact::Ground {
        normal: n,
        offset: if lowest.is_finite() { lowest } else { 0.0 },
    }
}

/// The reciprocal condition of `J_p J_pᵀ` (`J` without the actuated columns), from the
/// pivots of its Cholesky factor; 1 without closures, 0 where it is singular.
pub fn passive_rcond<
    L: LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
) -> f64 {
    if NC == 0 {
        return 1.0;
    }
    let mut jp = L::constraint_jacobian(q, p);
    for &a in L::ACTUATED.iter() {
        jp.column_mut(a).fill(0.0);
    }
    // J_p has at most as many independent rows as passive joints (fewer than its rows
    // on an over-actuated leg, whose motors load each other).
    let dense = leg_models::nalgebra::DMatrix::from_iterator(NC, NQ, jp.iter().copied());
    let mut sv: Vec<f64> = dense
        .svd(false, false)
        .singular_values
        .iter()
        .copied()
        .collect();
    sv.sort_by(|a, b| b.total_cmp(a));
    sv.truncate((NC - L::REDUNDANT_ROWS.min(NC)).min(NQ - NU));
    match (sv.first(), sv.last()) {
        (Some(&hi), Some(&lo)) if hi > 0.0 => (lo / hi).powi(2),
        _ => 0.0,
    }
}

/// `(σ_min / σ_max)²` of the closure rows `j`, not counting the leg's redundant rows (their
/// singular values are zero everywhere); 0 where they lose rank.
pub fn rcond_of_rows<
    L: LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    j: &leg_models::nalgebra::SMatrix<f64, NC, NQ>,
) -> f64 {
    let redundant = L::REDUNDANT_ROWS;
    let dense = leg_models::nalgebra::DMatrix::from_iterator(NC, NQ, j.iter().copied());
    let mut sv: Vec<f64> = dense
        .svd(false, false)
        .singular_values
        .iter()
        .copied()
        .collect();
    sv.sort_by(|a, b| b.total_cmp(a));
    sv.truncate(NC.min(NQ) - redundant.min(NC.min(NQ)));
    match (sv.first(), sv.last()) {
        (Some(&hi), Some(&lo)) if hi > 0.0 => (lo / hi).powi(2),
        _ => 0.0,
    }
}

/// CasADi's own C code of each model (generated/casadi/, compiled at -O3 by build.rs),
/// the benchmarks' peer.
#[cfg(feature = "peers")]
pub mod casadi {
    /// CasADi's calling convention: input and output pointer arrays, integer and real work.
    pub type CasadiFn =
        unsafe extern "C" fn(*const *const f64, *const *mut f64, *mut i64, *mut f64, i32) -> i32;

    /// One derivation's fused terms (M, N, J, J̇q̇) and forward dynamics (q̈, F; `None` on a
    /// spatial leg, whose symbolic KKT solve is too large a C file to compile).
    #[derive(Clone, Copy)]
    pub struct Pair {
        pub terms: CasadiFn,
        pub forward_dynamics: Option<CasadiFn>,
    }

    /// CasADi's C of the notes' Lagrange derivation and of the closed form ours uses.
    #[derive(Clone, Copy)]
    pub struct Peers {
        pub lagrange: Pair,
        pub closed: Pair,
        /// CasADi's `jacobian` of the closed form's forward dynamics: outputs q̈, F,
        /// ∂q̈/∂q, ∂q̈/∂q̇, ∂q̈/∂u, ∂F/∂q, ∂F/∂q̇, ∂F/∂u (dense, column-major); `None` on a
        /// spatial leg.
        pub derivatives: Option<CasadiFn>,
    }

    include!(concat!(env!("OUT_DIR"), "/casadi_peers.rs"));

    /// The functions of `model`.
    pub fn functions(model: &str) -> Peers {
        CASADI_C
            .iter()
            .find(|(n, _)| *n == model)
            .expect("CasADi C of every model")
            .1
    }

    /// A call of a CasADi function with its input and output pointer arrays built once, so
    /// that a measured loop does what a CasADi user's loop does: the call and nothing else.
    pub struct Prepared {
        f: CasadiFn,
        args: [*const f64; 4],
        res: [*mut f64; 8],
    }

    impl Prepared {
        /// `f` reading `inputs` and writing `outputs` (dense, column-major; the generated
        /// functions need no work arrays: `*_work` reports zero sizes). The output pointers
        /// come from `Vec::as_mut_ptr`, which makes no reference to the elements, so the
        /// caller may read the outputs between calls.
        pub fn new(f: CasadiFn, inputs: &[&[f64]], outputs: &mut [&mut Vec<f64>]) -> Prepared {
            assert!(inputs.len() <= 4 && outputs.len() <= 8);
            let args =
                core::array::from_fn(|i| inputs.get(i).map_or(core::ptr::null(), |s| s.as_ptr()));
            let mut res = [core::ptr::null_mut(); 8];
            for (r, o) in res.iter_mut().zip(outputs.iter_mut()) {
                *r = o.as_mut_ptr();
            }
            Prepared { f, args, res }
        }

        /// Calls the function; its status (0 when it succeeded).
        ///
        /// # Safety
        /// The buffers given to [`Prepared::new`] are alive, not reallocated, and of the
        /// dense sizes of the function's inputs and outputs; nothing holds a reference into
        /// the outputs during the call.
        #[inline]
        pub unsafe fn call(&self) -> i32 {
            // SAFETY: as the caller promises; the functions use no work memory.
            unsafe {
                (self.f)(
                    self.args.as_ptr(),
                    self.res.as_ptr(),
                    core::ptr::null_mut(),
                    core::ptr::null_mut(),
                    0,
                )
            }
        }
    }

    /// The parameters as the vector CasADi's functions read, in the generated order.
    pub fn parameter_vector<P: leg_models::Parameters<f64>>(p: &P) -> Vec<f64> {
        (0..P::NAMES.len()).map(|i| p.get(i).unwrap()).collect()
    }
}
