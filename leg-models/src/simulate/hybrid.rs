//! Hybrid simulation of a leg on the ground (DESIGN.md §3.1): contact modes (flight,
//! sticking, sliding), events located inside the step by root finding, the plastic impact
//! map at touchdown, friction-cone switching, and projection onto every active constraint
//! after each step. A step allocates nothing; [`HybridSimulator::run`] (with `std`)
//! records samples and events in vectors reserved before the first step.
//!
//! Planar legs (`ND = 2`) and spatial ones (`ND = 3`) step alike: contact `k` owns rows
//! `ND k …` (its tangential rows, then its normal row), and the friction cone is exact,
//! `|λ_t| ≤ μ λ_n` with the Euclidean norm. Each contact has guards that are
//! non-negative while its mode is valid, on its first tangential row and its normal row:
//!
//! | mode  | first tangential row `ND k`       | normal row `ND k + ND − 1` |
//! |-------|-----------------------------------|----------------------------|
//! | flight| —                                 | gap `n·x_c − d + δ`        |
//! | stick | `μ λ_n − |λ_t|`                   | `λ_n`                      |
//! | slide | slip speed along `ŝ`, `ŝ · v_t`   | `λ_n`                      |
//!
//! `ŝ` is the slip direction at the start of the step ([`HybridState::slip`]): `±1` on a
//! planar leg, a unit vector along the ground on a spatial one, where friction opposes
//! the slip velocity itself (its direction turns while it slides) and the slide ends when
//! that velocity turns back against the direction it had. A spatial contact that starts
//! to slip from rest slips in the direction its acceleration then takes, found by
//! iteration ([`HybridSimulator::slip_from_rest`]).
//!
//! `δ` is the projection's tolerance ([`Tolerance::relative_residual`] of the leg's size):
//! a held contact sits on the ground only to within it, so a contact that has just lifted
//! off may start its flight up to `δ` under the ground, and it is under the ground only
//! below that. (With the gap itself as the guard, such a contact leaving at rest — the
//! normal force vanishing, the gap growing as the cube of the time — did not clear the
//! ground before the end of a step that had little left after the liftoff: every step's
//! end then found a "crossing" at its start, and touchdowns and liftoffs a picosecond apart
//! filled the step. The shorter the step, the more often a liftoff fell that close to
//! its end.)
//!
//! A step integrates (RK4, torques held) in the current modes; if a guard ends negative,
//! the earliest crossing is found by the Illinois method on the step length (to
//! [`HybridOptions::time_tolerance`]), the state advanced there, the event handled
//! (touchdown: impact and stick; liftoff: flight; slip: slide; a slide that stops:
//! stick), the modes made consistent, and the rest of the step taken the same way.

use core::fmt;
use core::marker::PhantomData;

use nalgebra::{SMatrix, SVector};

use crate::assembly::{leg_size, AssemblyError, Tolerance};
use crate::dynamics::contact::{
    consistent_slip, impact_map, set_unit, solve_structured, spec_friction, tangential_norm,
    ContactMode, ContactRows, ContactSolution, ContactSystem, Ground, ImpactError, Modes,
};
use crate::dynamics::forward::{actuation, Baumgarte, DynamicsError};
use crate::model::contract::{ContactModel, Real};
use crate::model::linalg::{mul, Cholesky};
use crate::simulate::source::ControlError;
use crate::simulate::source::{ControlUpdate, State};

/// A leg's state with its contacts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HybridState<T: Real, const NQ: usize, const NK: usize, const ND: usize = 2> {
    /// The joint state `(q, q̇)`.
    pub state: State<T, NQ>,
    /// Each contact's mode.
    pub modes: Modes<NK, ND>,
    /// Ground coordinates the held rows keep: a sticking contact's tangential position at
    /// touchdown (its tangential entries) and the ground (its normal entry, always 0).
    pub anchors: SVector<T, NK>,
    /// The slip direction of each sliding contact of a spatial leg at the start of the
    /// current step (unit, on its tangential rows; zero elsewhere and on a planar leg,
    /// whose direction is its mode's): the direction a slide from rest takes, and the
    /// one its slide guard measures the slip speed along.
    pub slip: SVector<T, NK>,
}

impl<T: Real, const NQ: usize, const NK: usize, const ND: usize> HybridState<T, NQ, NK, ND> {
    /// Every contact in flight.
    pub fn flight(state: State<T, NQ>) -> Self {
        HybridState {
            state,
            modes: Modes::flight(),
            anchors: SVector::zeros(),
            slip: SVector::zeros(),
        }
    }
}

/// What happened to a contact.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EventKind {
    /// The contact reached the ground (an impact, unless it was resting).
    Touchdown,
    /// The normal force reached zero: the contact leaves the ground.
    Liftoff,
    /// The friction force reached the cone: sticking becomes sliding.
    Slip,
    /// The slip speed reached zero: sliding becomes sticking.
    Stick,
}

/// One located event.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Event<T: Real> {
    /// When it happened (s).
    pub t: T,
    /// What happened.
    pub kind: EventKind,
    /// The contact's index (in [`ContactModel::CONTACT_NAMES`]).
    pub contact: usize,
    /// The ground's impulse on the leg at a touchdown `(Λ_t, Λ_n)` [N s]; zero otherwise.
    /// `Λ_t` is signed along the ground's tangent on a planar leg, the tangential
    /// impulse's magnitude on a spatial one.
    pub impulse: [T; 2],
    /// Kinetic energy the impact took (J); zero for other events.
    pub energy_lost: T,
}

impl<T: Real> Event<T> {
    /// A change of mode without an impulse (liftoff, slip, stick).
    fn switch(t: T, kind: EventKind, contact: usize) -> Self {
        Event {
            t,
            kind,
            contact,
            impulse: [T::zero(); 2],
            energy_lost: T::zero(),
        }
    }
}

/// The most events one step may hold; more means the contacts chatter (a Zeno
/// sequence), reported as [`HybridError::TooManyEvents`].
pub const MAX_EVENTS_PER_STEP: usize = 8;

/// The events of one step, in time order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepEvents<T: Real> {
    events: [Option<Event<T>>; MAX_EVENTS_PER_STEP],
    count: usize,
}

