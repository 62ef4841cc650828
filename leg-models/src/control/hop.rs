//! Hopping: a controller for a leg on a body that hops, in place to a commanded apex
//! height, or forward at a commanded speed when the body can move along the ground, for
//! any leg with contacts whose body rises along one coordinate (a body on a rail; the
//! height of a floating body). Raibert's three-part hopping controller (Raibert, *Legged
//! Robots That Balance*, 1986, ch. 2–3), with the stance solved on the exact model:
//!
//! - **Drives.** A motor joined to a leg joint by a coupling spring (a series-elastic
//!   actuator, as on ATRIAS) drives that joint through the spring: the controller computes
//!   the effort wanted on the driven joint (the spring's torque `τ*`) and, in stance, an
//!   inner loop puts the motor where the spring's deflection gives it, `q_m* = q_d + σ r +
//!   τ*/k`, with `u = τ_spring + I_m (q̈_d + ω² (q_m* − q_m) + 2 ω (q̇_d + τ̇*/k − q̇_m))`
//!   (critically damped, `I_m` the motor's inertia, `q̈_d` the driven joint's acceleration
//!   under `τ*`, `τ̇*` from the last evaluation; `ω` [`HopSettings::drive_frequency`]:
//!   without the two feedforwards the spring lags and pumps energy into each hop). In
//!   flight the motor goes where its spring is relaxed at the target, one slower loop
//!   ([`HopSettings::flight_drive_frequency`]: each motor's acceleration turns the body
//!   the other way). Any other motor drives its own joint. [`drives`] finds them from the
//!   spec's springs.
//! - **Flight**: the driven joints go to a touchdown posture (joint PD; in free fall the
//!   leg's relative motion needs no gravity compensation), the targets following it in a
//!   first-order lag. With a forward coordinate the posture places the foot (Raibert): `x_f
//!   = v T_st / 2 + k (v − v_des) + x_learnt` ahead of the hip, `v` the centre of mass's
//!   speed ([`centre_of_mass_speed`]), `T_st` the last stance's duration and `x_learnt` an
//!   integral of each hop's mean-speed error (what the estimate of the neutral point
//!   misses); the foot swings back at the body's speed over the last
//!   [`Forward::retraction_time`] before touchdown (swing-leg retraction: it meets the
//!   ground at rest along it), the leg is shortened by [`Forward::retraction`] while the
//!   body rises and back at full length 0.1 s before touchdown. The posture is the leg's
//!   inverse kinematics with the body held ([`foot_inverse_holding`]).
//! - **Stance**: inverse dynamics through the hybrid model. The accelerations and the
//!   ground forces of the stance (loop closures and held contacts in one structured
//!   solve, [`ContactSystem`]) are affine in the drive efforts, `q̈ = a₀ + Q δ`, `λ = λ₀ +
//!   Λ δ` (NU + 1 solves of one factorization); the efforts meet up to three tasks in the
//!   least-squares sense: the body height follows a virtual leg spring, `ÿ = ω² (y_td −
//!   y) − g + a_thrust` (`a_thrust` while the body rises, phased in over its first
//!   0.1 m/s); a body that can pitch is held by Raibert's attitude servo, here on
//!   `ψ = θ + r φ` ([`Pitch::flight_lead`]: it leaves the ground without angular momentum and
//!   lands upright after the leg's swing); and, when the body cannot move along the
//!   ground and a motor is left, the first held contact's tangential force is zero (no
//!   push along the ground, so no slip). Torques are clipped to the motors' limits.
//! - **Height regulation**: at each apex (the body's vertical rate crossing zero in flight)
//!   the energy the apex missed, `m g (h_cmd − h_apex)`, spread over the last stance's
//!   rise as a thrust (`m a · stroke`), sets the next thrust: a share `k_h` of it
//!   (proportional), on top of a learnt part (integral, a fifth of it per hop) that pays
//!   for the impact loss of every hop.

use nalgebra::{SMatrix, SVector};

use crate::assembly::{foot_inverse_holding, Tolerance};
use crate::dynamics::contact::{ContactMode, ContactSystem, Ground};
use crate::model::contract::{ContactModel, JointKind, LegModel, Parameters, Real};
use crate::model::linalg::Cholesky;
use crate::simulate::hybrid::{HybridOptions, HybridState, HybridTorqueSource};
use crate::simulate::source::ControlError;

/// The body's height coordinate of leg `L` at `q`: the prismatic joint that raises the
/// contacts most along the ground's normal (a vertical slider), if any joint raises them.
pub fn height_joint<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
) -> Option<usize>
where
    L: ContactModel<NQ, NC, NU, NK> + LegModel<NQ, NC, NU>,
    T: Real,
{
    slider_along::<L, T, NQ, NC, NU, NK>(params, q, 1)
}

/// The body's forward coordinate of leg `L` at `q`: the prismatic joint of the body that
/// moves the contacts most along the ground (a horizontal slider), if any.
pub fn forward_joint<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
) -> Option<usize>
where
    L: ContactModel<NQ, NC, NU, NK> + LegModel<NQ, NC, NU>,
    T: Real,
{
    slider_along::<L, T, NQ, NC, NU, NK>(params, q, 0)
}

