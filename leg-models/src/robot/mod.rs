//! Whole robots: legs on a body that floats (DESIGN.md §3.3).
//!
//! A floating robot's spec gives its body a free joint ([`LegDynamics::FREE_JOINT`]):
//! the generated model then has six coordinates for it, a translation `δ` along the base
//! frame's axes and a ball joint's angles `(α, β, γ)`, and its base frame is a chart's
//! centre rather than a place in the world. [`RobotState`] holds the body's pose in the
//! world, a position and a unit quaternion, and keeps the chart centred on it:
//!
//! ```text
//! p = p₀ + R₀ δ,   R = R₀ R_x(α) R_y(β) R_z(γ),   gravity in the chart = R₀ᵀ g
//! ```
//!
//! At the centre (`δ = 0`, angles zero) the chart's rates are the robot's velocity `v`:
//! the body's linear velocity `Rᵀ ṗ` and angular velocity `ω`, both in the body frame,
//! then the joint rates. So `q̇ ≠ v` for the pose (`ṗ = R v_b`, `q̇_quat = ½ q ⊗ (0, ω)`,
//! [`RobotState::pose_rate`]) while the dynamics are the generated ones, unchanged. A
//! step ([`step`]) integrates in the chart centred at the step's start, with every
//! integrator and projection of [`crate::simulate::step`], then moves the centre to
//! where the body went ([`RobotState::recentre`]): the Runge–Kutta–Munthe-Kaas idea,
//! with the ball joint's angles as the chart. They are singular only at `β = ±π/2`,
//! which a step of a body turning at less than `π/(2 dt)` rad/s never nears; the
//! quaternion is renormalized after each step, so it stays unit to rounding.
//!
//! Gravity is a parameter of the generated model: the robot's parameters hold it in
//! the world, and each call turns it into the chart's, `R₀ᵀ g` ([`chart_params`]). Closures are
//! between the robot's own links, so they do not see the chart at all.

#[cfg(feature = "balance")]
pub mod balance;
#[cfg(feature = "std")]
pub mod standing;
#[cfg(feature = "std")]
pub mod time_stepping;

use core::fmt;

use nalgebra::{Quaternion, SMatrix, SVector, UnitQuaternion, Vector3};

use crate::assembly::{project_position, project_position_near, AssemblyError, Tolerance};
use crate::dynamics::contact::{
    impact_map, project_held_velocity, slip_directions, ContactRows, ContactSolution,
    ContactSystem, Ground, Impact, ImpactError, Modes, StructuredSolve,
};
use crate::dynamics::forward::factor_mass;
use crate::dynamics::{actuation, forward_dynamics, Acceleration, DynamicsError};
use crate::model::contract::{ContactModel, LegDynamics, Parameters, Real};
use crate::model::linalg::Cholesky;
use crate::simulate::step::advance;
use crate::simulate::{self, Method, State, StepError, StepOptions, StepReport, TorqueSource};

/// Why a robot's operation cannot be done.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RobotError {
    /// The model has no free joint: its base is fixed (use the leg's own functions).
    NotFloating {
        /// The model's name.
        model: &'static str,
    },
    /// The model's parameters have no gravity named `gravity_x`, `gravity_y`,
    /// `gravity_z` (a model not made by `cargo xtask gen`).
    NoGravity {
        /// The model's name.
        model: &'static str,
    },
}

impl fmt::Display for RobotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RobotError::NotFloating { model } => write!(
                f,
                "`{model}` has a fixed base: a robot's body is a link with `joint = \"free\"`"
            ),
            RobotError::NoGravity { model } => write!(
                f,
                "`{model}` has no parameters gravity_x, gravity_y, gravity_z to turn into the body's chart"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for RobotError {}

/// The free joint's first coordinate, or why the model has none.
pub fn free_joint<L, const NQ: usize, const NC: usize, const NU: usize>(
) -> Result<usize, RobotError>
where
    L: LegDynamics<NQ, NC, NU>,
{
    match L::FREE_JOINT {
        Some(f) if f + 6 <= NQ && L::DIMENSION == 3 => Ok(f),
        _ => Err(RobotError::NotFloating { model: L::NAME }),
    }
}

/// The indices of `gravity_x`, `gravity_y`, `gravity_z` in the parameters.
fn gravity_indices<L, T, const NQ: usize, const NC: usize, const NU: usize>(
) -> Result<[usize; 3], RobotError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let names = <L::Params<T> as Parameters<T>>::NAMES;
    let mut out = [0; 3];
    for (k, want) in ["gravity_x", "gravity_y", "gravity_z"].iter().enumerate() {
        out[k] = names
            .iter()
            .position(|n| n == want)
            .ok_or(RobotError::NoGravity { model: L::NAME })?;
    }
    Ok(out)
}

/// The robot's gravity in the world (its parameters' `gravity_*`).
pub fn world_gravity<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
) -> Result<Vector3<T>, RobotError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let [x, y, z] = gravity_indices::<L, T, NQ, NC, NU>()?;
    let get = |i| params.get(i).expect("an index of NAMES");
    Ok(Vector3::new(get(x), get(y), get(z)))
}

