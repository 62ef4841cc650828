//! Reference trajectories with analytic first and second derivatives.

use nalgebra::SVector;

use crate::model::contract::Real;

/// Position, velocity and acceleration of a reference at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoint<T: Real, const N: usize> {
    /// The coordinates (rad, or m).
    pub position: SVector<T, N>,
    /// Their rates (per s).
    pub velocity: SVector<T, N>,
    /// Their second derivatives (per s²).
    pub acceleration: SVector<T, N>,
}

/// A trajectory in `N` coordinates (joint angles, or a foot position with `N = 2`).
pub trait Reference<T: Real, const N: usize> {
    /// The setpoint at time `t` (s).
    fn sample(&self, t: T) -> Setpoint<T, N>;
}

/// `offset + amplitude · sin(2π f t + phase)`, per coordinate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sinusoid<T: Real, const N: usize> {
    /// The centre of the oscillation.
    pub offset: SVector<T, N>,
    /// The largest excursion from `offset`.
    pub amplitude: SVector<T, N>,
    /// Hz.
    pub frequency: SVector<T, N>,
    /// rad.
    pub phase: SVector<T, N>,
}

impl<T: Real, const N: usize> Reference<T, N> for Sinusoid<T, N> {
    fn sample(&self, t: T) -> Setpoint<T, N> {
        let mut s = Setpoint {
            position: self.offset,
            velocity: SVector::zeros(),
            acceleration: SVector::zeros(),
        };
        for i in 0..N {
            let w = T::two_pi() * self.frequency[i];
            let (sin, cos) = (w * t + self.phase[i]).sin_cos();
            let a = self.amplitude[i];
            s.position[i] += a * sin;
            s.velocity[i] = a * w * cos;
            s.acceleration[i] = -a * w * w * sin;
        }
        s
    }
}

/// `start + rate · t` per coordinate: a crank turning at a steady speed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ramp<T: Real, const N: usize> {
    /// The position at `t = 0`.
    pub start: SVector<T, N>,
    /// Per second.
    pub rate: SVector<T, N>,
}

impl<T: Real, const N: usize> Reference<T, N> for Ramp<T, N> {
    fn sample(&self, t: T) -> Setpoint<T, N> {
        Setpoint {
            position: self.start + self.rate * t,
            velocity: self.rate,
            acceleration: SVector::zeros(),
        }
    }
}

/// A minimum-jerk move from `start` to `goal` over `duration` seconds from `t0`
/// (quintic with zero velocity and acceleration at both ends); it holds `start` before
/// and `goal` after.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MinimumJerk<T: Real, const N: usize> {
    /// Where the move starts.
    pub start: SVector<T, N>,
    /// Where it ends.
    pub goal: SVector<T, N>,
    /// When it starts (s).
    pub t0: T,
    /// How long it takes (s).
    pub duration: T,
}

impl<T: Real, const N: usize> Reference<T, N> for MinimumJerk<T, N> {
    fn sample(&self, t: T) -> Setpoint<T, N> {
        let d = self.duration;
        let s = ((t - self.t0) / d).max(T::zero()).min(T::one());
        let moving = t > self.t0 && t < self.t0 + d;
        let (s2, s3) = (s * s, s * s * s);
        // p(s) = 10 s³ − 15 s⁴ + 6 s⁵ and its derivatives in time.
        let p = s3 * (T::lit(10.0) - T::lit(15.0) * s + T::lit(6.0) * s2);
        let (dp, ddp) = if moving {
            (
                s2 * (T::lit(30.0) - T::lit(60.0) * s + T::lit(30.0) * s2) / d,
                s * (T::lit(60.0) - T::lit(180.0) * s + T::lit(120.0) * s2) / (d * d),
            )
        } else {
            (T::zero(), T::zero())
        };
        let delta = self.goal - self.start;
        Setpoint {
            position: self.start + delta * p,
            velocity: delta * dp,
            acceleration: delta * ddp,
        }
    }
}

/// One pose, held: zero velocity and acceleration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hold<T: Real, const N: usize>(pub SVector<T, N>);

impl<T: Real, const N: usize> Reference<T, N> for Hold<T, N> {
    fn sample(&self, _t: T) -> Setpoint<T, N> {
        Setpoint {
            position: self.0,
            velocity: SVector::zeros(),
            acceleration: SVector::zeros(),
        }
    }
}