/// The body prismatic joint moving every contact most along the ground's tangent
/// (`row = 0`) or normal (`row = 1`), by more than half a metre per metre.
fn slider_along<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    row: usize,
) -> Option<usize>
where
    L: ContactModel<NQ, NC, NU, NK> + LegModel<NQ, NC, NU>,
    T: Real,
{
    let rows = Ground::<T>::of::<L, NQ, NC, NU, NK>().rows(&L::contact_jacobian(q, params));
    // How much each joint moves the contacts, summed over them.
    let along = |i: usize| (0..NK / 2).fold(T::zero(), |a, k| a + rows[(2 * k + row, i)]);
    let body = body_joints::<L, NQ, NC, NU>();
    (0..NQ)
        .filter(|&i| {
            body[i]
                && L::JOINT_KINDS[i] == JointKind::Prismatic
                && along(i) > T::lit(0.5) * T::lit((NK / 2) as f64)
        })
        .max_by(|&a, &b| {
            along(a)
                .partial_cmp(&along(b))
                .unwrap_or(core::cmp::Ordering::Equal)
        })
}

/// The body's joints: the joints that carry the motors, every ancestor of a motor's
/// joint that neither is a motor's nor hangs below one (a knee motor's thigh, driven by
/// the hip motor, is the leg's, not the body's; for a leg hung from the base, none).
pub fn body_joints<L, const NQ: usize, const NC: usize, const NU: usize>() -> [bool; NQ]
where
    L: LegModel<NQ, NC, NU>,
{
    let below_a_motor = |j: usize| {
        let mut a = Some(j);
        while let Some(i) = a {
            if L::ACTUATED.contains(&i) {
                return true;
            }
            a = L::PARENTS[i];
        }
        false
    };
    let mut body = [false; NQ];
    for &a in &L::ACTUATED {
        let mut j = L::PARENTS[a];
        while let Some(p) = j {
            body[p] = !below_a_motor(p);
            j = L::PARENTS[p];
        }
    }
    body
}

/// The body's pitch: a revolute joint of the body that no motor drives, if any (the
/// first in the tree from the base).
pub fn pitch_joint<L, const NQ: usize, const NC: usize, const NU: usize>() -> Option<usize>
where
    L: LegModel<NQ, NC, NU>,
{
    let body = body_joints::<L, NQ, NC, NU>();
    (0..NQ)
        .find(|&i| body[i] && L::JOINT_KINDS[i] == JointKind::Revolute && !L::ACTUATED.contains(&i))
}

/// How a motor's effort reaches the leg.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Drive {
    /// The motor's joint.
    pub motor: usize,
    /// The joint its effort moves: the motor's own, or the one a coupling spring joins
    /// it to (a series-elastic actuator).
    pub joint: usize,
    /// The coupling spring (index into [`LegDynamics::SPRINGS`](crate::LegDynamics::SPRINGS)) and whether the motor is
    /// the spring's `a` (the spring acts on `q_a − q_b`).
    pub spring: Option<(usize, bool)>,
}

/// Each motor's drive (see the module docs): series-elastic where a coupling spring joins
/// the motor's joint to a leg joint no motor drives (not to the body that carries the
/// motor: a spring from the hip to the body acts beside the motor, not in series).
pub fn drives<L, const NQ: usize, const NC: usize, const NU: usize>() -> [Drive; NU]
where
    L: LegModel<NQ, NC, NU>,
{
    let body = body_joints::<L, NQ, NC, NU>();
    core::array::from_fn(|k| {
        let motor = L::ACTUATED[k];
        let series = L::SPRINGS.iter().enumerate().find_map(|(i, s)| {
            let b = s.b?;
            let (other, motor_is_a) = if s.a == motor {
                (b, true)
            } else if b == motor {
                (s.a, false)
            } else {
                return None;
            };
            (!L::ACTUATED.contains(&other) && !body[other]).then_some((i, other, motor_is_a))
        });
        match series {
            Some((i, joint, a)) => Drive {
                motor,
                joint,
                spring: Some((i, a)),
            },
            None => Drive {
                motor,
                joint: motor,
                spring: None,
            },
        }
    })
}

/// The body's attitude in stance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pitch<T: Real> {
    /// The body's pitch joint ([`pitch_joint`]).
    pub joint: usize,
    /// The pitch held (rad).
    pub target: T,
    /// The attitude servo's natural frequency (rad/s) (critically damped).
    pub frequency: T,
    /// `r`, how far the body turns back for each radian the leg swings in flight
    /// ([`flight_turn`], negated). The servo acts on `ψ = θ + r φ` (`φ` the leg's angle
    /// from the hip to the foot), which in flight changes only with the body's angular
    /// momentum: it drives `ψ` to `θ* + r φ_next` (`φ_next` the leg's angle at the next
    /// touchdown) and `ψ̇` to zero, so that the body leaves the ground without momentum
    /// and lands at `θ*` once the leg has swung to `φ_next`.
    pub flight_lead: T,
    /// `φ_next` without foot placement: the leg's angle at home (rad).
    pub neutral_leg_angle: T,
}

