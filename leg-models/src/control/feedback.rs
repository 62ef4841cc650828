//! The feedback laws in the motor coordinates: joint- and foot-space feedback
//! linearization (exact, through the reduction `Ã θ̈ = b̃ + u`), PD with gravity
//! compensation in joint or foot space, and torque saturation around any source.

use core::marker::PhantomData;

use nalgebra::{SMatrix, SVector};

use crate::control::reduction::actuated_reduction;
use crate::control::reduction::actuated_reduction_null_space;
use crate::control::reduction::check_finite;
use crate::control::reduction::null_space;
use crate::control::reduction::passive_forces;
use crate::control::reduction::reduce_with;
use crate::control::reduction::ActuatedDynamics;
use crate::control::reduction::NullSpace;
use crate::control::reference::Reference;
use crate::dynamics::forward::{rcond_floor, to_f64};
use crate::dynamics::structure::{Actuation, Structure};
use crate::model::contract::{DynamicsTerms, LegDynamics, LegModel, Real};
use crate::model::linalg::{mul, Cholesky};
use crate::simulate::source::{ControlError, MAX_GAIN};
use crate::simulate::source::{State, TorqueSource};

/// A torque that is not finite (a parameter or a reference that is NaN or infinite, or
/// an overflow) is an error, never a command.
fn finite_torque<T: Real, const NU: usize>(
    u: SVector<T, NU>,
) -> Result<SVector<T, NU>, ControlError> {
    if crate::model::linalg::all_finite(&u) {
        Ok(u)
    } else {
        Err(ControlError::NonFinite)
    }
}

/// Proportional and derivative gains per coordinate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gains<T: Real, const N: usize> {
    /// `k_p` per coordinate.
    pub kp: SVector<T, N>,
    /// `k_d` per coordinate.
    pub kd: SVector<T, N>,
}

impl<T: Real, const N: usize> Gains<T, N> {
    /// The same `k_p` and `k_d` on every coordinate.
    pub fn new(kp: T, kd: T) -> Self {
        Gains {
            kp: SVector::from_element(kp),
            kd: SVector::from_element(kd),
        }
    }

    /// `k_d = 2√k_p`: the error dynamics `ë + k_d ė + k_p e = 0` are critically damped.
    pub fn critically_damped(kp: T) -> Self {
        Gains::new(kp, T::lit(2.0) * kp.sqrt())
    }

    /// Every gain zero or more and at most [`MAX_GAIN`]: a negative, NaN or huge gain is
    /// refused by name (a negative `k_p` gave `k_d = 2√k_p = NaN`, reported as a non-finite
    /// state; `k_p` = 1e308 overflowed the first torque).
    pub fn check(&self) -> Result<(), ControlError> {
        for (name, v) in [("kp", &self.kp), ("kd", &self.kd)] {
            for (k, &x) in v.iter().enumerate() {
                if !(x >= T::zero() && to_f64(x) <= MAX_GAIN) {
                    return Err(ControlError::Gain {
                        name,
                        coordinate: k,
                        value: to_f64(x),
                    });
                }
            }
        }
        Ok(())
    }

    fn feedback(&self, e: &SVector<T, N>, ed: &SVector<T, N>) -> SVector<T, N> {
        self.kp.component_mul(e) + self.kd.component_mul(ed)
    }
}

fn motor_state<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    state: &State<T, NQ>,
) -> (SVector<T, NU>, SVector<T, NU>)
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    (
        SVector::from_fn(|k, _| state.q[L::ACTUATED[k]]),
        SVector::from_fn(|k, _| state.qd[L::ACTUATED[k]]),
    )
}

/// The reduction a controller uses: the null-space form where the motors determine the
/// leg (cheaper; equal to the Schur form, tested), the Schur form on an under-actuated leg.
fn reduction<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    terms: &DynamicsTerms<T, NQ, NC>,
    qd: &SVector<T, NQ>,
) -> Result<ActuatedDynamics<T, NU>, ControlError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    match Structure::of::<L, NQ, NC, NU>().actuation() {
        Actuation::Full => actuated_reduction_null_space::<L, T, NQ, NC, NU>(params, terms, qd),
        _ => actuated_reduction::<L, T, NQ, NC, NU>(params, terms, qd),
    }
}

