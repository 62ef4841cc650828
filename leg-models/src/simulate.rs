//! A simulator that steps a leg under a torque source and records what happened. The
//! record is allocated once, before the first step; a step allocates nothing.

use core::fmt;
use core::marker::PhantomData;

use nalgebra::SVector;

use crate::integrate::{energy, step, State, StepError, StepOptions};
use crate::model::{LegModel, Real};

/// Motor torques as a function of time and state: a controller, or any closure
/// `FnMut(t, &State) -> u`.
pub trait TorqueSource<T: Real, const NQ: usize, const NU: usize> {
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> SVector<T, NU>;
}

impl<T: Real, const NQ: usize, const NU: usize, F> TorqueSource<T, NQ, NU> for F
where
    F: FnMut(T, &State<T, NQ>) -> SVector<T, NU>,
{
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> SVector<T, NU> {
        self(t, state)
    }
}

/// One recorded instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample<T: Real, const NQ: usize, const NC: usize, const NU: usize> {
    pub t: T,
    pub state: State<T, NQ>,
    /// The torques applied from this instant to the next.
    pub u: SVector<T, NU>,
    /// The closure forces at this instant.
    pub forces: SVector<T, NC>,
    /// `T + V`.
    pub energy: T,
    /// `max |φ|` (m).
    pub closure_residual: T,
}

/// A simulation that stopped early: why, when, and everything recorded until then.
#[derive(Clone, Debug, PartialEq)]
pub struct Stopped<T: Real, const NQ: usize, const NC: usize, const NU: usize> {
    pub t: T,
    pub cause: StepError,
    pub samples: Vec<Sample<T, NQ, NC, NU>>,
}

impl<T: Real, const NQ: usize, const NC: usize, const NU: usize> fmt::Display
    for Stopped<T, NQ, NC, NU>
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "simulation stopped at t = {} s after {} samples: {}",
            self.t,
            self.samples.len(),
            self.cause
        )
    }
}

impl<T: Real, const NQ: usize, const NC: usize, const NU: usize> std::error::Error
    for Stopped<T, NQ, NC, NU>
{
}

/// Steps leg `L` with fixed options.
#[derive(Clone, Copy, Debug)]
pub struct Simulator<L, T: Real, const NQ: usize, const NC: usize, const NU: usize>
where
    L: LegModel<NQ, NC, NU>,
{
    pub params: L::Params<T>,
    pub options: StepOptions<T>,
    model: PhantomData<L>,
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize> Simulator<L, T, NQ, NC, NU>
where
    L: LegModel<NQ, NC, NU>,
    T: Real,
{
    pub fn new(params: L::Params<T>, options: StepOptions<T>) -> Self {
        Simulator {
            params,
            options,
            model: PhantomData,
        }
    }

    fn sample(
        &self,
        t: T,
        state: State<T, NQ>,
        u: SVector<T, NU>,
        forces: SVector<T, NC>,
    ) -> Sample<T, NQ, NC, NU> {
        Sample {
            t,
            state,
            u,
            forces,
            energy: energy::<L, T, NQ, NC, NU>(&self.params, &state),
            closure_residual: if NC == 0 {
                T::zero()
            } else {
                L::closure_residual(&state.q, &self.params).amax()
            },
        }
    }

    /// Runs `steps` steps from `initial`; records the initial state and every step.
    pub fn run(
        &self,
        initial: State<T, NQ>,
        steps: usize,
        source: &mut impl TorqueSource<T, NQ, NU>,
    ) -> Result<Vec<Sample<T, NQ, NC, NU>>, Stopped<T, NQ, NC, NU>> {
        let mut samples = Vec::with_capacity(steps + 1);
        let mut state = initial;
        let mut t = T::zero();
        for k in 0..steps {
            let u = source.torque(t, &state);
            let before = state;
            match step::<L, T, NQ, NC, NU>(&self.params, &mut state, &u, &self.options) {
                Ok(acc) => samples.push(self.sample(t, before, u, acc.forces)),
                Err(cause) => return Err(Stopped { t, cause, samples }),
            }
            t = self.options.dt * T::lit((k + 1) as f64);
        }
        // The last state: its forces under the last torques, for a complete record.
        let u = source.torque(t, &state);
        match crate::dynamics::forward_dynamics::<L, T, NQ, NC, NU>(
            &self.params,
            &state.q,
            &state.qd,
            &u,
            self.options.baumgarte,
        ) {
            Ok(acc) => samples.push(self.sample(t, state, u, acc.forces)),
            Err(e) => {
                return Err(Stopped {
                    t,
                    cause: StepError::Dynamics(e),
                    samples,
                })
            }
        }
        Ok(samples)
    }
}