/// How far the body of leg `L` turns (rad) for each radian the whole leg swings about the
/// hip in flight, at `q`: the free body's momentum `M_bb q̇_b + M_bl q̇_l` is unchanged
/// by the swing (gravity acts on body and leg alike), so `q̇_b = −M_bb⁻¹ M_bl e φ̇`, `e`
/// the swing (every joint hung from the pitch joint turning at `φ̇`, the joints below
/// them still). Negative: the body turns against the leg. `None` if the body has more
/// than three joints or `M_bb` is singular.
pub fn flight_turn<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    pitch: usize,
) -> Option<T>
where
    L: LegModel<NQ, NC, NU>,
    T: Real,
{
    let body = body_joints::<L, NQ, NC, NU>();
    let m = L::mass_matrix(q, params);
    let mut index = [0usize; 3];
    let mut nb = 0;
    for (i, &b) in body.iter().enumerate() {
        if b {
            if nb == 3 {
                return None;
            }
            index[nb] = i;
            nb += 1;
        }
    }
    let mut mbb = SMatrix::<T, 3, 3>::identity();
    let mut rhs = SVector::<T, 3>::zeros();
    for (a, &i) in index.iter().enumerate().take(nb) {
        for (b, &j) in index.iter().enumerate().take(nb) {
            mbb[(a, b)] = m[(i, j)];
        }
        rhs[a] = (0..NQ)
            .filter(|&j| L::PARENTS[j] == Some(pitch))
            .fold(T::zero(), |s, j| s + m[(i, j)]);
    }
    let chol = Cholesky::new(&mbb)?;
    chol.solve_mut(&mut rhs);
    let k = index.iter().take(nb).position(|&i| i == pitch)?;
    Some(-rhs[k])
}

/// Forward hopping: foot placement in flight (Raibert).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Forward<T: Real> {
    /// The body's forward coordinate ([`forward_joint`]).
    pub joint: usize,
    /// Commanded speed along the ground (m/s).
    pub speed: T,
    /// The share of a speed error the placement corrects in one stance: `k` in `x_f =
    /// v T_st / 2 + k (v − v_des)` is `gain · ℓ / (g T_st)`, the foot placed `Δx` ahead
    /// slowing an inverted pendulum of length `ℓ` by about `g T_st Δx / ℓ` over the stance
    /// (so one share fits legs of every size and stance time).
    pub gain: T,
    /// The same share for each hop's mean-speed error, added to the learnt placement.
    pub learn_rate: T,
    /// The foot's offset from the hip at touchdown, in ground coordinates (along, up),
    /// with the foot placement added along the ground (m).
    pub neutral: SVector<T, 2>,
    /// How much the leg is shortened while the body rises in flight (m).
    pub retraction: T,
    /// The share of the body's speed at which the foot swings back before touchdown
    /// (1: the foot meets the ground at rest along it).
    pub retraction_speed: T,
    /// How long before touchdown the swing back starts (s).
    pub retraction_time: T,
    /// The largest foot placement either way (m).
    pub reach: T,
}

/// What the hopping controller aims at, and how hard.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HopSettings<T: Real, const NU: usize> {
    /// The body coordinate that is the height (a vertical slider).
    pub height_joint: usize,
    /// Commanded apex of `q[height_joint]` (m).
    pub apex: T,
    /// Angles of the driven joints ([`drives`]) held in flight without foot placement.
    pub posture: SVector<T, NU>,
    /// Flight PD gains on the driven joints.
    pub kp: SVector<T, NU>,
    /// Flight derivative gains on the driven joints.
    pub kd: SVector<T, NU>,
    /// The virtual leg spring's natural frequency in stance (rad/s).
    pub stance_frequency: T,
    /// The share of each hop's apex error corrected at the next hop (0 to 1): the thrust
    /// is `learnt + share · g (h_cmd − h_apex) / stroke`, the energy `m g Δh` spread over
    /// the last stance's rise.
    pub height_gain: T,
    /// `|u_k|` limits (N m).
    pub torque_limits: SVector<T, NU>,
    /// Gravity's magnitude along the height (m/s²).
    pub gravity: T,
    /// The body's attitude servo, for a body that can pitch.
    pub pitch: Option<Pitch<T>>,
    /// Foot placement, for a body that can move along the ground.
    pub forward: Option<Forward<T>>,
    /// The series-elastic drives' inner loop natural frequency in stance (rad/s).
    pub drive_frequency: T,
    /// The same in flight (rad/s).
    pub flight_drive_frequency: T,
    /// The time constant with which the flight targets follow the posture wanted (s).
    pub posture_time: T,
}

/// Why [`HopSettings::for_leg`] cannot set the controller up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HopSetupError {
    /// No prismatic joint of the body raises the contacts.
    NoHeightJoint,
    /// A speed was commanded and no prismatic joint of the body moves along the ground.
    NoForwardJoint,
    /// The mass matrix at `home` is not positive definite, or an inertia is not finite.
    Inertia,
}

impl core::fmt::Display for HopSetupError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            HopSetupError::NoHeightJoint => write!(
                f,
                "hopping needs a body that rises along a prismatic joint (a vertical slider) and none raises the contacts"
            ),
            HopSetupError::NoForwardJoint => write!(
                f,
                "a forward speed needs a body that moves along the ground on a prismatic joint (a horizontal slider) and none moves the contacts along it"
            ),
            HopSetupError::Inertia => {
                write!(f, "the mass matrix at the home pose is not positive definite")
            }
        }
    }
}

