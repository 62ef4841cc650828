//! Design measures of a leg (DESIGN.md §3, in the motor coordinates of the reduction):
//! what a designer compares before building one. At one assembled pose, allocation-free:
//!
//! - **Singularities** (Gosselin and Angeles 1990, "Singularity analysis of closed-loop
//!   kinematic chains", IEEE T-RA 6(3)). The passive joints lose rank where `J_p` (the
//!   closure Jacobian without the motors' columns) does: with the motors held the
//!   mechanism gains a freedom ("type II", [`PointMeasures::passive_rank`]), the null-space
//!   map `q̇ = G θ̇` does not exist and `assemble` reports `Singular`. The foot loses a
//!   direction where the foot Jacobian in motor coordinates `J_θ = J_f G` loses rank
//!   ("type I", [`PointMeasures::foot_rank`]): the edge of the workspace.
//! - **Transparency**: the condition number of `J_θ` (Kenneally, De and Koditschek 2016,
//!   "Design principles for a family of direct-drive legged robots", IEEE RA-L 1(2)).
//! - **Force capacity**: with the leg at rest, the motors hold `u = Gᵀ G(q) + J_θᵀ f` for
//!   a force `f` the foot puts on the ground (`Gᵀ B = I`, `Gᵀ Jᵀ = 0`; `G(q)` the gravity
//!   and spring torques). Limits `|u_k| ≤ τ_k` bound `f` to a polygon (a polytope for a
//!   spatial foot, [`polytope`]), the intersection of one slab per motor
//!   ([`force_polygon`], [`capacity_sets`]); the largest downward push is
//!   [`PointMeasures::vertical_force`].
//! - **Speed capacity**: `ẏ = J_θ θ̇` with `|θ̇_k| ≤ ω_k`: a zonotope ([`speed_polygon`]; in
//!   space its volume, [`polytope::speed_zonotope_volume`]);
//!   the fastest vertical foot speed is [`PointMeasures::vertical_speed`].
//! - **Operational-space inertia at the foot** (Khatib 1987): `Λ⁻¹ = J_f C J_fᵀ` with
//!   `C` the inverse inertia of the closed chain (`M⁻¹` projected onto `J q̇ = 0`),
//!   reflected rotor inertia included in `M`. With the motors free (unpowered, rotors
//!   turning) and with them locked (their joints fixed). [`foot_inverse_inertia`] gives
//!   `Λ⁻¹`, which exists at every pose (a one-motor linkage's foot moves on a line: `Λ⁻¹`
//!   has rank one and the effective mass along that line is finite).
//! - **Impact mitigation factor** (Wensing, Wang, Seok, Otten, Lang and Kim 2017,
//!   "Proprioceptive actuator design in the MIT Cheetah: impact mitigation and
//!   high-bandwidth physical interaction for dynamic legged robots", IEEE T-RO 33(3),
//!   §IV): `ξ = det(I − Λ Λ_L⁻¹)`, `Λ` the foot's operational-space inertia of the
//!   robot on a floating body with its joints free (the rotors backdriven), `Λ_L` with
//!   its joints locked. `ξ = 0` when backdriving changes nothing, `ξ → 1` when the leg
//!   keeps the body's inertia away from the ground. It needs a body: a leg with body
//!   joints of its own (a hopper) uses them; a leg on a fixed hip is put on a body that
//!   translates in the plane, or in space for a spatial leg ([`Body::Translating`]).
//!
//! A spatial leg's foot has three coordinates (`ND = 3`, vertical `z`): the same measures
//! with 3 × 3 inertias and determinants, `κ` over three directions (one-sided Jacobi), the
//! polytope for the polygon; its workspace is mapped in a slice through the stance foot or
//! as a volume ([`workspace`]).
//!
//! A leg with body joints of its own (passive joints above every motor: a hopper's
//! sliders) is analysed in its body's frame ([`LegFrame`]): those joints are held where
//! the pose has them, the rest is the leg. Which measures apply is decided by the leg's
//! properties, never its name: motor coordinates need motors that determine the leg
//! (mobility with the body held = motors), the force and speed sets as many motors as the
//! foot has coordinates or more ([`LegFrame::foot_spans`]).
//!
//! [`workspace`] (with `std`) runs these over a grid of foot positions; [`summary`] gives a
//! design's row of `cargo xtask analyze`'s table, with the command's defaults.
//!
//! May import: [`crate::assembly`], [`crate::dynamics`], the contract ([`LegModel`], [`Real`], [`linalg`](crate::linalg)); not the controllers or the simulators.

use core::fmt;

use nalgebra::{SMatrix, SVector, Vector2};

use crate::assembly::{check_on_closures, AssemblyError};
use crate::dynamics::forward::rcond_floor;
use crate::dynamics::structure::{Actuation, NotApplicable};
use crate::model::contract::{LegDynamics, LegModel, Parameters, Real};
use crate::model::linalg::{mul, mul_tn, Cholesky, PivotedLdlt};

pub mod polytope;
#[cfg(feature = "std")]
pub mod summary;
#[cfg(feature = "std")]
pub mod workspace;

/// The most motors the polygons handle (their vertices are stored on the stack).
pub const MAX_MOTORS: usize = 8;

/// Why a measure does not apply to a leg: a property of the leg, said in words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Inapplicable {
    /// Motor coordinates or the foot's two directions need other motors
    /// ([`NotApplicable`]: under-, over-actuated, or one motor for a 2-D polygon).
    Structure(NotApplicable),
    /// One motor moves the foot along a curve: no area, no polygon (nor a volume or a
    /// polytope in space).
    FootOnACurve,
    /// Two motors move a spatial leg's foot over a surface: no volume, no 3-D force or
    /// speed polytope.
    FootOnASurface,
    /// The foot's path over one motor's turn is for a one-motor leg; this one has more
    /// (its workspace is an area).
    NotOneMotor {
        /// The leg's motors.
        motors: usize,
    },
    /// A slice plane was given for a planar leg, whose workspace is its own plane.
    PlanarSlice,
    /// More than [`MAX_MOTORS`] motors.
    TooManyMotors {
        /// The leg's motors.
        motors: usize,
    },
    /// With its motors free the foot still cannot move in every direction (its closures
    /// hold it, as a toe pinned to the ground): the foot's inertia `Λ` does not exist, so
    /// neither does the impact mitigation factor, whatever the number of motors.
    FootHeld,
    /// With its motors locked the foot cannot move (a leg on a fixed hip): the impact
    /// mitigation factor needs a body that moves ([`Body::Translating`]).
    RigidWhenLocked,
    /// The leg's parameters have no `gravity_x`/`gravity_y` (and `gravity_z` in space) or
    /// no `<link>_mass` (a hand-written model): the body's coupling cannot be computed.
    MissingParameters,
}

