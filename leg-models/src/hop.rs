//! Hopping: a controller for a leg on a body that hops in place to a commanded apex
//! height, for any leg with contacts whose body rises along one coordinate (a body on a
//! rail; the height of a floating body).
//!
//! - **Flight**: the motors return to a touchdown posture (joint PD in the motor angles;
//!   in free fall the leg's relative motion needs no gravity compensation).
//! - **Stance**: inverse dynamics through the hybrid model. The accelerations and the
//!   ground forces of the stance (loop closures and held contacts in the structured solve)
//!   are affine in the motor torques, `q̈ = a₀ + Q u`, `λ = λ₀ + Λ u` (NU + 1 solves); the
//!   torques meet two tasks in the least-squares sense: the body height follows a virtual
//!   leg spring, `ÿ = ω² (y_td − y) − g + a_thrust` (`a_thrust` only while the body rises),
//!   and the first held contact's tangential force is zero (no push along the ground, so
//!   no slip). Torques are clipped to the motors' limits.
//! - **Height regulation**: at each apex (the body's vertical rate crossing zero in flight)
//!   the energy the apex missed, `m g (h_cmd − h_apex)`, spread over the last stance's
//!   rise as a thrust (`m a · stroke`), sets the next thrust: a share `k_h` of it
//!   (proportional), on top of a learnt part (integral, a fifth of it per hop) that pays
//!   for the impact loss of every hop.

use nalgebra::{SMatrix, SVector};

use crate::contact::Ground;
use crate::contact::{forward_dynamics_with_contacts, ContactMode};
use crate::control::ControlError;
use crate::hybrid::{HybridOptions, HybridState, HybridTorqueSource};
use crate::linalg::Cholesky;
use crate::model::{ContactModel, JointKind, Real};

/// The body's height coordinate of leg `L` at `q`: the prismatic joint that raises the
/// contacts most along the ground's normal (a vertical slider), if any joint raises them.
pub fn height_joint<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
) -> Option<usize>
where
    L: ContactModel<NQ, NC, NU, NK>,
    T: Real,
{
    let rows = Ground::<T>::of::<L, NQ, NC, NU, NK>().rows(&L::contact_jacobian(q, params));
    // How much each joint raises the contacts, summed over them.
    let rise = |i: usize| (0..NK / 2).fold(T::zero(), |a, k| a + rows[(2 * k + 1, i)]);
    (0..NQ)
        .filter(|&i| {
            L::JOINT_KINDS[i] == JointKind::Prismatic
                && rise(i) > T::lit(0.5) * T::lit((NK / 2) as f64)
        })
        .max_by(|&a, &b| {
            rise(a)
                .partial_cmp(&rise(b))
                .unwrap_or(core::cmp::Ordering::Equal)
        })
}

/// What the hopping controller aims at, and how hard.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HopSettings<T: Real, const NU: usize> {
    /// The body coordinate that is the height (a vertical slider).
    pub height_joint: usize,
    /// Commanded apex of `q[height_joint]` [m].
    pub apex: T,
    /// Motor angles held in flight (and at touchdown).
    pub posture: SVector<T, NU>,
    /// Flight PD gains on the motor angles.
    pub kp: T,
    pub kd: T,
    /// The virtual leg spring's natural frequency in stance [rad/s].
    pub stance_frequency: T,
    /// The share of each hop's apex error corrected at the next hop (0 to 1): the thrust
    /// is `learnt + share · g (h_cmd − h_apex) / stroke`, the energy `m g Δh` spread over
    /// the last stance's rise.
    pub height_gain: T,
    /// `|u_k|` limits [N m].
    pub torque_limits: SVector<T, NU>,
    /// Gravity's magnitude along the height [m/s²].
    pub gravity: T,
}

/// The hopping controller (see the module docs); it also counts what happened.
#[derive(Clone, Copy, Debug)]
pub struct HopController<
    L,
    T: Real,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