impl<T: Real, const NU: usize> HopSettings<T, NU> {
    /// Settings for leg `L` standing at `home` (assembled, contacts on the ground): the
    /// height and (with `speed`) forward joints and the pitch found from the model, the
    /// flight posture that of `home`, flight gains from the driven joints' inertias (a
    /// 30 rad/s loop, damping 0.7), a 18 rad/s stance spring, series-elastic drive loops
    /// at 150 rad/s in stance and 30 rad/s in flight, the attitude servo at 20 rad/s with
    /// the lead [`flight_turn`] gives, and Raibert's placement correcting 0.63 of a speed
    /// error per stance (0.17 learnt per hop).
    pub fn for_leg<L, const NQ: usize, const NC: usize, const NK: usize>(
        params: &L::Params<T>,
        home: &SVector<T, NQ>,
        apex: T,
        speed: Option<T>,
        torque_limit: T,
    ) -> Result<Self, HopSetupError>
    where
        L: ContactModel<NQ, NC, NU, NK> + LegModel<NQ, NC, NU>,
    {
        let height_joint = height_joint::<L, T, NQ, NC, NU, NK>(params, home)
            .ok_or(HopSetupError::NoHeightJoint)?;
        let drives = drives::<L, NQ, NC, NU>();
        let m = L::mass_matrix(home, params);
        let inertia = SVector::<T, NU>::from_fn(|k, _| {
            let d = drives[k];
            if d.spring.is_some() {
                m[(d.joint, d.joint)]
            } else {
                // A motor's own joint: its inertia through the closures (the reduction).
                crate::control::feedback::joint_inertias::<L, T, NQ, NC, NU>(params, home)
                    .map(|i| i[k])
                    .unwrap_or(m[(d.joint, d.joint)])
            }
        });
        if !inertia.iter().all(|i| i.is_finite() && *i > T::zero()) {
            return Err(HopSetupError::Inertia);
        }
        let gravity = {
            let get = |name: &str| {
                let names = <L::Params<T> as Parameters<T>>::NAMES;
                names
                    .iter()
                    .position(|n| *n == name)
                    .and_then(|i| params.get(i))
                    .unwrap_or(T::zero())
            };
            let n = Ground::<T>::of::<L, NQ, NC, NU, NK>().normal;
            -(get("gravity_x") * n[0] + get("gravity_y") * n[1])
        };
        let forward = match speed {
            None => None,
            Some(speed) => {
                let joint = forward_joint::<L, T, NQ, NC, NU, NK>(params, home)
                    .ok_or(HopSetupError::NoForwardJoint)?;
                let ground = Ground::<T>::of::<L, NQ, NC, NU, NK>();
                let offset = L::foot_position(home, params)
                    - hip(&L::joint_positions(home, params), drives[0].motor);
                let neutral =
                    SVector::<T, 2>::new(ground.tangent().dot(&offset), ground.normal.dot(&offset));
                let length = offset.norm();
                Some(Forward {
                    joint,
                    speed,
                    gain: T::lit(0.63),
                    learn_rate: T::lit(0.17),
                    neutral,
                    retraction: T::lit(0.03) * length,
                    retraction_speed: T::one(),
                    retraction_time: T::lit(0.1),
                    reach: T::lit(0.4) * length,
                })
            }
        };
        let omega = T::lit(30.0);
        Ok(HopSettings {
            height_joint,
            apex,
            posture: SVector::from_fn(|k, _| home[drives[k].joint]),
            kp: inertia * (omega * omega),
            kd: inertia * (T::lit(2.0 * 0.7) * omega),
            stance_frequency: T::lit(18.0),
            height_gain: T::lit(0.8),
            torque_limits: SVector::from_element(torque_limit),
            gravity,
            pitch: pitch_joint::<L, NQ, NC, NU>().map(|joint| Pitch {
                joint,
                target: home[joint],
                frequency: T::lit(20.0),
                flight_lead: flight_turn::<L, T, NQ, NC, NU>(params, home, joint)
                    .map_or(T::zero(), |turn| -turn),
                neutral_leg_angle: {
                    let ground = Ground::<T>::of::<L, NQ, NC, NU, NK>();
                    let d = L::foot_position(home, params)
                        - hip(&L::joint_positions(home, params), drives[0].motor);
                    ground.tangent().dot(&d).atan2(-ground.normal.dot(&d))
                },
            }),
            forward,
            drive_frequency: T::lit(150.0),
            flight_drive_frequency: T::lit(30.0),
            posture_time: T::lit(0.03),
        })
    }
}

/// The speed of the centre of mass along a body slider `joint`: the slider's generalized
/// momentum `(M q̇)_j` is the whole leg's momentum along it, `M_jj` its mass. (Not the
/// slider's own rate: the body turning in flight moves the hip under its centre of mass.)
pub fn centre_of_mass_speed<T: Real, const NQ: usize>(
    m: &SMatrix<T, NQ, NQ>,
    qd: &SVector<T, NQ>,
    joint: usize,
) -> T {
    (0..NQ).fold(T::zero(), |s, j| s + m[(joint, j)] * qd[j]) / m[(joint, joint)]
}