/// Joint-space feedback linearization: `u = Ã (θ̈_ref + k_p e + k_d ė) − b̃`, so that
/// `ë + k_d ė + k_p e = 0` with `e = θ_ref − θ`. With no closure (`two_link`) `Ã = M`
/// and `b̃ = −N − D q̇`: the open-chain law `u = M(q̈_ref + k_p e + k_d ė) + N`. On an
/// under-actuated leg it commands the motors' own accelerations (the passive joints
/// follow on their own); a leg whose motors over-determine it has no such law.
pub struct JointFeedbackLinearization<
    L,
    T: Real,
    R,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
> where
    L: LegDynamics<NQ, NC, NU>,
{
    /// The controller's model of the leg (it may differ from the plant's).
    pub params: L::Params<T>,
    /// Gains on the motor-angle error `e = θ_ref − θ` (`k_p` in 1/s², `k_d` in 1/s).
    pub gains: Gains<T, NU>,
    /// The motor angles' reference `θ_ref(t)`.
    pub reference: R,
    model: PhantomData<L>,
}

impl<L, T, R, const NQ: usize, const NC: usize, const NU: usize>
    JointFeedbackLinearization<L, T, R, NQ, NC, NU>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
    R: Reference<T, NU>,
{
    /// Fails with [`ControlError::NotApplicable`] on a leg whose motors over-determine it.
    pub fn new(
        params: L::Params<T>,
        gains: Gains<T, NU>,
        reference: R,
    ) -> Result<Self, ControlError> {
        Structure::of::<L, NQ, NC, NU>().joint_space()?;
        gains.check()?;
        Ok(JointFeedbackLinearization {
            params,
            gains,
            reference,
            model: PhantomData,
        })
    }
}

impl<L, T, R, const NQ: usize, const NC: usize, const NU: usize> TorqueSource<T, NQ, NU>
    for JointFeedbackLinearization<L, T, R, NQ, NC, NU>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
    R: Reference<T, NU>,
{
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> Result<SVector<T, NU>, ControlError> {
        check_finite(state)?;
        let terms = L::dynamics_terms(&state.q, &state.qd, &self.params);
        let red = reduction::<L, T, NQ, NC, NU>(&self.params, &terms, &state.qd)?;
        let (theta, theta_dot) = motor_state::<L, T, NQ, NC, NU>(state);
        let r = self.reference.sample(t);
        let v = r.acceleration
            + self
                .gains
                .feedback(&(r.position - theta), &(r.velocity - theta_dot));
        finite_torque(mul(&red.a_tilde, &v) - red.b_tilde)
    }
}

/// What the foot controllers need at a state: the foot, its rate, `J_f G` and the part of
/// the foot's acceleration that does not come from `θ̈`.
struct FootKinematics<T: Real, const NU: usize, const ND: usize> {
    position: SVector<T, ND>,
    velocity: SVector<T, ND>,
    jacobian: SMatrix<T, ND, NU>,
    drift: SVector<T, ND>,
}

fn foot_kinematics<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    params: &L::Params<T>,
    state: &State<T, NQ>,
    ns: &NullSpace<T, NQ, NU>,
) -> FootKinematics<T, NU, ND>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    let jf = L::foot_jacobian(&state.q, params);
    FootKinematics {
        position: L::foot_position(&state.q, params),
        velocity: jf * state.qd,
        jacobian: jf * ns.g,
        drift: jf * ns.c + L::foot_bias(&state.q, &state.qd, params),
    }
}

/// Foot-space feedback linearization: the motor accelerations that give the foot
/// `ÿ = ÿ_ref + k_p e + k_d ė`, then `u = Ã θ̈ − b̃`. With more motors than the foot has
/// coordinates (`ND`: two in the plane, three in space) the foot task leaves motions
/// free: they are held at the motor angles of the first state by a posture law (same
/// gains) in the task's null space, so they neither drift nor fight the foot.
pub struct FootFeedbackLinearization<
    L,
    T: Real,
    R,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize = 2,
    const NP: usize = NC,