impl<T: Real> StepEvents<T> {
    fn new() -> Self {
        StepEvents {
            events: [None; MAX_EVENTS_PER_STEP],
            count: 0,
        }
    }

    fn push(&mut self, e: Event<T>, t: T) -> Result<(), HybridError> {
        if self.count == MAX_EVENTS_PER_STEP {
            return Err(HybridError::TooManyEvents { t: to_f64(t) });
        }
        self.events[self.count] = Some(e);
        self.count += 1;
        Ok(())
    }

    /// The events, in time order.
    pub fn iter(&self) -> impl Iterator<Item = &Event<T>> {
        self.events[..self.count].iter().flatten()
    }

    /// How many events the step held.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether the step held no event.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

/// Why a hybrid step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HybridError {
    /// The constrained dynamics in the current modes cannot be solved (the mass matrix
    /// is not positive definite, the closures or held contacts are singular, or a value
    /// is not finite).
    Dynamics(DynamicsError),
    /// The impact map at a touchdown failed.
    Impact(ImpactError),
    /// Projecting the state onto the closures and held contacts failed.
    Projection(AssemblyError),
    /// The torque source could not act.
    Control(ControlError),
    /// More than [`MAX_EVENTS_PER_STEP`] events in one step at time `t`.
    TooManyEvents {
        /// The time of the event that would have been one too many (s).
        t: f64,
    },
    /// The record a run would keep is larger than its budget: refused before the first
    /// step.
    RecordTooLarge(crate::simulate::step::RecordTooLarge),
    /// The start has contact `contact` under the ground by `depth` (m), more than
    /// [`ON_CLOSURES`](crate::assembly::ON_CLOSURES) of the leg's size: it was moved up
    /// onto the ground without a word; a start must be on or above the ground.
    StartsUnderGround {
        /// The contact's name.
        contact: &'static str,
        /// How far under (m, positive).
        depth: f64,
    },
}

impl fmt::Display for HybridError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            HybridError::Dynamics(e) => write!(f, "dynamics: {e}"),
            HybridError::Impact(e) => write!(f, "{e}"),
            HybridError::Projection(e) => write!(f, "projection onto the constraints: {e}"),
            HybridError::Control(e) => write!(f, "control: {e}"),
            HybridError::TooManyEvents { t } => write!(
                f,
                "more than {MAX_EVENTS_PER_STEP} contact events in the step at t = {t} s (the contacts chatter)"
            ),
            HybridError::RecordTooLarge(e) => write!(f, "{e}"),
            HybridError::StartsUnderGround { contact, depth } => write!(
                f,
                "the start has contact `{contact}` {depth:.3e} m under the ground: start on or above it (raise the body or fold the leg)"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for HybridError {}

impl From<DynamicsError> for HybridError {
    fn from(e: DynamicsError) -> Self {
        HybridError::Dynamics(e)
    }
}
impl From<ImpactError> for HybridError {
    fn from(e: ImpactError) -> Self {
        HybridError::Impact(e)
    }
}
impl From<AssemblyError> for HybridError {
    fn from(e: AssemblyError) -> Self {
        HybridError::Projection(e)
    }
}
impl From<ControlError> for HybridError {
    fn from(e: ControlError) -> Self {
        HybridError::Control(e)
    }
}

fn to_f64<T: Real>(x: T) -> f64 {
    x.to_subset().unwrap_or(f64::NAN)
}

/// Motor torques from the time and the hybrid state (the contact modes included): a
/// hopping controller, or any closure `FnMut(t, &HybridState) -> u`.
pub trait HybridTorqueSource<
    T: Real,
    const NQ: usize,
    const NK: usize,
    const NU: usize,
    const ND: usize = 2,
>
{
    /// The motor torques `u` at time `t` (s) and hybrid state `state`, or why there are none.
    fn torque(
        &mut self,
        t: T,
        state: &HybridState<T, NQ, NK, ND>,
    ) -> Result<SVector<T, NU>, ControlError>;
}

impl<T: Real, const NQ: usize, const NK: usize, const NU: usize, const ND: usize, F>
    HybridTorqueSource<T, NQ, NK, NU, ND> for F
where
    F: FnMut(T, &HybridState<T, NQ, NK, ND>) -> SVector<T, NU>,
{
    fn torque(
        &mut self,
        t: T,
        state: &HybridState<T, NQ, NK, ND>,
    ) -> Result<SVector<T, NU>, ControlError> {
        Ok(self(t, state))
    }
}

/// How to step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HybridOptions<T: Real, const NK: usize, const ND: usize = 2> {
    /// The step (s).
    pub dt: T,
    /// The ground the contacts meet.
    pub ground: Ground<T, ND>,
    /// Coulomb μ per row (every row of contact `k` holds its value).
    pub friction: SVector<T, NK>,
    /// Baumgarte terms on closures and held contacts (`None`: projection only).
    pub baumgarte: Option<Baumgarte<T>>,
    /// For the position projection.
    pub tolerance: Tolerance<T>,
    /// How closely an event's time is located (s).
    pub time_tolerance: T,
    /// Torques held over each step (and re-asked after each event), or asked at every
    /// integrator stage and guard evaluation (a continuous-time law).
    pub control: ControlUpdate,
    /// Settle the contacts' modes after an impact under torques asked right after it
    /// (`true`), or under those the step started with (`false`, the default). With the
    /// step's, a controller that brakes the fall pulls the landed contact off again at the
    /// impact's instant (a liftoff, then a second, tiny touchdown); asked after, it
    /// answers the impact. The hopping controller is tuned with the step's: its stance
    /// law asked at a landing's instant drove `atrias_hopper` to diverge.
    pub ask_after_impact: bool,
}

/// Steps leg `L` on the ground.
#[derive(Clone, Copy, Debug)]
pub struct HybridSimulator<
    L,
    T: Real,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize = 2,
> where
    L: ContactModel<NQ, NC, NU, NK, ND>,
{
    /// The leg's parameters.
    pub params: L::Params<T>,
    /// How to step.
    pub options: HybridOptions<T, NK, ND>,
    model: PhantomData<L>,
}