/// The parameters of the chart centred on a body turned by `orientation`: the robot's
/// (`params`, gravity in the world) with gravity turned into the body's frame, `R₀ᵀ g`.
pub fn chart_params<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    orientation: &UnitQuaternion<T>,
) -> Result<L::Params<T>, RobotError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let mut out = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut out, orientation)?;
    Ok(out)
}

/// Turns the robot's parameters, in place, into those of the chart centred on a body
/// turned by `orientation` (gravity `g` in the world becomes `R₀ᵀ g`). The hot paths
/// copy the parameters once and turn the copy; returning the copy in a `Result`
/// ([`chart_params`]) moved it twice more, and a robot's are 8 KB.
fn into_chart<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &mut L::Params<T>,
    orientation: &UnitQuaternion<T>,
) -> Result<(), RobotError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let idx = gravity_indices::<L, T, NQ, NC, NU>()?;
    let get = |i| params.get(i).expect("an index of NAMES");
    let g = Vector3::new(get(idx[0]), get(idx[1]), get(idx[2]));
    let local = orientation.inverse_transform_vector(&g);
    params.set_many(&[(idx[0], local[0]), (idx[1], local[1]), (idx[2], local[2])]);
    Ok(())
}

/// `R_x(α) R_y(β) R_z(γ)`, the ball joint's rotation, as a unit quaternion.
pub fn ball_rotation<T: Real>(angles: &Vector3<T>) -> UnitQuaternion<T> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), angles[0])
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), angles[1])
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angles[2])
}

/// `ω = E(β, γ) (α̇, β̇, γ̇)`, the body-frame angular velocity of the ball joint's angle
/// rates (`E`'s columns are `R_z(γ)ᵀ R_y(β)ᵀ x̂`, `R_z(γ)ᵀ ŷ`, `ẑ`).
pub fn ball_angular_velocity<T: Real>(angles: &Vector3<T>, rates: &Vector3<T>) -> Vector3<T> {
    let (sb, cb) = angles[1].sincos();
    let (sg, cg) = angles[2].sincos();
    Vector3::new(
        cb * cg * rates[0] + sg * rates[1],
        -cb * sg * rates[0] + cg * rates[1],
        sb * rates[0] + rates[2],
    )
}

/// A floating robot's state: the body's pose in the world and the chart's coordinates
/// and rates, centred on it after every [`step`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotState<T: Real, const NQ: usize> {
    /// The chart's centre: the body frame's origin in the world (m).
    pub position: Vector3<T>,
    /// The chart's centre: the body frame's orientation (body to world).
    pub orientation: UnitQuaternion<T>,
    /// The chart's coordinates: the free joint's six (zero when centred), then the
    /// joints' (rad, or m).
    pub q: SVector<T, NQ>,
    /// The chart's rates. Centred, they are the velocity `v`: the body's linear
    /// velocity `Rᵀ ṗ` (m/s) and angular velocity `ω` (rad/s), both in the body frame,
    /// then the joint rates.
    pub v: SVector<T, NQ>,
}

impl<T: Real, const NQ: usize> RobotState<T, NQ> {
    /// The body at `position` turned by `orientation`, the joints at `q` (the free
    /// joint's six entries are the chart's: give zeros), everything at rest.
    pub fn at_rest(
        position: Vector3<T>,
        orientation: UnitQuaternion<T>,
        q: SVector<T, NQ>,
    ) -> Self {
        RobotState {
            position,
            orientation,
            q,
            v: SVector::zeros(),
        }
    }

    /// Moves the chart's centre to the body's pose: the free joint's coordinates
    /// (from `f`) become zero and its rates the body-frame velocities there.
    pub fn recentre(&mut self, f: usize) {
        let delta = Vector3::new(self.q[f], self.q[f + 1], self.q[f + 2]);
        let angles = Vector3::new(self.q[f + 3], self.q[f + 4], self.q[f + 5]);
        let delta_rate = Vector3::new(self.v[f], self.v[f + 1], self.v[f + 2]);
        let angle_rates = Vector3::new(self.v[f + 3], self.v[f + 4], self.v[f + 5]);
        let turn = ball_rotation(&angles);
        // ṗ = R₀ δ̇, so Rᵀ ṗ = (R₀ turn)ᵀ R₀ δ̇ = turnᵀ δ̇.
        let linear = turn.inverse_transform_vector(&delta_rate);
        let angular = ball_angular_velocity(&angles, &angle_rates);
        self.position += self.orientation.transform_vector(&delta);
        // Renormalized: the product of unit quaternions drifts off the unit sphere by
        // rounding alone, step after step.
        self.orientation =
            UnitQuaternion::new_normalize(self.orientation.into_inner() * turn.into_inner());
        for k in 0..3 {
            self.q[f + k] = T::zero();
            self.q[f + 3 + k] = T::zero();
            self.v[f + k] = linear[k];
            self.v[f + 3 + k] = angular[k];
        }
    }

