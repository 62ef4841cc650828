//! Contact with the ground: the contact rows in the ground's frame, the constrained
//! dynamics with loop closures and contact rows in one structured solve, and the plastic
//! impact map (DESIGN.md §3.1).
//!
//! Contact `k` owns rows `2k` (tangential, along `t`) and `2k + 1` (normal, along `n`) of
//! every contact quantity here: `C = R J_c` with `R = diag([t; n], …)`, the forces
//! `λ = (λ_t, λ_n)` the ground puts on the leg, the impulses `Λ` of an impact. A row is
//! held (an equation `C_r q̈ = r_r` with its force unknown) or free (its force known:
//! zero in flight, `λ_t = −μ s λ_n` when sliding).
//!
//! The structured solve eliminates the closure rows as the swing-leg dynamics do
//! (`S = J M⁻¹ Jᵀ`, pivoted for redundant rows) and then the held contact rows
//! (`K = C P M⁻¹ Wᵀ`, `P` the closure projection, `W` the force directions: `W = C`
//! except on a sliding normal row, `C_n − μ s C_t`), by Gaussian elimination over the
//! held rows. Everything is fixed-size and on the stack.

use core::fmt;

use nalgebra::{SMatrix, SVector};

use crate::dynamics::forward::{actuation, rcond_floor, Baumgarte, DynamicsError};
use crate::model::contract::{ContactModel, Real};
use crate::model::linalg::{all_finite, mul, Cholesky, PivotedLdlt};

/// The ground line `n · x = d` (base frame), `n` a unit normal out of the ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ground<T: Real> {
    /// The unit normal `n`, pointing out of the ground (base frame).
    pub normal: SVector<T, 2>,
    /// The offset `d` (m).
    pub offset: T,
}

impl<T: Real> Ground<T> {
    /// The ground of leg `L`'s spec.
    pub fn of<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>() -> Self
    where
        L: ContactModel<NQ, NC, NU, NK>,
    {
        let [x, y] = L::GROUND_NORMAL;
        Ground {
            normal: SVector::<T, 2>::new(T::lit(x), T::lit(y)),
            offset: T::lit(L::GROUND_OFFSET),
        }
    }

    /// The unit tangent `t = (n_y, −n_x)`: `+x` on level ground.
    pub fn tangent(&self) -> SVector<T, 2> {
        SVector::<T, 2>::new(self.normal[1], -self.normal[0])
    }

    /// Stacked base-frame rows (`x, y` per contact) turned into ground rows (`t, n`).
    pub fn rows<const NK: usize, const C: usize>(
        &self,
        base: &SMatrix<T, NK, C>,
    ) -> SMatrix<T, NK, C> {
        let (t, n) = (self.tangent(), self.normal);
        let mut out = SMatrix::<T, NK, C>::zeros();
        for k in 0..NK / 2 {
            for c in 0..C {
                let (x, y) = (base[(2 * k, c)], base[(2 * k + 1, c)]);
                out[(2 * k, c)] = t[0] * x + t[1] * y;
                out[(2 * k + 1, c)] = n[0] * x + n[1] * y;
            }
        }
        out
    }

    /// Contact positions in ground coordinates: `(t · x_c, n · x_c − d)` per contact (the
    /// second is the gap).
    pub fn coordinates<const NK: usize>(&self, positions: &SVector<T, NK>) -> SVector<T, NK> {
        let mut out = self.rows(positions);
        for k in 0..NK / 2 {
            out[2 * k + 1] -= self.offset;
        }
        out
    }
}

/// What a contact is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ContactMode {
    /// Off the ground: no force.
    Flight,
    /// On the ground, held where it touched down.
    Stick,
    /// On the ground, sliding along `+t` (`forward`) or `−t`; the friction force is
    /// `μ λ_n` against the slip.
    Slide {
        /// Sliding along `+t` (`false`: along `−t`).
        forward: bool,
    },
}

impl ContactMode {
    /// Whether the contact touches the ground (sticking or sliding).
    pub fn on_ground(self) -> bool {
        self != ContactMode::Flight
    }
}

