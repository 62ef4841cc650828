//! The model trait: what generated code provides and the runtime consumes.

use core::fmt::Debug;
use core::ops::{Add, Div, Mul, Neg, Sub};
use nalgebra::{ComplexField, RealField, SMatrix, SVector};

/// The scalar the generated code is generic over (`f32` and `f64`).
///
/// Generated code writes every constant as an `f64` literal that round-trips exactly and
/// converts it with [`Real::lit`], so `f64` models carry the derivation's constants bit
/// for bit and `f32` models their nearest `f32`.
pub trait Real: RealField + Copy {
    /// Converts an `f64` literal of generated code into this scalar.
    fn lit(value: f64) -> Self;

    /// `(sin self, cos self)` with one argument reduction: the one trigonometric call
    /// generated code makes per revolute joint. Within an ulp of `(sin, cos)`; the
    /// default is nalgebra's `sin_cos`.
    #[inline(always)]
    fn sincos(self) -> (Self, Self) {
        self.sin_cos()
    }
}

impl Real for f64 {
    #[inline(always)]
    fn lit(value: f64) -> Self {
        value
    }

    #[inline(always)]
    fn sincos(self) -> (Self, Self) {
        crate::model::trig::sincos(self)
    }
}

impl Real for f32 {
    #[inline(always)]
    fn lit(value: f64) -> Self {
        value as f32
    }

    /// In `f64`, rounded once to `f32`.
    #[inline(always)]
    fn sincos(self) -> (Self, Self) {
        let (s, c) = crate::model::trig::sincos(self as f64);
        (s as f32, c as f32)
    }
}

/// The arithmetic generated code does, and nothing more: the runtime's scalars (every
/// [`Real`], `f64` and `f32`) and SIMD lanes ([`crate::simd::F64x4`], several states in
/// one call) implement it. Generated functions and the [`LegModel`] methods are generic
/// over it; the runtime's algorithms, which compare and branch, over [`Real`].
pub trait Arithmetic:
    Copy
    + Debug
    + PartialEq
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// An `f64` literal of generated code in this scalar ([`Real::lit`]).
    fn lit(value: f64) -> Self;
    /// `(sin self, cos self)` with one argument reduction ([`Real::sincos`]).
    fn sincos(self) -> (Self, Self);
    /// `√self`.
    fn sqrt(self) -> Self;
    /// `sin self` (`self` in rad).
    fn sin(self) -> Self;
    /// `cos self` (`self` in rad).
    fn cos(self) -> Self;
    /// `tan self` (`self` in rad).
    fn tan(self) -> Self;
    /// `asin self` (rad).
    fn asin(self) -> Self;
    /// `acos self` (rad).
    fn acos(self) -> Self;
    /// `atan self` (rad).
    fn atan(self) -> Self;
    /// `sinh self`.
    fn sinh(self) -> Self;
    /// `cosh self`.
    fn cosh(self) -> Self;
    /// `tanh self`.
    fn tanh(self) -> Self;
    /// `exp self`.
    fn exp(self) -> Self;
    /// The natural logarithm `ln self`.
    fn ln(self) -> Self;
    /// `|self|`.
    fn abs(self) -> Self;
    /// `self^exponent`.
    fn powf(self, exponent: Self) -> Self;
    /// `atan2(self, x)` (rad): the angle of the point `(x, self)`.
    fn atan2(self, x: Self) -> Self;
    /// The smaller of `self` and `other`.
    fn min(self, other: Self) -> Self;
    /// The larger of `self` and `other`.
    fn max(self, other: Self) -> Self;
}