> where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    /// The controller's model of the leg (it may differ from the plant's).
    pub params: L::Params<T>,
    /// Gains on the foot error `e = y_ref − y` (`k_p` in 1/s², `k_d` in 1/s); the posture
    /// law uses the first coordinate's.
    pub gains: Gains<T, ND>,
    /// The foot's reference `y_ref(t)` in the base frame (m).
    pub reference: R,
    /// The motor angles the free motions are held at (set from the first state).
    pub posture: Option<SVector<T, NU>>,
    model: PhantomData<L>,
}

impl<
        L,
        T,
        R,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const ND: usize,
        const NP: usize,
    > FootFeedbackLinearization<L, T, R, NQ, NC, NU, ND, NP>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
    R: Reference<T, ND>,
{
    /// Fails with [`ControlError::NotApplicable`] unless the motors can place the foot
    /// (at least as many as its coordinates, and they determine the leg).
    pub fn new(
        params: L::Params<T>,
        gains: Gains<T, ND>,
        reference: R,
    ) -> Result<Self, ControlError> {
        Structure::of::<L, NQ, NC, NU>().foot_space()?;
        gains.check()?;
        Ok(FootFeedbackLinearization {
            params,
            gains,
            reference,
            posture: None,
            model: PhantomData,
        })
    }
}

/// `J⁺ w` for an `ND × NU` task Jacobian of full row rank, `J⁺ = Jᵀ (J Jᵀ)⁻¹`.
fn task_solve<T: Real, const NU: usize, const ND: usize>(
    jy: &SMatrix<T, ND, NU>,
    w: &SVector<T, ND>,
) -> Result<SVector<T, NU>, ControlError> {
    let chol = Cholesky::new(&(jy * jy.transpose())).ok_or(ControlError::SingularTask)?;
    if chol.rcond < rcond_floor::<T>() {
        return Err(ControlError::SingularTask);
    }
    let mut x = *w;
    chol.solve_mut(&mut x);
    Ok(jy.transpose() * x)
}

impl<
        L,
        T,
        R,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const ND: usize,
        const NP: usize,
    > TorqueSource<T, NQ, NU> for FootFeedbackLinearization<L, T, R, NQ, NC, NU, ND, NP>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
    R: Reference<T, ND>,
{
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> Result<SVector<T, NU>, ControlError> {
        check_finite(state)?;
        let p = &self.params;
        let terms = L::dynamics_terms(&state.q, &state.qd, p);
        let ns =
            null_space::<L, T, NQ, NC, NU>(&terms.constraint_jacobian, &terms.constraint_bias)?;
        let red = reduce_with(
            &ns,
            &terms,
            &passive_forces::<L, T, NQ, NC, NU>(p, &terms, &state.qd),
        );
        let foot = foot_kinematics::<L, T, NQ, NC, NU, ND, NP>(p, state, &ns);
        let r = self.reference.sample(t);
        let v = r.acceleration
            + self
                .gains
                .feedback(&(r.position - foot.position), &(r.velocity - foot.velocity))
            - foot.drift;
        let jy = foot.jacobian;
        let theta_dd = if NU > ND {
            let (theta, theta_dot) = motor_state::<L, T, NQ, NC, NU>(state);
            let posture = *self.posture.get_or_insert(theta);
            let (kp, kd) = (self.gains.kp[0], self.gains.kd[0]);
            let hold = (posture - theta) * kp - theta_dot * kd;
            // J⁺ v + (I − J⁺ J) hold
            task_solve(&jy, &(v - jy * hold))? + hold
        } else {
            task_solve(&jy, &v)?
        };
        finite_torque(red.a_tilde * theta_dd - red.b_tilde)
    }
}

/// The motor torques that hold the leg still against gravity: `−b̃(q, 0)`, which is
/// `Gᵀ G(q)` where the motors determine the leg (computed so), and the torques that keep
/// the motors from accelerating on an under-actuated leg.
fn gravity_compensation<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
) -> Result<SVector<T, NU>, ControlError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    if Structure::of::<L, NQ, NC, NU>().actuation() == Actuation::Full {
        let ns =
            null_space::<L, T, NQ, NC, NU>(&L::constraint_jacobian(q, params), &SVector::zeros())?;
        return Ok(ns.g.transpose() * L::gravity_forces(q, params));
    }
    let rest = SVector::<T, NQ>::zeros();
    let terms = L::dynamics_terms(q, &rest, params);
    Ok(-actuated_reduction::<L, T, NQ, NC, NU>(params, &terms, &rest)?.b_tilde)
}