/// The modes of every contact, indexed by contact (entry `2k` of an `NK`-array holds
/// contact `k`; entry `2k + 1` mirrors it, so that the array has one entry per row).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Modes<const NK: usize>(pub [ContactMode; NK]);

impl<const NK: usize> Modes<NK> {
    /// Every contact in flight.
    pub fn flight() -> Self {
        Modes([ContactMode::Flight; NK])
    }

    /// The number of contacts, `NK / 2`.
    pub fn contacts(&self) -> usize {
        NK / 2
    }

    /// The mode of contact `k`.
    pub fn get(&self, k: usize) -> ContactMode {
        self.0[2 * k]
    }

    /// Sets the mode of contact `k` (both its rows).
    pub fn set(&mut self, k: usize, mode: ContactMode) {
        self.0[2 * k] = mode;
        self.0[2 * k + 1] = mode;
    }

    /// Which rows are held: both of a sticking contact, the normal one of a sliding one.
    pub fn held_rows(&self) -> [bool; NK] {
        core::array::from_fn(|r| match self.0[r] {
            ContactMode::Flight => false,
            ContactMode::Stick => true,
            ContactMode::Slide { .. } => r % 2 == 1,
        })
    }
}

/// The solution of the structured system with contact rows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactSolution<T: Real, const NQ: usize, const NC: usize, const NK: usize> {
    /// `q̈` (or `q̇⁺` for an impact).
    pub x: SVector<T, NQ>,
    /// Closure forces (impulses), base frame, as [`crate::dynamics::Acceleration`].
    pub closure: SVector<T, NC>,
    /// Ground forces (impulses) on the leg per contact, `(λ_t, λ_n)`; zero in flight,
    /// `λ_t = −μ s λ_n` when sliding.
    pub contact: SVector<T, NK>,
}

/// `x = M⁻¹ τ` corrected by the closure rows (`J x = r_j`) and the held contact rows
/// (`C_r x = r_c,r`), with closure forces along `Jᵀ` and contact forces along `Wᵀ`:
///
/// ```text
/// [ M   −Jᵀ  −Wᵀ ] [ x ]   [ τ   ]
/// [ J    0    0  ] [ F ] = [ r_j ]
/// [ C    0    0  ] [ λ ]   [ r_c ]      (held rows of C only; λ_r = 0 on the others)
/// ```
///
/// `rows.w` holds the force direction of every held row (zero rows elsewhere). After the
/// solve the free tangential rows of sliding contacts get `λ_t = slide[r] λ_n`
/// (`rows.slide[2k] = −μ s`, zero for other rows).
pub fn solve_structured<T: Real, const NQ: usize, const NC: usize, const NK: usize>(
    chol_m: &Cholesky<T, NQ>,
    j: &SMatrix<T, NC, NQ>,
    r_j: &SVector<T, NC>,
    closure_deficiency: usize,
    rows: &ContactRows<T, NQ, NK>,
    r_c: &SVector<T, NK>,
    tau: &SVector<T, NQ>,
) -> Result<ContactSolution<T, NQ, NC, NK>, DynamicsError> {
    let (x, closure, contact) =
        solve_structured_columns(chol_m, j, r_j, closure_deficiency, rows, r_c, tau)?;
    Ok(ContactSolution {
        x,
        closure,
        contact,
    })
}

/// [`solve_structured`] for `C` right-hand sides at once (columns of `τ`, `r_j`, `r_c`),
/// with one elimination of the closure and contact rows: what the derivatives of the
/// dynamics ([`crate::dynamics::derivatives`]) solve. Returns `(x, F, λ)`, a column each.
#[allow(clippy::type_complexity)]
pub fn solve_structured_columns<
    T: Real,
    const NQ: usize,
    const NC: usize,
    const NK: usize,
    const C: usize,
