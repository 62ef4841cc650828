//! A simulator that steps a leg under a torque source and records what happened. The
//! record is allocated once, before the first step; a step allocates nothing.

use core::fmt;
use core::marker::PhantomData;

use nalgebra::SVector;

use crate::model::contract::{LegDynamics, Real};
use crate::simulate::source::State;
use crate::simulate::source::TorqueSource;
use crate::simulate::step::{check_record, energy, step, StepError, StepOptions};

/// One recorded instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample<T: Real, const NQ: usize, const NC: usize, const NU: usize> {
    /// Time (s).
    pub t: T,
    /// The joint state `(q, q̇)`.
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
    /// When it stopped (s): the start of the step that failed, or the end of the run if
    /// the last sample failed.
    pub t: T,
    /// Why it failed.
    pub cause: StepError,
    /// Everything recorded before.
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
    L: LegDynamics<NQ, NC, NU>,
{
    /// The leg's parameters.
    pub params: L::Params<T>,
    /// How each step is taken.
    pub options: StepOptions<T>,
    model: PhantomData<L>,
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize> Simulator<L, T, NQ, NC, NU>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    /// A simulator of leg `L` with `params`, stepping with `options`.
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

    /// Runs `steps` steps from `initial`; records the initial state and every step. A
    /// record larger than [`MAX_RECORD_BYTES`](crate::simulate::MAX_RECORD_BYTES) is
    /// refused before anything is allocated.
    pub fn run(
        &self,
        initial: State<T, NQ>,
        steps: usize,
        source: &mut impl TorqueSource<T, NQ, NU>,
    ) -> Result<Vec<Sample<T, NQ, NC, NU>>, Stopped<T, NQ, NC, NU>> {
        check_record(steps, core::mem::size_of::<Sample<T, NQ, NC, NU>>()).map_err(|e| {
            Stopped {
                t: T::zero(),
                cause: StepError::RecordTooLarge(e),
                samples: Vec::new(),
            }
        })?;
        let mut samples = Vec::with_capacity(steps + 1);
        let mut state = initial;
        let mut t = T::zero();
        for k in 0..steps {
            let before = state;
            match step::<L, T, NQ, NC, NU>(&self.params, &mut state, t, source, &self.options) {
                Ok(r) => samples.push(self.sample(t, before, r.u, r.acceleration.forces)),
                Err(cause) => return Err(Stopped { t, cause, samples }),
            }
            t = self.options.dt * T::lit((k + 1) as f64);
        }
        // The last state, with its torques and forces, for a complete record.
        let last = source
            .torque(t, &state)
            .map_err(StepError::Control)
            .and_then(|u| {
                crate::dynamics::forward::forward_dynamics::<L, T, NQ, NC, NU>(
                    &self.params,
                    &state.q,
                    &state.qd,
                    &u,
                    self.options.baumgarte,
                )
                .map(|acc| (u, acc))
                .map_err(StepError::Dynamics)
            });
        match last {
            Ok((u, acc)) => samples.push(self.sample(t, state, u, acc.forces)),
            Err(cause) => return Err(Stopped { t, cause, samples }),
        }
        Ok(samples)
    }
}