/// The baseline: joint PD with gravity compensation, `u = k_p e + k_d ė − b̃(q, 0)`.
pub struct PdGravity<L, T: Real, R, const NQ: usize, const NC: usize, const NU: usize>
where
    L: LegDynamics<NQ, NC, NU>,
{
    /// The controller's model of the leg (it may differ from the plant's).
    pub params: L::Params<T>,
    /// Gains on the motor-angle error (`k_p` in N m/rad, `k_d` in N m s/rad on revolute
    /// motors).
    pub gains: Gains<T, NU>,
    /// The motor angles' reference `θ_ref(t)`.
    pub reference: R,
    model: PhantomData<L>,
}

impl<L, T, R, const NQ: usize, const NC: usize, const NU: usize> PdGravity<L, T, R, NQ, NC, NU>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
    R: Reference<T, NU>,
{
    /// Fails with [`ControlError::NotApplicable`] on a leg whose motors over-determine it.
    pub fn new(
        params: L::Params<T>,
        gains: Gains<T, NU>,
        reference: R,
    ) -> Result<Self, ControlError> {
        Structure::of::<L, NQ, NC, NU>().joint_space()?;
        gains.check()?;
        Ok(PdGravity {
            params,
            gains,
            reference,
            model: PhantomData,
        })
    }
}

impl<L, T, R, const NQ: usize, const NC: usize, const NU: usize> TorqueSource<T, NQ, NU>
    for PdGravity<L, T, R, NQ, NC, NU>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
    R: Reference<T, NU>,
{
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> Result<SVector<T, NU>, ControlError> {
        check_finite(state)?;
        let g = gravity_compensation::<L, T, NQ, NC, NU>(&self.params, &state.q)?;
        let (theta, theta_dot) = motor_state::<L, T, NQ, NC, NU>(state);
        let r = self.reference.sample(t);
        finite_torque(
            self.gains
                .feedback(&(r.position - theta), &(r.velocity - theta_dot))
                + g,
        )
    }
}

/// The foot-space baseline: a virtual spring-damper at the foot through the Jacobian
/// transpose, with gravity compensation, `u = (J_f G)ᵀ (K_p e + K_d ė) + Gᵀ G(q)`.
pub struct FootPdGravity<
    L,
    T: Real,
    R,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize = 2,
    const NP: usize = NC,
> where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    /// The controller's model of the leg (it may differ from the plant's).
    pub params: L::Params<T>,
    /// Stiffness (N/m) and damping (N s/m) at the foot.
    pub gains: Gains<T, ND>,
    /// The foot's reference in the base frame (m).
    pub reference: R,
    model: PhantomData<L>,
}