    /// The pose's time derivative at a centred state (`q̇ ≠ v`): the body's velocity in
    /// the world `ṗ = R v_b`, and `q̇_quat = ½ q ⊗ (0, ω)`.
    pub fn pose_rate(&self, f: usize) -> (Vector3<T>, Quaternion<T>) {
        let linear = Vector3::new(self.v[f], self.v[f + 1], self.v[f + 2]);
        let omega = Vector3::new(self.v[f + 3], self.v[f + 4], self.v[f + 5]);
        let half = T::lit(0.5);
        (
            self.orientation.transform_vector(&linear),
            self.orientation.into_inner() * Quaternion::from_imag(omega) * half,
        )
    }
}

/// The robot's forward dynamics at a state (centred first, on a copy): `q̈` of the chart
/// and the closure forces. The free joint's accelerations are the chart's: `Rᵀ p̈` and the
/// angles'; [`velocity_derivative`] turns them into `v̇`.
pub fn forward_dynamics_at<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &RobotState<T, NQ>,
    u: &SVector<T, NU>,
) -> Result<Acceleration<T, NQ, NC>, RobotDynamicsError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut s = *state;
    s.recentre(f);
    let mut chart = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut chart, &s.orientation)?;
    Ok(forward_dynamics::<L, T, NQ, NC, NU>(
        &chart, &s.q, &s.v, u, None,
    )?)
}

/// `v̇` at a centred state from the chart's `q̈` there: the body's `d(Rᵀ ṗ)/dt =
/// Rᵀ p̈ − ω × v_b` and `ω̇ = θ̈ + Ė θ̇` (the angles' rate map at zero moves with them),
/// both in the body frame, then the joints' `q̈`. This is what Pinocchio's `aba` returns
/// for a free flyer.
pub fn velocity_derivative<T: Real, const NQ: usize>(
    f: usize,
    v: &SVector<T, NQ>,
    qdd: &SVector<T, NQ>,
) -> SVector<T, NQ> {
    let lin = Vector3::new(v[f], v[f + 1], v[f + 2]);
    let w = Vector3::new(v[f + 3], v[f + 4], v[f + 5]);
    let coriolis = w.cross(&lin);
    // Ė at zero angles, times the rates (= ω there): (ω_y ω_z, −ω_x ω_z, ω_x ω_y).
    let turn = Vector3::new(w[1] * w[2], -w[0] * w[2], w[0] * w[1]);
    let mut out = *qdd;
    for k in 0..3 {
        out[f + k] -= coriolis[k];
        out[f + 3 + k] += turn[k];
    }
    out
}

/// Why the robot's dynamics failed: not a floating robot, or the dynamics' own reason.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RobotDynamicsError {
    /// See [`RobotError`].
    Robot(RobotError),
    /// See [`DynamicsError`].
    Dynamics(DynamicsError),
}

impl From<RobotError> for RobotDynamicsError {
    fn from(e: RobotError) -> Self {
        RobotDynamicsError::Robot(e)
    }
}

impl From<DynamicsError> for RobotDynamicsError {
    fn from(e: DynamicsError) -> Self {
        RobotDynamicsError::Dynamics(e)
    }
}

impl fmt::Display for RobotDynamicsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RobotDynamicsError::Robot(e) => write!(f, "{e}"),
            RobotDynamicsError::Dynamics(e) => write!(f, "dynamics: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for RobotDynamicsError {}

/// Why a robot's step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RobotStepError {
    /// See [`RobotError`].
    Robot(RobotError),
    /// See [`StepError`].
    Step(StepError),
    /// The step length is not positive and finite.
    TimeStep {
        /// The step asked for (s).
        dt: f64,
    },
}

impl From<RobotError> for RobotStepError {
    fn from(e: RobotError) -> Self {
        RobotStepError::Robot(e)
    }
}

impl From<StepError> for RobotStepError {
    fn from(e: StepError) -> Self {
        RobotStepError::Step(e)
    }
}

impl fmt::Display for RobotStepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RobotStepError::Robot(e) => write!(f, "{e}"),
            RobotStepError::Step(e) => write!(f, "{e}"),
            RobotStepError::TimeStep { dt } => {
                write!(f, "the time step {dt} s is not positive and finite")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for RobotStepError {}

/// Advances a floating robot from time `t` by one step of `opts` (any integrator,
/// projection onto the closures, Baumgarte terms), with motor torques from `source`.
/// The chart is centred on the body at the step's start and on where it went at the
/// end. The source sees the chart: at the step's start the free joint's coordinates are
/// zero and its rates `v`; with `ControlUpdate::PerStage` it is also asked at the later
/// stages, where they are the chart's `δ`, angles and their rates. The report's
/// acceleration is the chart's `q̈` at the start ([`velocity_derivative`] turns it into
/// `v̇`). On an error `state` is left as it was.
pub fn step<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &mut RobotState<T, NQ>,
    t: T,
    source: &mut impl TorqueSource<T, NQ, NU>,
    opts: &StepOptions<T>,
) -> Result<StepReport<T, NQ, NC, NU>, RobotStepError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut next = *state;
    next.recentre(f);
    let mut chart = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut chart, &next.orientation)?;
    let mut local = State {
        q: next.q,
        qd: next.v,
    };
    let report = simulate::step::<L, T, NQ, NC, NU>(&chart, &mut local, t, source, opts)?;
    next.q = local.q;
    next.v = local.qd;
    next.recentre(f);
    *state = next;
    Ok(report)
}