>(
    chol_m: &Cholesky<T, NQ>,
    j: &SMatrix<T, NC, NQ>,
    r_j: &SMatrix<T, NC, C>,
    closure_deficiency: usize,
    rows: &ContactRows<T, NQ, NK>,
    r_c: &SMatrix<T, NK, C>,
    tau: &SMatrix<T, NQ, C>,
) -> Result<(SMatrix<T, NQ, C>, SMatrix<T, NC, C>, SMatrix<T, NK, C>), DynamicsError> {
    let (c, held) = (&rows.c, &rows.held);
    let mut a = *tau;
    chol_m.solve_mut(&mut a); // M⁻¹ τ
    let mut z = rows.w.transpose();
    for (r, &h) in held.iter().enumerate() {
        if !h {
            z.column_mut(r).fill(T::zero());
        }
    }
    chol_m.solve_mut(&mut z); // Z = M⁻¹ Wᵀ
                              // Closure elimination: a0 = a + Y S⁻¹ (r_j − J a), Zp = Z − Y S⁻¹ J Z.
    let (mut a0, mut zp) = (a, z);
    let mut f0 = SMatrix::<T, NC, C>::zeros();
    let mut g = SMatrix::<T, NC, NK>::zeros();
    if NC > 0 {
        let mut y = j.transpose();
        chol_m.solve_mut(&mut y);
        let s = mul(j, &y);
        f0 = r_j - mul(j, &a);
        g = mul(j, &z);
        if closure_deficiency == 0 {
            let chol_s =
                Cholesky::new(&s).ok_or(DynamicsError::SingularConstraints { rcond: 0.0 })?;
            if chol_s.rcond < rcond_floor::<T>() {
                return Err(DynamicsError::SingularConstraints {
                    rcond: to_f64(chol_s.rcond),
                });
            }
            chol_s.solve_mut(&mut f0);
            chol_s.solve_mut(&mut g);
        } else {
            let ldlt = PivotedLdlt::new(&s, closure_deficiency, rcond_floor::<T>())
                .ok_or(DynamicsError::SingularConstraints { rcond: 0.0 })?;
            ldlt.solve_mut(&mut f0);
            ldlt.solve_mut(&mut g);
        }
        a0 += mul(&y, &f0);
        zp -= mul(&y, &g);
    }
    // Held contact rows: K λ = r_c − C a0, K = C Zp.
    let k = mul(c, &zp);
    let rhs = r_c - mul(c, &a0);
    let lambda = solve_held(&k, &rhs, held)?;
    let x = a0 + mul(&zp, &lambda);
    let closure = f0 - mul(&g, &lambda);
    let mut contact = lambda;
    for r in (0..NK).step_by(2) {
        if !held[r] && held[r + 1] {
            for col in 0..C {
                contact[(r, col)] = rows.slide[r] * lambda[(r + 1, col)];
            }
        }
    }
    if !(all_finite(&x) && all_finite(&closure) && all_finite(&contact) && all_finite(tau)) {
        return Err(DynamicsError::NonFinite);
    }
    Ok((x, closure, contact))
}