/// A foot step cycle: an ellipse under the hip, `center + (a cos ωt, b sin ωt)` with
/// `a` half the stride and `b` half the step height, traversed once per `period`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepCycle<T: Real> {
    /// The ellipse's centre in the base frame (m).
    pub center: SVector<T, 2>,
    /// `a`, half the stride (m).
    pub half_stride: T,
    /// `b`, half the step height (m).
    pub half_height: T,
    /// s.
    pub period: T,
}

impl<T: Real> Reference<T, 2> for StepCycle<T> {
    fn sample(&self, t: T) -> Setpoint<T, 2> {
        let w = T::two_pi() / self.period;
        let (sin, cos) = (w * t).sin_cos();
        let (a, b) = (self.half_stride, self.half_height);
        Setpoint {
            position: self.center + SVector::<T, 2>::new(a * cos, b * sin),
            velocity: SVector::<T, 2>::new(-a * w * sin, b * w * cos),
            acceleration: SVector::<T, 2>::new(-a * w * w * cos, -b * w * w * sin),
        }
    }
}

/// A setpoint is the reference that is that setpoint at every instant (its velocity and
/// acceleration as given, not integrated): what a controller evaluated at one state needs.
impl<T: Real, const N: usize> Reference<T, N> for Setpoint<T, N> {
    fn sample(&self, _t: T) -> Setpoint<T, N> {
        *self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    /// Velocity and acceleration against central differences of the position.
    fn check<R: Reference<f64, N>, const N: usize>(r: &R, times: &[f64]) {
        let h = 1e-5;
        for &t in times {
            let s = r.sample(t);
            let (a, b) = (r.sample(t - h), r.sample(t + h));
            let v = (b.position - a.position) / (2.0 * h);
            let acc = (b.velocity - a.velocity) / (2.0 * h);
            assert!(
                (v - s.velocity).amax() < 1e-7 * (1.0 + v.amax()),
                "velocity at {t}: {v} vs {}",
                s.velocity
            );
            assert!(
                (acc - s.acceleration).amax() < 1e-6 * (1.0 + acc.amax()),
                "acceleration at {t}"
            );
        }
    }

    #[test]
    fn ramp_derivatives() {
        let r = Ramp {
            start: Vector2::new(0.3, -1.0),
            rate: Vector2::new(6.0, -0.5),
        };
        check(&r, &[0.0, 0.4, 2.5]);
        assert!((r.sample(2.0).position - Vector2::new(12.3, -2.0)).amax() < 1e-15);
    }

    #[test]
    fn sinusoid_derivatives() {
        let r = Sinusoid {
            offset: Vector2::new(0.3, -1.0),
            amplitude: Vector2::new(0.2, 0.5),
            frequency: Vector2::new(1.5, 0.25),
            phase: Vector2::new(0.0, 1.0),
        };
        check(&r, &[0.0, 0.1, 0.77, 3.2]);
        assert!(
            (r.sample(0.0).position - Vector2::new(0.3, -1.0 + 0.5 * 1f64.sin())).amax() < 1e-15
        );
    }

    #[test]
    fn minimum_jerk_derivatives_and_ends() {
        let r = MinimumJerk {
            start: Vector2::new(0.0, 1.0),
            goal: Vector2::new(1.0, -1.0),
            t0: 0.5,
            duration: 2.0,
        };
        check(&r, &[0.6, 1.0, 1.5, 2.3]);
        for (t, p) in [(0.0, r.start), (0.5, r.start), (2.5, r.goal), (4.0, r.goal)] {
            let s = r.sample(t);
            assert!(
                (s.position - p).amax() < 1e-15
                    && s.velocity.amax() == 0.0
                    && s.acceleration.amax() == 0.0
            );
        }
        // Symmetric: half way at mid time, with the peak speed 15/8 of the mean.
        let mid = r.sample(1.5);
        assert!((mid.position - (r.start + r.goal) / 2.0).amax() < 1e-15);
        assert!((mid.velocity[0] - 1.875 / 2.0).abs() < 1e-12);
    }

    #[test]
    fn step_cycle_derivatives_and_shape() {
        let r = StepCycle {
            center: Vector2::new(0.01, -0.2),
            half_stride: 0.04,
            half_height: 0.015,
            period: 0.4,
        };
        check(&r, &[0.0, 0.05, 0.13, 0.39]);
        for k in 0..20 {
            let d = r.sample(0.02 * k as f64).position - r.center;
            let on_ellipse = (d[0] / 0.04).powi(2) + (d[1] / 0.015).powi(2);
            assert!((on_ellipse - 1.0).abs() < 1e-12);
        }
        assert!(
            (r.sample(0.4).position - r.sample(0.0).position).amax() < 1e-15,
            "closed, period 0.4 s"
        );
    }
}