/// The robot's kinetic and potential energy in the world (J): the chart's kinetic
/// energy, and its potential plus the body's height's share, `−m g·p₀` (the total
/// weight `m g` read off the chart's generalized gravity on the translation, `G_δ =
/// −m R₀ᵀ g`).
pub fn energies<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &RobotState<T, NQ>,
) -> Result<(T, T), RobotError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut s = *state;
    s.recentre(f);
    let mut chart = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut chart, &s.orientation)?;
    let kinetic = L::kinetic_energy(&s.q, &s.v, &chart);
    let g = L::gravity_forces(&s.q, &chart);
    let weight_in_world = s
        .orientation
        .transform_vector(&Vector3::new(g[f], g[f + 1], g[f + 2]));
    let potential = L::potential_energy(&s.q, &chart) + weight_in_world.dot(&s.position);
    Ok((kinetic, potential))
}

/// The robot's momentum in the world: linear (kg m/s) and angular about the world's
/// origin (kg m²/s), the model's (a rotor's own spin, `I n q̇` about its axis, is not in
/// it: the model keeps only its reflected inertia on the joint, as the generated `M`
/// does). At the centre the chart's generalized momentum `M v` on the
/// translation is the linear momentum in the body frame, and on the angles (whose rates
/// are `ω` there) the angular momentum about the body's origin in the body frame.
pub fn momentum<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    state: &RobotState<T, NQ>,
) -> Result<(Vector3<T>, Vector3<T>), RobotError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut s = *state;
    s.recentre(f);
    let mut chart = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut chart, &s.orientation)?;
    let h = L::mass_matrix(&s.q, &chart) * s.v;
    let linear = s
        .orientation
        .transform_vector(&Vector3::new(h[f], h[f + 1], h[f + 2]));
    let about_body = s
        .orientation
        .transform_vector(&Vector3::new(h[f + 3], h[f + 4], h[f + 5]));
    Ok((linear, about_body + s.position.cross(&linear)))
}

/// The robot's centre of mass in the chart's base frame (m), read off the generated
/// potential energy `V = −Σ mᵢ g·cᵢ` under unit gravities along each axis (`V = −m c_k`
/// for gravity along `k`, less `V` without gravity: the springs' energy), the mass from
/// the mass matrix's translation block.
pub fn centre_of_mass<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
) -> Result<Vector3<T>, RobotError>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let f = free_joint::<L, NQ, NC, NU>()?;
    let idx = gravity_indices::<L, T, NQ, NC, NU>()?;
    let mass = L::mass_matrix(q, params)[(f, f)];
    let with = |k: Option<usize>| {
        let mut p = *params;
        let unit = |i: usize| if Some(i) == k { T::one() } else { T::zero() };
        p.set_many(&[(idx[0], unit(0)), (idx[1], unit(1)), (idx[2], unit(2))]);
        L::potential_energy(q, &p)
    };
    let springs = with(None);
    Ok(Vector3::new(
        springs - with(Some(0)),
        springs - with(Some(1)),
        springs - with(Some(2)),
    ) / mass)
}