/// Gaussian elimination with complete pivoting over the held rows and columns of `k`
/// (the others' unknowns are zero), for `C` right-hand sides. Held rows may repeat each
/// other (two contacts of one flat foot: the distance between them is fixed, so their
/// tangential rows are one): once every remaining pivot is below `rcond_floor` of the
/// first, the remaining unknowns are zero, provided their equations then hold (to the
/// same relative precision); otherwise the held rows contradict each other or the
/// closures and the solve refuses.
fn solve_held<T: Real, const N: usize, const C: usize>(
    k: &SMatrix<T, N, N>,
    rhs: &SMatrix<T, N, C>,
    held: &[bool; N],
) -> Result<SMatrix<T, N, C>, DynamicsError> {
    let mut idx = [0usize; N];
    let mut m = 0;
    for (r, &h) in held.iter().enumerate() {
        if h {
            idx[m] = r;
            m += 1;
        }
    }
    let mut a = SMatrix::<T, N, N>::zeros();
    let mut b = SMatrix::<T, N, C>::zeros();
    for i in 0..m {
        for col in 0..C {
            b[(i, col)] = rhs[(idx[i], col)];
        }
        for jj in 0..m {
            a[(i, jj)] = k[(idx[i], idx[jj])];
        }
    }
    if !(all_finite(&a) && all_finite(&b)) {
        return Err(DynamicsError::NonFinite);
    }
    // Columns follow their unknowns through the pivoting.
    let mut cols: [usize; N] = core::array::from_fn(|i| i);
    let (mut first, mut rank) = (T::zero(), m);
    let b_scale: [T; C] = core::array::from_fn(|col| b.column(col).amax());
    for col in 0..m {
        let (mut pr, mut pc, mut best) = (col, col, T::zero());
        for i in col..m {
            for jj in col..m {
                if a[(i, jj)].abs() > best {
                    (pr, pc, best) = (i, jj, a[(i, jj)].abs());
                }
            }
        }
        if col == 0 {
            first = best;
        }
        if best <= rcond_floor::<T>() * first || best == T::zero() {
            rank = col;
            break;
        }
        a.swap_rows(col, pr);
        b.swap_rows(col, pr);
        a.swap_columns(col, pc);
        cols.swap(col, pc);
        let d = a[(col, col)];
        for i in col + 1..m {
            let factor = a[(i, col)] / d;
            for jj in col..m {
                let v = a[(col, jj)];
                a[(i, jj)] -= factor * v;
            }
            for rc in 0..C {
                let v = b[(col, rc)];
                b[(i, rc)] -= factor * v;
            }
        }
    }
    // The rows left out must hold with their unknowns at zero.
    for i in rank..m {
        for (rc, scale) in b_scale.iter().enumerate() {
            if b[(i, rc)].abs() > T::default_epsilon().sqrt() * *scale {
                return Err(DynamicsError::SingularContacts { rcond: 0.0 });
            }
        }
    }
    let mut out = SMatrix::<T, N, C>::zeros();
    for rc in 0..C {
        let mut x = SVector::<T, N>::zeros();
        for i in (0..rank).rev() {
            let mut s = b[(i, rc)];
            for jj in i + 1..rank {
                s -= a[(i, jj)] * x[jj];
            }
            x[i] = s / a[(i, i)];
        }
        for i in 0..rank {
            out[(idx[cols[i]], rc)] = x[i];
        }
    }
    Ok(out)
}

fn to_f64<T: Real>(x: T) -> f64 {
    x.to_subset().unwrap_or(f64::NAN)
}

/// The contact rows of leg `L` at `q` in the ground's frame, and the force directions of
/// the held rows under `modes` with friction `mu` (per contact, entry `2k`).
#[derive(Clone, Copy, Debug)]
pub struct ContactRows<T: Real, const NQ: usize, const NK: usize> {
    /// `C = R J_c`.
    pub c: SMatrix<T, NK, NQ>,
    /// `W`: `C` on held rows, `C_n − μ s C_t` on a sliding normal row.
    pub w: SMatrix<T, NK, NQ>,
    /// `−μ s` on the tangential row of a sliding contact, zero elsewhere.
    pub slide: SVector<T, NK>,
    /// Which rows are held ([`Modes::held_rows`]).
    pub held: [bool; NK],
}

impl<T: Real, const NQ: usize, const NK: usize> ContactRows<T, NQ, NK> {
    /// The rows of the base-frame contact Jacobian `jacobian` (`J_c`) on `ground`, under
    /// `modes`, with friction `mu` (per contact, entry `2k`).
    pub fn new(
        ground: &Ground<T>,
        jacobian: &SMatrix<T, NK, NQ>,
        modes: &Modes<NK>,
        mu: &SVector<T, NK>,
    ) -> Self {
        let c = ground.rows(jacobian);
        let held = modes.held_rows();
        let mut w = c;
        let mut slide = SVector::<T, NK>::zeros();
        for k in 0..NK / 2 {
            match modes.get(k) {
                ContactMode::Slide { forward } => {
                    let s = if forward { T::one() } else { -T::one() };
                    let coefficient = -mu[2 * k] * s;
                    slide[2 * k] = coefficient;
                    for col in 0..NQ {
                        w[(2 * k + 1, col)] = c[(2 * k + 1, col)] + coefficient * c[(2 * k, col)];
                        w[(2 * k, col)] = T::zero();
                    }
                }
                ContactMode::Flight => {
                    w.row_mut(2 * k).fill(T::zero());
                    w.row_mut(2 * k + 1).fill(T::zero());
                }
                ContactMode::Stick => {}
            }
        }
        ContactRows { c, w, slide, held }
    }
}