impl<T: Real> Arithmetic for T {
    #[inline(always)]
    fn lit(value: f64) -> Self {
        <T as Real>::lit(value)
    }
    #[inline(always)]
    fn sincos(self) -> (Self, Self) {
        <T as Real>::sincos(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        ComplexField::sqrt(self)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        ComplexField::sin(self)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        ComplexField::cos(self)
    }
    #[inline(always)]
    fn tan(self) -> Self {
        ComplexField::tan(self)
    }
    #[inline(always)]
    fn asin(self) -> Self {
        ComplexField::asin(self)
    }
    #[inline(always)]
    fn acos(self) -> Self {
        ComplexField::acos(self)
    }
    #[inline(always)]
    fn atan(self) -> Self {
        ComplexField::atan(self)
    }
    #[inline(always)]
    fn sinh(self) -> Self {
        ComplexField::sinh(self)
    }
    #[inline(always)]
    fn cosh(self) -> Self {
        ComplexField::cosh(self)
    }
    #[inline(always)]
    fn tanh(self) -> Self {
        ComplexField::tanh(self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        ComplexField::exp(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        ComplexField::ln(self)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        ComplexField::abs(self)
    }
    #[inline(always)]
    fn powf(self, exponent: Self) -> Self {
        ComplexField::powf(self, exponent)
    }
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        RealField::atan2(self, x)
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        RealField::min(self, other)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        RealField::max(self, other)
    }
}

/// Named access to a model's parameters, for identification, randomization and tools
/// that treat every geometry alike.
pub trait Parameters<T>: Sized {
    /// The field names, in declaration order.
    const NAMES: &'static [&'static str];
    /// The value of parameter `i` (an index into [`Parameters::NAMES`]).
    fn get(&self, i: usize) -> Option<T>;
    /// Sets parameter `i`; returns `false` (and changes nothing) if there is none.
    fn set(&mut self, i: usize, value: T) -> bool {
        self.set_many(&[(i, value)])
    }
    /// Sets several parameters `(i, value)`, in order, then prepares the parameter-only
    /// quantities once, and only if a changed parameter enters them (a floating robot's
    /// gravity does not); returns `false` (and changes nothing) if any `i` names no parameter.
    fn set_many(&mut self, changes: &[(usize, T)]) -> bool;
}

/// The terms of the constrained equations of motion at one state, evaluated together so
/// that they share subexpressions (`M q̈ + N = Jᵀ F + B u`, `J q̈ + J̇ q̇ = 0`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DynamicsTerms<T: Arithmetic, const NQ: usize, const NC: usize> {
    /// `M(q)`, including the reflected rotor inertia `I_rotor · gear²` of actuated joints.
    pub mass_matrix: SMatrix<T, NQ, NQ>,
    /// `N(q, q̇) = C(q, q̇) q̇ + G(q)`.
    pub bias_forces: SVector<T, NQ>,
    /// `J(q) = ∂φ/∂q`.
    pub constraint_jacobian: SMatrix<T, NC, NQ>,
    /// `J̇(q, q̇) q̇`.
    pub constraint_bias: SVector<T, NC>,
}

/// The derivatives of the constrained equations of motion at one state, accelerations
/// `a` and closure forces `f` (DESIGN.md §3.2), evaluated together: what linearizing the
/// forward dynamics needs besides the [`DynamicsTerms`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DynamicsDerivatives<T: Arithmetic, const NQ: usize, const NC: usize> {
    /// `∂(M a + N − Jᵀ f)/∂q`.
    pub dynamics_q: SMatrix<T, NQ, NQ>,
    /// `∂(N + D q̇)/∂q̇`.
    pub dynamics_qd: SMatrix<T, NQ, NQ>,
    /// `∂(J a + J̇ q̇)/∂q`.
    pub constraint_q: SMatrix<T, NC, NQ>,
    /// `J̇(q, q̇)`; `∂(J̇ q̇)/∂q̇ = 2 J̇`.
    pub jacobian_rate: SMatrix<T, NC, NQ>,
}

/// The derivatives of a set of constraint rows `J` (closures, or contact points `J_c`) at
/// forces `f` on them and accelerations `a`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstraintDerivatives<T: Arithmetic, const NQ: usize, const NR: usize> {
    /// `∂(Jᵀ f)/∂q`.
    pub force_q: SMatrix<T, NQ, NQ>,
    /// `∂(J a)/∂q`.
    pub jacobian_q: SMatrix<T, NR, NQ>,
    /// `∂(J̇ q̇)/∂q`.
    pub bias_q: SMatrix<T, NR, NQ>,
    /// `J̇(q, q̇)`.
    pub jacobian_rate: SMatrix<T, NR, NQ>,
}