impl fmt::Display for Inapplicable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Inapplicable::Structure(n) => write!(f, "{n}"),
            Inapplicable::FootOnACurve => write!(
                f,
                "the leg has 1 motor: it moves the foot along a curve, so there is no workspace area (or volume) and no force or speed polygon (or polytope)"
            ),
            Inapplicable::FootOnASurface => write!(
                f,
                "the foot has three coordinates but the leg has 2 motors: they move the foot over a surface, so there is no workspace volume and no 3-D force or speed polytope"
            ),
            Inapplicable::FootHeld => write!(
                f,
                "with its motors free the foot cannot move in every direction (the closures hold it): its inertia Λ does not exist"
            ),
            Inapplicable::NotOneMotor { motors } => write!(
                f,
                "the foot's path over a motor's turn is for a one-motor leg; this one has {motors} motors (its workspace is an area)"
            ),
            Inapplicable::PlanarSlice => write!(
                f,
                "a planar leg's workspace is its own plane: it takes no slice plane (a spatial leg does)"
            ),
            Inapplicable::TooManyMotors { motors } => write!(
                f,
                "the leg has {motors} motors; the force and speed sets handle at most {MAX_MOTORS}"
            ),
            Inapplicable::RigidWhenLocked => write!(
                f,
                "with the motors locked the foot cannot move (the hip is fixed): the impact mitigation factor needs a body (give its mass)"
            ),
            Inapplicable::MissingParameters => write!(
                f,
                "the model's parameters lack gravity_x, gravity_y (gravity_z in space) or a <link>_mass: the body's coupling cannot be computed"
            ),
        }
    }
}

/// Why a measure cannot be computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AnalysisError {
    /// It does not apply to this leg (a property of the leg).
    NotApplicable(Inapplicable),
    /// The pose cannot be assembled as asked.
    Assembly(AssemblyError),
    /// The passive joints lose rank here ("type II"): `q̇ = G θ̇` does not exist.
    PassiveSingular,
    /// The foot Jacobian in motor coordinates loses rank here ("type I").
    FootSingular,
    /// `M` is not positive definite (a parameter set out of range).
    MassMatrix,
    /// An input or a result is NaN or infinite.
    NonFinite,
    /// The starting pose has motor `motor` (0-based, in `ACTUATED` order) at `angle`,
    /// outside the range `(low, high)` the workspace is limited to.
    StartOutOfRange {
        /// The motor.
        motor: usize,
        /// Its angle at the start (rad, or m).
        angle: f64,
        /// The range.
        range: (f64, f64),
    },
    /// The workspace grid's options are out of their ranges ([`workspace::GridOptions::check`]):
    /// `what` says which rule, `value` the value given.
    Grid {
        /// The rule broken ("nodes per side from 2 to 2000").
        what: &'static str,
        /// The value given.
        value: f64,
    },
}

impl fmt::Display for AnalysisError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AnalysisError::NotApplicable(why) => write!(f, "not applicable: {why}"),
            AnalysisError::Assembly(e) => write!(f, "{e}"),
            AnalysisError::PassiveSingular => {
                write!(f, "singular configuration: the passive joints lose rank")
            }
            AnalysisError::FootSingular => write!(
                f,
                "singular configuration: the foot Jacobian in motor coordinates loses rank"
            ),
            AnalysisError::MassMatrix => write!(f, "the mass matrix is not positive definite"),
            AnalysisError::NonFinite => write!(f, "non-finite input or result"),
            AnalysisError::StartOutOfRange {
                motor,
                angle,
                range: (low, high),
            } => write!(
                f,
                "the starting pose has motor {} at {angle:.4}, outside the motor range {low}:{high}: start from a pose in range (or widen the range)",
                motor + 1
            ),
            AnalysisError::Grid { what, value } => write!(
                f,
                "the workspace grid needs {what}, got {}",
                crate::ShownNumber(*value)
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for AnalysisError {}

impl From<AssemblyError> for AnalysisError {
    fn from(e: AssemblyError) -> Self {
        AnalysisError::Assembly(e)
    }
}

impl From<Inapplicable> for AnalysisError {
    fn from(e: Inapplicable) -> Self {
        AnalysisError::NotApplicable(e)
    }
}

/// The frame a leg is analysed in: its body joints held, the rest free.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LegFrame<const NQ: usize> {
    /// The body's joints: passive joints above every motor in the tree (a hopper's
    /// sliders and pitch), held where the pose has them. None on a leg with a fixed hip.
    pub held: [bool; NQ],
    /// Degrees of freedom with those joints held: `MOBILITY` minus their count.
    pub mobility: usize,
    /// The motors.
    pub motors: usize,
}

impl<const NQ: usize> LegFrame<NQ> {
    /// The frame of leg `L`.
    pub fn of<L, const NC: usize, const NU: usize>() -> Self
    where
        L: LegDynamics<NQ, NC, NU>,
    {
        let above = |j: usize, a: usize| {
            let mut k = L::PARENTS[a];
            while let Some(p) = k {
                if p == j {
                    return true;
                }
                k = L::PARENTS[p];
            }
            false
        };
        let held: [bool; NQ] = core::array::from_fn(|j| {
            NU > 0 && !L::ACTUATED.contains(&j) && L::ACTUATED.iter().all(|&a| above(j, a))
        });
        let count = held.iter().filter(|&&h| h).count();
        LegFrame {
            held,
            mobility: L::MOBILITY.saturating_sub(count),
            motors: NU,
        }
    }

    /// Whether the leg has body joints of its own.
    pub fn has_body(&self) -> bool {
        self.held.iter().any(|&h| h)
    }

    /// How the motors compare with the mobility of the leg in this frame.
    pub fn actuation(&self) -> Actuation {
        match self.mobility.cmp(&self.motors) {
            core::cmp::Ordering::Equal => Actuation::Full,
            core::cmp::Ordering::Greater => Actuation::Under,
            core::cmp::Ordering::Less => Actuation::Over,
        }
    }

    /// The motor angles determine the leg in this frame (motor coordinates exist).
    pub fn motor_coordinates(&self) -> Result<(), Inapplicable> {
        let (mobility, motors) = (self.mobility, self.motors);
        match self.actuation() {
            Actuation::Full => Ok(()),
            Actuation::Under => Err(Inapplicable::Structure(NotApplicable::UnderActuated {
                mobility,
                motors,
            })),
            Actuation::Over => Err(Inapplicable::Structure(NotApplicable::OverActuated {
                mobility,
                motors,
            })),
        }
    }

    /// The motors span the planar foot's two directions: motor coordinates, and two
    /// motors or more (at most [`MAX_MOTORS`]).
    pub fn foot_polygons(&self) -> Result<(), Inapplicable> {
        self.foot_spans(2)
    }

    /// The motors can span a foot of `dims` coordinates (2 planar, 3 spatial): motor
    /// coordinates, and `dims` motors or more (at most [`MAX_MOTORS`]).
    pub fn foot_spans(&self, dims: usize) -> Result<(), Inapplicable> {
        self.motor_coordinates()?;
        if self.motors < dims {
            return Err(if self.motors < 2 {
                Inapplicable::FootOnACurve
            } else {
                Inapplicable::FootOnASurface
            });
        }
        if self.motors > MAX_MOTORS {
            return Err(Inapplicable::TooManyMotors {
                motors: self.motors,
            });
        }
        Ok(())
    }
}

/// Motor limits: the torque each motor can hold (N m, or N on a prismatic joint) and the
/// speed it can turn (rad/s, or m/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorLimits<T: Real, const NU: usize> {
    /// `τ_k`.
    pub torque: SVector<T, NU>,
    /// `ω_k`.
    pub speed: SVector<T, NU>,
}

/// The body a leg's hip is on, for the impact mitigation factor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Body<T: Real> {
    /// The hip on a fixed base (or, on a leg with body joints, the spec's own body).
    Fixed,
    /// The hip on a body of this mass (kg) that translates (held upright): in the plane
    /// for a planar leg, in space for a spatial one. The base frame moves with it.
    Translating {
        /// The body's mass without the leg (kg).
        mass: T,
    },
}