/// Friction coefficients of leg `L`'s spec, one per row (both rows of contact `k` hold
/// its `μ`).
pub fn spec_friction<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
) -> SVector<T, NK>
where
    L: ContactModel<NQ, NC, NU, NK>,
    T: Real,
{
    SVector::from_fn(|r, _| T::lit(L::CONTACT_FRICTION[r / 2]))
}

/// Constrained forward dynamics with the contacts in `modes`: closure rows and held
/// contact rows in one structured solve. Baumgarte terms, when given, act on the closure
/// residual and on the held contacts' drift from `anchors` (ground coordinates: the
/// tangential entry of a sticking contact is where it touched down; the normal entry is
/// the ground, 0).
#[allow(clippy::too_many_arguments)]
pub fn forward_dynamics_with_contacts<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
    modes: &Modes<NK>,
    anchors: &SVector<T, NK>,
    ground: &Ground<T>,
    mu: &SVector<T, NK>,
    baumgarte: Option<Baumgarte<T>>,
) -> Result<ContactSolution<T, NQ, NC, NK>, DynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK>,
    T: Real,
{
    ContactSystem::new::<L, NU>(params, q, qd, modes, anchors, ground, mu, baumgarte)?
        .solve(&actuation::<L, T, NQ, NC, NU>(u))
}

/// The stance (or flight) system of leg `L` at one state, evaluated and factored once,
/// for the solves of several applied forces: what a controller that needs the response
/// to each motor (or to any generalized force) calls instead of
/// [`forward_dynamics_with_contacts`] once per right-hand side.
#[derive(Clone, Copy, Debug)]
pub struct ContactSystem<T: Real, const NQ: usize, const NC: usize, const NK: usize> {
    pub(crate) chol_m: Cholesky<T, NQ>,
    pub(crate) jacobian: SMatrix<T, NC, NQ>,
    pub(crate) r_j: SVector<T, NC>,
    redundant_rows: usize,
    pub(crate) rows: ContactRows<T, NQ, NK>,
    pub(crate) r_c: SVector<T, NK>,
    /// `−N − D q̇`: the forces that act whatever is applied.
    pub(crate) passive: SVector<T, NQ>,
    /// `M(q)`.
    pub mass_matrix: SMatrix<T, NQ, NQ>,
}

