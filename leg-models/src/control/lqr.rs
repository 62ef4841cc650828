//! Discrete LQR on the constraint manifold: the Riccati equation of a linearized step
//! ([`crate::control::linearize::ManifoldChart::linearize_step`]) solved once, and a controller that
//! holds a leg at a pose or tracks a slow reference of the chart's coordinates with it,
//! under torque limits.
//!
//! The discrete algebraic Riccati equation `P = Q + Aᵀ P A − Aᵀ P B (R + Bᵀ P B)⁻¹ Bᵀ P A`
//! is solved by the structure-preserving doubling algorithm (Chu, Fan, Lin and Wang,
//! 2004): the Riccati iteration with its step doubled each round, so that it converges
//! quadratically where the plain iteration needs thousands of rounds for a step much
//! shorter than the leg's time constants. Fixed-size and allocation-free.

use core::marker::PhantomData;

use nalgebra::{SMatrix, SVector};

use crate::assembly::Tolerance;
use crate::control::linearize::ManifoldChart;
use crate::control::reference::Reference;
use crate::model::contract::{LegDynamics, Real};
use crate::model::linalg::{all_finite, Cholesky, Lu};
use crate::simulate::source::ControlError;
use crate::simulate::source::LinearizationError;
pub use crate::simulate::source::LqrError;
use crate::simulate::source::{State, TorqueSource};
use crate::simulate::step::StepOptions;

/// The optimal state feedback `δu = −K δx` of `δx⁺ = A δx + B δu` with the cost
/// `Σ δxᵀ Q δx + δuᵀ R δu`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lqr<T: Real, const NX: usize, const NU: usize> {
    /// `K = (R + Bᵀ P B)⁻¹ Bᵀ P A`.
    pub gain: SMatrix<T, NU, NX>,
    /// `P`, the cost-to-go `δxᵀ P δx`.
    pub cost: SMatrix<T, NX, NX>,
    /// `A − B K`.
    pub closed_loop: SMatrix<T, NX, NX>,
    /// Doubling rounds taken.
    pub iterations: usize,
}

impl<T: Real, const NX: usize, const NU: usize> Lqr<T, NX, NU> {
    /// Solves the Riccati equation (at most 64 doubling rounds: `2⁶⁴` Riccati steps).
    pub fn new(
        a: &SMatrix<T, NX, NX>,
        b: &SMatrix<T, NX, NU>,
        q: &SMatrix<T, NX, NX>,
        r: &SMatrix<T, NU, NU>,
    ) -> Result<Self, LqrError> {
        if !(all_finite(a) && all_finite(b) && all_finite(q) && all_finite(r)) {
            return Err(LqrError::NonFinite);
        }
        let chol_r = Cholesky::new(r).ok_or(LqrError::NotPositiveDefinite)?;
        let mut rinv_bt = b.transpose();
        chol_r.solve_mut(&mut rinv_bt);
        // Doubling: A_k, G_k = the controllability Gramian-like term, H_k → P.
        let (mut ak, mut gk, mut hk) = (*a, b * rinv_bt, *q);
        let eye = SMatrix::<T, NX, NX>::identity();
        let max_rounds = 64;
        let mut rounds = 0;
        loop {
            rounds += 1;
            let lu = Lu::new(&(eye + gk * hk)).ok_or(LqrError::NotPositiveDefinite)?;
            let (w_a, w_g) = (lu.solve(&ak), lu.solve(&gk)); // (I + G H)⁻¹ A, (I + G H)⁻¹ G
            let h_next = hk + ak.transpose() * hk * w_a;
            let g_next = gk + ak * w_g * ak.transpose();
            let a_next = ak * w_a;
            if !(all_finite(&h_next) && all_finite(&g_next) && all_finite(&a_next)) {
                return Err(LqrError::NonFinite);
            }
            let change = (h_next - hk).amax();
            // Symmetrize against rounding.
            hk = (h_next + h_next.transpose()) * T::lit(0.5);
            gk = (g_next + g_next.transpose()) * T::lit(0.5);
            ak = a_next;
            if change <= T::default_epsilon() * T::lit(1000.0) * hk.amax() {
                break;
            }
            if rounds == max_rounds {
                return Err(LqrError::NotConverged { iterations: rounds });
            }
        }
        let p = hk;
        let chol =
            Cholesky::new(&(r + b.transpose() * p * b)).ok_or(LqrError::NotPositiveDefinite)?;
        let mut gain = b.transpose() * p * a;
        chol.solve_mut(&mut gain);
        Ok(Lqr {
            gain,
            cost: p,
            closed_loop: a - b * gain,
            iterations: rounds,
        })
    }

    /// The residual of the Riccati equation at `P`, largest entry: a check of the solve.
    pub fn riccati_residual(
        &self,
        a: &SMatrix<T, NX, NX>,
        b: &SMatrix<T, NX, NU>,
        q: &SMatrix<T, NX, NX>,
    ) -> T {
        let p = &self.cost;
        let bt_p_a = b.transpose() * p * a;
        let rhs = q + a.transpose() * p * a - bt_p_a.transpose() * self.gain;
        (rhs - p).amax()
    }
}