/// The motion of a leg in its motor coordinates at one pose: `q̇ = G θ̇`, `ẏ = J_θ θ̇`,
/// the foot `ẏ` with `ND` coordinates (2 planar, the default; 3 spatial).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorKinematics<T: Real, const NQ: usize, const NU: usize, const ND: usize = 2> {
    /// `G` (`NQ × NU`): the joint rates when motor `k` turns at unit rate (held joints
    /// at rest).
    pub g: SMatrix<T, NQ, NU>,
    /// `J_θ = J_f G`: the foot's velocity per unit motor rate.
    pub foot_jacobian: SMatrix<T, ND, NU>,
    /// `J_f`: the foot's velocity per unit joint rate.
    pub joint_foot_jacobian: SMatrix<T, ND, NQ>,
    /// The passive joints' rank measure ([`PointMeasures::passive_rank`]).
    pub passive_rank: T,
}

fn all_finite_slice<T: Real>(x: &[T]) -> bool {
    x.iter().all(|v| v.is_finite())
}

/// `det(A)` by Gaussian elimination with partial pivoting (any fixed size).
fn determinant<T: Real, const N: usize>(mut a: SMatrix<T, N, N>) -> T {
    let mut det = T::one();
    for k in 0..N {
        let mut p = k;
        for i in k + 1..N {
            if a[(i, k)].abs() > a[(p, k)].abs() {
                p = i;
            }
        }
        if a[(p, k)] == T::zero() {
            return T::zero();
        }
        if p != k {
            a.swap_rows(p, k);
            det = -det;
        }
        let pivot = a[(k, k)];
        det *= pivot;
        for i in k + 1..N {
            let factor = a[(i, k)] / pivot;
            for c in k + 1..N {
                let v = a[(k, c)];
                a[(i, c)] -= factor * v;
            }
        }
    }
    det
}

/// The passive joints' rank measure of the closure Jacobian `j` with the columns in
/// `fixed` (motors and held joints) left out: where the passive columns and the
/// independent rows make a square matrix, its determinant over the product of its
/// column lengths (Hadamard's ratio, in `[−1, 1]`, signed, zero exactly at the
/// singularity); otherwise `√rcond` of `J_p J_pᵀ` (unsigned). `1` without closures.
fn passive_rank<T: Real, const NQ: usize, const NC: usize>(
    j: &SMatrix<T, NC, NQ>,
    fixed: &[bool; NQ],
    redundant_rows: usize,
) -> T {
    if NC == 0 {
        return T::one();
    }
    let passive = fixed.iter().filter(|&&f| !f).count();
    if passive == NC && redundant_rows == 0 {
        let mut s = SMatrix::<T, NC, NC>::zeros();
        let mut norms = T::one();
        let mut c = 0;
        for (col, &f) in fixed.iter().enumerate() {
            if !f {
                s.set_column(c, &j.column(col));
                norms *= j.column(col).norm();
                c += 1;
            }
        }
        if norms == T::zero() {
            return T::zero();
        }
        return determinant(s) / norms;
    }
    let mut jp = *j;
    for (col, &f) in fixed.iter().enumerate() {
        if f {
            jp.column_mut(col).fill(T::zero());
        }
    }
    // Every pivot counts here (no floor): a singular `J_p` gives rcond 0. Where rows are
    // structurally redundant their pivots are rounding, never a measure of the pose: the
    // floor leaves them out (it counted them, and a leg far from any singularity measured
    // 1e-9), and any other pivot under it makes the measure zero.
    let floor = if redundant_rows > 0 {
        rcond_floor::<T>()
    } else {
        T::zero()
    };
    match PivotedLdlt::new(&mul(&jp, &jp.transpose()), redundant_rows, floor) {
        Some(f) => f.rcond.max(T::zero()).sqrt(),
        None => T::zero(),
    }
}

/// `G` and `J_θ` at an assembled pose `q`, the joints of `frame.held` at rest. Fails
/// where the passive joints lose rank ([`AnalysisError::PassiveSingular`]) and where
/// motor coordinates do not exist for this leg.
pub fn motor_kinematics<
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
    frame: &LegFrame<NQ>,
) -> Result<MotorKinematics<T, NQ, NU, ND>, AnalysisError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    frame.motor_coordinates()?;
    if !all_finite_slice(q.as_slice()) {
        return Err(AnalysisError::NonFinite);
    }
    let fixed: [bool; NQ] = core::array::from_fn(|c| frame.held[c] || L::ACTUATED.contains(&c));
    let j = L::constraint_jacobian(q, params);
    let rank = passive_rank(&j, &fixed, L::REDUNDANT_ROWS);
    let mut g = SMatrix::<T, NQ, NU>::zeros();
    for (k, &a) in L::ACTUATED.iter().enumerate() {
        g[(a, k)] = T::one();
    }
    if NC > 0 {
        let mut jp = j;
        for (c, &f) in fixed.iter().enumerate() {
            if f {
                jp.column_mut(c).fill(T::zero());
            }
        }
        let s = mul(&jp, &jp.transpose());
        let chol = PivotedLdlt::new(&s, L::REDUNDANT_ROWS, rcond_floor::<T>())
            .ok_or(AnalysisError::PassiveSingular)?;
        // The passive rates that cancel each motor's closure velocity, smallest norm:
        // `x = J_pᵀ (J_p J_pᵀ)⁻¹ (−J e_k)`.
        let mut w = -mul(&j, &g);
        chol.solve_mut(&mut w);
        g += mul(&jp.transpose(), &w);
        // The rows left out by the pivots must hold too (a singular J_p can pass the
        // factorization of a redundant system).
        let residual = mul(&j, &g);
        let scale = g.amax().max(T::one()) * j.amax().max(T::one());
        if residual.amax() > scale * rcond_floor::<T>().sqrt() {
            return Err(AnalysisError::PassiveSingular);
        }
    }
    let joint_foot_jacobian = L::foot_jacobian(q, params);
    let foot_jacobian = mul(&joint_foot_jacobian, &g);
    if !all_finite_slice(g.as_slice()) || !all_finite_slice(foot_jacobian.as_slice()) {
        return Err(AnalysisError::NonFinite);
    }
    Ok(MotorKinematics {
        g,
        foot_jacobian,
        joint_foot_jacobian,
        passive_rank: rank,
    })
}

/// The singular values `(σ_max, σ_min)` of a `2 × N` matrix (closed form of `A Aᵀ`;
/// `σ_min² = det(A Aᵀ) / σ_max²` with `det(A Aᵀ)` the sum of the squared 2 × 2 minors of
/// `A` (Cauchy–Binet), which keeps its digits where `σ_min ≪ σ_max`).
pub fn singular_values<T: Real, const N: usize>(a: &SMatrix<T, 2, N>) -> (T, T) {
    let s = mul(a, &a.transpose());
    let half = T::lit(0.5);
    let tr = s[(0, 0)] + s[(1, 1)];
    let diff = (s[(0, 0)] - s[(1, 1)]) * half;
    let root = (diff * diff + s[(0, 1)] * s[(1, 0)]).sqrt();
    let hi = tr * half + root;
    if hi <= T::zero() {
        return (T::zero(), T::zero());
    }
    let mut det = T::zero();
    for i in 0..N {
        for j in i + 1..N {
            let minor = a[(0, i)] * a[(1, j)] - a[(0, j)] * a[(1, i)];
            det += minor * minor;
        }
    }
    (hi.sqrt(), (det / hi).sqrt())
}