> where
    L: ContactModel<NQ, NC, NU, NK>,
{
    pub params: L::Params<T>,
    pub options: HybridOptions<T, NK>,
    pub settings: HopSettings<T, NU>,
    /// The thrust acceleration added while the body rises in stance.
    pub thrust: T,
    /// Its learnt part: what pays for each hop's impact loss.
    pub loss_thrust: T,
    /// Body height at the last touchdown.
    pub touchdown_height: T,
    /// The lowest body height of the last stance.
    pub bottom: T,
    /// Apexes seen (hops completed).
    pub hops: usize,
    /// The last apex height.
    pub last_apex: Option<T>,
    /// Evaluations in which motor `k` was clipped.
    pub saturations: [usize; NU],
    in_stance: bool,
    rising: bool,
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    HopController<L, T, NQ, NC, NU, NK>
where
    L: ContactModel<NQ, NC, NU, NK>,
    T: Real,
{
    pub fn new(
        params: L::Params<T>,
        options: HybridOptions<T, NK>,
        settings: HopSettings<T, NU>,
    ) -> Self {
        HopController {
            params,
            options,
            settings,
            thrust: T::zero(),
            loss_thrust: T::zero(),
            touchdown_height: T::zero(),
            bottom: T::zero(),
            hops: 0,
            last_apex: None,
            saturations: [0; NU],
            in_stance: false,
            rising: false,
        }
    }

    fn clip(&mut self, mut u: SVector<T, NU>) -> SVector<T, NU> {
        for k in 0..NU {
            let lim = self.settings.torque_limits[k];
            if u[k].abs() > lim {
                u[k] = u[k].max(-lim).min(lim);
                self.saturations[k] += 1;
            }
        }
        u
    }

    fn flight(&self, hs: &HybridState<T, NQ, NK>) -> SVector<T, NU> {
        let s = &self.settings;
        SVector::from_fn(|k, _| {
            let j = L::ACTUATED[k];
            s.kp * (s.posture[k] - hs.state.q[j]) - s.kd * hs.state.qd[j]
        })
    }

    /// The stance's accelerations and ground forces under torques `u`.
    fn solve(
        &self,
        hs: &HybridState<T, NQ, NK>,
        u: &SVector<T, NU>,
    ) -> Result<crate::contact::ContactSolution<T, NQ, NC, NK>, ControlError> {
        forward_dynamics_with_contacts::<L, T, NQ, NC, NU, NK>(
            &self.params,
            &hs.state.q,
            &hs.state.qd,
            u,
            &hs.modes,
            &hs.anchors,
            &self.options.ground,
            &self.options.friction,
            self.options.baumgarte,
        )
        .map_err(ControlError::Dynamics)
    }

    /// How much the motors move the body's height at a stance state: the norm of
    /// `∂ÿ/∂u`. Zero where they act on it only through springs (series-elastic
    /// actuators): this controller's stance then does not apply.
    pub fn height_authority(&self, hs: &HybridState<T, NQ, NK>) -> Result<T, ControlError> {
        let solve = |u: &SVector<T, NU>| self.solve(hs, u);
        let h = self.settings.height_joint;
        let base = solve(&SVector::zeros())?.x[h];
        let mut sum = T::zero();
        for k in 0..NU {
            let mut e = SVector::<T, NU>::zeros();
            e[k] = T::one();
            let d = solve(&e)?.x[h] - base;
            sum += d * d;
        }
        Ok(sum.sqrt())
    }

    fn stance(&self, hs: &HybridState<T, NQ, NK>) -> Result<SVector<T, NU>, ControlError> {
        let s = &self.settings;
        let (q, qd) = (&hs.state.q, &hs.state.qd);
        let solve = |u: &SVector<T, NU>| self.solve(hs, u);
        let base = solve(&SVector::zeros())?;
        // Task rows: body height acceleration, and the first held contact's tangential force.
        let tangential = (0..NK / 2).find(|&k| hs.modes.get(k) == ContactMode::Stick);
        let h = s.height_joint;
        let mut rows = SMatrix::<T, 2, NU>::zeros();
        for k in 0..NU {
            let mut e = SVector::<T, NU>::zeros();
            e[k] = T::one();
            let unit = solve(&e)?;
            rows[(0, k)] = unit.x[h] - base.x[h];
            if let Some(c) = tangential {
                rows[(1, k)] = unit.contact[2 * c] - base.contact[2 * c];
            }
        }
        let omega2 = s.stance_frequency * s.stance_frequency;
        let mut target = omega2 * (self.touchdown_height - q[h]) - s.gravity;
        if qd[h] > T::zero() {
            target += self.thrust;
        }
        let goal = nalgebra::Vector2::new(
            target - base.x[h],
            match tangential {
                Some(c) => -base.contact[2 * c],
                None => T::zero(),
            },
        );
        // Weighted least squares with a small ridge (the tasks may be fewer than the
        // motors, or depend on them alike): rows scaled to unit size first.
        let mut w = rows;
        let mut g = goal;
        for r in 0..2 {
            let norm = w.row(r).norm();
            if norm > T::zero() {
                let inv = T::one() / norm;
                for k in 0..NU {
                    w[(r, k)] *= inv;
                }
                g[r] *= inv;
            }
        }
        let mut normal = w.transpose() * w;
        for k in 0..NU {
            normal[(k, k)] += T::lit(1e-9);
        }
        let chol = Cholesky::new(&normal).ok_or(ControlError::NonFinite)?;
        let mut u = w.transpose() * g;
        chol.solve_mut(&mut u);
        Ok(u)
    }
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    HybridTorqueSource<T, NQ, NK, NU> for HopController<L, T, NQ, NC, NU, NK>
where
    L: ContactModel<NQ, NC, NU, NK>,
    T: Real,
{
    fn torque(
        &mut self,
        _t: T,
        hs: &HybridState<T, NQ, NK>,
    ) -> Result<SVector<T, NU>, ControlError> {
        let h = self.settings.height_joint;
        let on_ground = (0..NK / 2).any(|k| hs.modes.get(k).on_ground());
        let (y, vy) = (hs.state.q[h], hs.state.qd[h]);
        if on_ground && !self.in_stance {
            self.touchdown_height = y;
            self.bottom = y;
        }
        if on_ground {
            self.bottom = self.bottom.min(y);
        }
        if !on_ground {
            // Apex: the rise ends in flight.
            if self.rising && vy <= T::zero() {
                self.hops += 1;
                self.last_apex = Some(y);
                // The energy the apex missed, as a thrust over the last stroke. Energy
                // carries from hop to hop (the plant integrates the thrust's work), so
                // the thrust is that correction (proportional) on top of a slowly learnt
                // share that pays for each hop's impact loss (integral).
                let stroke = (self.touchdown_height - self.bottom).max(T::lit(1e-3));
                let missed = self.settings.gravity * (self.settings.apex - y) / stroke;
                self.loss_thrust = (self.loss_thrust + T::lit(0.2) * missed).max(T::zero());
                self.thrust =
                    (self.loss_thrust + self.settings.height_gain * missed).max(T::zero());
            }
            self.rising = vy > T::zero();
        } else {
            self.rising = false;
        }
        self.in_stance = on_ground;
        let u = if on_ground {
            self.stance(hs)?
        } else {
            self.flight(hs)
        };
        if !u.iter().all(|x| x.is_finite()) {
            return Err(ControlError::NonFinite);
        }
        Ok(self.clip(u))
    }
}