impl<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize, const ND: usize>
    HybridSimulator<L, T, NQ, NC, NU, NK, ND>
where
    L: ContactModel<NQ, NC, NU, NK, ND>,
    T: Real,
{
    /// The spec's ground and friction, RK4 steps of `dt`, events to 1e-12 s (`f64`).
    pub fn new(params: L::Params<T>, dt: T) -> Self {
        HybridSimulator {
            params,
            options: HybridOptions {
                dt,
                ground: Ground::of::<L, NQ, NC, NU, NK>(),
                friction: spec_friction::<L, T, NQ, NC, NU, NK, ND>(),
                baumgarte: None,
                tolerance: Tolerance::default(),
                time_tolerance: T::lit(1e-12).max(T::default_epsilon() * T::lit(10.0)),
                control: ControlUpdate::PerStep,
                ask_after_impact: false,
            },
            model: PhantomData,
        }
    }

    /// Constrained accelerations and forces in the state's modes.
    /// A spatial contact sliding from rest slides along [`HybridState::slip`].
    pub fn dynamics(
        &self,
        hs: &HybridState<T, NQ, NK, ND>,
        u: &SVector<T, NU>,
    ) -> Result<ContactSolution<T, NQ, NC, NK>, DynamicsError> {
        ContactSystem::with_slip::<L, NU>(
            &self.params,
            &hs.state.q,
            &hs.state.qd,
            &hs.modes,
            &hs.anchors,
            &self.options.ground,
            &self.options.friction,
            self.options.baumgarte,
            Some(&hs.slip),
        )?
        .solve(&actuation::<L, T, NQ, NC, NU>(u))
    }

    /// Contact positions and velocities in ground coordinates `(t, [t₂,] n − d)`.
    pub fn contact_coordinates(&self, state: &State<T, NQ>) -> (SVector<T, NK>, SVector<T, NK>) {
        let g = &self.options.ground;
        let x = g.coordinates(&L::contact_positions(&state.q, &self.params));
        let v = g.rows(&(L::contact_jacobian(&state.q, &self.params) * state.qd));
        (x, v)
    }

    /// The torques at time `t` and state `hs` for a step that started with `u0`.
    fn torque_at(
        &self,
        source: &mut impl HybridTorqueSource<T, NQ, NK, NU, ND>,
        t: T,
        hs: &HybridState<T, NQ, NK, ND>,
        u0: &SVector<T, NU>,
    ) -> Result<SVector<T, NU>, HybridError> {
        match self.options.control {
            ControlUpdate::PerStep => Ok(*u0),
            ControlUpdate::PerStage => Ok(source.torque(t, hs)?),
        }
    }

    /// One RK4 step of length `h` from time `t0` in fixed modes.
    fn rk4(
        &self,
        hs: &HybridState<T, NQ, NK, ND>,
        source: &mut impl HybridTorqueSource<T, NQ, NK, NU, ND>,
        t0: T,
        u0: &SVector<T, NU>,
        h: T,
    ) -> Result<State<T, NQ>, HybridError> {
        let mut f = |tau: T,
                     q: SVector<T, NQ>,
                     qd: SVector<T, NQ>|
         -> Result<SVector<T, NQ>, HybridError> {
            let s = HybridState {
                state: State { q, qd },
                ..*hs
            };
            let u = self.torque_at(source, t0 + tau, &s, u0)?;
            Ok(self.dynamics(&s, &u)?.x)
        };
        let (q, qd) = (hs.state.q, hs.state.qd);
        let half = h * T::lit(0.5);
        let (k1q, k1v) = (qd, f(T::zero(), q, qd)?);
        let (k2q, k2v) = (qd + k1v * half, f(half, q + k1q * half, qd + k1v * half)?);
        let (k3q, k3v) = (qd + k2v * half, f(half, q + k2q * half, qd + k2v * half)?);
        let (k4q, k4v) = (qd + k3v * h, f(h, q + k3q * h, qd + k3v * h)?);
        let sixth = h / T::lit(6.0);
        Ok(State {
            q: q + (k1q + (k2q + k3q) * T::lit(2.0) + k4q) * sixth,
            qd: qd + (k1v + (k2v + k3v) * T::lit(2.0) + k4v) * sixth,
        })
    }

    /// Forces below this are rounding [N]: `√ε` of the leg's weight and motor torques,
    /// as generalized forces over the leg's size. It keeps the friction cone from
    /// reporting a slip where both forces vanish together (just before a liftoff).
    fn force_floor(&self, q: &SVector<T, NQ>, u: &SVector<T, NU>) -> T {
        let size = leg_size::<L, T, NQ, NC, NU>(&self.params, q);
        let scale = (L::gravity_forces(q, &self.params).amax() + u.amax()) / size;
        T::default_epsilon().sqrt() * scale
    }

    /// The guards of every row (see the module docs); `+∞` where a row has none.
    pub fn guards(
        &self,
        hs: &HybridState<T, NQ, NK, ND>,
        u: &SVector<T, NU>,
    ) -> Result<SVector<T, NK>, DynamicsError> {
        let mut g = SVector::<T, NK>::from_element(T::max_value().unwrap_or(T::one()));
        let any_ground = (0..NK / ND).any(|k| hs.modes.get(k).on_ground());
        let forces = if any_ground {
            self.dynamics(hs, u)?.contact
        } else {
            SVector::zeros()
        };
        let (x, v) = self.contact_coordinates(&hs.state);
        let floor = self.force_floor(&hs.state.q, u);
        // Within the projection's tolerance of the ground is on it (see the module docs).
        let band = self.options.tolerance.relative_residual
            * leg_size::<L, T, NQ, NC, NU>(&self.params, &hs.state.q);
        for k in 0..NK / ND {
            let (t, n) = (ND * k, ND * k + ND - 1);
            match hs.modes.get(k) {
                ContactMode::Flight => g[n] = x[n] + band,
                ContactMode::Stick => {
                    g[n] = forces[n];
                    g[t] = self.options.friction[t] * forces[n] + floor
                        - tangential_norm::<T, NK, ND>(&forces, k);
                }
                ContactMode::Slide { forward } => {
                    g[n] = forces[n];
                    g[t] = self.slip_speed(hs, &v, k, forward);
                }
            }
        }
        Ok(g)
    }

    /// The slip speed of sliding contact `k` along the direction of its slide: `±v_t` on a
    /// planar leg, `ŝ · v_t` with `ŝ` the state's [`HybridState::slip`] on a spatial one.
    fn slip_speed(
        &self,
        hs: &HybridState<T, NQ, NK, ND>,
        v: &SVector<T, NK>,
        k: usize,
        forward: bool,
    ) -> T {
        if ND == 2 {
            return if forward { v[ND * k] } else { -v[ND * k] };
        }
        (ND * k..ND * k + ND - 1).fold(T::zero(), |a, r| a + hs.slip[r] * v[r])
    }

    /// Moves `q` onto every active constraint (closures, held contacts at their anchors)
    /// by the smallest correction, and `q̇` onto their velocity constraints in the metric
    /// of `M`.
    pub fn project(&self, hs: &mut HybridState<T, NQ, NK, ND>) -> Result<(), HybridError> {
        let p = &self.params;
        let g = &self.options.ground;
        let identity = Cholesky::new(&SMatrix::<T, NQ, NQ>::identity())
            .ok_or(DynamicsError::MassMatrixNotPositiveDefinite)?;
        let held = hs.modes.held_rows();
        if NC == 0 && !held.iter().any(|&h| h) {
            return Ok(()); // nothing to project onto
        }
        let tol = &self.options.tolerance;
        let residuals = |q: &SVector<T, NQ>| {
            let phi = L::closure_residual(q, p);
            let mut rc = g.coordinates(&L::contact_positions(q, p)) - hs.anchors;
            for (r, &h) in held.iter().enumerate() {
                if !h {
                    rc[r] = T::zero();
                }
            }
            (phi, rc)
        };
        // Corrections along the rows themselves (W = C), none sliding.
        let rows_at = |q: &SVector<T, NQ>| {
            let rows = ContactRows::new(
                g,
                &L::contact_jacobian(q, p),
                &hs.modes,
                &self.options.friction,
                &SVector::zeros(),
            );
            ContactRows {
                w: rows.c,
                slide: SVector::zeros(),
                ..rows
            }
        };
        let mut q = hs.state.q;
        let mut converged = false;
        let mut worst = T::zero();
        for _ in 0..tol.max_iterations {
            let (phi, rc) = residuals(&q);
            let limit = tol.relative_residual * leg_size::<L, T, NQ, NC, NU>(p, &q);
            worst = phi.amax().max(rc.amax());
            if !(worst.is_finite() && limit.is_finite()) {
                return Err(AssemblyError::NonFinite.into());
            }
            if worst <= limit {
                converged = true;
                break;
            }
            let sol = solve_structured(
                &identity,
                &L::constraint_jacobian(&q, p),
                &-phi,
                L::REDUNDANT_ROWS,
                &rows_at(&q),
                &-rc,
                &SVector::zeros(),
            )
            .map_err(|_| AssemblyError::Singular)?;
            q += sol.x;
        }
        if !converged {
            return Err(AssemblyError::Unreachable {
                residual: to_f64(worst),
            }
            .into());
        }
        hs.state.q = q;
        let m = L::mass_matrix(&q, p);
        let chol_m = Cholesky::new(&m).ok_or(DynamicsError::MassMatrixNotPositiveDefinite)?;
        let sol = solve_structured(
            &chol_m,
            &L::constraint_jacobian(&q, p),
            &SVector::zeros(),
            L::REDUNDANT_ROWS,
            &rows_at(&q),
            &SVector::zeros(),
            &mul(&m, &hs.state.qd),
        )?;
        hs.state.qd = sol.x;
        Ok(())
    }

    /// Holds contact `k` where it is now: its tangential anchors at its position, its
    /// normal one on the ground.
    fn anchor(&self, hs: &mut HybridState<T, NQ, NK, ND>, k: usize) {
        let (x, _) = self.contact_coordinates(&hs.state);
        for r in ND * k..ND * k + ND - 1 {
            hs.anchors[r] = x[r];
        }
        hs.anchors[ND * k + ND - 1] = T::zero();
    }

    /// Touchdown of contact `k` at the current state: stick there, with the plastic impact
    /// of every held row; a contact that would pull stays (or goes) in flight.
    fn touchdown(
        &self,
        hs: &mut HybridState<T, NQ, NK, ND>,
        k: usize,
        t: T,
        events: &mut StepEvents<T>,
    ) -> Result<(), HybridError> {
        hs.modes.set(k, ContactMode::Stick);
        self.anchor(hs, k);
        for _ in 0..=NK / ND {
            let mut modes = hs.modes;
            match impact_map::<L, T, NQ, NC, NU, NK, ND>(
                &self.params,
                &hs.state.q,
                &hs.state.qd,
                &mut modes,
                &self.options.ground,
                &self.options.friction,
            ) {
                Ok(imp) => {
                    hs.modes = modes;
                    hs.state.qd = imp.qd_plus;
                    if ND > 2 {
                        hs.slip = imp.slip;
                    }
                    let tangential = if ND == 2 {
                        imp.impulses[ND * k]
                    } else {
                        tangential_norm::<T, NK, ND>(&imp.impulses, k)
                    };
                    return events.push(
                        Event {
                            t,
                            kind: EventKind::Touchdown,
                            contact: k,
                            impulse: [tangential, imp.impulses[ND * k + ND - 1]],
                            energy_lost: imp.energy_lost,
                        },
                        t,
                    );
                }
                Err(ImpactError::Pulling { contact, .. }) => {
                    hs.modes.set(contact, ContactMode::Flight);
                    if contact == k {
                        // Grazing: nothing to stop, the contact stays in the air.
                        return Ok(());
                    }
                }
                Err(e) => return Err(e.into()),
            }
        }
        Ok(())
    }

    /// The direction in which sliding contact `k` of a spatial leg, at rest along the
    /// ground, starts to slip under `u`: the unit `ŝ` for which the tangential
    /// acceleration it gets sliding along `ŝ` (friction `μ λ_n` against it) points along
    /// `ŝ` (`consistent_slip`: a few fixed-point rounds from `start`, the sticking force's
    /// opposite, then a scan of the circle refined by bisection). Returns the state's
    /// slip directions with contact `k`'s set, and whether that slide is consistent (the
    /// acceleration along `ŝ`, the normal force pushing).
    pub fn slip_from_rest(
        &self,
        hs: &HybridState<T, NQ, NK, ND>,
        k: usize,
        u: &SVector<T, NU>,
        start: &SVector<T, NK>,
    ) -> Result<(SVector<T, NK>, bool), HybridError> {
        let (t0, t1) = (ND * k, ND * k + 1);
        let mut trial = *hs;
        trial.modes.set(k, ContactMode::Slide { forward: true });
        set_unit(&mut trial.slip, start, t0..t0 + ND - 1);
        let along = |d: [T; 2]| {
            let mut s = trial;
            (s.slip[t0], s.slip[t1]) = (d[0], d[1]);
            s
        };
        let (found, consistent) = consistent_slip([trial.slip[t0], trial.slip[t1]], |d| {
            let s = along(d);
            let a = self.contact_acceleration(&s, &self.dynamics(&s, u)?.x);
            Ok::<_, HybridError>([a[t0], a[t1]])
        })?;
        let s = along(found);
        let pushes = self.dynamics(&s, u)?.contact[ND * k + ND - 1] >= T::zero();
        Ok((s.slip, consistent && pushes))
    }

    /// The contacts' accelerations in ground coordinates, `R (J_c q̈ + J̇_c q̇)`.
    fn contact_acceleration(
        &self,
        hs: &HybridState<T, NQ, NK, ND>,
        qdd: &SVector<T, NQ>,
    ) -> SVector<T, NK> {
        let (q, qd) = (&hs.state.q, &hs.state.qd);
        self.options.ground.rows(
            &(L::contact_jacobian(q, &self.params) * qdd + L::contact_bias(q, qd, &self.params)),
        )
    }

    /// Makes the modes consistent with the forces at the current state: a held contact
    /// that pulls lifts off, one outside the cone slides, a slide that has stopped sticks.
    fn settle(
        &self,
        hs: &mut HybridState<T, NQ, NK, ND>,
        u: &SVector<T, NU>,
        t: T,
        events: &mut StepEvents<T>,
    ) -> Result<(), HybridError> {
        for _ in 0..NK + 2 {
            let forces = self.dynamics(hs, u)?.contact;
            let (_, v) = self.contact_coordinates(&hs.state);
            let floor = self.force_floor(&hs.state.q, u);
            // A contact speed below rounding (as in `step`).
            let still = self.options.tolerance.relative_residual
                * leg_size::<L, T, NQ, NC, NU>(&self.params, &hs.state.q)
                / self.options.dt;
            let mut change = None;
            for k in 0..NK / ND {
                let (ti, ni) = (ND * k, ND * k + ND - 1);
                let mu = self.options.friction[ti];
                match hs.modes.get(k) {
                    ContactMode::Flight => {}
                    mode @ ContactMode::Slide { .. } if forces[ni] < T::zero() => {
                        // A slide that would pull: at rest along the ground (it just
                        // started), the mode consistent with the forces and motions
                        // (Painlevé: Coulomb sliding may pull where sticking pushes
                        // out of the cone and flight would sink); else it lifts off.
                        let next = if tangential_norm::<T, NK, ND>(&v, k) <= still {
                            // Another mode, or on a spatial leg the same slide in
                            // another direction.
                            let other = |m: &(ContactMode, SVector<T, NK>)| {
                                m.0 != mode
                                    || (ND > 2
                                        && (ti..ni).any(|r| {
                                            (m.1[r] - hs.slip[r]).abs()
                                                > T::default_epsilon().sqrt()
                                        }))
                            };
                            self.consistent_mode(hs, k, u, floor)?
                                .filter(other)
                                .unwrap_or((ContactMode::Flight, hs.slip))
                        } else {
                            (ContactMode::Flight, hs.slip)
                        };
                        change = Some((k, next, kind_of(next.0)));
                    }
                    _ if forces[ni] < T::zero() => {
                        change = Some((k, (ContactMode::Flight, hs.slip), EventKind::Liftoff))
                    }
                    ContactMode::Stick
                        if tangential_norm::<T, NK, ND>(&forces, k) > mu * forces[ni] + floor =>
                    {
                        // It slips: the way the unheld demand pushes it, if that slide
                        // is consistent, else the other way (or off the ground).
                        let slide = self.slide_against(hs, &forces, k);
                        let next = match self.consistent_mode(hs, k, u, floor)? {
                            Some(m) if m.0 != ContactMode::Stick => m,
                            _ => slide,
                        };
                        change = Some((k, next, kind_of(next.0)));
                    }
                    ContactMode::Slide { forward } => {
                        if self.slip_speed(hs, &v, k, forward) <= T::zero() {
                            // Stopped: it sticks if the cone can hold it there, else it
                            // slides the way the unheld friction demand pushes it.
                            let mut held = *hs;
                            held.modes.set(k, ContactMode::Stick);
                            self.anchor(&mut held, k);
                            let f = self.dynamics(&held, u)?.contact;
                            if tangential_norm::<T, NK, ND>(&f, k) <= mu * f[ni] + floor {
                                *hs = HybridState {
                                    modes: hs.modes,
                                    ..held
                                };
                                change = Some((k, (ContactMode::Stick, hs.slip), EventKind::Stick));
                            } else if ND == 2 {
                                if (f[ti] < T::zero()) != forward {
                                    let slide = self.slide_against(hs, &f, k);
                                    change = Some((k, slide, EventKind::Slip));
                                }
                            } else {
                                let (slip, _) = self.slip_from_rest(hs, k, u, &-f)?;
                                let turn = (ti..ni)
                                    .fold(T::zero(), |m, r| m.max((slip[r] - hs.slip[r]).abs()));
                                if turn > T::default_epsilon().sqrt() {
                                    change = Some((k, (hs.modes.get(k), slip), EventKind::Slip));
                                }
                            }
                        }
                    }
                    ContactMode::Stick => {}
                }
                if change.is_some() {
                    break;
                }
            }
            match change {
                None => return Ok(()),
                Some((k, (mode, slip), kind)) => {
                    hs.modes.set(k, mode);
                    hs.slip = slip;
                    events.push(Event::switch(t, kind, k), t)?;
                }
            }
        }
        Err(HybridError::TooManyEvents { t: to_f64(t) })
    }

    /// Contact `k` sliding against the tangential force `forces` holds it with (the way
    /// that force's opposite points), and the state's slip directions with its own.
    fn slide_against(
        &self,
        hs: &HybridState<T, NQ, NK, ND>,
        forces: &SVector<T, NK>,
        k: usize,
    ) -> (ContactMode, SVector<T, NK>) {
        let mut slip = hs.slip;
        if ND > 2 {
            set_unit(&mut slip, &-forces, ND * k..ND * k + ND - 1);
        }
        let forward = ND > 2 || forces[ND * k] < T::zero();
        (ContactMode::Slide { forward }, slip)
    }

    /// The first mode of contact `k` (others as they are) that its forces and motion are
    /// consistent with, in the order stick, slide (planar: either way, the way the
    /// sticking force points first; spatial: in the direction of
    /// [`HybridSimulator::slip_from_rest`]), flight; `None` if none is. Stick: `λ_n ≥ 0`
    /// in the cone. Slide from rest: `λ_n ≥ 0` and the contact accelerating the way it
    /// slides. Flight: the contact not accelerating into the ground. Each comes with the
    /// state's slip directions for it.
    #[allow(clippy::type_complexity)]
    fn consistent_mode(
        &self,
        hs: &HybridState<T, NQ, NK, ND>,
        k: usize,
        u: &SVector<T, NU>,
        floor: T,
    ) -> Result<Option<(ContactMode, SVector<T, NK>)>, HybridError> {
        let (ti, ni) = (ND * k, ND * k + ND - 1);
        let mu = self.options.friction[ti];
        let with = |mode: ContactMode| {
            let mut trial = *hs;
            trial.modes.set(k, mode);
            if mode == ContactMode::Stick {
                self.anchor(&mut trial, k);
            }
            trial
        };
        let stick = with(ContactMode::Stick);
        let f = self.dynamics(&stick, u)?.contact;
        if f[ni] >= T::zero() && tangential_norm::<T, NK, ND>(&f, k) <= mu * f[ni] + floor {
            return Ok(Some((ContactMode::Stick, hs.slip)));
        }
        if ND == 2 {
            let first = f[ti] < T::zero();
            for forward in [first, !first] {
                let mode = ContactMode::Slide { forward };
                let trial = with(mode);
                let sol = self.dynamics(&trial, u)?;
                let a = self.contact_acceleration(&trial, &sol.x)[ti];
                let along = if forward { a } else { -a };
                if sol.contact[ni] >= T::zero() && along >= T::zero() {
                    return Ok(Some((mode, hs.slip)));
                }
            }
        } else {
            let (slip, consistent) = self.slip_from_rest(hs, k, u, &-f)?;
            if consistent {
                return Ok(Some((ContactMode::Slide { forward: true }, slip)));
            }
        }
        let flight = with(ContactMode::Flight);
        let sol = self.dynamics(&flight, u)?;
        if self.contact_acceleration(&flight, &sol.x)[ni] >= T::zero() {
            return Ok(Some((ContactMode::Flight, hs.slip)));
        }
        Ok(None)
    }

    /// Puts resting contacts on the ground: flight contacts at or below the ground
    /// and not moving away stick where they are (no impact is applied; use a state at
    /// rest), then the modes are settled against the forces under `u`.
    pub fn start(
        &self,
        state: State<T, NQ>,
        u: &SVector<T, NU>,
    ) -> Result<HybridState<T, NQ, NK, ND>, HybridError> {
        let mut hs = HybridState::flight(state);
        let (x, v) = self.contact_coordinates(&state);
        let size = leg_size::<L, T, NQ, NC, NU>(&self.params, &state.q);
        // A contact under the ground is refused, not moved up onto it (issue 29).
        for k in 0..NK / ND {
            let n = ND * k + ND - 1;
            if x[n] < -(size * T::lit(crate::assembly::ON_CLOSURES)) {
                return Err(HybridError::StartsUnderGround {
                    contact: L::CONTACT_NAMES[k],
                    depth: -to_f64(x[n]),
                });
            }
        }
        for k in 0..NK / ND {
            let n = ND * k + ND - 1;
            if x[n] <= self.options.tolerance.relative_residual * size && v[n] <= T::zero() {
                hs.modes.set(k, ContactMode::Stick);
                for r in ND * k..n {
                    hs.anchors[r] = x[r];
                }
            }
        }
        let mut events = StepEvents::new();
        self.settle(&mut hs, u, T::zero(), &mut events)?;
        self.project(&mut hs)?;
        Ok(hs)
    }

    /// Settles the modes after an impact at `now`: under torques asked again
    /// ([`HybridOptions::ask_after_impact`], returned to be held for the rest of the step)
    /// or under `u`, the step's.
    fn settle_after_impact(
        &self,
        hs: &mut HybridState<T, NQ, NK, ND>,
        source: &mut impl HybridTorqueSource<T, NQ, NK, NU, ND>,
        u: &SVector<T, NU>,
        now: T,
        events: &mut StepEvents<T>,
    ) -> Result<Option<SVector<T, NU>>, HybridError> {
        if !self.options.ask_after_impact {
            self.settle(hs, u, now, events)?;
            return Ok(None);
        }
        let after = source.torque(now, hs)?;
        self.settle(hs, &after, now, events)?;
        Ok(Some(after))
    }

    /// Advances `hs` from `t` by one step of [`HybridOptions::dt`] with torques from
    /// `source` (asked at the step's start and after each event), and returns the
    /// step's events.
    pub fn step(
        &self,
        hs: &mut HybridState<T, NQ, NK, ND>,
        t: T,
        source: &mut impl HybridTorqueSource<T, NQ, NK, NU, ND>,
    ) -> Result<StepEvents<T>, HybridError> {
        let mut events = StepEvents::new();
        let mut now = t;
        let end = t + self.options.dt;
        let tol = self.options.time_tolerance;
        // Torques asked after an event, for the event's new modes and the rest of the step.
        let mut asked: Option<SVector<T, NU>> = None;
        loop {
            let h = end - now;
            if h <= tol {
                break;
            }
            let u = match asked.take() {
                Some(u) => u,
                None => source.torque(now, hs)?,
            };
            // A flight contact at or under the ground and moving in touches down now. A
            // contact that just lifted off sits at the ground with no normal speed (up
            // to rounding: below `size · tolerance / dt`); it is left to fly.
            let (x, v) = self.contact_coordinates(&hs.state);
            let size = leg_size::<L, T, NQ, NC, NU>(&self.params, &hs.state.q);
            let still = self.options.tolerance.relative_residual * size / self.options.dt;
            if let Some(k) = (0..NK / ND).find(|&k| {
                let n = ND * k + ND - 1;
                hs.modes.get(k) == ContactMode::Flight && x[n] <= T::zero() && v[n] < -still
            }) {
                self.touchdown(hs, k, now, &mut events)?;
                asked = self.settle_after_impact(hs, source, &u, now, &mut events)?;
                continue;
            }
            // A spatial slide's guard measures the slip speed along the direction it has
            // now (which it keeps from rest until it moves).
            if ND > 2 {
                for k in 0..NK / ND {
                    if let ContactMode::Slide { .. } = hs.modes.get(k) {
                        if tangential_norm::<T, NK, ND>(&v, k) > still {
                            set_unit(&mut hs.slip, &v, ND * k..ND * k + ND - 1);
                        }
                    }
                }
            }
            let trial = self.rk4(hs, source, now, &u, h)?;
            let at = |s: State<T, NQ>| HybridState { state: s, ..*hs };
            let u1 = self.torque_at(source, end, &at(trial), &u)?;
            let g1 = self.guards(&at(trial), &u1)?;
            if !(0..NK).any(|r| g1[r] < T::zero()) {
                hs.state = trial;
                self.project(hs)?;
                break;
            }
            // The earliest crossing among the rows whose guard ends negative.
            let mut best: Option<(T, usize, State<T, NQ>)> = None;
            for r in 0..NK {
                if g1[r] >= T::zero() {
                    continue;
                }
                let limit = best.as_ref().map_or(h, |b| b.0);
                let mut guard = |tau: T| -> Result<(T, State<T, NQ>), HybridError> {
                    let s = self.rk4(hs, source, now, &u, tau)?;
                    let us = self.torque_at(source, now + tau, &at(s), &u)?;
                    Ok((self.guards(&at(s), &us)?[r], s))
                };
                let (g_limit, s_limit) = if limit == h {
                    (g1[r], trial)
                } else {
                    guard(limit)?
                };
                if g_limit >= T::zero() {
                    continue; // this row crosses after the best found so far
                }
                let g0 = self.guards(hs, &u)?[r];
                let (tau, s) = illinois(g0, g_limit, limit, s_limit, tol, guard)?;
                best = Some((tau, r, s));
            }
            let Some((tau, r, s)) = best else {
                // Rounding: no crossing confirmed; accept the step.
                hs.state = trial;
                self.project(hs)?;
                break;
            };
            hs.state = s;
            now += tau;
            self.project(hs)?;
            let k = r / ND;
            let landed = hs.modes.get(k) == ContactMode::Flight;
            match (hs.modes.get(k), r % ND == ND - 1) {
                (ContactMode::Flight, _) => self.touchdown(hs, k, now, &mut events)?,
                (_, true) => {
                    hs.modes.set(k, ContactMode::Flight);
                    events.push(Event::switch(now, EventKind::Liftoff, k), now)?;
                }
                (ContactMode::Stick, _) => {
                    let forces = self.dynamics(hs, &u)?.contact;
                    let (mode, slip) = self.slide_against(hs, &forces, k);
                    hs.modes.set(k, mode);
                    hs.slip = slip;
                    events.push(Event::switch(now, EventKind::Slip, k), now)?;
                }
                (ContactMode::Slide { .. }, _) => {
                    self.anchor(hs, k);
                    hs.modes.set(k, ContactMode::Stick);
                    events.push(Event::switch(now, EventKind::Stick, k), now)?;
                }
            }
            self.project(hs)?;
            if landed {
                asked = self.settle_after_impact(hs, source, &u, now, &mut events)?;
            } else {
                self.settle(hs, &u, now, &mut events)?;
            }
        }
        Ok(events)
    }
}