/// The extreme singular values `(σ_max, σ_min)` of an `ND × N` matrix over its `ND`
/// rows (`σ_min = 0` where `N < ND`): the closed form of [`singular_values`] in the
/// plane; in space one-sided Jacobi rotations (Hestenes 1958) on the columns of `Aᵀ`,
/// which keep `σ_min` to relative accuracy where `A Aᵀ`'s eigenvalues would lose it.
pub fn extreme_singular_values<T: Real, const ND: usize, const N: usize>(
    a: &SMatrix<T, ND, N>,
) -> (T, T) {
    if ND == 2 {
        return singular_values(&SMatrix::<T, 2, N>::from_fn(|r, c| a[(r, c)]));
    }
    if !a.iter().all(|x| x.is_finite()) {
        return (T::zero() / T::zero(), T::zero() / T::zero());
    }
    let mut b = a.transpose();
    // Rotations until every pair of columns is orthogonal to rounding; a few sweeps do
    // at these sizes, the bound keeps a NaN from looping.
    for _ in 0..64 {
        let mut rotated = false;
        for i in 0..ND {
            for k in i + 1..ND {
                let alpha = b.column(i).norm_squared();
                let beta = b.column(k).norm_squared();
                let gamma = b.column(i).dot(&b.column(k));
                if !gamma.is_finite() || gamma.abs() <= T::default_epsilon() * (alpha * beta).sqrt()
                {
                    continue;
                }
                rotated = true;
                let zeta = (beta - alpha) / (gamma * T::lit(2.0));
                // hypot: ζ² overflows where a column is rounding beside another.
                let t = zeta.signum() / (zeta.abs() + T::one().hypot(zeta));
                let c = T::one() / T::one().hypot(t);
                let s = c * t;
                for r in 0..N {
                    let (x, y) = (b[(r, i)], b[(r, k)]);
                    b[(r, i)] = c * x - s * y;
                    b[(r, k)] = s * x + c * y;
                }
            }
        }
        if !rotated {
            break;
        }
    }
    let mut hi = T::zero();
    let mut lo = T::one() / T::zero();
    for i in 0..ND {
        let n = b.column(i).norm();
        hi = hi.max(n);
        lo = lo.min(n);
    }
    // Fewer columns than rows: a direction is missing, whatever rounding leaves.
    (hi, if N < ND { T::zero() } else { lo })
}

/// Whether the passive joints' Jacobian `J_p` (the closures' columns of the joints that
/// are neither motors nor held) is square with no redundant rows: then
/// [`PointMeasures::passive_rank`] is the signed `det J_p` over its columns' norms.
pub fn passive_square<L, const NQ: usize, const NC: usize, const NU: usize>(
    frame: &LegFrame<NQ>,
) -> bool
where
    L: LegDynamics<NQ, NC, NU>,
{
    let passive = (0..NQ)
        .filter(|&c| !frame.held[c] && !L::ACTUATED.contains(&c))
        .count();
    L::REDUNDANT_ROWS == 0 && passive == NC
}

/// The foot's rank measure ("type I") with motor kinematics `kin`: `σ_min / σ_max` of
/// `J_f Q` over the foot's `ND` directions, `Q` an orthonormal basis of the motions the mechanism has with the held
/// joints at rest (the span of `G`). It depends on where the foot can move and not on
/// how the motors parametrize that motion: zero exactly where the foot loses a
/// direction, and finite where the passive joints lose rank (there `J_θ = J_f G` blows
/// up and its columns align, so a measure of `J_θ`'s own shape would vanish). With as
/// many motors as the foot has coordinates and a square `J_p` ([`passive_square`]) it
/// carries the sign of `det J_p · det J_θ`, which is `± det [J; J_f]` over the free
/// joints (the sign fixed by the joints' order): it changes across a foot singularity
/// and not across a passive one. Zero with fewer motors than the foot's coordinates (the
/// foot moves on a curve or a surface).
pub fn foot_rank<L, T, const NQ: usize, const NC: usize, const NU: usize, const ND: usize>(
    frame: &LegFrame<NQ>,
    kin: &MotorKinematics<T, NQ, NU, ND>,
) -> T
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    // Gram–Schmidt, twice per column: G's columns can be nearly parallel near a passive
    // singularity (their passive parts grow alike).
    let mut basis = kin.g;
    for k in 0..NU {
        for _ in 0..2 {
            for i in 0..k {
                let along = basis.column(i).dot(&basis.column(k));
                let prev = basis.column(i).into_owned();
                basis.column_mut(k).axpy(-along, &prev, T::one());
            }
        }
        let norm = basis.column(k).norm();
        if norm == T::zero() || !norm.is_finite() {
            return T::zero();
        }
        basis.column_mut(k).unscale_mut(norm);
    }
    let (hi, lo) = extreme_singular_values(&mul(&kin.joint_foot_jacobian, &basis));
    if hi == T::zero() || NU < ND {
        return T::zero();
    }
    let ratio = lo / hi;
    if NU == ND && passive_square::<L, NQ, NC, NU>(frame) {
        let jt = &kin.foot_jacobian;
        let det = small_determinant(SMatrix::<T, ND, ND>::from_fn(|r, c| jt[(r, c)]));
        if (det < T::zero()) != (kin.passive_rank < T::zero()) {
            return -ratio;
        }
    }
    ratio
}

/// A convex polygon in the plane, vertices counter-clockwise, on the stack.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Polygon<T: Real> {
    vertices: [Vector2<T>; 2 * MAX_MOTORS],
    len: usize,
}

impl<T: Real> Polygon<T> {
    fn empty() -> Self {
        Polygon {
            vertices: [Vector2::zeros(); 2 * MAX_MOTORS],
            len: 0,
        }
    }

    fn push(&mut self, v: Vector2<T>) {
        if self.len < 2 * MAX_MOTORS {
            self.vertices[self.len] = v;
            self.len += 1;
        }
    }

    /// The vertices, counter-clockwise.
    pub fn vertices(&self) -> &[Vector2<T>] {
        &self.vertices[..self.len]
    }

    /// The enclosed area (shoelace formula).
    pub fn area(&self) -> T {
        let v = self.vertices();
        let mut twice = T::zero();
        for i in 0..v.len() {
            let (a, b) = (v[i], v[(i + 1) % v.len()]);
            twice += a[0] * b[1] - a[1] * b[0];
        }
        twice * T::lit(0.5)
    }

    /// Sorts the vertices counter-clockwise about their centroid.
    fn sort(&mut self) {
        let n = self.len;
        if n == 0 {
            return;
        }
        let mut c = Vector2::zeros();
        for v in &self.vertices[..n] {
            c += v;
        }
        c /= T::from_usize(n).unwrap_or_else(T::one);
        let angle = |v: &Vector2<T>| (v[1] - c[1]).atan2(v[0] - c[0]);
        // Insertion sort: at most 2·MAX_MOTORS vertices.
        for i in 1..n {
            let mut k = i;
            while k > 0 && angle(&self.vertices[k - 1]) > angle(&self.vertices[k]) {
                self.vertices.swap(k - 1, k);
                k -= 1;
            }
        }
    }
}