/// How a joint moves its link (DESIGN.md §3, "Joints and springs").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum JointKind {
    /// `q` (rad) turns the link about the joint point.
    Revolute,
    /// `q` (m) slides the link along a fixed axis of its parent, keeping its orientation.
    Prismatic,
}

/// A spring of the spec: on joint `a` (`½ k (q_a − rest)²`), or, with `b`, a coupling
/// spring on `q_a − q_b` (a series-elastic actuator when `a` is a motor's joint).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Spring {
    /// The spec's name of the spring.
    pub name: &'static str,
    /// The joint it acts on (an index into `q`); for a coupling spring, the first of
    /// `q_a − q_b`.
    pub a: usize,
    /// The second joint of a coupling spring (`½ k (q_a − q_b − rest)²`); `None` for a
    /// spring on joint `a` alone.
    pub b: Option<usize>,
    /// Indices of its stiffness and rest value in the parameters ([`Parameters::get`]):
    /// they are run-time parameters like every other.
    pub stiffness: usize,
    /// Index of its rest value in the parameters (rad, or m on a prismatic joint).
    pub rest: usize,
}

/// What every leg has in any dimension: its structure and its dynamics (`M`, `N`, `φ`,
/// `J`, `J̇ q̇`, energies, derivatives). Implemented by generated code (`cargo xtask gen`),
/// one type per geometry, beside [`LegModel`] (its points); the runtime's algorithms that
/// read only these (forward dynamics, assembly, projection) are bounded by it and so take
/// planar and spatial legs alike.
///
/// - `NQ`: joints (one per link, relative angles, in spec order);
/// - `NC`: closure rows (per closure, the coordinates of point a minus point b: two on a
///   planar leg, three on a spatial one);
/// - `NU`: actuated joints.
///
/// All methods are straight-line code: no allocation, no panic, no loop.
pub trait LegDynamics<const NQ: usize, const NC: usize, const NU: usize> {
    /// The geometry's name (its spec's file stem).
    const NAME: &'static str;
    /// The name of the link each joint moves, in coordinate order.
    const JOINT_NAMES: [&'static str; NQ];
    /// How each joint moves, in coordinate order.
    const JOINT_KINDS: [JointKind; NQ];
    /// The parent joint of each joint (`None`: it hangs from the base), in coordinate
    /// order: the spec's tree.
    const PARENTS: [Option<usize>; NQ];
    /// The spec's springs.
    const SPRINGS: &'static [Spring];
    /// Indices (into `q`) of the actuated joints, in the order of the input vector `u`.
    const ACTUATED: [usize; NU];
    /// A typical assembled pose (rad, or m for a prismatic joint) from the spec: the default guess of loop assembly
    /// (it picks the assembly mode) and the default initial state of simulations.
    const HOME: [f64; NQ];
    /// How many closure rows the others imply on this geometry (a parallelogram closed
    /// twice): `NC − rank J`, found by `cargo xtask gen` at the assembled home pose with the
    /// spec's parameters. The solvers' pivots leave that many rows out (which ones depends
    /// on the pose) and hold their forces at zero.
    const REDUNDANT_ROWS: usize;
    /// Degrees of freedom of the closed chain, `NQ − rank J`, at the assembled home pose.
    /// Compared with `NU`, it says which methods apply (see [`crate::dynamics::structure`]).
    const MOBILITY: usize;
    /// The first coordinate of each ball joint (spatial legs): its three angles
    /// `q[b..b + 3]` are `(α, β, γ)` of `R = R_x(α) R_y(β) R_z(γ)` in the link's frame,
    /// singular at `cos β = 0`, where forward dynamics returns
    /// [`DynamicsError::BallJointSingular`](crate::dynamics::DynamicsError::BallJointSingular).
    /// None by default.
    const BALL_JOINTS: &'static [usize] = &[];
    /// The free joint of a floating robot's body (spatial robots): its first coordinate
    /// `f`, with `q[f..f + 3]` a translation along the base frame's axes (m) and
    /// `q[f + 3..f + 6]` a ball joint's angles (listed in [`LegDynamics::BALL_JOINTS`]).
    /// The base frame is then not a place in the world but the chart's centre, which
    /// [`crate::robot`] keeps on the body's pose (a position and a unit quaternion) and
    /// moves with it every step; gravity, a parameter, is turned into it. `None` (the
    /// default): the base is fixed.
    const FREE_JOINT: Option<usize> = None;
    /// The space the leg moves in: 2 for a planar leg (the default), 3 for a spatial one;
    /// the `ND` of its [`LegModel`] (a foot with that many coordinates).
    const DIMENSION: usize = 2;
    /// The closures that are rods (spatial legs): closure `k` listed here has one row in
    /// `φ`, `(|a − b|² − L²) / (2L)`, zero where the points are the rod's length apart
    /// (and equal to `|a − b| − L` to first order); every other closure one row per
    /// coordinate of `a − b`. Rows follow the closures' order. None by default.
    const DISTANCE_CLOSURES: &'static [usize] = &[];
    /// The revolute closures (spatial legs): closure `k` listed here has five rows, the
    /// point's three (`a − b`) and two that keep link a's axis along link b's,
    /// `(R_a â)·(R_b û)` and `(R_a â)·(R_b ŵ)` (`û`, `ŵ` perpendicular to b's axis): their
    /// forces are the joint's reaction force and the two moments across its axis. None by
    /// default.
    const REVOLUTE_CLOSURES: &'static [usize] = &[];

    /// The physical parameters (lengths, masses, centres of mass, inertias, rotor
    /// inertias and gear ratios, damping, gravity). `Default` holds the spec's values.
    type Params<T: Arithmetic>: Clone + Copy + Debug + PartialEq + Default + Parameters<T>;

    /// `M(q) = ∂²L/∂q̇²`, with reflected rotor inertia on the actuated joints.
    fn mass_matrix<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>) -> SMatrix<T, NQ, NQ>;
    /// `N(q, q̇) = (∂²L/∂q̇∂q) q̇ − ∂L/∂q = C q̇ + G` (without damping).
    fn bias_forces<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> SVector<T, NQ>;
    /// `G(q) = ∂V/∂q`.
    fn gravity_forces<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>) -> SVector<T, NQ>;
    /// Viscous joint damping torques `D q̇` (they enter as `M q̈ + N + D q̇ = …`).
    fn damping_forces<T: Arithmetic>(qd: &SVector<T, NQ>, p: &Self::Params<T>) -> SVector<T, NQ>;
    /// The closure residual `φ(q)`: for each closure, point a minus point b.
    fn closure_residual<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>) -> SVector<T, NC>;
    /// `J(q) = ∂φ/∂q`.
    fn constraint_jacobian<T: Arithmetic>(
        q: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> SMatrix<T, NC, NQ>;
    /// `J̇(q, q̇) q̇`.
    fn constraint_bias<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> SVector<T, NC>;
    /// Kinetic energy `½ q̇ᵀ M q̇` (links and rotors).
    fn kinetic_energy<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> T;
    /// The leg's size at `q` (m): the largest coordinate of any joint or link tip in the
    /// base frame. A closure residual is a difference of such coordinates, so its rounding
    /// error scales with it, and so do the runtime's tolerances.
    fn leg_size<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>) -> T;
    /// Potential energy `−Σ m g·c` (zero at the base origin).
    fn potential_energy<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>) -> T;
    /// `M`, `N`, `J` and `J̇ q̇` together, sharing subexpressions.
    fn dynamics_terms<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> DynamicsTerms<T, NQ, NC>;
    /// `∂(M a)/∂q` at the accelerations `a`.
    fn mass_matrix_derivative<T: Arithmetic>(
        q: &SVector<T, NQ>,
        a: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> SMatrix<T, NQ, NQ>;
    /// `(∂N/∂q, ∂N/∂q̇)`.
    fn bias_forces_derivatives<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> (SMatrix<T, NQ, NQ>, SMatrix<T, NQ, NQ>);
    /// The closures' `∂(Jᵀ f)/∂q`, `∂(J a)/∂q`, `∂(J̇ q̇)/∂q` and `J̇`.
    fn constraint_derivatives<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        a: &SVector<T, NQ>,
        f: &SVector<T, NC>,
        p: &Self::Params<T>,
    ) -> ConstraintDerivatives<T, NQ, NC>;
    /// What linearizing the forward dynamics needs, together ([`DynamicsDerivatives`]).
    fn dynamics_derivatives<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        a: &SVector<T, NQ>,
        f: &SVector<T, NC>,
        p: &Self::Params<T>,
    ) -> DynamicsDerivatives<T, NQ, NC>;
}