/// The event a switch to `mode` is.
fn kind_of(mode: ContactMode) -> EventKind {
    match mode {
        ContactMode::Flight => EventKind::Liftoff,
        ContactMode::Stick => EventKind::Stick,
        ContactMode::Slide { .. } => EventKind::Slip,
    }
}

/// The Illinois variant of regula falsi on `g(τ)` over `[0, b]` with `g(0) = g0 ≥ 0 >
/// g(b) = gb`: the smallest bracket end `b` where `g < 0`, once the bracket is shorter
/// than `tol` (the event has happened at the returned time, by at most `tol`).
fn illinois<T: Real, S: Copy>(
    g0: T,
    gb: T,
    b: T,
    sb: S,
    tol: T,
    mut g: impl FnMut(T) -> Result<(T, S), HybridError>,
) -> Result<(T, S), HybridError> {
    let (mut a, mut ga) = (T::zero(), g0.max(T::zero()));
    let (mut b, mut gb, mut sb) = (b, gb, sb);
    let mut side = 0i8;
    for _ in 0..200 {
        if b - a <= tol {
            break;
        }
        let mut c = if ga - gb > T::zero() {
            b - gb * (b - a) / (gb - ga)
        } else {
            (a + b) * T::lit(0.5)
        };
        // Keep inside the bracket, away from its ends by a little, so that it shrinks.
        let margin = tol * T::lit(0.25);
        if !(c > a + margin && c < b - margin) {
            c = (a + b) * T::lit(0.5);
        }
        let (gc, sc) = g(c)?;
        if gc < T::zero() {
            (b, gb, sb) = (c, gc, sc);
            if side == -1 {
                ga *= T::lit(0.5);
            }
            side = -1;
        } else {
            (a, ga) = (c, gc);
            if side == 1 {
                gb *= T::lit(0.5);
            }
            side = 1;
        }
    }
    Ok((b, sb))
}