/// The polygon `{f : lo_k ≤ (Aᵀ f)_k ≤ hi_k}` (one slab per column `a_k` of `A`), by
/// the pairwise intersections of the slabs' edges that satisfy every slab. Empty when
/// the slabs do not meet.
fn slab_polygon<T: Real, const NU: usize>(
    a: &SMatrix<T, 2, NU>,
    lo: &SVector<T, NU>,
    hi: &SVector<T, NU>,
) -> Polygon<T> {
    let mut poly = Polygon::empty();
    let scale = a.amax() * (lo.amax().max(hi.amax()));
    let slack = scale * T::default_epsilon() * T::lit(1e4);
    for i in 0..NU {
        for k in i + 1..NU {
            let (ai, ak) = (a.column(i), a.column(k));
            let det = ai[0] * ak[1] - ai[1] * ak[0];
            if det.abs() <= ai.norm() * ak.norm() * T::default_epsilon() * T::lit(1e3) {
                continue;
            }
            for bi in [lo[i], hi[i]] {
                for bk in [lo[k], hi[k]] {
                    // [aᵢᵀ; a_kᵀ] f = (bᵢ, b_k) by Cramer's rule.
                    let f = Vector2::new(
                        (bi * ak[1] - bk * ai[1]) / det,
                        (ai[0] * bk - ak[0] * bi) / det,
                    );
                    let inside = (0..NU).all(|m| {
                        let v = a.column(m).dot(&f);
                        v >= lo[m] - slack && v <= hi[m] + slack
                    });
                    let seen = poly.vertices().iter().any(|p| (p - f).amax() <= slack);
                    if inside && !seen {
                        poly.push(f);
                    }
                }
            }
        }
    }
    poly.sort();
    poly
}

/// The foot forces (N, on the ground, base frame) the motors hold at rest at pose `q`
/// within `torque` limits: `|Gᵀ G(q) + J_θᵀ f|_k ≤ τ_k`, gravity and springs included.
/// Where the motors cannot hold the leg itself within their limits the polygon leaves
/// out `f = 0` (with two motors it is never empty; with more it can be).
pub fn force_polygon<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    kin: &MotorKinematics<T, NQ, NU>,
    torque: &SVector<T, NU>,
) -> Polygon<T>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let hold = holding_torque::<L, T, NQ, NC, NU, 2>(params, q, kin);
    slab_polygon(&kin.foot_jacobian, &(-torque - hold), &(torque - hold))
}

/// The force and speed sets at a pose, by the foot's dimension ([`capacity_sets`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CapacitySets<T: Real> {
    /// A planar foot's force and speed polygons ([`force_polygon`], [`speed_polygon`]).
    Planar {
        /// Foot forces held at rest within the torque limits (N).
        force: Polygon<T>,
        /// Foot velocities within the speed limits (m/s).
        speed: Polygon<T>,
    },
    /// A spatial foot's force polytope ([`polytope::force_polytope`]) and the volume of
    /// its speed zonotope ([`polytope::speed_zonotope_volume`], m³/s³).
    Spatial {
        /// Foot forces held at rest within the torque limits (N).
        force: polytope::Polytope<T>,
        /// The speed zonotope's volume.
        speed_volume: T,
    },
}

/// The force and speed sets of a leg at the assembled pose `q` with motor kinematics
/// `kin`: polygons for a planar foot, the polytope and the zonotope's volume for a spatial
/// one. Fails where the motors do not span the foot ([`LegFrame::foot_spans`]).
pub fn capacity_sets<L, T, const NQ: usize, const NC: usize, const NU: usize, const ND: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    frame: &LegFrame<NQ>,
    kin: &MotorKinematics<T, NQ, NU, ND>,
    limits: &MotorLimits<T, NU>,
) -> Result<CapacitySets<T>, Inapplicable>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    frame.foot_spans(ND)?;
    // The same kinematics typed with the foot's dimension (ND is 2 or 3 here).
    fn retyped<T: Real, const NQ: usize, const NU: usize, const A: usize, const B: usize>(
        k: &MotorKinematics<T, NQ, NU, A>,
    ) -> MotorKinematics<T, NQ, NU, B> {
        MotorKinematics {
            g: k.g,
            foot_jacobian: SMatrix::from_fn(|r, c| k.foot_jacobian[(r, c)]),
            joint_foot_jacobian: SMatrix::from_fn(|r, c| k.joint_foot_jacobian[(r, c)]),
            passive_rank: k.passive_rank,
        }
    }
    const { assert!(ND == 2 || ND == 3, "a foot has 2 or 3 coordinates") };
    Ok(if ND == 3 {
        let kin = retyped::<T, NQ, NU, ND, 3>(kin);
        CapacitySets::Spatial {
            force: polytope::force_polytope::<L, T, NQ, NC, NU>(params, q, &kin, &limits.torque),
            speed_volume: polytope::speed_zonotope_volume(&kin.foot_jacobian, &limits.speed),
        }
    } else {
        let kin = retyped::<T, NQ, NU, ND, 2>(kin);
        CapacitySets::Planar {
            force: force_polygon::<L, T, NQ, NC, NU>(params, q, &kin, &limits.torque),
            speed: speed_polygon(&kin.foot_jacobian, &limits.speed),
        }
    })
}

/// `Gᵀ G(q)`: the motor torques that hold the leg still with no force at the foot.
pub fn holding_torque<L, T, const NQ: usize, const NC: usize, const NU: usize, const ND: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    kin: &MotorKinematics<T, NQ, NU, ND>,
) -> SVector<T, NU>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    mul_tn(&kin.g, &L::gravity_forces(q, params))
}

/// The largest downward push `F ≥ 0` (the foot putting `−F` along the vertical, `y` in
/// the plane and `z` in space, on the ground) the motors hold at rest within `torque`;
/// `None` where no downward force can be held, infinite where no motor takes any of it
/// (the structure holds it all).
pub fn vertical_force<T: Real, const ND: usize, const NU: usize>(
    foot_jacobian: &SMatrix<T, ND, NU>,
    hold: &SVector<T, NU>,
    torque: &SVector<T, NU>,
) -> Option<T> {
    // u_k = hold_k − F a_k with a_k = J_θ[vertical, k]: F within [lo, hi] for every
    // motor. Unbounded until a motor bounds it: infinite where no motor is loaded by a
    // vertical force (the structure holds it).
    let (mut lo, mut hi) = (T::zero(), T::one() / T::zero());
    for k in 0..NU {
        let a = foot_jacobian[(ND - 1, k)];
        let (below, above) = (-torque[k] - hold[k], torque[k] - hold[k]);
        // −F a ∈ [below, above]
        if a == T::zero() {
            if below > T::zero() || above < T::zero() {
                return None;
            }
        } else {
            let (x, y) = (-above / a, -below / a);
            let (from, to) = if x < y { (x, y) } else { (y, x) };
            lo = lo.max(from);
            hi = hi.min(to);
        }
    }
    (lo <= hi).then_some(hi)
}