/// A leg's points: the foot, the joints, the link tips and the closure points, in `ND`
/// coordinates (2 for a planar leg, the default: `LegModel<NQ, NC, NU>` is a planar leg;
/// 3 for a spatial one). `NP` counts the closure points, two per closure (`NC` on a
/// planar leg, the default).
///
/// All methods are straight-line code: no allocation, no panic, no loop.
pub trait LegModel<
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize = 2,
    const NP: usize = NC,
>: LegDynamics<NQ, NC, NU>
{
    /// The foot point in the base frame.
    fn foot_position<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>) -> SVector<T, ND>;
    /// `J_f(q) = ∂(foot)/∂q`.
    fn foot_jacobian<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>) -> SMatrix<T, ND, NQ>;
    /// `J̇_f(q, q̇) q̇`.
    fn foot_bias<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> SVector<T, ND>;
    /// Each link's joint position in the base frame (column `i` for joint `i`).
    fn joint_positions<T: Arithmetic>(
        q: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> SMatrix<T, ND, NQ>;
    /// Each link's tip (the end of its length vector) in the base frame.
    fn link_tips<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>) -> SMatrix<T, ND, NQ>;
    /// The closure points in the base frame: columns `2k` and `2k + 1` are points a and b
    /// of closure `k` (they coincide on an assembled leg).
    fn closure_points<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>)
        -> SMatrix<T, ND, NP>;
}