#[cfg(feature = "std")]
pub use record::*;

#[cfg(feature = "std")]
mod record {
    use super::*;
    use crate::simulate::step::energy;

    /// One recorded instant of a hybrid run.
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct HybridSample<
        T: Real,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const NK: usize,
        const ND: usize = 2,
    > {
        /// Time (s).
        pub t: T,
        /// The state and contact modes.
        pub state: HybridState<T, NQ, NK, ND>,
        /// The torques the source gives at this instant.
        pub u: SVector<T, NU>,
        /// Ground forces `(λ_t, λ_n)` per contact at this instant, in the ground's frame.
        pub contact_forces: SVector<T, NK>,
        /// The closure forces `F` at this instant (base frame).
        pub closure_forces: SVector<T, NC>,
        /// `T + V`.
        pub energy: T,
        /// `max |φ|` (m).
        pub closure_residual: T,
        /// The held contacts' largest distance from their anchors (m).
        pub contact_residual: T,
    }

    /// A hybrid run: samples at every step's start (and the last state) and every event.
    #[derive(Clone, Debug, PartialEq)]
    pub struct HybridRecord<
        T: Real,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const NK: usize,
        const ND: usize = 2,
    > {
        /// The recorded instants, in time order.
        pub samples: Vec<HybridSample<T, NQ, NC, NU, NK, ND>>,
        /// Every event, in time order.
        pub events: Vec<Event<T>>,
    }