/// Puts every contact point on one plane square to `up` (a unit vector in the chart's
/// base frame, the body's where the chart is centred on it): from `q`, moves the joints,
/// not the free joint's six coordinates, until the closures close and the contact
/// points' heights along `up` are equal, the robot's feet put flat for a stance. Damped
/// Gauss–Newton on the closure rows and the heights' differences from the first
/// contact's, the damping `|r|²` plus `1e-10` of the normal matrix's size, which keeps
/// the step least where the rows leave joints free (most of a robot's); backtracking as
/// the assembly's. Fails as [`crate::assembly::project_position`] does: `Unreachable`
/// with the residual left where the feet cannot be put flat from `q`; `NonFinite` for a
/// non-finite `q` or a zero or non-finite `up`; `Singular` on a fixed base.
pub fn feet_on_a_plane<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    q: &mut SVector<T, NQ>,
    up: &Vector3<T>,
    tol: &Tolerance<T>,
) -> Result<(), AssemblyError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    // A fixed base has no body to hold still: `Singular`, as for any request without a
    // determined answer.
    let f = free_joint::<L, NQ, NC, NU>().map_err(|_| AssemblyError::Singular)?;
    if !q.iter().chain(up.iter()).all(|x| x.is_finite()) || up.norm() == T::zero() {
        return Err(AssemblyError::NonFinite);
    }
    let up = &up.normalize();
    let contacts = NK / 3;
    if contacts < 2 {
        // One contact point, or none: on a plane already.
        return Ok(());
    }
    let body = |c: usize| c >= f && c < f + 6;
    // The heights' differences from the first contact's; the closures beside them.
    let rows = |q: &SVector<T, NQ>| {
        let x = L::contact_positions(q, params);
        let at = |k: usize| Vector3::new(x[3 * k], x[3 * k + 1], x[3 * k + 2]);
        let mut r = SVector::<T, NK>::zeros();
        for k in 1..contacts {
            r[k - 1] = up.dot(&(at(k) - at(0)));
        }
        r
    };
    let cost = |r: &(SVector<T, NC>, SVector<T, NK>)| r.0.norm_squared() + r.1.norm_squared();
    let residual = |q: &SVector<T, NQ>| (L::closure_residual(q, params), rows(q));
    let mut r = residual(q);
    let limit = tol.relative_residual * crate::assembly::leg_size::<L, T, NQ, NC, NU>(params, q);
    let done = |r: &(SVector<T, NC>, SVector<T, NK>)| r.0.amax() <= limit && r.1.amax() <= limit;
    for _ in 0..tol.max_iterations {
        if done(&r) {
            return Ok(());
        }
        let mut jc = L::constraint_jacobian(q, params);
        let xj = L::contact_jacobian(q, params);
        let mut jh = SMatrix::<T, NK, NQ>::zeros();
        for c in (0..NQ).filter(|&c| !body(c)) {
            let d = |k: usize| {
                up[0] * xj[(3 * k, c)] + up[1] * xj[(3 * k + 1, c)] + up[2] * xj[(3 * k + 2, c)]
            };
            for k in 1..contacts {
                jh[(k - 1, c)] = d(k) - d(0);
            }
        }
        for c in (0..NQ).filter(|&c| body(c)) {
            jc.column_mut(c).fill(T::zero());
        }
        let mut a = jc.transpose() * jc + jh.transpose() * jh;
        let size = (0..NQ).fold(T::zero(), |m, i| m.max(a[(i, i)]));
        let damping = cost(&r) + T::lit(1e-10) * size;
        for c in 0..NQ {
            if body(c) {
                a.row_mut(c).fill(T::zero());
                a.column_mut(c).fill(T::zero());
                a[(c, c)] = T::one();
            } else {
                a[(c, c)] += damping;
            }
        }
        let chol = Cholesky::new(&a).ok_or(AssemblyError::Singular)?;
        let mut step = jc.transpose() * r.0 + jh.transpose() * r.1;
        chol.solve_mut(&mut step);
        // Backtracking: the first of step, step/2, … that lowers the cost.
        let (mut alpha, c0) = (T::one(), cost(&r));
        let mut moved = false;
        for _ in 0..40 {
            let trial = *q - step * alpha;
            let rt = residual(&trial);
            if cost(&rt) < c0 {
                (*q, r) = (trial, rt);
                moved = true;
                break;
            }
            alpha *= T::lit(0.5);
        }
        if !moved {
            break;
        }
    }
    if done(&r) {
        Ok(())
    } else {
        Err(AssemblyError::Unreachable {
            residual: r.0.amax().max(r.1.amax()).to_subset().unwrap_or(f64::NAN),
        })
    }
}

/// The world's ground `n · x = d` seen from the chart centred on a body at `position`
/// turned by `orientation`: `n₀ = R₀ᵀ n`, `d₀ = d − n · p₀`.
pub fn ground_in_chart<T: Real>(
    ground: &Ground<T, 3>,
    position: &Vector3<T>,
    orientation: &UnitQuaternion<T>,
) -> Ground<T, 3> {
    Ground {
        normal: orientation.inverse_transform_vector(&ground.normal),
        offset: ground.offset - ground.normal.dot(position),
    }
}

/// The ground forces on the robot in the world, per contact a vector (stacked `x, y, z`),
/// from the solution's `(λ_t₁, λ_t₂, λ_n)` in the frame of the chart's ground
/// ([`Ground::frame`]).
pub fn forces_in_world<T: Real, const NK: usize>(
    chart_ground: &Ground<T, 3>,
    orientation: &UnitQuaternion<T>,
    lambda: &SVector<T, NK>,
) -> SVector<T, NK> {
    let frame = chart_ground.frame();
    let mut out = SVector::<T, NK>::zeros();
    for k in 0..NK / 3 {
        let local =
            frame.transpose() * Vector3::new(lambda[3 * k], lambda[3 * k + 1], lambda[3 * k + 2]);
        let world = orientation.transform_vector(&local);
        for i in 0..3 {
            out[3 * k + i] = world[i];
        }
    }
    out
}

/// What the robot's dynamics on the ground give at one state: the chart's solution and
/// the ground forces in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stance<T: Real, const NQ: usize, const NC: usize, const NK: usize> {
    /// `q̈` of the chart, closure forces, and ground forces in the chart ground's frame.
    pub solution: ContactSolution<T, NQ, NC, NK>,
    /// The ground force on each contact in the world (stacked `x, y, z`).
    pub world_forces: SVector<T, NK>,
}

/// The stance system factored in the chart, the ground seen from it, and the chart's
/// orientation.
pub(crate) type ChartStance<T, const NQ: usize, const NC: usize, const NK: usize> = (
    ContactSystem<T, NQ, NC, NK, 3>,
    Ground<T, 3>,
    UnitQuaternion<T>,
);