impl<T: Real, const NQ: usize, const NC: usize, const NK: usize> ContactSystem<T, NQ, NC, NK> {
    /// Evaluates the terms and factors `M` (the arguments as for
    /// [`forward_dynamics_with_contacts`]).
    #[allow(clippy::too_many_arguments)]
    pub fn new<L, const NU: usize>(
        params: &L::Params<T>,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        modes: &Modes<NK>,
        anchors: &SVector<T, NK>,
        ground: &Ground<T>,
        mu: &SVector<T, NK>,
        baumgarte: Option<Baumgarte<T>>,
    ) -> Result<Self, DynamicsError>
    where
        L: ContactModel<NQ, NC, NU, NK>,
    {
        let terms = L::dynamics_terms(q, qd, params);
        let chol_m = Cholesky::new(&terms.mass_matrix)
            .ok_or(DynamicsError::MassMatrixNotPositiveDefinite)?;
        if chol_m.rcond < rcond_floor::<T>() {
            return Err(DynamicsError::MassMatrixNotPositiveDefinite);
        }
        let passive = -terms.bias_forces - L::damping_forces(qd, params);
        let mut r_j = -terms.constraint_bias;
        let jc = L::contact_jacobian(q, params);
        let rows = ContactRows::new(ground, &jc, modes, mu);
        let mut r_c = -ground.rows(&L::contact_bias(q, qd, params));
        if let Some(b) = baumgarte {
            let (two_alpha, beta2) = (b.alpha + b.alpha, b.beta * b.beta);
            if NC > 0 {
                let phi = L::closure_residual(q, params);
                r_j -= (terms.constraint_jacobian * qd) * two_alpha + phi * beta2;
            }
            let drift = ground.coordinates(&L::contact_positions(q, params)) - anchors;
            r_c -= (rows.c * qd) * two_alpha + drift * beta2;
        }
        Ok(ContactSystem {
            chol_m,
            jacobian: terms.constraint_jacobian,
            r_j,
            redundant_rows: L::REDUNDANT_ROWS,
            rows,
            r_c,
            passive,
            mass_matrix: terms.mass_matrix,
        })
    }

    /// Accelerations and forces under the applied generalized forces `applied` (`B u`
    /// for motor torques `u`, [`crate::dynamics::actuation`]).
    pub fn solve(
        &self,
        applied: &SVector<T, NQ>,
    ) -> Result<ContactSolution<T, NQ, NC, NK>, DynamicsError> {
        solve_structured(
            &self.chol_m,
            &self.jacobian,
            &self.r_j,
            self.redundant_rows,
            &self.rows,
            &self.r_c,
            &(applied + self.passive),
        )
    }
}

/// A plastic impact: the velocities after it and what it cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Impact<T: Real, const NQ: usize, const NC: usize, const NK: usize> {
    /// `q̇⁺`: every closure and every held contact row at rest (`J q̇⁺ = 0`, `C q̇⁺ = 0`).
    pub qd_plus: SVector<T, NQ>,
    /// Closure impulses (base frame).
    pub closure_impulses: SVector<T, NC>,
    /// Ground impulses per contact `(Λ_t, Λ_n)`.
    pub impulses: SVector<T, NK>,
    /// `T(q̇⁻) − T(q̇⁺)`; for a sticking impact it equals `½ Δq̇ᵀ M Δq̇ ≥ 0`.
    pub energy_lost: T,
}

/// Why an impact cannot be resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ImpactError {
    /// The system of the impact is singular or `M` is not positive definite.
    Dynamics(DynamicsError),
    /// The normal impulse of contact `contact` would pull the leg into the ground
    /// (`Λ_n < 0`): the contact is separating, not impacting.
    Pulling {
        /// The contact's index.
        contact: usize,
        /// Its normal impulse `Λ_n` (N s), negative.
        normal_impulse: f64,
    },
}