    /// A run that stopped early: why, when, and everything recorded until then.
    #[derive(Clone, Debug, PartialEq)]
    pub struct HybridStopped<
        T: Real,
        const NQ: usize,
        const NC: usize,
        const NU: usize,
        const NK: usize,
        const ND: usize = 2,
    > {
        /// When it stopped (s): the start of the step, or the instant of the sample, that
        /// failed.
        pub t: T,
        /// Why it failed.
        pub cause: HybridError,
        /// Everything recorded before.
        pub record: HybridRecord<T, NQ, NC, NU, NK, ND>,
    }

    impl<
            T: Real,
            const NQ: usize,
            const NC: usize,
            const NU: usize,
            const NK: usize,
            const ND: usize,
        > fmt::Display for HybridStopped<T, NQ, NC, NU, NK, ND>
    {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(
                f,
                "simulation stopped at t = {} s after {} samples and {} events: {}",
                self.t,
                self.record.samples.len(),
                self.record.events.len(),
                self.cause
            )
        }
    }

    impl<
            T: Real,
            const NQ: usize,
            const NC: usize,
            const NU: usize,
            const NK: usize,
            const ND: usize,
        > std::error::Error for HybridStopped<T, NQ, NC, NU, NK, ND>
    {
    }

    impl<
            L,
            T,
            const NQ: usize,
            const NC: usize,
            const NU: usize,
            const NK: usize,
            const ND: usize,
        > HybridSimulator<L, T, NQ, NC, NU, NK, ND>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
        T: Real,
    {
        fn sample(
            &self,
            t: T,
            hs: &HybridState<T, NQ, NK, ND>,
            u: SVector<T, NU>,
        ) -> Result<HybridSample<T, NQ, NC, NU, NK, ND>, HybridError> {
            let sol = self.dynamics(hs, &u)?;
            let (x, _) = self.contact_coordinates(&hs.state);
            let held = hs.modes.held_rows();
            let contact_residual = (0..NK)
                .filter(|&r| held[r])
                .map(|r| (x[r] - hs.anchors[r]).abs())
                .fold(T::zero(), |a, b| a.max(b));
            Ok(HybridSample {
                t,
                state: *hs,
                u,
                contact_forces: sol.contact,
                closure_forces: sol.closure,
                energy: energy::<L, T, NQ, NC, NU>(&self.params, &hs.state),
                closure_residual: if NC == 0 {
                    T::zero()
                } else {
                    L::closure_residual(&hs.state.q, &self.params).amax()
                },
                contact_residual,
            })
        }

        /// Runs `steps` steps from `initial`; records the initial state, every step and
        /// every event. Stops at the first failure, keeping the record so far.
        pub fn run(
            &self,
            initial: HybridState<T, NQ, NK, ND>,
            steps: usize,
            source: &mut impl HybridTorqueSource<T, NQ, NK, NU, ND>,
        ) -> Result<HybridRecord<T, NQ, NC, NU, NK, ND>, HybridStopped<T, NQ, NC, NU, NK, ND>>
        {
            crate::simulate::step::check_record(
                steps,
                core::mem::size_of::<HybridSample<T, NQ, NC, NU, NK, ND>>(),
            )
            .map_err(|e| HybridStopped {
                t: T::zero(),
                cause: HybridError::RecordTooLarge(e),
                record: HybridRecord {
                    samples: Vec::new(),
                    events: Vec::new(),
                },
            })?;
            let mut record = HybridRecord {
                samples: Vec::with_capacity(steps + 1),
                events: Vec::with_capacity(64),
            };
            let mut hs = initial;
            let mut t = T::zero();
            for k in 0..=steps {
                let outcome = source
                    .torque(t, &hs)
                    .map_err(HybridError::from)
                    .and_then(|u| self.sample(t, &hs, u));
                match outcome {
                    Ok(s) => record.samples.push(s),
                    Err(cause) => return Err(HybridStopped { t, cause, record }),
                }
                if k == steps {
                    break;
                }
                match self.step(&mut hs, t, source) {
                    Ok(events) => record.events.extend(events.iter().copied()),
                    Err(cause) => return Err(HybridStopped { t, cause, record }),
                }
                t = self.options.dt * T::lit((k + 1) as f64);
            }
            Ok(record)
        }
    }
}