/// The stance system at a state: the chart centred on the body, gravity and the ground
/// turned into it, the contacts in `modes` held (sticking, or sliding with friction
/// `mu`), evaluated and factored once. Inlined, so that the system (~28 KB for Cassie)
/// is built where its caller keeps it rather than moved out through the `Result`s.
#[inline(always)]
pub(crate) fn stance_system<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>(
    params: &L::Params<T>,
    state: &RobotState<T, NQ>,
    modes: &Modes<NK, 3>,
    ground: &Ground<T, 3>,
    mu: &SVector<T, NK>,
) -> Result<ChartStance<T, NQ, NC, NK>, RobotDynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut s = *state;
    s.recentre(f);
    let mut chart = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut chart, &s.orientation)?;
    let local = ground_in_chart(ground, &s.position, &s.orientation);
    let system = ContactSystem::new::<L, NU>(
        &chart,
        &s.q,
        &s.v,
        modes,
        &SVector::zeros(),
        &local,
        mu,
        None,
    )?;
    Ok((system, local, s.orientation))
}

/// The robot's forward dynamics on the ground: the contacts in `modes` held (sticking or
/// sliding), the closures closed, motor torques `u`. The ground and its forces are the
/// world's.
pub fn stance_dynamics<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    state: &RobotState<T, NQ>,
    u: &SVector<T, NU>,
    modes: &Modes<NK, 3>,
    ground: &Ground<T, 3>,
    mu: &SVector<T, NK>,
) -> Result<Stance<T, NQ, NC, NK>, RobotDynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    let (system, local, orientation) =
        stance_system::<L, T, NQ, NC, NU, NK>(params, state, modes, ground, mu)?;
    let solution = system.solve(&actuation::<L, T, NQ, NC, NU>(u))?;
    Ok(Stance {
        world_forces: forces_in_world(&local, &orientation, &solution.contact),
        solution,
    })
}

/// Motor torques that hold the robot still where it stands (`q̈ = 0` with the contacts
/// in `modes` held), the least ones in the least-squares sense, and the largest `|q̈|`
/// they leave: zero to rounding where the motors can hold the pose, more where they
/// cannot (too few motors for what the contacts leave free). `q̈` is affine in `u`, so
/// its response to each motor comes from one factorization.
pub fn holding_torques<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    state: &RobotState<T, NQ>,
    modes: &Modes<NK, 3>,
    ground: &Ground<T, 3>,
    mu: &SVector<T, NK>,
) -> Result<(SVector<T, NU>, T), RobotDynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    let (system, _, _) = stance_system::<L, T, NQ, NC, NU, NK>(params, state, modes, ground, mu)?;
    let free = system.solve(&SVector::zeros())?.x;
    let mut response = SMatrix::<T, NQ, NU>::zeros();
    for i in 0..NU {
        let mut e = SVector::<T, NU>::zeros();
        e[i] = T::one();
        let x = system.solve(&actuation::<L, T, NQ, NC, NU>(&e))?.x;
        response.set_column(i, &(x - free));
    }
    // The least-squares torques, the least ones where several hold (the response has
    // the rank of what the contacts leave free, often less than NU): a ridge of 1e-10
    // of the normal matrix's size, then refinement, which removes the ridge's bias by a
    // factor of ridge / (σ² + ridge) a pass.
    let normal = response.transpose() * response;
    let size = (0..NU).fold(T::zero(), |a, i| a.max(normal[(i, i)]));
    if size <= T::zero() {
        // No motor moves anything the contacts leave free.
        return Ok((SVector::zeros(), free.amax()));
    }
    let ridge = T::lit(1e-10) * size;
    let chol = Cholesky::new(&(normal + SMatrix::<T, NU, NU>::identity() * ridge))
        .ok_or(RobotDynamicsError::Dynamics(DynamicsError::NonFinite))?;
    // Refined until a pass changes nothing (a motor that moves little, its σ² near the
    // ridge, takes many), 200 passes at most.
    let mut u = SVector::<T, NU>::zeros();
    for _ in 0..200 {
        let mut step = response.transpose() * (-(response * u + free));
        chol.solve_mut(&mut step);
        u += step;
        if step.amax() <= T::default_epsilon() * u.amax() {
            break;
        }
    }
    let left = (response * u + free).amax();
    Ok((u, left))
}

/// One step of the robot on the ground with the contacts in `modes` held, RK4 in the
/// chart centred at the step's start, the closures projected after it and the rates put
/// back on the closures and the held contacts ([`project_held_velocity`]; the contacts'
/// drift in position, of the integrator's order, is left: a stance that lasts long wants
/// Baumgarte terms, next). Torques `u` are held over the step. On an error `state` is left as it
/// was.
#[allow(clippy::too_many_arguments)]
pub fn stance_step<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    state: &mut RobotState<T, NQ>,
    u: &SVector<T, NU>,
    modes: &Modes<NK, 3>,
    ground: &Ground<T, 3>,
    mu: &SVector<T, NK>,
    dt: T,
) -> Result<Stance<T, NQ, NC, NK>, RobotStepError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    pushed_stance_step::<L, T, NQ, NC, NU, NK>(
        params,
        state,
        u,
        &Vector3::zeros(),
        modes,
        ground,
        mu,
        dt,
    )
}