/// A leg's contact points and the ground they may touch (DESIGN.md §3.1), in `ND`
/// coordinates (2 for a planar leg, the default; 3 for a spatial one). Every planar
/// generated model implements it; a leg without `[[contacts]]` has `NK = 0`.
///
/// - `NK`: contact rows, `ND` per contact point (its base-frame coordinates), in spec
///   order.
///
/// The ground is `n · x = d` (a line in the plane, a plane in space) with unit normal `n`
/// pointing out of the ground; a contact's gap is `n · x_c − d`.
pub trait ContactModel<
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize = 2,
>: LegDynamics<NQ, NC, NU>
{
    /// The contact points' names; contact `k` owns rows `ND k … ND k + ND − 1`.
    const CONTACT_NAMES: &'static [&'static str];
    /// The spec's Coulomb friction coefficient of each contact with the ground.
    const CONTACT_FRICTION: &'static [f64];
    /// The spec's ground normal `n` (unit, base frame).
    const GROUND_NORMAL: [f64; ND];
    /// The spec's ground offset `d` (m).
    const GROUND_OFFSET: f64;

    /// The contact points in the base frame, stacked `(x₀, y₀, [z₀,] x₁, y₁, …)`.
    fn contact_positions<T: Arithmetic>(q: &SVector<T, NQ>, p: &Self::Params<T>) -> SVector<T, NK>;
    /// `J_c(q) = ∂x_c/∂q`, the rows of [`ContactModel::contact_positions`].
    fn contact_jacobian<T: Arithmetic>(
        q: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> SMatrix<T, NK, NQ>;
    /// `J̇_c(q, q̇) q̇`.
    fn contact_bias<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        p: &Self::Params<T>,
    ) -> SVector<T, NK>;
    /// The contact rows' `∂(J_cᵀ λ)/∂q`, `∂(J_c a)/∂q`, `∂(J̇_c q̇)/∂q` and `J̇_c`, with `λ`
    /// the forces on the contact points in the base frame.
    fn contact_derivatives<T: Arithmetic>(
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        a: &SVector<T, NQ>,
        lambda: &SVector<T, NK>,
        p: &Self::Params<T>,
    ) -> ConstraintDerivatives<T, NQ, NK>;
}