impl<
        L,
        T,
        R,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const ND: usize,
        const NP: usize,
    > FootPdGravity<L, T, R, NQ, NC, NU, ND, NP>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
    R: Reference<T, ND>,
{
    /// Fails with [`ControlError::NotApplicable`] unless the motors can place the foot.
    pub fn new(
        params: L::Params<T>,
        gains: Gains<T, ND>,
        reference: R,
    ) -> Result<Self, ControlError> {
        Structure::of::<L, NQ, NC, NU>().foot_space()?;
        gains.check()?;
        Ok(FootPdGravity {
            params,
            gains,
            reference,
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
        const ND: usize,
        const NP: usize,
    > TorqueSource<T, NQ, NU> for FootPdGravity<L, T, R, NQ, NC, NU, ND, NP>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
    R: Reference<T, ND>,
{
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> Result<SVector<T, NU>, ControlError> {
        check_finite(state)?;
        let ns = null_space::<L, T, NQ, NC, NU>(
            &L::constraint_jacobian(&state.q, &self.params),
            &SVector::zeros(),
        )?;
        let g = ns.g.transpose() * L::gravity_forces(&state.q, &self.params);
        let foot = foot_kinematics::<L, T, NQ, NC, NU, ND, NP>(&self.params, state, &ns);
        let r = self.reference.sample(t);
        let force = self
            .gains
            .feedback(&(r.position - foot.position), &(r.velocity - foot.velocity));
        finite_torque(foot.jacobian.transpose() * force + g)
    }
}

/// Each motor's effective inertia at a pose, with the loop closed: the diagonal of `Ã`
/// at rest (to scale joint-space baseline gains to a bandwidth).
pub fn joint_inertias<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
) -> Result<SVector<T, NU>, ControlError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let rest = SVector::<T, NQ>::zeros();
    let terms = L::dynamics_terms(q, &rest, params);
    Ok(
        actuated_reduction::<L, T, NQ, NC, NU>(params, &terms, &rest)?
            .a_tilde
            .diagonal(),
    )
}

/// The foot's effective inertia at a pose: the diagonal of the foot-space inertia
/// `Λ = (J_y Ã⁻¹ J_yᵀ)⁻¹`, `J_y = J_f G`, at rest (to scale foot-space baseline gains).
/// Only where the motors can place the foot.
pub fn foot_inertias<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
) -> Result<SVector<T, ND>, ControlError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    Structure::of::<L, NQ, NC, NU>().foot_space()?;
    let rest = SVector::<T, NQ>::zeros();
    let terms = L::dynamics_terms(q, &rest, params);
    let ns = null_space::<L, T, NQ, NC, NU>(&terms.constraint_jacobian, &terms.constraint_bias)?;
    let red = reduce_with(
        &ns,
        &terms,
        &passive_forces::<L, T, NQ, NC, NU>(params, &terms, &rest),
    );
    let jy = L::foot_jacobian(q, params) * ns.g;
    let a = Cholesky::new(&red.a_tilde).ok_or(ControlError::SingularPassive)?;
    let mut y = jy.transpose();
    a.solve_mut(&mut y); // Ã⁻¹ J_yᵀ
    let lambda_inv = Cholesky::new(&(jy * y)).ok_or(ControlError::SingularTask)?;
    Ok(lambda_inv.inverse().diagonal())
}

/// Torque limits per motor around any torque source, counting how often each motor
/// saturated (per evaluation of the source).
pub struct Saturated<C, T: Real, const NU: usize> {
    /// The torque source whose torques are clipped.
    pub inner: C,
    /// The largest `|u_k|` each motor can give.
    pub limits: SVector<T, NU>,
    /// Evaluations in which motor `k` was clipped.
    pub saturations: [usize; NU],
    /// The largest `|u_k|` the inner source asked for.
    pub peak_request: SVector<T, NU>,
}

impl<C, T: Real, const NU: usize> Saturated<C, T, NU> {
    /// `inner` clipped to `±limits`, with the counts at zero. A limit that is negative or
    /// NaN is refused ([`ControlError::TorqueLimit`]): `max`/`min` would clip every torque
    /// to it, or nothing.
    pub fn new(inner: C, limits: SVector<T, NU>) -> Result<Self, ControlError> {
        check_torque_limits(&limits)?;
        Ok(Saturated {
            inner,
            limits,
            saturations: [0; NU],
            peak_request: SVector::zeros(),
        })
    }
}

/// Torque limits are zero or more (infinite for none): the one check every entry point
/// that takes limits shares.
pub fn check_torque_limits<T: Real, const NU: usize>(
    limits: &SVector<T, NU>,
) -> Result<(), ControlError> {
    // NaN compares false both ways: a limit is good only if it is at least zero.
    match limits
        .iter()
        .position(|l| l.partial_cmp(&T::zero()).is_none_or(|o| o.is_lt()))
    {
        Some(motor) => Err(ControlError::TorqueLimit {
            motor,
            value: limits[motor].to_subset().unwrap_or(f64::NAN),
        }),
        None => Ok(()),
    }
}

impl<C, T, const NQ: usize, const NU: usize> TorqueSource<T, NQ, NU> for Saturated<C, T, NU>
where
    C: TorqueSource<T, NQ, NU>,
    T: Real,
{
    fn torque(&mut self, t: T, state: &State<T, NQ>) -> Result<SVector<T, NU>, ControlError> {
        let mut u = self.inner.torque(t, state)?;
        for k in 0..NU {
            self.peak_request[k] = self.peak_request[k].max(u[k].abs());
            let lim = self.limits[k];
            if u[k].abs() > lim {
                u[k] = u[k].max(-lim).min(lim);
                self.saturations[k] += 1;
            }
        }
        Ok(u)
    }
}