/// The foot velocities reachable with motor speeds `|θ̇_k| ≤ ω_k`: the zonotope
/// `Σ [−1, 1] ω_k c_k` of `J_θ`'s columns `c_k`, `2 NU` vertices counter-clockwise.
pub fn speed_polygon<T: Real, const NU: usize>(
    foot_jacobian: &SMatrix<T, 2, NU>,
    speed: &SVector<T, NU>,
) -> Polygon<T> {
    let mut gens = [Vector2::<T>::zeros(); MAX_MOTORS];
    let n = NU.min(MAX_MOTORS);
    for (k, g) in gens.iter_mut().enumerate().take(n) {
        let c = foot_jacobian.column(k) * speed[k];
        // Each generator pointing into the upper half-plane (angle in [0, π)).
        *g = if c[1] < T::zero() || (c[1] == T::zero() && c[0] < T::zero()) {
            -c
        } else {
            c
        };
    }
    let gens = &mut gens[..n];
    for i in 1..n {
        let mut k = i;
        while k > 0 && gens[k - 1][1].atan2(gens[k - 1][0]) > gens[k][1].atan2(gens[k][0]) {
            gens.swap(k - 1, k);
            k -= 1;
        }
    }
    let mut poly = Polygon::empty();
    let mut v = Vector2::zeros();
    for g in gens.iter() {
        v -= g;
    }
    // From the lowest vertex, each generator in turn by angle, then back.
    for g in gens.iter() {
        poly.push(v);
        v += g * T::lit(2.0);
    }
    for g in gens.iter() {
        poly.push(v);
        v -= g * T::lit(2.0);
    }
    poly
}

/// The fastest vertical foot speed with motor speeds `|θ̇_k| ≤ ω_k` and no sideways
/// motion: the largest `v` with `(0, v)` in [`speed_polygon`], or `(0, 0, v)` in the
/// speed zonotope of a spatial leg ([`polytope::zonotope_reach`]).
pub fn vertical_speed<T: Real, const ND: usize, const NU: usize>(
    foot_jacobian: &SMatrix<T, ND, NU>,
    speed: &SVector<T, NU>,
) -> T {
    const { assert!(ND == 2 || ND == 3, "a foot has 2 or 3 coordinates") };
    if ND == 3 {
        let jt = SMatrix::<T, 3, NU>::from_fn(|r, c| foot_jacobian[(r, c)]);
        return polytope::zonotope_reach(&jt, speed, &nalgebra::Vector3::z());
    }
    let jt = SMatrix::<T, 2, NU>::from_fn(|r, c| foot_jacobian[(r, c)]);
    let poly = speed_polygon(&jt, speed);
    ray_reach(&poly, &Vector2::new(T::zero(), T::one()))
}

/// How far the ray from the origin along `d` stays inside a convex polygon that holds
/// the origin (zero when it does not).
pub fn ray_reach<T: Real>(poly: &Polygon<T>, d: &Vector2<T>) -> T {
    let v = poly.vertices();
    // Infinite if no edge faces the ray (a degenerate polygon, unbounded that way).
    let mut best = T::one() / T::zero();
    if v.len() < 3 {
        return T::zero();
    }
    for i in 0..v.len() {
        let (a, b) = (v[i], v[(i + 1) % v.len()]);
        // Outward normal of a counter-clockwise edge.
        let n = Vector2::new(b[1] - a[1], a[0] - b[0]);
        let along = n.dot(d);
        let offset = n.dot(&a);
        if offset < T::zero() {
            return T::zero();
        }
        if along > T::zero() {
            best = best.min(offset / along);
        }
    }
    best
}

/// `A C Aᵀ` with `C` the inverse inertia of the closed chain (Khatib's `Λ⁻¹` for the
/// rows `A`): `C = M⁻¹ − M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁻¹ J M⁻¹`, the joints in `locked` fixed (their
/// rows and columns of `M` replaced by the identity and their columns of `J` and `A`
/// zeroed, so they neither move nor couple).
fn delassus<T: Real, const NQ: usize, const NC: usize, const NR: usize>(
    m: &SMatrix<T, NQ, NQ>,
    j: &SMatrix<T, NC, NQ>,
    a: &SMatrix<T, NR, NQ>,
    locked: &[bool; NQ],
    redundant_rows: usize,
) -> Result<SMatrix<T, NR, NR>, AnalysisError> {
    // A closure row that is zero before any joint is locked is not a row that locking
    // freed: the closures lose rank at this pose (a five-bar stretched flat), a
    // singularity, not a row to leave out (Minitaur at q = 0 gave ξ = 0 and a Λ⁻¹ with a
    // zero row).
    let zero_rows = (0..NC).filter(|&r| j.row(r).amax() == T::zero()).count();
    if zero_rows > redundant_rows {
        return Err(AnalysisError::PassiveSingular);
    }
    let (mut m, mut j, mut a) = (*m, *j, *a);
    for (c, &l) in locked.iter().enumerate() {
        if l {
            m.row_mut(c).fill(T::zero());
            m.column_mut(c).fill(T::zero());
            m[(c, c)] = T::one();
            j.column_mut(c).fill(T::zero());
            a.column_mut(c).fill(T::zero());
        }
    }
    let chol = Cholesky::new(&m).ok_or(AnalysisError::MassMatrix)?;
    if chol.rcond < rcond_floor::<T>() {
        return Err(AnalysisError::MassMatrix);
    }
    let mut y = a.transpose();
    chol.solve_mut(&mut y); // M⁻¹ Aᵀ
    let mut d = mul(&a, &y);
    if NC > 0 {
        // Rows of J with every column locked are no constraint: the pivots leave them out.
        let free_rows = (0..NC).filter(|&r| j.row(r).amax() == T::zero()).count();
        let mut x = j.transpose();
        chol.solve_mut(&mut x); // M⁻¹ Jᵀ
        let s = mul(&j, &x);
        let factor = PivotedLdlt::new(&s, redundant_rows.max(free_rows), rcond_floor::<T>());
        let factor = match factor {
            Some(f) => f,
            // Locking joints can make more rows repeat the others than the leg's
            // redundant rows: allow every row that is not independent.
            None => PivotedLdlt::new(&s, NC, rcond_floor::<T>())
                .ok_or(AnalysisError::PassiveSingular)?,
        };
        let jy = mul(&j, &y); // J M⁻¹ Aᵀ
        let mut w = jy;
        factor.solve_mut(&mut w);
        d -= mul_tn(&jy, &w);
    }
    if !all_finite_slice(d.as_slice()) {
        return Err(AnalysisError::NonFinite);
    }
    Ok((d + d.transpose()) * T::lit(0.5))
}

/// The foot's inverse operational-space inertia `Λ⁻¹ = J_f C J_fᵀ` (1/kg) at `q`: the
/// foot's velocity change per unit impulse there. The joints of `frame.held` fixed (the
/// leg in its body's frame); with `motors_locked`, the motors' joints too.
pub fn foot_inverse_inertia<
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
    frame: &LegFrame<NQ>,
    motors_locked: bool,
) -> Result<SMatrix<T, ND, ND>, AnalysisError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    check_on_closures::<L, T, NQ, NC, NU>(params, q)?;
    inverse_inertia_on_closures::<L, T, NQ, NC, NU, ND, NP>(params, q, frame, motors_locked)
}

/// [`foot_inverse_inertia`] at a pose already checked to be on its closures (the check
/// solves for `φ`; [`point_measures`] does it once for all its measures).
fn inverse_inertia_on_closures<
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
    frame: &LegFrame<NQ>,
    motors_locked: bool,
) -> Result<SMatrix<T, ND, ND>, AnalysisError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    let locked: [bool; NQ] =
        core::array::from_fn(|c| frame.held[c] || (motors_locked && L::ACTUATED.contains(&c)));
    delassus(
        &L::mass_matrix(q, params),
        &L::constraint_jacobian(q, params),
        &L::foot_jacobian(q, params),
        &locked,
        L::REDUNDANT_ROWS,
    )
}