impl fmt::Display for ImpactError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImpactError::Dynamics(e) => write!(f, "impact: {e}"),
            ImpactError::Pulling {
                contact,
                normal_impulse,
            } => write!(
                f,
                "impact: contact {contact} would need a pulling normal impulse ({normal_impulse:.3e} N s): it separates instead"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ImpactError {}

impl From<DynamicsError> for ImpactError {
    fn from(e: DynamicsError) -> Self {
        ImpactError::Dynamics(e)
    }
}

/// The plastic impact map of DESIGN.md §3.1 at `q` with pre-impact velocities `qd`:
///
/// ```text
/// [ M    −Jᵀ   −Wᵀ ] [ q̇⁺ ]   [ M q̇⁻ ]
/// [ J     0     0  ] [ Λ  ] = [ 0    ]
/// [ C     0     0  ] [ Λ_c]   [ 0    ]
/// ```
///
/// over the rows `modes` hold. A sticking contact whose impulse leaves the friction cone
/// (`|Λ_t| > μ Λ_n`) is resolved again as sliding, its friction impulse `μ Λ_n` against
/// the slip after the impact, and its mode in `modes` becomes `Slide`. Every held normal
/// impulse must be non-negative ([`ImpactError::Pulling`] otherwise).
///
/// A sticking impact loses exactly `½ Δq̇ᵀ M Δq̇`. A sliding one loses energy unless the
/// impulse reverses the slip (then Coulomb's law applied to impulses can add energy, a
/// known limit of the model, Stronge 1991); `energy_lost` reports what happened.
#[allow(clippy::too_many_arguments)]
pub fn impact_map<L, T, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    modes: &mut Modes<NK>,
    ground: &Ground<T>,
    mu: &SVector<T, NK>,
) -> Result<Impact<T, NQ, NC, NK>, ImpactError>
where
    L: ContactModel<NQ, NC, NU, NK>,
    T: Real,
{
    if !(all_finite(q) && all_finite(qd)) {
        return Err(DynamicsError::NonFinite.into());
    }
    let m = L::mass_matrix(q, params);
    let chol_m = Cholesky::new(&m).ok_or(if all_finite(&m) {
        DynamicsError::MassMatrixNotPositiveDefinite
    } else {
        DynamicsError::NonFinite
    })?;
    if chol_m.rcond < rcond_floor::<T>() {
        return Err(DynamicsError::MassMatrixNotPositiveDefinite.into());
    }
    let j = L::constraint_jacobian(q, params);
    let jc = L::contact_jacobian(q, params);
    let momentum = mul(&m, qd);
    let solve = |modes: &Modes<NK>| {
        let rows = ContactRows::new(ground, &jc, modes, mu);
        solve_structured(
            &chol_m,
            &j,
            &SVector::zeros(),
            L::REDUNDANT_ROWS,
            &rows,
            &SVector::zeros(),
            &momentum,
        )
    };
    let mut sol = solve(modes)?;
    // A sticking impulse outside the cone slides instead (at most once per contact).
    let mut changed = false;
    for k in 0..NK / 2 {
        if modes.get(k) == ContactMode::Stick {
            let (lt, ln) = (sol.contact[2 * k], sol.contact[2 * k + 1]);
            if lt.abs() > mu[2 * k] * ln {
                // λ_t = −μ s λ_n: the slip runs against the friction impulse.
                modes.set(
                    k,
                    ContactMode::Slide {
                        forward: lt < T::zero(),
                    },
                );
                changed = true;
            }
        }
    }
    if changed {
        sol = solve(modes)?;
        // The slip after the impact must run the way its friction opposes; where it does
        // not (the impulse reversed the slip), the other direction is the consistent one.
        let slip = ground.rows(&mul(&jc, &sol.x));
        let mut flipped = false;
        for k in 0..NK / 2 {
            if let ContactMode::Slide { forward } = modes.get(k) {
                let along = if forward { slip[2 * k] } else { -slip[2 * k] };
                if along < T::zero() {
                    modes.set(k, ContactMode::Slide { forward: !forward });
                    flipped = true;
                }
            }
        }
        if flipped {
            sol = solve(modes)?;
        }
    }
    for k in 0..NK / 2 {
        if modes.get(k).on_ground() && sol.contact[2 * k + 1] < T::zero() {
            return Err(ImpactError::Pulling {
                contact: k,
                normal_impulse: to_f64(sol.contact[2 * k + 1]),
            });
        }
    }
    let half = T::lit(0.5);
    let energy_lost = half * qd.dot(&momentum) - half * sol.x.dot(&mul(&m, &sol.x));
    // Rates so large that the momentum or the energy exceed f64's range: said, not
    // returned as an infinite or NaN energy.
    let finite = all_finite(&sol.x)
        && all_finite(&sol.contact)
        && all_finite(&sol.closure)
        && (energy_lost * T::zero()) == T::zero();
    if !finite {
        return Err(DynamicsError::Overflow.into());
    }
    Ok(Impact {
        qd_plus: sol.x,
        closure_impulses: sol.closure,
        impulses: sol.contact,
        energy_lost,
    })
}