/// [`stance_step`] with a force `push` (N, in the world) on the body frame's origin,
/// held over the step: a push, or any load carried at that point. In the chart centred
/// at the step's start the origin is `p₀ + R₀ δ`, so the push's generalized force is
/// `R₀ᵀ F` on `δ` and nothing on the angles, exactly, for the whole step.
#[allow(clippy::too_many_arguments)]
pub fn pushed_stance_step<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>(
    params: &L::Params<T>,
    state: &mut RobotState<T, NQ>,
    u: &SVector<T, NU>,
    push: &Vector3<T>,
    modes: &Modes<NK, 3>,
    ground: &Ground<T, 3>,
    mu: &SVector<T, NK>,
    dt: T,
) -> Result<Stance<T, NQ, NC, NK>, RobotStepError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    pushed_stance_step_by::<L, T, NQ, NC, NU, NK>(
        Method::Rk4,
        params,
        state,
        u,
        push,
        modes,
        ground,
        mu,
        dt,
    )
}

/// [`pushed_stance_step`] with the integrator `method`: [`Method::Rk4`] (four stance
/// solves a step) or [`Method::SemiImplicitEuler`] (one, as MuJoCo's default integrator
/// takes; first order). Semi-implicit Euler steps at the velocity level: the rates after
/// the step keep the closures and the held contacts at the step's start (`J v⁺ = 0`,
/// `C v⁺ = 0`), the forces are the step's impulses over `dt`, and `solution.x` is
/// `(v⁺ − v) / dt`; the closures are projected after it as after RK4, so they stay
/// exact. Only RK4's rates are projected onto the held rows after the step (its
/// acceleration-level solve needs them there). A `dt` that is not positive and finite is
/// refused ([`RobotStepError::TimeStep`]).
#[allow(clippy::too_many_arguments)]
pub fn pushed_stance_step_by<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>(
    method: Method,
    params: &L::Params<T>,
    state: &mut RobotState<T, NQ>,
    u: &SVector<T, NU>,
    push: &Vector3<T>,
    modes: &Modes<NK, 3>,
    ground: &Ground<T, 3>,
    mu: &SVector<T, NK>,
    dt: T,
) -> Result<Stance<T, NQ, NC, NK>, RobotStepError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    // Euler divides by it; neither integrator means anything with it.
    if !(dt.is_finite() && dt > T::zero()) {
        return Err(RobotStepError::TimeStep {
            dt: dt.to_subset().unwrap_or(f64::NAN),
        });
    }
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut next = *state;
    next.recentre(f);
    let mut chart = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut chart, &next.orientation)?;
    let local = ground_in_chart(ground, &next.position, &next.orientation);
    // The forces are in the chart of the step's start, turned by its centre.
    let centre = next.orientation;
    let mut applied = actuation::<L, T, NQ, NC, NU>(u);
    let on_body = centre.inverse_transform_vector(push);
    for k in 0..3 {
        applied[f + k] += on_body[k];
    }
    let first = match method {
        Method::Rk4 => {
            let accel = |q: &SVector<T, NQ>, qd: &SVector<T, NQ>| {
                ContactSystem::new::<L, NU>(
                    &chart,
                    q,
                    qd,
                    modes,
                    &SVector::zeros(),
                    &local,
                    mu,
                    None,
                )
                .and_then(|s| s.solve(&applied))
                .map_err(StepError::from)
            };
            let first = accel(&next.q, &next.v)?;
            let out = advance(method, dt, &next.q, &next.v, first.x, |_, q, qd| {
                accel(&q, &qd).map(|s| s.x)
            })?;
            next.q = out.q;
            next.v = out.qd;
            first
        }
        Method::SemiImplicitEuler => {
            // At the velocity level (Moreau's time stepping): the rates after the step
            // are held on the closures and the held rows at the step's start,
            // `J v⁺ = 0`, `C v⁺ = 0`, by the same solve with `−J v / dt`, `−C v / dt` on
            // its rows where the acceleration's takes `−J̇ v`, `−Ċ v`. Rows that repeat
            // each other (a rigid foot's toe and heel) then always agree, whatever the
            // rates, so the held rates need no projection after the step; each step's
            // solve puts them back on the rows where the pose moved them.
            // The system's parts built here rather than as a `ContactSystem` (the same
            // terms, factor and rows): moving that whole struct (M, its factor, the rows)
            // out of its constructor's `Result` cost a tenth of the step.
            let (q, v) = (&next.q, &next.v);
            let terms = L::dynamics_terms(q, v, &chart);
            let chol_m =
                factor_mass::<L, T, NQ, NC, NU>(&terms.mass_matrix).map_err(StepError::from)?;
            let c = local.rows(&L::contact_jacobian(q, &chart));
            let slip = slip_directions(&c, v, modes, None).map_err(StepError::from)?;
            let rows = ContactRows::from_rows(c, modes, mu, &slip);
            let per_dt = T::one() / dt;
            let r_j = -(terms.constraint_jacobian * v) * per_dt;
            let r_c = -(rows.c * v) * per_dt;
            let tau = applied - terms.bias_forces - L::damping_forces(v, &chart);
            let (x, closure, contact) = chol_m
                .solve_structured(
                    &terms.constraint_jacobian,
                    &r_j,
                    L::REDUNDANT_ROWS,
                    &rows,
                    &r_c,
                    &tau,
                )
                .map_err(StepError::from)?;
            next.v += x * dt;
            let start = next.q;
            next.q += next.v * dt;
            // The closures' Jacobian at the step's start serves the projection too.
            project_position_near::<L, T, NQ, NC, NU>(
                &chart,
                &mut next.q,
                &start,
                &terms.constraint_jacobian,
                &Tolerance::default(),
            )
            .map_err(StepError::from)?;
            ContactSolution {
                x,
                closure,
                contact,
            }
        }
    };
    if method == Method::Rk4 {
        if NC > 0 {
            project_position::<L, T, NQ, NC, NU>(&chart, &mut next.q, &Tolerance::default())
                .map_err(StepError::from)?;
        }
        // The rates back on the closures and the held contacts: the step's drift off
        // them would make the held rows of one rigid foot contradict each other next
        // step.
        project_held_velocity::<L, T, NQ, NC, NU, NK, 3>(
            &chart,
            &next.q,
            &mut next.v,
            modes,
            &local,
        )
        .map_err(StepError::from)?;
    }
    next.recentre(f);
    let stance = Stance {
        world_forces: forces_in_world(&local, &centre, &first.contact),
        solution: first,
    };
    *state = next;
    Ok(stance)
}