/// The effective mass along the unit direction `d` of a foot with inverse inertia
/// `inv`: `1 / (dᵀ Λ⁻¹ d)` (infinite where the foot cannot move along `d`).
pub fn effective_mass<T: Real, const ND: usize>(inv: &SMatrix<T, ND, ND>, d: &SVector<T, ND>) -> T {
    let x = d.dot(&(inv * d));
    if x > T::zero() {
        T::one() / x
    } else {
        T::one() / T::zero()
    }
}

/// The effective mass felt by a vertical impact at the foot (`y` in the plane, `z` in
/// space) with inverse inertia `inv` at `q`: [`effective_mass`] along the vertical, and
/// infinite where `inv` has no vertical part beyond rounding, judged against the open
/// chain's `J_f M⁻¹ J_fᵀ` (a leg stretched straight down gave 1.9e30 kg, rounding's
/// reciprocal).
pub fn vertical_effective_mass<
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
    inv: &SMatrix<T, ND, ND>,
) -> T
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    let up = vertical::<T, ND>();
    let along = up.dot(&(inv * up));
    let open = delassus::<T, NQ, 0, ND>(
        &L::mass_matrix(q, params),
        &SMatrix::zeros(),
        &L::foot_jacobian(q, params),
        &[false; NQ],
        0,
    )
    .map_or(T::zero(), |d| d.amax());
    if along <= open * T::default_epsilon() * T::lit(1e3) {
        return T::one() / T::zero();
    }
    effective_mass(inv, &up)
}

/// What the body of [`Body::Translating`] needs from the leg's parameters: copies with
/// gravity along each axis of the leg's space (`x`, `y`, and `z` on a spatial leg) and
/// off (so that `∂V/∂q` gives the momentum Jacobian of the links, `P = Σ mᵢ J_cᵢ`), and
/// the leg's mass. Prepared once per parameter set.
#[derive(Clone, Copy, Debug)]
pub struct BodyCoupling<P> {
    /// Gravity of 1 along axis `i` (the first `dimension` used).
    units: [P; 3],
    zero: P,
    /// 2 on a planar leg, 3 on a spatial one.
    dimension: usize,
    /// The leg's mass (kg): the sum of its links' `<link>_mass`.
    pub leg_mass: f64,
}

impl<P> BodyCoupling<P> {
    /// From the parameters of leg `L`; `None` without `gravity_x`, `gravity_y` (and
    /// `gravity_z` on a spatial leg) or a link's `<link>_mass`. A ball joint's three
    /// coordinates (`rod.x`, `rod.y`, `rod.z`) move one link, `rod`, counted once.
    pub fn new<L, T, const NQ: usize, const NC: usize, const NU: usize>(params: &P) -> Option<Self>
    where
        L: LegDynamics<NQ, NC, NU, Params<T> = P>,
        T: Real,
        P: Parameters<T> + Clone,
    {
        let index = |name: &str| P::NAMES.iter().position(|n| *n == name);
        let dimension = L::DIMENSION;
        let axes = [
            index("gravity_x")?,
            index("gravity_y")?,
            index("gravity_z").unwrap_or(usize::MAX),
        ];
        if dimension == 3 && axes[2] == usize::MAX {
            return None;
        }
        let mut leg_mass = 0.0;
        for (j, joint) in L::JOINT_NAMES.iter().enumerate() {
            // A ball joint's second and third angles move the link its first one names.
            if L::BALL_JOINTS.iter().any(|&b| j == b + 1 || j == b + 2) {
                continue;
            }
            let link = if L::BALL_JOINTS.contains(&j) {
                joint.strip_suffix(".x").unwrap_or(joint)
            } else {
                joint
            };
            let i = P::NAMES.iter().position(|n| {
                n.strip_prefix(link)
                    .and_then(|rest| rest.strip_prefix('_'))
                    .is_some_and(|rest| rest == "mass")
            })?;
            let m: f64 = params.get(i)?.to_subset()?;
            leg_mass += m;
        }
        let with = |along: Option<usize>| {
            let mut p = params.clone();
            let unit = core::array::from_fn::<_, 3, _>(|k| {
                (axes[k], T::lit(if along == Some(k) { 1.0 } else { 0.0 }))
            });
            p.set_many(&unit[..dimension]);
            p
        };
        Some(BodyCoupling {
            units: [with(Some(0)), with(Some(1)), with(Some(2))],
            zero: with(None),
            dimension,
            leg_mass,
        })
    }
}

/// The impact mitigation factor `ξ = det(I − Λ Λ_L⁻¹) = det(Λ⁻¹ − Λ_L⁻¹) / det Λ⁻¹`
/// (Wensing et al. 2017, §IV) at the foot at pose `q`. On a leg with body joints of its
/// own (`frame.has_body()`), `body` must be [`Body::Fixed`] and the spec's body moves;
/// otherwise the hip is put on `body` (a translating body of mass `m_b`: with the links'
/// momentum Jacobian `P` and `m_t = m_b + m_leg`, `Λ⁻¹ = I/m_t + Ā C(M̄) Āᵀ` with
/// `M̄ = M − PᵀP/m_t`, `Ā = J_f − P/m_t`; locked, `Λ_L = m_t I`). In space the body
/// translates along all three axes and the determinants are 3 × 3.
pub fn impact_mitigation<
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
    frame: &LegFrame<NQ>,
    body: &Body<T>,
    coupling: Option<&BodyCoupling<L::Params<T>>>,
) -> Result<T, AnalysisError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    check_on_closures::<L, T, NQ, NC, NU>(params, q)?;
    let actuated: [bool; NQ] = core::array::from_fn(|c| L::ACTUATED.contains(&c));
    let m = L::mass_matrix(q, params);
    let j = L::constraint_jacobian(q, params);
    let jf = L::foot_jacobian(q, params);
    let none = [false; NQ];
    let (free, locked) = match (body, frame.has_body()) {
        (Body::Translating { mass }, false) => {
            let c = coupling.ok_or(Inapplicable::MissingParameters)?;
            if c.dimension != ND {
                return Err(Inapplicable::MissingParameters.into());
            }
            let g0 = L::gravity_forces(q, &c.zero);
            // ∂V/∂q with unit gravity along x is −Σ mᵢ J_cᵢ,xᵀ (springs cancel with g0).
            let mut p = SMatrix::<T, ND, NQ>::zeros();
            for (r, unit) in c.units.iter().enumerate().take(ND) {
                p.set_row(r, &(g0 - L::gravity_forces(q, unit)).transpose());
            }
            let total = *mass + T::lit(c.leg_mass);
            if total <= T::zero() || !total.is_finite() {
                return Err(AnalysisError::NonFinite);
            }
            let inv_t = T::one() / total;
            let m_bar = m - mul_tn(&p, &p) * inv_t;
            let a_bar = jf - p * inv_t;
            let own = SMatrix::<T, ND, ND>::identity() * inv_t;
            let leg_free = delassus(&m_bar, &j, &a_bar, &none, L::REDUNDANT_ROWS)?;
            // A foot the closures hold to the body moves only with it: free and locked are
            // both the body's own 1/m, and their difference is rounding (ξ = 3 was found).
            let scale = leg_free.amax();
            let det = small_determinant(leg_free);
            if !det.is_finite() || det <= power(scale, ND) * T::default_epsilon() * T::lit(1e3) {
                return Err(Inapplicable::FootHeld.into());
            }
            let free = own + leg_free;
            let locked = own + delassus(&m_bar, &j, &a_bar, &actuated, L::REDUNDANT_ROWS)?;
            (free, locked)
        }
        _ => (
            delassus(&m, &j, &jf, &none, L::REDUNDANT_ROWS)?,
            delassus(&m, &j, &jf, &actuated, L::REDUNDANT_ROWS)?,
        ),
    };
    let det_free = small_determinant(free);
    if !det_free.is_finite() {
        return Err(AnalysisError::NonFinite);
    }
    // Singular to rounding, relative to its size: a foot a closure holds gave a det of
    // rounding's size, and ξ = 3.
    // The scale is the foot's inverse inertia with the closures cut (J_f M⁻¹ J_fᵀ): a
    // pinned foot's Λ⁻¹ is all rounding, small against it.
    let scale = delassus::<T, NQ, 0, ND>(&m, &SMatrix::zeros(), &jf, &none, 0)?
        .amax()
        .max(free.amax());
    if det_free <= power(scale, ND) * T::default_epsilon() * T::lit(1e3) {
        // Λ⁻¹ with the motors free is singular: a direction the foot cannot move in,
        // whatever the motors (their number is not the reason).
        return Err(Inapplicable::FootHeld.into());
    }
    // On a translating body Λ_L⁻¹ holds the body's own 1/m: never singular, only small for
    // a heavy body, where ξ → 1 (a body of 1e308 kg was refused as "give its mass").
    let on_body = matches!(body, Body::Translating { .. }) && !frame.has_body();
    if !on_body && locked.amax() <= free.amax() * T::default_epsilon() * T::lit(1e3) {
        return Err(Inapplicable::RigidWhenLocked.into());
    }
    Ok(small_determinant(free - locked) / det_free)
}