/// Discrete LQR on the constraint manifold around a pose: `u = u_hold(θ_ref) − K (x − x_ref)`
/// with `x = (θ, θ̇)` the chart's coordinates and their rates, `x_ref` the reference's
/// position and velocity, `u_hold(θ_ref)` the torques that hold the leg at rest at the
/// reference pose (so a slow reference is tracked without a steady offset), each torque
/// clipped to `±torque_limit`. `NX = 2 M`.
pub struct ManifoldLqr<
    L,
    T: Real,
    R,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const M: usize,
    const NX: usize,
> where
    L: LegDynamics<NQ, NC, NU>,
{
    /// The controller's model of the leg.
    pub params: L::Params<T>,
    /// The chart whose coordinates `θ` the state `x = (θ, θ̇)` is in.
    pub chart: ManifoldChart<T, NQ, M>,
    /// The gain `K` (and the Riccati solution) of the linearization at the pose.
    pub lqr: Lqr<T, NX, NU>,
    /// The reference of the chart's coordinates.
    pub reference: R,
    /// `|u_k|` limits per motor.
    pub torque_limit: SVector<T, NU>,
    /// The last reference pose lifted to joints: the next lift's guess.
    guess: SVector<T, NQ>,
    /// The last reference pose and its holding torques.
    hold: Option<(SVector<T, M>, SVector<T, NU>)>,
    model: PhantomData<L>,
}

impl<
        L,
        T,
        R,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const M: usize,
        const NX: usize,
    > ManifoldLqr<L, T, R, NQ, NC, NU, M, NX>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
    R: Reference<T, M>,
{
    /// Linearizes the step `opts` at rest at the assembled `pose` under its holding
    /// torques, and solves the LQR of weights `q` (on `x = (θ, θ̇)`) and `r` (on `u`).
    #[allow(clippy::too_many_arguments)]
    pub fn at_pose(
        params: L::Params<T>,
        pose: &SVector<T, NQ>,
        opts: &StepOptions<T>,
        q: &SMatrix<T, NX, NX>,
        r: &SMatrix<T, NU, NU>,
        reference: R,
        torque_limit: SVector<T, NU>,
    ) -> Result<Self, ControlError> {
        let chart = ManifoldChart::<T, NQ, M>::new::<L, NC, NU>(&params, pose)?;
        let u_hold = chart.holding_torque::<L, NC, NU>(&params, pose)?;
        let rest = State {
            q: *pose,
            qd: SVector::zeros(),
        };
        let lin = chart.linearize_step::<L, NC, NU, NX>(&params, &rest, &u_hold, opts)?;
        let lqr = Lqr::new(&lin.a, &lin.b, q, r)?;
        Ok(ManifoldLqr {
            params,
            chart,
            lqr,
            reference,
            torque_limit,
            guess: *pose,
            hold: None,
            model: PhantomData,
        })
    }
}

impl<
        L,
        T,
        R,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const M: usize,
        const NX: usize,
    > TorqueSource<T, NQ, NU> for ManifoldLqr<L, T, R, NQ, NC, NU, M, NX>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
    R: Reference<T, M>,
{
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> Result<SVector<T, NU>, ControlError> {
        if !state.q.iter().chain(state.qd.iter()).all(|x| x.is_finite()) {
            return Err(ControlError::NonFinite);
        }
        let target = self.reference.sample(t);
        // The feedforward depends on the reference pose only: computed again (a lift and a
        // solve) only when that pose moves, not at every call of a held pose.
        if self.hold.map(|(pose, _)| pose) != Some(target.position) {
            let mut chart = self.chart;
            chart.origin = self.guess;
            let lifted = chart.lift::<L, NC, NU>(
                &self.params,
                &target.position,
                &SVector::zeros(),
                &Tolerance::default(),
            )?;
            self.guess = lifted.q;
            let u = chart.holding_torque::<L, NC, NU>(&self.params, &lifted.q)?;
            self.hold = Some((target.position, u));
        }
        let u_hold = self.hold.map_or(SVector::zeros(), |(_, u)| u);
        let (theta, theta_dot) = self.chart.coordinates_of(state);
        let mut error = SVector::<T, NX>::zeros();
        for k in 0..M {
            error[k] = theta[k] - target.position[k];
            error[M + k] = theta_dot[k] - target.velocity[k];
        }
        let mut u = u_hold - self.lqr.gain * error;
        // Checked before the clip: `max`/`min` would turn a NaN into a limit.
        if !(u.iter().all(|x| x.is_finite()) && self.torque_limit.iter().all(|l| *l >= T::zero())) {
            return Err(ControlError::NonFinite);
        }
        for (k, limit) in self.torque_limit.iter().enumerate() {
            u[k] = u[k].max(-*limit).min(*limit);
        }
        Ok(u)
    }
}

impl From<LinearizationError> for ControlError {
    fn from(e: LinearizationError) -> Self {
        ControlError::Linearization(e)
    }
}

impl From<LqrError> for ControlError {
    fn from(e: LqrError) -> Self {
        ControlError::Lqr(e)
    }
}