/// The robot's rates put back on its closures and on the contacts `modes` holds, in the
/// metric of `M` (the least kinetic energy taken away; [`project_held_velocity`] in the
/// chart centred on the body): what a stance controller that plans every foot held
/// should see of a robot whose feet are free ([`time_stepping`]), where a foot that
/// slides or turns would make a rigid foot's held rows contradict each other. On an
/// error `state` is left as it was.
pub fn project_held_rates<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>(
    params: &L::Params<T>,
    state: &mut RobotState<T, NQ>,
    modes: &Modes<NK, 3>,
    ground: &Ground<T, 3>,
) -> Result<(), RobotDynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut next = *state;
    next.recentre(f);
    let mut chart = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut chart, &next.orientation)?;
    let local = ground_in_chart(ground, &next.position, &next.orientation);
    project_held_velocity::<L, T, NQ, NC, NU, NK, 3>(&chart, &next.q, &mut next.v, modes, &local)?;
    *state = next;
    Ok(())
}

/// A plastic impact of the robot on the world's ground: the contacts in `modes` (those
/// touching) held after it, every closure kept, a sticking impulse outside the cone
/// resolved as sliding (and its mode changed), by [`impact_map`] in the chart centred on
/// the body. The state's velocities jump in place (the pose does not move); the impulses
/// are returned in the chart ground's frame with the energy lost, and in the world (per
/// contact a vector) beside them. On an error `state` and `modes` are left as they were.
pub fn impact<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    state: &mut RobotState<T, NQ>,
    modes: &mut Modes<NK, 3>,
    ground: &Ground<T, 3>,
    mu: &SVector<T, NK>,
) -> Result<(Impact<T, NQ, NC, NK>, SVector<T, NK>), RobotImpactError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
    T: Real,
{
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut next = *state;
    next.recentre(f);
    let mut chart = *params;
    into_chart::<L, T, NQ, NC, NU>(&mut chart, &next.orientation)?;
    let local = ground_in_chart(ground, &next.position, &next.orientation);
    // `modes` changes (a sticking contact resolved as sliding) only if the impact does.
    let mut resolved = *modes;
    let out =
        impact_map::<L, T, NQ, NC, NU, NK, 3>(&chart, &next.q, &next.v, &mut resolved, &local, mu)?;
    *modes = resolved;
    next.v = out.qd_plus;
    let world = forces_in_world(&local, &next.orientation, &out.impulses);
    *state = next;
    Ok((out, world))
}

/// Why a robot's impact failed: not a floating robot, or the impact's own reason.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RobotImpactError {
    /// See [`RobotError`].
    Robot(RobotError),
    /// See [`ImpactError`].
    Impact(ImpactError),
}

impl From<RobotError> for RobotImpactError {
    fn from(e: RobotError) -> Self {
        RobotImpactError::Robot(e)
    }
}

impl From<ImpactError> for RobotImpactError {
    fn from(e: ImpactError) -> Self {
        RobotImpactError::Impact(e)
    }
}

impl fmt::Display for RobotImpactError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RobotImpactError::Robot(e) => write!(f, "{e}"),
            RobotImpactError::Impact(e) => write!(f, "{e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for RobotImpactError {}