/// `det A` of the foot's small matrices: the 2 × 2 closed form in the plane (as before
/// spatial legs, to the bit), elimination otherwise.
fn small_determinant<T: Real, const N: usize>(a: SMatrix<T, N, N>) -> T {
    if N == 2 {
        a[(0, 0)] * a[(1, 1)] - a[(1, 0)] * a[(0, 1)]
    } else {
        determinant(a)
    }
}

/// `x^n`.
fn power<T: Real>(x: T, n: usize) -> T {
    (0..n).fold(T::one(), |p, _| p * x)
}

/// Every measure at one assembled pose, in the leg's frame; the foot has `ND`
/// coordinates (2 planar, the default; 3 spatial, vertical `z`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointMeasures<T: Real, const NQ: usize, const NU: usize, const ND: usize = 2> {
    /// The foot (base frame, m).
    pub foot: SVector<T, ND>,
    /// The motor angles.
    pub motor_angles: SVector<T, NU>,
    /// `q̇ = G θ̇` and `J_θ`.
    pub kinematics: MotorKinematics<T, NQ, NU, ND>,
    /// Passive joints' rank ("type II"): signed Hadamard ratio of `J_p` where it is square,
    /// `√rcond(J_p J_pᵀ)` otherwise; zero at the singularity.
    pub passive_rank: T,
    /// Foot's rank ("type I", [`foot_rank`]): `σ_min / σ_max` of the foot's Jacobian on an
    /// orthonormal basis of the mechanism's motions, signed where that is square; zero
    /// at the singularity, finite at a passive one.
    pub foot_rank: T,
    /// `κ(J_θ) = σ_max / σ_min` over the foot's `ND` directions (infinite with fewer
    /// motors than those: `J_θ` has lost rank).
    pub condition: T,
    /// Largest downward push at rest within the torque limits (N); `None` where the
    /// motors cannot push down here (or fewer motors than the foot's coordinates).
    pub vertical_force: Option<T>,
    /// Fastest vertical foot speed within the speed limits (m/s), no sideways motion.
    pub vertical_speed: T,
    /// `Λ⁻¹` with the motors free (rotors backdriven), the body held (1/kg).
    pub inverse_inertia: SMatrix<T, ND, ND>,
    /// `Λ⁻¹` with the motors locked, the body held (zero on a fully actuated leg).
    pub inverse_inertia_locked: SMatrix<T, ND, ND>,
    /// Effective mass felt by a vertical impact at the foot, motors free (kg).
    pub effective_mass: T,
}

/// Every measure at the assembled pose `q` (allocation-free). Fails where motor
/// coordinates do not apply or the passive joints lose rank.
pub fn point_measures<
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
    frame: &LegFrame<NQ>,
    limits: &MotorLimits<T, NU>,
) -> Result<PointMeasures<T, NQ, NU, ND>, AnalysisError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    T: Real,
{
    // Measures of a pose the leg cannot take are refused, not returned (issue 29).
    check_on_closures::<L, T, NQ, NC, NU>(params, q)?;
    let kin = motor_kinematics::<L, T, NQ, NC, NU, ND, NP>(params, q, frame)?;
    let jt = kin.foot_jacobian;
    // The motors span the foot's directions (two in the plane, three in space).
    let spans = NU >= ND;
    let (hi, lo) = extreme_singular_values(&jt);
    let condition = if spans && lo > T::zero() {
        hi / lo
    } else {
        // Fewer motors than directions (or a lost direction): σ_min = 0.
        T::one() / T::zero()
    };
    let hold = holding_torque::<L, T, NQ, NC, NU, ND>(params, q, &kin);
    let inverse_inertia =
        inverse_inertia_on_closures::<L, T, NQ, NC, NU, ND, NP>(params, q, frame, false)?;
    let inverse_inertia_locked =
        inverse_inertia_on_closures::<L, T, NQ, NC, NU, ND, NP>(params, q, frame, true)?;
    let foot = L::foot_position(q, params);
    // A NaN parameter the terms do not use passes every solve: the foot shows it.
    if !foot.iter().all(|x| x.is_finite()) {
        return Err(AnalysisError::NonFinite);
    }
    Ok(PointMeasures {
        foot,
        motor_angles: SVector::<T, NU>::from_fn(|k, _| q[L::ACTUATED[k]]),
        kinematics: kin,
        passive_rank: kin.passive_rank,
        foot_rank: foot_rank::<L, T, NQ, NC, NU, ND>(frame, &kin),
        condition,
        vertical_force: if spans {
            vertical_force(&jt, &hold, &limits.torque)
        } else {
            None
        },
        vertical_speed: if spans {
            vertical_speed(&jt, &limits.speed)
        } else {
            T::zero()
        },
        inverse_inertia,
        inverse_inertia_locked,
        effective_mass: vertical_effective_mass::<L, T, NQ, NC, NU, ND, NP>(
            params,
            q,
            &inverse_inertia,
        ),
    })
}

/// The unit vertical of the foot's space: `y` in the plane, `z` in space.
pub fn vertical<T: Real, const ND: usize>() -> SVector<T, ND> {
    SVector::<T, ND>::from_fn(|r, _| if r + 1 == ND { T::one() } else { T::zero() })
}

/// The passive joints' rank measure at `q` ([`PointMeasures::passive_rank`]), computed
/// even where the passive joints lose rank (where [`motor_kinematics`] fails).
pub fn passive_rank_at<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    frame: &LegFrame<NQ>,
) -> T
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let fixed: [bool; NQ] = core::array::from_fn(|c| frame.held[c] || L::ACTUATED.contains(&c));
    passive_rank(
        &L::constraint_jacobian(q, params),
        &fixed,
        L::REDUNDANT_ROWS,
    )
}