/// The hip: where the first motor's joint is.
fn hip<T: Real, const NQ: usize>(joints: &SMatrix<T, 2, NQ>, motor: usize) -> SVector<T, 2> {
    SVector::<T, 2>::new(joints[(0, motor)], joints[(1, motor)])
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
    L: ContactModel<NQ, NC, NU, NK> + LegModel<NQ, NC, NU>,
{
    /// The controller's model of the leg.
    pub params: L::Params<T>,
    /// The ground, friction, Baumgarte terms and step the controller plans with.
    pub options: HybridOptions<T, NK>,
    /// What it aims at, and how hard.
    pub settings: HopSettings<T, NU>,
    /// Each motor's drive.
    pub drives: [Drive; NU],
    /// The thrust acceleration added while the body rises in stance.
    pub thrust: T,
    /// Its learnt part: what pays for each hop's impact loss.
    pub loss_thrust: T,
    /// The learnt part of the foot placement (m).
    pub learnt_placement: T,
    /// Body height at the last touchdown.
    pub touchdown_height: T,
    /// The lowest body height of the last stance.
    pub bottom: T,
    /// The last stance's duration (s).
    pub stance_time: T,
    /// Apexes seen (hops completed).
    pub hops: usize,
    /// The last apex height.
    pub last_apex: Option<T>,
    /// The mean forward speed from the apex before the last to the last (m/s).
    pub last_speed: Option<T>,
    /// Evaluations in which motor `k` was clipped.
    pub saturations: [usize; NU],
    /// Flight evaluations whose foot placement the leg could not reach (the posture of
    /// the last reachable one was kept).
    pub unreachable_placements: usize,
    in_stance: bool,
    rising: bool,
    touchdown_time: T,
    apex_at: Option<(T, T)>,
    placement: Option<SVector<T, NQ>>,
    flight_posture: Option<(T, SVector<T, NU>)>,
    last_effort: Option<(T, SVector<T, NU>)>,
    effort_rate: SVector<T, NU>,
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    HopController<L, T, NQ, NC, NU, NK>
where
    L: ContactModel<NQ, NC, NU, NK> + LegModel<NQ, NC, NU>,
    T: Real,
{
    /// A controller that has seen no hop yet (nothing learnt; the last stance taken to last
    /// `π / stance_frequency`), with the drives of the spec ([`drives`]).
    pub fn new(
        params: L::Params<T>,
        options: HybridOptions<T, NK>,
        settings: HopSettings<T, NU>,
    ) -> Self {
        HopController {
            params,
            options,
            settings,
            drives: drives::<L, NQ, NC, NU>(),
            thrust: T::zero(),
            loss_thrust: T::zero(),
            learnt_placement: T::zero(),
            touchdown_height: T::zero(),
            bottom: T::zero(),
            stance_time: T::lit(core::f64::consts::PI) / settings.stance_frequency,
            hops: 0,
            last_apex: None,
            last_speed: None,
            saturations: [0; NU],
            unreachable_placements: 0,
            in_stance: false,
            rising: false,
            touchdown_time: T::zero(),
            apex_at: None,
            placement: None,
            flight_posture: None,
            last_effort: None,
            effort_rate: SVector::zeros(),
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

    /// `ℓ / (g T_st)` (s): the inverted pendulum's placement per unit of speed change.
    fn placement_scale(&self, fw: &Forward<T>) -> T {
        let g = self.settings.gravity.max(T::lit(1e-9));
        fw.neutral.norm() / (g * self.stance_time.max(T::lit(1e-3)))
    }

    /// A series-elastic drive's spring: stiffness, and its rest value as seen from the
    /// motor (`τ = k (q_m − q_d − r)`).
    fn spring(&self, k: usize) -> Option<(T, T)> {
        let (i, motor_is_a) = self.drives[k].spring?;
        let s = &L::SPRINGS[i];
        let stiffness = self.params.get(s.stiffness)?;
        let rest = self.params.get(s.rest)?;
        Some((stiffness, if motor_is_a { rest } else { -rest }))
    }

    /// The effort each drive puts on its joint now: the spring's torque for a
    /// series-elastic drive, nothing (it is the torque asked) for a direct one.
    fn present_efforts(&self, q: &SVector<T, NQ>) -> SVector<T, NU> {
        SVector::from_fn(|k, _| match self.spring(k) {
            Some((stiffness, rest)) => {
                let d = self.drives[k];
                stiffness * (q[d.motor] - q[d.joint] - rest)
            }
            None => T::zero(),
        })
    }

    /// Motor torques that give the drive efforts `effort` (see the module docs).
    /// `drive_acceleration`, when known (stance), is the driven joints' acceleration
    /// under `effort`: the motor follows it (feedforward), so the spring's deflection
    /// does not lag the joint's motion.
    fn motor_torques(
        &self,
        hs: &HybridState<T, NQ, NK>,
        effort: &SVector<T, NU>,
        mass_matrix: &SMatrix<T, NQ, NQ>,
        drive_acceleration: &SVector<T, NU>,
        effort_rate: &SVector<T, NU>,
    ) -> SVector<T, NU> {
        let (q, qd) = (&hs.state.q, &hs.state.qd);
        let present = self.present_efforts(q);
        let omega = self.settings.drive_frequency;
        SVector::from_fn(|k, _| match self.spring(k) {
            None => effort[k],
            Some((stiffness, rest)) => {
                let d = self.drives[k];
                let inertia = mass_matrix[(d.motor, d.motor)];
                let target = q[d.joint] + rest + effort[k] / stiffness;
                let (follow, lead) = (drive_acceleration[k], effort_rate[k]);
                present[k]
                    + inertia
                        * (follow
                            + omega * omega * (target - q[d.motor])
                            + (omega + omega) * (qd[d.joint] + lead / stiffness - qd[d.motor]))
            }
        })
    }

    /// The driven joints' flight targets: the foot placed (with a forward coordinate)
    /// or the fixed posture.
    fn flight_targets(&mut self, hs: &HybridState<T, NQ, NK>) -> SVector<T, NU> {
        let Some(fw) = self.settings.forward else {
            return self.settings.posture;
        };
        let q = &hs.state.q;
        let v = centre_of_mass_speed(&L::mass_matrix(q, &self.params), &hs.state.qd, fw.joint);
        let half = T::lit(0.5);
        let ground = self.options.ground;
        // Swing-leg retraction: the foot ahead of its touchdown placement by what the body
        // covers until touchdown (a ballistic fall of the foot's gap), so that it swings
        // back at the body's speed and meets the ground at rest (no tangential impulse).
        let gap =
            (ground.normal.dot(&L::foot_position(q, &self.params)) - ground.offset).max(T::zero());
        let (vy, g) = (
            hs.state.qd[self.settings.height_joint],
            self.settings.gravity,
        );
        let to_touchdown = if g > T::zero() {
            (vy + (vy * vy + (g + g) * gap).sqrt()) / g
        } else {
            T::zero()
        };
        let x_f = (v * self.stance_time * half
            + fw.gain * self.placement_scale(&fw) * (v - fw.speed)
            + self.learnt_placement
            + fw.retraction_speed * v * to_touchdown.min(fw.retraction_time))
        .max(-fw.reach)
        .min(fw.reach);
        // Shortened while rising; back to full length smoothly (zero rate) from 0.15 s
        // to 0.05 s before touchdown, so the foot meets the ground with the leg at rest.
        let up = if self.rising {
            fw.retraction
        } else {
            let u = ((to_touchdown - T::lit(0.1)) / T::lit(0.1))
                .max(T::zero())
                .min(T::one());
            fw.retraction * u * u * (T::lit(3.0) - u - u)
        };
        let hip = hip(&L::joint_positions(q, &self.params), self.drives[0].motor);
        let target =
            hip + ground.tangent() * (fw.neutral[0] + x_f) + ground.normal * (fw.neutral[1] + up);
        let body = body_joints::<L, NQ, NC, NU>();
        let mut guess = self.placement.unwrap_or(*q);
        for i in 0..NQ {
            if body[i] {
                guess[i] = q[i];
            }
        }
        match foot_inverse_holding::<L, T, NQ, NC, NU, 2, NC>(
            &self.params,
            &target,
            &guess,
            &Tolerance::default(),
            &body,
        ) {
            Ok(placed) => self.placement = Some(placed),
            Err(_) => self.unreachable_placements += 1,
        }
        match &self.placement {
            Some(placed) => SVector::from_fn(|k, _| placed[self.drives[k].joint]),
            None => self.settings.posture,
        }
    }

    fn flight(&mut self, t: T, hs: &HybridState<T, NQ, NK>) -> SVector<T, NU> {
        let wanted = self.flight_targets(hs);
        // The targets move from where the leg left the ground toward the wanted posture
        // in a first-order lag (a step would jolt the body at liftoff).
        let targets = match self.flight_posture {
            Some((t0, previous)) if t >= t0 => {
                let a = T::one() - (-(t - t0) / self.settings.posture_time).exp();
                previous + (wanted - previous) * a
            }
            _ => SVector::from_fn(|k, _| hs.state.q[self.drives[k].joint]),
        };
        self.flight_posture = Some((t, targets));
        let s = &self.settings;
        let (q, qd) = (&hs.state.q, &hs.state.qd);
        let present = self.present_efforts(q);
        let omega = s.flight_drive_frequency;
        let mut m = None;
        SVector::from_fn(|k, _| {
            let d = self.drives[k];
            match self.spring(k) {
                // A joint PD on a direct drive.
                None => s.kp[k] * (targets[k] - q[d.joint]) - s.kd[k] * qd[d.joint],
                // A series-elastic drive's motor goes where its spring is relaxed at the
                // target (the leg's joints follow through the stiff spring): one slow
                // loop, since each motor's acceleration turns the body the other way.
                Some((_, rest)) => {
                    let inertia = m.get_or_insert_with(|| L::mass_matrix(q, &self.params))
                        [(d.motor, d.motor)];
                    present[k]
                        + inertia
                            * (omega * omega * (targets[k] + rest - q[d.motor])
                                - (omega + omega) * qd[d.motor])
                }
            }
        })
    }

    /// The stance system at `hs`, and the applied forces with every series-elastic motor
    /// holding its spring (direct motors at zero).
    #[allow(clippy::type_complexity)]
    fn system(
        &self,
        hs: &HybridState<T, NQ, NK>,
    ) -> Result<(ContactSystem<T, NQ, NC, NK>, SVector<T, NQ>, SVector<T, NU>), ControlError> {
        let system = ContactSystem::new::<L, NU>(
            &self.params,
            &hs.state.q,
            &hs.state.qd,
            &hs.modes,
            &hs.anchors,
            &self.options.ground,
            &self.options.friction,
            self.options.baumgarte,
        )
        .map_err(ControlError::Dynamics)?;
        let present = self.present_efforts(&hs.state.q);
        let mut applied = SVector::<T, NQ>::zeros();
        for k in 0..NU {
            applied[self.drives[k].motor] += present[k];
        }
        Ok((system, applied, present))
    }

    /// A unit effort of drive `k`: on its joint, and held by its motor when it acts
    /// through a spring.
    fn unit_effort(&self, k: usize) -> SVector<T, NQ> {
        let d = self.drives[k];
        let mut e = SVector::<T, NQ>::zeros();
        e[d.joint] = T::one();
        if d.spring.is_some() {
            e[d.motor] += T::one();
        }
        e
    }

    /// How much the drives move the body's height at a stance state: the norm of
    /// `∂ÿ/∂δ` over the drive efforts. Zero where they cannot (the controller's stance
    /// then does not apply).
    pub fn height_authority(&self, hs: &HybridState<T, NQ, NK>) -> Result<T, ControlError> {
        let (system, applied, _) = self.system(hs)?;
        let h = self.settings.height_joint;
        let solve = |f: &SVector<T, NQ>| system.solve(f).map_err(ControlError::Dynamics);
        let base = solve(&applied)?.x[h];
        let mut sum = T::zero();
        for k in 0..NU {
            let d = solve(&(applied + self.unit_effort(k)))?.x[h] - base;
            sum += d * d;
        }
        Ok(sum.sqrt())
    }

    /// The drive efforts of the stance, the driven joints' accelerations under them,
    /// and `M`.
    #[allow(clippy::type_complexity)]
    fn stance(
        &self,
        hs: &HybridState<T, NQ, NK>,
    ) -> Result<(SVector<T, NU>, SVector<T, NU>, SMatrix<T, NQ, NQ>), ControlError> {
        let s = &self.settings;
        let (q, qd) = (&hs.state.q, &hs.state.qd);
        let (system, applied, present) = self.system(hs)?;
        let solve = |f: &SVector<T, NQ>| system.solve(f).map_err(ControlError::Dynamics);
        let base = solve(&applied)?;
        // Task rows: body height acceleration, the pitch's, and (body held along the
        // ground, a motor left) the first held contact's tangential force.
        let tangential = match (s.forward, s.pitch) {
            (None, None) if NU >= 2 => (0..NK / 2).find(|&k| hs.modes.get(k) == ContactMode::Stick),
            _ => None,
        };
        let h = s.height_joint;
        let mut rows = SMatrix::<T, 3, NU>::zeros();
        // The driven joints' accelerations per unit effort.
        let mut drive_rows = SMatrix::<T, NU, NU>::zeros();
        // The ground forces per unit effort.
        let mut force_rows = SMatrix::<T, NK, NU>::zeros();
        for k in 0..NU {
            let unit = solve(&(applied + self.unit_effort(k)))?;
            for i in 0..NU {
                let j = self.drives[i].joint;
                drive_rows[(i, k)] = unit.x[j] - base.x[j];
            }
            for c in 0..NK {
                force_rows[(c, k)] = unit.contact[c] - base.contact[c];
            }
            rows[(0, k)] = unit.x[h] - base.x[h];
            if let Some(p) = s.pitch {
                rows[(1, k)] = unit.x[p.joint] - base.x[p.joint];
            }
            if let Some(c) = tangential {
                rows[(2, k)] = unit.contact[2 * c] - base.contact[2 * c];
            }
        }
        let omega2 = s.stance_frequency * s.stance_frequency;
        let mut target = omega2 * (self.touchdown_height - q[h]) - s.gravity;
        // The thrust while the body rises, phased in over its first 0.1 m/s (a step in
        // the efforts asked would be a spike in their rate).
        if qd[h] > T::zero() {
            target += self.thrust * (qd[h] / T::lit(0.1)).min(T::one());
        }
        let pitch_goal = match s.pitch {
            Some(p) => {
                let w = p.frequency;
                // The leg's angle from the hip to the foot (from straight down, along
                // the ground positive), and its rate (central difference along q̇).
                let ground = self.options.ground;
                let leg_angle = |q: &SVector<T, NQ>| {
                    let hip = hip(&L::joint_positions(q, &self.params), self.drives[0].motor);
                    let d = L::foot_position(q, &self.params) - hip;
                    ground.tangent().dot(&d).atan2(-ground.normal.dot(&d))
                };
                let now = leg_angle(q);
                let eps = T::lit(1e-6);
                let rate = (leg_angle(&(q + qd * eps)) - leg_angle(&(q - qd * eps))) / (eps + eps);
                let next = match s.forward {
                    Some(fw) => {
                        let v = centre_of_mass_speed(&system.mass_matrix, qd, fw.joint);
                        let x_f = (v * self.stance_time * T::lit(0.5)
                            + fw.gain * self.placement_scale(&fw) * (v - fw.speed)
                            + self.learnt_placement)
                            .max(-fw.reach)
                            .min(fw.reach);
                        (fw.neutral[0] + x_f).atan2(-fw.neutral[1])
                    }
                    None => p.neutral_leg_angle,
                };
                // ψ = θ + r φ changes in flight only with the body's momentum: servo it to
                // the pitch target plus the turn the coming swing will take back, at rest.
                let r = p.flight_lead;
                w * w * (p.target + r * (next - now) - q[p.joint])
                    - (w + w) * (qd[p.joint] + r * rate)
                    - base.x[p.joint]
            }
            None => T::zero(),
        };
        let goal = nalgebra::Vector3::new(
            target - base.x[h],
            pitch_goal,
            match tangential {
                Some(c) => -base.contact[2 * c],
                None => T::zero(),
            },
        );
        // Weighted least squares with a small ridge (the tasks may be fewer than the
        // motors, or depend on them alike): rows scaled to unit size first.
        let mut w = rows;
        let mut g = goal;
        for r in 0..3 {
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
        let mut delta = w.transpose() * g;
        chol.solve_mut(&mut delta);
        if s.pitch.is_some() {
            // The attitude servo's share is cut where it would push a sticking contact
            // out of the friction cone (a touchdown, where the leg pushes little yet):
            // the largest share in [0, 1] that keeps every sticking contact within 0.7 of
            // its cone (the efforts are linear in the share).
            let mut without = g;
            without[1] = T::zero();
            let mut delta0 = w.transpose() * without;
            chol.solve_mut(&mut delta0);
            let (f0, f1) = (
                base.contact + force_rows * delta0,
                base.contact + force_rows * delta,
            );
            let mut share = T::one();
            for k in (0..NK / 2).filter(|&k| hs.modes.get(k) == ContactMode::Stick) {
                let mu = T::lit(0.7) * self.options.friction[2 * k];
                for side in [T::one(), -T::one()] {
                    // side λ_t − μ λ_n ≤ 0 along the share.
                    let at = |f: &SVector<T, NK>| side * f[2 * k] - mu * f[2 * k + 1];
                    let (a0, a1) = (at(&f0), at(&f1));
                    if a1 > T::zero() && a0 < a1 {
                        share = share.min((-a0 / (a1 - a0)).max(T::zero()));
                    }
                }
            }
            delta = delta0 + (delta - delta0) * share;
        }
        let drive_acceleration =
            SVector::<T, NU>::from_fn(|i, _| base.x[self.drives[i].joint]) + drive_rows * delta;
        Ok((present + delta, drive_acceleration, system.mass_matrix))
    }
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    HybridTorqueSource<T, NQ, NK, NU> for HopController<L, T, NQ, NC, NU, NK>
where
    L: ContactModel<NQ, NC, NU, NK> + LegModel<NQ, NC, NU>,
    T: Real,
{
    fn torque(
        &mut self,
        t: T,
        hs: &HybridState<T, NQ, NK>,
    ) -> Result<SVector<T, NU>, ControlError> {
        let h = self.settings.height_joint;
        let on_ground = (0..NK / 2).any(|k| hs.modes.get(k).on_ground());
        let (y, vy) = (hs.state.q[h], hs.state.qd[h]);
        if on_ground && !self.in_stance {
            self.touchdown_height = y;
            self.bottom = y;
            self.touchdown_time = t;
        }
        if !on_ground && self.in_stance {
            self.stance_time = t - self.touchdown_time;
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
                self.loss_thrust += T::lit(0.2) * missed;
                // Negative: the stance brakes the rise (a leg that gains energy in
                // stance, as one whose springs lag the motors does, needs it).
                self.thrust = self.loss_thrust + self.settings.height_gain * missed;
                if let Some(fw) = self.settings.forward {
                    let x = hs.state.q[fw.joint];
                    if let Some((t0, x0)) = self.apex_at {
                        if t > t0 {
                            let speed = (x - x0) / (t - t0);
                            self.last_speed = Some(speed);
                            self.learnt_placement +=
                                fw.learn_rate * self.placement_scale(&fw) * (speed - fw.speed);
                        }
                    }
                    self.apex_at = Some((t, x));
                }
            }
            self.rising = vy > T::zero();
        } else {
            self.rising = false;
        }
        self.in_stance = on_ground;
        if on_ground {
            self.flight_posture = None;
        }
        let u = if on_ground {
            let (effort, acceleration, m) = self.stance(hs)?;
            // The efforts' rate (the motors lead the springs by it), from the last
            // evaluation in this stance a step or more ago, filtered over 1/ω: a jump in
            // the efforts (a slide turning to stick) was a rate of Δτ*/h for one step, a
            // torque spike growing as 1/dt (35 kN m at 0.1 ms on atrias_hopper); filtered,
            // it peaks at Δτ*/(1/ω + h), whatever the step.
            let rate = match self.last_effort {
                Some((t0, e0)) if t - t0 >= T::lit(0.5) * self.options.dt => {
                    let h = t - t0;
                    let raw = (effort - e0) / h;
                    let lag = T::one() / self.settings.drive_frequency;
                    let r = self.effort_rate + (raw - self.effort_rate) * (h / (lag + h));
                    self.last_effort = Some((t, effort));
                    r
                }
                Some(_) => self.effort_rate,
                None => {
                    self.last_effort = Some((t, effort));
                    SVector::zeros()
                }
            };
            self.effort_rate = rate;
            self.motor_torques(hs, &effort, &m, &acceleration, &rate)
        } else {
            self.last_effort = None;
            self.flight(t, hs)
        };
        if !u.iter().all(|x| x.is_finite()) {
            return Err(ControlError::NonFinite);
        }
        Ok(self.clip(u))
    }
}
