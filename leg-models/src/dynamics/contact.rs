//! Contact with the ground: the contact rows in the ground's frame, the constrained
//! dynamics with loop closures and contact rows in one structured solve, and the plastic
//! impact map (DESIGN.md §3.1), for planar legs (`ND = 2`) and spatial ones (`ND = 3`).
//!
//! Contact `k` owns rows `ND k … ND k + ND − 1` of every contact quantity here: first its
//! tangential rows (along the ground's tangents, [`Ground::frame`]), last its normal row
//! (along `n`): `C = R J_c` with `R = diag(frame, …)`, the forces `λ = (λ_t, λ_n)` the
//! ground puts on the leg, the impulses `Λ` of an impact. A row is held (an equation
//! `C_r q̈ = r_r` with its force unknown) or free (its force known: zero in flight,
//! `λ_t = −μ ŝ λ_n` when sliding along the unit slip direction `ŝ`).
//!
//! The friction law is Coulomb's with its exact cone, `|λ_t| ≤ μ λ_n` with `|·|` the
//! Euclidean norm of the tangential force (two entries in 3-D): no pyramid anywhere. A
//! planar contact is its special case, one tangent and `ŝ = ±1`.
//!
//! The structured solve eliminates the closure rows as the swing-leg dynamics do
//! (`S = J M⁻¹ Jᵀ`, pivoted for redundant rows) and then the held contact rows
//! (`K = C P M⁻¹ Wᵀ`, `P` the closure projection, `W` the force directions: `W = C`
//! except on a sliding normal row, `C_n − μ ŝ · C_t`), by Gaussian elimination over the
//! held rows. Everything is fixed-size and on the stack.

use core::fmt;

use nalgebra::{SMatrix, SVector};

use crate::dynamics::forward::{
    actuation, checked_mass_factor, factor_mass, mass_tree, rcond_floor, redundant_closure_factor,
    regular_closure_factor, Baumgarte, ConstraintFactor, DynamicsError,
};
use crate::model::contract::{ContactModel, DynamicsTerms, Real};
use crate::model::linalg::{
    all_finite, column_spans, mul, mul_nt_spans, mul_tn, scale_columns, scale_rows, Cholesky,
    Factored, MassFactor, TreeLdl,
};

/// The ground `n · x = d` (base frame), `n` a unit normal out of the ground: a line for a
/// planar leg (`ND = 2`), a plane for a spatial one (`ND = 3`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ground<T: Real, const ND: usize = 2> {
    /// The unit normal `n`, pointing out of the ground (base frame).
    pub normal: SVector<T, ND>,
    /// The offset `d` (m).
    pub offset: T,
}

impl<T: Real, const ND: usize> Ground<T, ND> {
    /// The ground of leg `L`'s spec.
    pub fn of<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>() -> Self
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        Ground {
            normal: SVector::from_fn(|i, _| T::lit(L::GROUND_NORMAL[i])),
            offset: T::lit(L::GROUND_OFFSET),
        }
    }

    /// The ground's frame as rows: the tangents, then the normal `n`. Planar: the tangent
    /// `t = (n_y, −n_x)`, `+x` on level ground. Spatial: `t₁` the base's x axis (its y
    /// where x is within 26° of the normal) projected on the ground, `t₂ = n × t₁`, so
    /// that `(t₁, t₂, n)` is right-handed: the base's `(x, y, z)` on level ground.
    pub fn frame(&self) -> SMatrix<T, ND, ND> {
        let n = &self.normal;
        let mut out = SMatrix::<T, ND, ND>::zeros();
        if ND == 2 {
            out[(0, 0)] = n[1];
            out[(0, 1)] = -n[0];
        } else if ND == 3 {
            let axis = if n[0].abs() < T::lit(0.9) { 0 } else { 1 };
            let mut t1 = -(n * n[axis]);
            t1[axis] += T::one();
            let t1 = t1 / t1.norm();
            let t2 = [
                n[1] * t1[2] - n[2] * t1[1],
                n[2] * t1[0] - n[0] * t1[2],
                n[0] * t1[1] - n[1] * t1[0],
            ];
            for j in 0..3 {
                out[(0, j)] = t1[j];
                out[(1, j)] = t2[j];
            }
        }
        for j in 0..ND {
            out[(ND - 1, j)] = n[j];
        }
        out
    }

    /// The first tangent (the frame's first row): `+x` on level ground.
    pub fn tangent(&self) -> SVector<T, ND> {
        self.frame().row(0).transpose()
    }

    /// Stacked base-frame rows (`ND` per contact) turned into ground rows (the tangents,
    /// then the normal).
    pub fn rows<const NK: usize, const C: usize>(
        &self,
        base: &SMatrix<T, NK, C>,
    ) -> SMatrix<T, NK, C> {
        let frame = self.frame();
        let mut out = SMatrix::<T, NK, C>::zeros();
        for k in 0..NK / ND {
            for c in 0..C {
                for i in 0..ND {
                    let mut s = frame[(i, 0)] * base[(ND * k, c)];
                    for j in 1..ND {
                        s += frame[(i, j)] * base[(ND * k + j, c)];
                    }
                    out[(ND * k + i, c)] = s;
                }
            }
        }
        out
    }

    /// Contact positions in ground coordinates: `(t · x_c, …, n · x_c − d)` per contact
    /// (the last is the gap).
    pub fn coordinates<const NK: usize>(&self, positions: &SVector<T, NK>) -> SVector<T, NK> {
        let mut out = self.rows(positions);
        for k in 0..NK / ND {
            out[ND * k + ND - 1] -= self.offset;
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
    /// On the ground and sliding; the friction force is `μ λ_n` against the slip. On a
    /// planar leg the slip runs along `+t` (`forward`) or `−t`. On a spatial leg it runs
    /// in any direction of the ground, the direction of the contact's velocity along it
    /// (or, from rest, the slip direction given with the state), and `forward` is
    /// unused (`true`).
    Slide {
        /// Sliding along `+t` (`false`: along `−t`); planar legs only.
        forward: bool,
    },
}

impl ContactMode {
    /// Whether the contact touches the ground (sticking or sliding).
    pub fn on_ground(self) -> bool {
        self != ContactMode::Flight
    }
}

/// The modes of every contact, indexed by contact (entry `ND k` of an `NK`-array holds
/// contact `k`; its other rows' entries mirror it, so that the array has one entry per
/// row).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Modes<const NK: usize, const ND: usize = 2>(pub [ContactMode; NK]);

impl<const NK: usize, const ND: usize> Modes<NK, ND> {
    /// Every contact in flight.
    pub fn flight() -> Self {
        Modes([ContactMode::Flight; NK])
    }

    /// Every contact held (sticking): a stance on all of them.
    pub fn stick() -> Self {
        Modes([ContactMode::Stick; NK])
    }

    /// The number of contacts, `NK / ND`.
    pub fn contacts(&self) -> usize {
        NK / ND
    }

    /// The mode of contact `k`.
    pub fn get(&self, k: usize) -> ContactMode {
        self.0[ND * k]
    }

    /// Sets the mode of contact `k` (all its rows).
    pub fn set(&mut self, k: usize, mode: ContactMode) {
        for r in ND * k..ND * (k + 1) {
            self.0[r] = mode;
        }
    }

    /// Which rows are held: all of a sticking contact, the normal one of a sliding one.
    pub fn held_rows(&self) -> [bool; NK] {
        core::array::from_fn(|r| match self.0[r] {
            ContactMode::Flight => false,
            ContactMode::Stick => true,
            ContactMode::Slide { .. } => r % ND == ND - 1,
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
/// (`rows.slide` holds `−μ ŝ` on the tangential rows of sliding contacts, zero for other
/// rows).
pub fn solve_structured<
    T: Real,
    const NQ: usize,
    const NC: usize,
    const NK: usize,
    const ND: usize,
    F: Factored<T, NQ>,
>(
    chol_m: &F,
    j: &SMatrix<T, NC, NQ>,
    r_j: &SVector<T, NC>,
    closure_deficiency: usize,
    rows: &ContactRows<T, NQ, NK, ND>,
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
    const ND: usize,
    const C: usize,
    F: Factored<T, NQ>,
>(
    chol_m: &F,
    j: &SMatrix<T, NC, NQ>,
    r_j: &SMatrix<T, NC, C>,
    closure_deficiency: usize,
    rows: &ContactRows<T, NQ, NK, ND>,
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
        // Written out, not through `ConstraintFactor`: the enum cost the small legs'
        // contact paths 2.6 to 2.9 % (abducted_five_bar contact_slide 7565 → 7761).
        if closure_deficiency == 0 {
            let chol_s = regular_closure_factor(&s)?;
            chol_s.solve_mut(&mut f0);
            chol_s.solve_mut(&mut g);
        } else {
            let ldlt = redundant_closure_factor(&s, closure_deficiency)?;
            ldlt.solve_mut(&mut f0);
            ldlt.solve_mut(&mut g);
        }
        a0 += mul(&y, &f0);
        zp -= mul(&y, &g);
    }
    // Held contact rows: K λ = r_c − C a0, K = C Zp.
    let k = mul(c, &zp);
    let rhs = r_c - mul(c, &a0);
    // The size of what the right-hand side is made of, per column: a held row left out
    // must hold to rounding of these, not of their difference (at rest, or nearly, the
    // difference is itself rounding). Only asked for where held rows repeat.
    let pieces = |col: usize| r_c.column(col).amax().max(c.amax() * a0.column(col).amax());
    let lambda = solve_held(&k, &rhs, held, pieces)?;
    let x = a0 + mul(&zp, &lambda);
    let closure = f0 - mul(&g, &lambda);
    finish_structured(rows, x, closure, lambda, tau)
}

/// [`solve_structured_columns`] with `M = Lᵀ D L` factored along the tree, in half
/// solves as [`crate::dynamics::forward`]'s tree path does: with `t = L⁻ᵀ τ` and the
/// rows' `L⁻ᵀ Jᵀ`, `L⁻ᵀ Wᵀ`, `L⁻ᵀ Cᵀ`, every product `X M⁻¹ Yᵀ` is `(L⁻ᵀ Xᵀ)ᵀ D⁻¹ (L⁻ᵀ Yᵀ)`
/// and `q̈` takes one last half solve: `NC + NK (+ NK where a slide makes W ≠ C) + 2 C`
/// half solves (`+ C` where held rows repeat, for `a0`'s size) where the full form takes
/// `NC + NK + C` whole ones, two half solves each (Featherstone, RBDA §8.5). The same
/// elimination, so the same refusals of the closures and the held rows (`M`'s own refusal
/// is the tree factor's: its pivot ratio is of another ordering than the dense one's).
/// On a robot, the products skip a leg's columns for the other legs' rows
/// ([`crate::model::linalg::Spans`]), and nothing that the closures couple through the body
/// is formed as a dense `NK × NQ` matrix.
#[allow(clippy::type_complexity)]
pub(crate) fn solve_structured_on_tree<
    T: Real,
    const NQ: usize,
    const NC: usize,
    const NK: usize,
    const ND: usize,
    const C: usize,
>(
    chol_m: &TreeLdl<T, NQ>,
    j: &SMatrix<T, NC, NQ>,
    r_j: &SMatrix<T, NC, C>,
    closure_deficiency: usize,
    rows: &ContactRows<T, NQ, NK, ND>,
    r_c: &SMatrix<T, NK, C>,
    tau: &SMatrix<T, NQ, C>,
) -> Result<(SMatrix<T, NQ, C>, SMatrix<T, NC, C>, SMatrix<T, NK, C>), DynamicsError> {
    let (c, held) = (&rows.c, &rows.held);
    let inv_d = chol_m.inv_diag();
    // The rows' factors kept as rows (`P = X L⁻¹`, X's layout as stored), so that the half
    // solves and the products `P D⁻¹ Qᵀ` run over contiguous columns.
    let mut t = *tau;
    chol_m.solve_lt_mut(&mut t); // L⁻ᵀ τ
                                 // The held rows only (the others' forces are zero and their equations not asked).
    let mut pw = rows.w;
    let mut same = true;
    for (r, &h) in held.iter().enumerate() {
        if h {
            same &= rows.w.row(r) == c.row(r);
        } else {
            pw.row_mut(r).fill(T::zero());
        }
    }
    // Each factor with the rows its columns may be nonzero in ([`Spans`]): the products
    // skip a leg's columns for another leg's rows.
    let mut pc = pw;
    chol_m.solve_lt_rows_mut(&mut pw); // W L⁻¹
    let w_spans = column_spans(&pw);
    let c_spans = if same {
        // Every held row sticks (or slides with W = C): C's rows are W's.
        pc = pw;
        w_spans
    } else {
        for (r, &h) in held.iter().enumerate() {
            if h {
                pc.set_row(r, &c.row(r));
            }
        }
        chol_m.solve_lt_rows_mut(&mut pc); // C L⁻¹
        column_spans(&pc)
    };
    // Closure elimination in the half space: u0 = t + Pjᵀ f0 (so a0 = L⁻¹ D⁻¹ u0), and the
    // held rows' matrix less the closures' response, K = C Zp = C M⁻¹ Wᵀ − Gcᵀ S⁻¹ G with
    // G = J M⁻¹ Wᵀ and Gc = J M⁻¹ Cᵀ (G itself where C's rows are W's). Pp = Pw − gᵀ Pj
    // (Zp = L⁻¹ D⁻¹ Ppᵀ) is never formed: the closures couple the legs through the body,
    // so it would be dense where Pw and Pj are leg by leg.
    let mut pj = *j;
    let j_spans = if NC > 0 {
        chol_m.solve_lt_rows_mut(&mut pj); // J L⁻¹
        column_spans(&pj)
    } else {
        [(0, 0); NQ]
    };
    let pj_d = scale_columns(&pj, inv_d);
    let mut k = mul_nt_spans(&pc, &c_spans, &scale_columns(&pw, inv_d), &w_spans);
    let mut u0 = t;
    let mut f0 = SMatrix::<T, NC, C>::zeros();
    let mut g = SMatrix::<T, NC, NK>::zeros();
    if NC > 0 {
        let s = mul_nt_spans(&pj, &j_spans, &pj_d, &j_spans);
        let s = ConstraintFactor::new(&s, closure_deficiency)?;
        f0 = r_j - mul(&pj_d, &t);
        g = mul_nt_spans(&pj_d, &j_spans, &pw, &w_spans);
        let gc = if same {
            g
        } else {
            mul_nt_spans(&pj_d, &j_spans, &pc, &c_spans)
        };
        s.solve_mut(&mut f0);
        s.solve_mut(&mut g);
        u0 += mul_tn(&pj, &f0);
        k -= mul_tn(&gc, &g);
    }
    let u0_d = scale_rows(&u0, inv_d);
    // Held contact rows: K λ = r_c − C a0.
    let rhs = r_c - mul(&pc, &u0_d);
    // a0 itself only where held rows repeat (its size judges the rows left out).
    let a0 = core::cell::OnceCell::new();
    let pieces = |col: usize| {
        let a0 = a0.get_or_init(|| {
            let mut a = u0_d;
            chol_m.solve_l_mut(&mut a);
            a
        });
        r_c.column(col).amax().max(c.amax() * a0.column(col).amax())
    };
    let lambda = solve_held(&k, &rhs, held, pieces)?;
    // q̈ = a0 + Zp λ = L⁻¹ D⁻¹ (u0 + Pwᵀ λ − Pjᵀ g λ).
    let g_lambda = mul(&g, &lambda);
    let half = u0 + mul_tn(&pw, &lambda) - mul_tn(&pj, &g_lambda);
    let mut x = scale_rows(&half, inv_d);
    chol_m.solve_l_mut(&mut x);
    let closure = f0 - g_lambda;
    finish_structured(rows, x, closure, lambda, tau)
}

/// The end of a structured solve: the free tangential rows of sliding contacts from their
/// normal force (`λ_t = slide λ_n`), and every result checked finite.
#[allow(clippy::type_complexity)]
#[inline(always)]
fn finish_structured<
    T: Real,
    const NQ: usize,
    const NC: usize,
    const NK: usize,
    const ND: usize,
    const C: usize,
>(
    rows: &ContactRows<T, NQ, NK, ND>,
    x: SMatrix<T, NQ, C>,
    closure: SMatrix<T, NC, C>,
    lambda: SMatrix<T, NK, C>,
    tau: &SMatrix<T, NQ, C>,
) -> Result<(SMatrix<T, NQ, C>, SMatrix<T, NC, C>, SMatrix<T, NK, C>), DynamicsError> {
    let held = &rows.held;
    let mut contact = lambda;
    for k in 0..NK / ND {
        let n = ND * k + ND - 1;
        if held[n] && !held[ND * k] {
            for r in ND * k..n {
                for col in 0..C {
                    contact[(r, col)] = rows.slide[r] * lambda[(n, col)];
                }
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
/// same relative precision of the right-hand side or of `pieces`, the size of what it
/// was computed from; otherwise the held rows contradict each other or the
/// closures and the solve refuses), and the solution is then made the least of all
/// ([`least_norm`]).
fn solve_held<T: Real, const N: usize, const C: usize>(
    k: &SMatrix<T, N, N>,
    rhs: &SMatrix<T, N, C>,
    held: &[bool; N],
    pieces: impl Fn(usize) -> T,
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
    if rank < m {
        for (rc, scale) in b_scale.iter().enumerate() {
            let scale = scale.max(pieces(rc));
            for i in rank..m {
                if b[(i, rc)].abs() > T::default_epsilon().sqrt() * scale {
                    return Err(DynamicsError::SingularContacts { rcond: 0.0 });
                }
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
    if rank < m {
        least_norm(&mut out, &a, rank, m, &idx, &cols);
    }
    Ok(out)
}

/// Turns the basic solution of a held system that lost rank (its unknowns past `rank`
/// zero) into the least one: its solutions differ by `K`'s null space, and the least is
/// the basic one less its projection on that space. The null space comes from the
/// elimination: in the pivoted order, `U₁₁ n₁ + U₁₂ n₂ = 0` with `n₂` each unit vector;
/// its vectors are made orthonormal (Gram–Schmidt) and projected out of every column.
/// Two contacts of one rigid foot then share the load along their distance equally,
/// rather than as the pivoting happened to order them. (For the derivative columns of
/// [`crate::dynamics::derivatives`] this projection is not the derivative of the least
/// solution, whose null space turns with `q`: there the forces' derivatives are not
/// exact, though `q̈`'s are, since the null space moves nothing.)
fn least_norm<T: Real, const N: usize, const C: usize>(
    out: &mut SMatrix<T, N, C>,
    a: &SMatrix<T, N, N>,
    rank: usize,
    m: usize,
    idx: &[usize; N],
    cols: &[usize; N],
) {
    let mut basis = SMatrix::<T, N, N>::zeros();
    let mut found = 0;
    for t in rank..m {
        let mut n = SVector::<T, N>::zeros();
        n[t] = T::one();
        for i in (0..rank).rev() {
            let mut s = -a[(i, t)];
            for jj in i + 1..rank {
                s -= a[(i, jj)] * n[jj];
            }
            n[i] = s / a[(i, i)];
        }
        // In the unknowns' own order.
        let mut v = SVector::<T, N>::zeros();
        for i in 0..m {
            v[idx[cols[i]]] = n[i];
        }
        for k in 0..found {
            let e = basis.column(k).into_owned();
            v -= e * e.dot(&v);
        }
        let norm = v.norm();
        if norm > T::zero() {
            basis.set_column(found, &(v / norm));
            found += 1;
        }
    }
    for rc in 0..C {
        let mut x = out.column(rc).into_owned();
        for k in 0..found {
            let e = basis.column(k).into_owned();
            x -= e * e.dot(&x);
        }
        out.set_column(rc, &x);
    }
}

fn to_f64<T: Real>(x: T) -> f64 {
    x.to_subset().unwrap_or(f64::NAN)
}

/// The slip direction `ŝ` (unit, along the ground's two tangents) that is consistent
/// with what sliding along it leaves: `motion(ŝ)` is the slip velocity (after an impact)
/// or acceleration (from rest) that sliding along `ŝ` gives, with friction against `ŝ`,
/// and `ŝ` is consistent where that points along `ŝ` (parallel, not opposed). From
/// `start`, a few rounds of `ŝ ← motion(ŝ)/|motion(ŝ)|`; where that does not settle to
/// `√ε`, a scan of the circle from `start`'s angle (36 directions) for where the
/// component of `motion` across `ŝ` changes sign with `motion` along `ŝ`, refined by
/// bisection. Returns the direction and whether it is consistent (else the last tried).
/// A `motion` of zero (the slip stops) is consistent with any direction.
pub(crate) fn consistent_slip<T: Real, E>(
    start: [T; 2],
    mut motion: impl FnMut([T; 2]) -> Result<[T; 2], E>,
) -> Result<([T; 2], bool), E> {
    let tol = T::default_epsilon().sqrt();
    let unit = |a: T| [a.cos(), a.sin()];
    // (across, along): the cross and dot products of ŝ and the motion.
    let split = |s: [T; 2], v: [T; 2]| (s[0] * v[1] - s[1] * v[0], s[0] * v[0] + s[1] * v[1]);
    let mut s = start;
    for _ in 0..8 {
        let v = motion(s)?;
        let norm = (v[0] * v[0] + v[1] * v[1]).sqrt();
        if norm == T::zero() {
            return Ok((s, true));
        }
        if !norm.is_finite() {
            break;
        }
        let next = [v[0] / norm, v[1] / norm];
        let turn = (next[0] - s[0]).abs().max((next[1] - s[1]).abs());
        s = next;
        if turn <= tol {
            return Ok((s, true));
        }
    }
    let a0 = start[1].atan2(start[0]);
    const SCAN: usize = 36;
    let step = T::two_pi() / T::lit(SCAN as f64);
    let mut previous: Option<(T, T)> = None;
    for i in 0..=SCAN {
        let a = a0 + step * T::lit(i as f64);
        let (across, _) = split(unit(a), motion(unit(a))?);
        if let Some((pa, pacross)) = previous {
            if (pacross <= T::zero()) != (across <= T::zero()) {
                let (mut lo, mut hi, mut lo_across) = (pa, a, pacross);
                for _ in 0..64 {
                    let mid = (lo + hi) * T::lit(0.5);
                    let (m_across, _) = split(unit(mid), motion(unit(mid))?);
                    if (m_across <= T::zero()) == (lo_across <= T::zero()) {
                        (lo, lo_across) = (mid, m_across);
                    } else {
                        hi = mid;
                    }
                    if hi - lo <= tol * tol {
                        break;
                    }
                }
                let root = (lo + hi) * T::lit(0.5);
                let (_, along_root) = split(unit(root), motion(unit(root))?);
                if along_root > T::zero() {
                    return Ok((unit(root), true));
                }
            }
        }
        previous = Some((a, across));
    }
    Ok((s, false))
}

/// `|λ_t|` of contact `k`: the Euclidean norm of its tangential entries (`ND − 1` of
/// them), the absolute value on a planar leg.
pub(crate) fn tangential_norm<T: Real, const NK: usize, const ND: usize>(
    v: &SVector<T, NK>,
    k: usize,
) -> T {
    if ND == 2 {
        return v[ND * k].abs();
    }
    (ND * k..ND * k + ND - 1)
        .fold(T::zero(), |a, r| a + v[r] * v[r])
        .sqrt()
}

/// Writes the unit direction of `v`'s entries `rows` into `slip`'s and says whether it
/// could; leaves them where `v` has none there (zero or not finite).
pub(crate) fn set_unit<T: Real, const NK: usize>(
    slip: &mut SVector<T, NK>,
    v: &SVector<T, NK>,
    rows: core::ops::Range<usize>,
) -> bool {
    let norm = rows.clone().fold(T::zero(), |a, r| a + v[r] * v[r]).sqrt();
    if !(norm > T::zero() && norm.is_finite()) {
        return false;
    }
    for r in rows {
        slip[r] = v[r] / norm;
    }
    true
}

/// Contact `k`'s velocity along the ground, `(C q̇)` on its tangential rows (`c` the
/// ground rows, [`Ground::rows`]), and whether it moves: `|v_t|` above rounding, `√ε` of
/// the speeds its rows could have at `q̇`.
pub(crate) fn tangential_velocity<T: Real, const NQ: usize, const NK: usize, const ND: usize>(
    c: &SMatrix<T, NK, NQ>,
    qd: &SVector<T, NQ>,
    k: usize,
) -> (SVector<T, NK>, bool) {
    let mut v = SVector::<T, NK>::zeros();
    let (mut speed, mut scale) = (T::zero(), T::zero());
    for r in ND * k..ND * k + ND - 1 {
        let mut s = T::zero();
        for j in 0..NQ {
            v[r] += c[(r, j)] * qd[j];
            s += (c[(r, j)] * qd[j]).abs();
        }
        speed += v[r] * v[r];
        scale += s * s;
    }
    let moving = speed.sqrt() > T::default_epsilon().sqrt() * scale.sqrt();
    (v, moving)
}

/// The contact rows of leg `L` at `q` in the ground's frame, and the force directions of
/// the held rows under `modes` with friction `mu` (per row, every row of contact `k`
/// holding its μ).
#[derive(Clone, Copy, Debug)]
pub struct ContactRows<T: Real, const NQ: usize, const NK: usize, const ND: usize = 2> {
    /// `C = R J_c`.
    pub c: SMatrix<T, NK, NQ>,
    /// `W`: `C` on held rows, `C_n − μ ŝ · C_t` on a sliding normal row.
    pub w: SMatrix<T, NK, NQ>,
    /// `−μ ŝ` on the tangential rows of a sliding contact, zero elsewhere.
    pub slide: SVector<T, NK>,
    /// Which rows are held ([`Modes::held_rows`]).
    pub held: [bool; NK],
}

impl<T: Real, const NQ: usize, const NK: usize, const ND: usize> ContactRows<T, NQ, NK, ND> {
    /// The rows of the base-frame contact Jacobian `jacobian` (`J_c`) on `ground`, under
    /// `modes`, with friction `mu`. `slip` holds the unit slip direction `ŝ` of each
    /// sliding contact on its tangential rows ([`slip_directions`]); a planar contact's
    /// is its mode's `forward` (`±1`) and `slip` is not read for it.
    pub fn new(
        ground: &Ground<T, ND>,
        jacobian: &SMatrix<T, NK, NQ>,
        modes: &Modes<NK, ND>,
        mu: &SVector<T, NK>,
        slip: &SVector<T, NK>,
    ) -> Self {
        Self::from_rows(ground.rows(jacobian), modes, mu, slip)
    }

    /// [`ContactRows::new`] from the rows already in the ground's frame, `C`.
    pub fn from_rows(
        c: SMatrix<T, NK, NQ>,
        modes: &Modes<NK, ND>,
        mu: &SVector<T, NK>,
        slip: &SVector<T, NK>,
    ) -> Self {
        let held = modes.held_rows();
        let mut w = c;
        let mut slide = SVector::<T, NK>::zeros();
        for k in 0..NK / ND {
            let n = ND * k + ND - 1;
            match modes.get(k) {
                ContactMode::Slide { forward } => {
                    for r in ND * k..n {
                        let s = if ND == 2 {
                            if forward {
                                T::one()
                            } else {
                                -T::one()
                            }
                        } else {
                            slip[r]
                        };
                        slide[r] = -mu[r] * s;
                    }
                    for col in 0..NQ {
                        let mut normal = c[(n, col)];
                        for r in ND * k..n {
                            normal += slide[r] * c[(r, col)];
                            w[(r, col)] = T::zero();
                        }
                        w[(n, col)] = normal;
                    }
                }
                ContactMode::Flight => {
                    for r in ND * k..=n {
                        w.row_mut(r).fill(T::zero());
                    }
                }
                ContactMode::Stick => {}
            }
        }
        ContactRows { c, w, slide, held }
    }
}

/// The unit slip direction `ŝ` of each sliding contact of a spatial leg, on its
/// tangential rows (zero elsewhere): the direction of its velocity along the ground,
/// `v_t / |v_t|` with `v = C q̇` (`c`, the ground rows [`Ground::rows`]). A contact whose
/// `|v_t|` is within rounding of zero (`√ε` of the speeds its rows could have at `q̇`)
/// slides from rest: its direction is `rest`'s (normalized), and without one it is
/// [`DynamicsError::SlipFromRest`]. Where `rest` is given, it is also the direction the
/// slide keeps once its velocity has turned back against it (`v_t · rest ≤ 0`): friction
/// then keeps its direction through the stop, as a planar slide's does, so that the
/// velocity crosses zero cleanly and the simulator's slide guard finds the stop instead
/// of friction turning over at every stage of a step around it. A planar contact's direction is its mode's, `±1`.
pub fn slip_directions<T: Real, const NQ: usize, const NK: usize, const ND: usize>(
    c: &SMatrix<T, NK, NQ>,
    qd: &SVector<T, NQ>,
    modes: &Modes<NK, ND>,
    rest: Option<&SVector<T, NK>>,
) -> Result<SVector<T, NK>, DynamicsError> {
    let mut out = SVector::<T, NK>::zeros();
    for k in 0..NK / ND {
        let ContactMode::Slide { forward } = modes.get(k) else {
            continue;
        };
        if ND == 2 {
            out[ND * k] = if forward { T::one() } else { -T::one() };
            continue;
        }
        let tangential = ND * k..ND * k + ND - 1;
        let (v, moving) = tangential_velocity::<T, NQ, NK, ND>(c, qd, k);
        let ahead = rest.map_or(T::one(), |d| {
            tangential.clone().fold(T::zero(), |a, r| a + d[r] * v[r])
        });
        if moving && ahead > T::zero() && set_unit(&mut out, &v, tangential.clone()) {
            continue;
        }
        match rest {
            Some(d) if set_unit(&mut out, d, tangential) => {}
            _ => return Err(DynamicsError::SlipFromRest { contact: k }),
        }
    }
    Ok(out)
}

/// Friction coefficients of leg `L`'s spec, one per row (every row of contact `k` holds
/// its `μ`).
pub fn spec_friction<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>() -> SVector<T, NK>
where
    L: ContactModel<NQ, NC, NU, NK, ND>,
    T: Real,
{
    SVector::from_fn(|r, _| T::lit(L::CONTACT_FRICTION[r / ND]))
}

/// Constrained forward dynamics with the contacts in `modes`: closure rows and held
/// contact rows in one structured solve. Baumgarte terms, when given, act on the closure
/// residual and on the held contacts' drift from `anchors` (ground coordinates: the
/// tangential entries of a sticking contact are where it touched down; the normal entry
/// is the ground, 0). A sliding contact of a spatial leg slides against its velocity along
/// the ground; one that slides from rest needs its direction:
/// [`ContactSystem::with_slip`].
#[allow(clippy::too_many_arguments)]
pub fn forward_dynamics_with_contacts<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    u: &SVector<T, NU>,
    modes: &Modes<NK, ND>,
    anchors: &SVector<T, NK>,
    ground: &Ground<T, ND>,
    mu: &SVector<T, NK>,
    baumgarte: Option<Baumgarte<T>>,
) -> Result<ContactSolution<T, NQ, NC, NK>, DynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK, ND>,
    T: Real,
{
    // The factor chosen at compile time (no `MassFactor` to carry and match: that cost
    // the small legs' contact paths 3 %, raibert_hopper contact_slide 3082 → 3174).
    let terms = L::dynamics_terms(q, qd, params);
    let m = &terms.mass_matrix;
    let applied = actuation::<L, T, NQ, NC, NU>(u);
    let args = (params, q, qd, modes, anchors, ground, mu, baumgarte, None);
    if let Some(ends) = mass_tree::<L, NQ, NC, NU>() {
        let f = positive_factor(TreeLdl::new(m, ends))?;
        ContactSystem::<T, NQ, NC, NK, ND, _>::assemble::<L, NU>(&terms, f, args)?.solve(&applied)
    } else {
        let f = positive_factor(Cholesky::new(m))?;
        ContactSystem::<T, NQ, NC, NK, ND, _>::assemble::<L, NU>(&terms, f, args)?.solve(&applied)
    }
}

/// How a factor of `M` solves a stance's structured system ([`solve_structured_columns`]
/// densely, in half solves along the tree): the solve belongs to the factor.
pub trait StructuredSolve<T: Real, const NQ: usize>: Factored<T, NQ> {
    /// [`solve_structured_columns`] with this factor.
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    fn solve_structured<const NC: usize, const NK: usize, const ND: usize, const C: usize>(
        &self,
        j: &SMatrix<T, NC, NQ>,
        r_j: &SMatrix<T, NC, C>,
        closure_deficiency: usize,
        rows: &ContactRows<T, NQ, NK, ND>,
        r_c: &SMatrix<T, NK, C>,
        tau: &SMatrix<T, NQ, C>,
    ) -> Result<(SMatrix<T, NQ, C>, SMatrix<T, NC, C>, SMatrix<T, NK, C>), DynamicsError>;
}

impl<T: Real, const NQ: usize> StructuredSolve<T, NQ> for Cholesky<T, NQ> {
    #[inline(always)]
    fn solve_structured<const NC: usize, const NK: usize, const ND: usize, const C: usize>(
        &self,
        j: &SMatrix<T, NC, NQ>,
        r_j: &SMatrix<T, NC, C>,
        d: usize,
        rows: &ContactRows<T, NQ, NK, ND>,
        r_c: &SMatrix<T, NK, C>,
        tau: &SMatrix<T, NQ, C>,
    ) -> Result<(SMatrix<T, NQ, C>, SMatrix<T, NC, C>, SMatrix<T, NK, C>), DynamicsError> {
        solve_structured_columns(self, j, r_j, d, rows, r_c, tau)
    }
}

impl<T: Real, const NQ: usize> StructuredSolve<T, NQ> for TreeLdl<T, NQ> {
    #[inline(always)]
    fn solve_structured<const NC: usize, const NK: usize, const ND: usize, const C: usize>(
        &self,
        j: &SMatrix<T, NC, NQ>,
        r_j: &SMatrix<T, NC, C>,
        d: usize,
        rows: &ContactRows<T, NQ, NK, ND>,
        r_c: &SMatrix<T, NK, C>,
        tau: &SMatrix<T, NQ, C>,
    ) -> Result<(SMatrix<T, NQ, C>, SMatrix<T, NC, C>, SMatrix<T, NK, C>), DynamicsError> {
        solve_structured_on_tree(self, j, r_j, d, rows, r_c, tau)
    }
}

impl<T: Real, const NQ: usize> StructuredSolve<T, NQ> for MassFactor<T, NQ> {
    #[inline(always)]
    fn solve_structured<const NC: usize, const NK: usize, const ND: usize, const C: usize>(
        &self,
        j: &SMatrix<T, NC, NQ>,
        r_j: &SMatrix<T, NC, C>,
        d: usize,
        rows: &ContactRows<T, NQ, NK, ND>,
        r_c: &SMatrix<T, NK, C>,
        tau: &SMatrix<T, NQ, C>,
    ) -> Result<(SMatrix<T, NQ, C>, SMatrix<T, NC, C>, SMatrix<T, NK, C>), DynamicsError> {
        match self {
            MassFactor::Dense(f) => f.solve_structured(j, r_j, d, rows, r_c, tau),
            MassFactor::Tree(f) => f.solve_structured(j, r_j, d, rows, r_c, tau),
        }
    }
}

/// A factor of `M`, refused where it failed or its pivot ratio is below [`rcond_floor`]
/// (`MassMatrixNotPositiveDefinite`; a NaN shows in the pivots).
#[inline(always)]
fn positive_factor<T: Real, F: Factored<T, NQ>, const NQ: usize>(
    f: Option<F>,
) -> Result<F, DynamicsError> {
    match f {
        Some(f) if f.rcond() >= rcond_floor::<T>() => Ok(f),
        _ => Err(DynamicsError::MassMatrixNotPositiveDefinite),
    }
}

/// The arguments of [`ContactSystem::with_slip`] after the model's terms:
/// `(params, q, qd, modes, anchors, ground, mu, baumgarte, rest)`.
type SystemArgs<'a, P, T, const NQ: usize, const NK: usize, const ND: usize> = (
    &'a P,
    &'a SVector<T, NQ>,
    &'a SVector<T, NQ>,
    &'a Modes<NK, ND>,
    &'a SVector<T, NK>,
    &'a Ground<T, ND>,
    &'a SVector<T, NK>,
    Option<Baumgarte<T>>,
    Option<&'a SVector<T, NK>>,
);

/// The stance (or flight) system of leg `L` at one state, evaluated and factored once,
/// for the solves of several applied forces: what a controller that needs the response
/// to each motor (or to any generalized force) calls instead of
/// [`forward_dynamics_with_contacts`] once per right-hand side.
#[derive(Clone, Copy, Debug)]
pub struct ContactSystem<
    T: Real,
    const NQ: usize,
    const NC: usize,
    const NK: usize,
    const ND: usize = 2,
    F = MassFactor<T, NQ>,
> {
    /// `M` factored densely, or along the tree where that pays ([`MassFactor`]).
    pub(crate) chol_m: F,
    pub(crate) jacobian: SMatrix<T, NC, NQ>,
    pub(crate) r_j: SVector<T, NC>,
    redundant_rows: usize,
    pub(crate) rows: ContactRows<T, NQ, NK, ND>,
    /// The slip direction of each sliding contact ([`slip_directions`]).
    pub slip: SVector<T, NK>,
    pub(crate) r_c: SVector<T, NK>,
    /// `−N − D q̇`: the forces that act whatever is applied.
    pub(crate) passive: SVector<T, NQ>,
    /// `M(q)`.
    pub mass_matrix: SMatrix<T, NQ, NQ>,
}

impl<T: Real, const NQ: usize, const NC: usize, const NK: usize, const ND: usize>
    ContactSystem<T, NQ, NC, NK, ND>
{
    /// Evaluates the terms and factors `M` (the arguments as for
    /// [`forward_dynamics_with_contacts`]).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn new<L, const NU: usize>(
        params: &L::Params<T>,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        modes: &Modes<NK, ND>,
        anchors: &SVector<T, NK>,
        ground: &Ground<T, ND>,
        mu: &SVector<T, NK>,
        baumgarte: Option<Baumgarte<T>>,
    ) -> Result<Self, DynamicsError>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        Self::with_slip::<L, NU>(params, q, qd, modes, anchors, ground, mu, baumgarte, None)
    }

    /// [`ContactSystem::new`] with the direction `rest` (unit, on the tangential rows) of
    /// each sliding contact of a spatial leg that slides from rest: a contact whose
    /// velocity along the ground is zero has no slip direction of its own, and the one it
    /// starts to slip in depends on the applied forces ([`slip_directions`]).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn with_slip<L, const NU: usize>(
        params: &L::Params<T>,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        modes: &Modes<NK, ND>,
        anchors: &SVector<T, NK>,
        ground: &Ground<T, ND>,
        mu: &SVector<T, NK>,
        baumgarte: Option<Baumgarte<T>>,
        rest: Option<&SVector<T, NK>>,
    ) -> Result<Self, DynamicsError>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        let terms = L::dynamics_terms(q, qd, params);
        let chol_m = factor_mass::<L, T, NQ, NC, NU>(&terms.mass_matrix)?;
        Self::assemble::<L, NU>(
            &terms,
            chol_m,
            (params, q, qd, modes, anchors, ground, mu, baumgarte, rest),
        )
    }
}

impl<
        T: Real,
        const NQ: usize,
        const NC: usize,
        const NK: usize,
        const ND: usize,
        F: StructuredSolve<T, NQ>,
    > ContactSystem<T, NQ, NC, NK, ND, F>
{
    /// The system from the model's terms and `M` factored.
    #[inline(always)]
    pub(crate) fn assemble<L, const NU: usize>(
        terms: &DynamicsTerms<T, NQ, NC>,
        chol_m: F,
        (params, q, qd, modes, anchors, ground, mu, baumgarte, rest): SystemArgs<
            '_,
            L::Params<T>,
            T,
            NQ,
            NK,
            ND,
        >,
    ) -> Result<Self, DynamicsError>
    where
        L: ContactModel<NQ, NC, NU, NK, ND>,
    {
        let passive = -terms.bias_forces - L::damping_forces(qd, params);
        let mut r_j = -terms.constraint_bias;
        let jc = L::contact_jacobian(q, params);
        // C once: the slip directions and the rows both read it.
        let c = ground.rows(&jc);
        let slip = slip_directions(&c, qd, modes, rest)?;
        let rows = ContactRows::from_rows(c, modes, mu, &slip);
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
            slip,
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
        let (x, closure, contact) =
            self.solve_columns(&(applied + self.passive), &self.r_j, &self.r_c)?;
        Ok(ContactSolution {
            x,
            closure,
            contact,
        })
    }

    /// The system's solve for `C` right-hand sides at once (columns of the whole
    /// generalized force `τ` and of the closure and contact rows' right-hand sides),
    /// along the tree where `M` was factored along it: what [`ContactSystem::solve`] and
    /// the derivatives call, so that their solutions agree to the bit. Returns `(x, F, λ)`.
    #[allow(clippy::type_complexity)]
    pub(crate) fn solve_columns<const C: usize>(
        &self,
        tau: &SMatrix<T, NQ, C>,
        r_j: &SMatrix<T, NC, C>,
        r_c: &SMatrix<T, NK, C>,
    ) -> Result<(SMatrix<T, NQ, C>, SMatrix<T, NC, C>, SMatrix<T, NK, C>), DynamicsError> {
        let (j, d, rows) = (&self.jacobian, self.redundant_rows, &self.rows);
        self.chol_m.solve_structured(j, r_j, d, rows, r_c, tau)
    }
}

/// Removes from `q̇` the part that moves a held contact or opens a closure, in the metric
/// of `M` (the least kinetic energy taken away): the velocity projection of a stance,
/// which keeps its held rows consistent step after step (two held contacts on one rigid
/// foot contradict each other as soon as the foot's points move apart in the rates, see
/// [`solve_structured`]). Only sticking contacts' rows count (a sliding one keeps its
/// speed along the ground, its normal rate removed). It is a plastic impact without its
/// friction cones: at the drift's size of a step's rounding, a cone has no say.
pub fn project_held_velocity<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &mut SVector<T, NQ>,
    modes: &Modes<NK, ND>,
    ground: &Ground<T, ND>,
) -> Result<(), DynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK, ND>,
    T: Real,
{
    if !(all_finite(q) && all_finite(qd)) {
        return Err(DynamicsError::NonFinite);
    }
    let m = L::mass_matrix(q, params);
    let j = L::constraint_jacobian(q, params);
    let jc = L::contact_jacobian(q, params);
    // A sliding contact's normal row only: its tangential rows are left out (friction
    // plays no part in a projection).
    let mut held = *modes;
    for k in 0..NK / ND {
        if let ContactMode::Slide { .. } = modes.get(k) {
            held.set(k, ContactMode::Slide { forward: true });
        }
    }
    let rows = ContactRows::new(ground, &jc, &held, &SVector::zeros(), &SVector::zeros());
    // M q̇⁺ − Rᵀ Λ = M q̇, R q̇⁺ = 0: the least change in M's metric onto the rows.
    // The factor's own structured solve: along the tree where `M` is factored there
    // (half solves, a leg's columns skipped for another leg's rows), not the dense
    // columns, which cost Cassie's projection more than its stance solve.
    fn onto<
        T: Real,
        F: StructuredSolve<T, NQ>,
        const NQ: usize,
        const NC: usize,
        const NK: usize,
        const ND: usize,
    >(
        chol_m: &F,
        j: &SMatrix<T, NC, NQ>,
        deficiency: usize,
        rows: &ContactRows<T, NQ, NK, ND>,
        momentum: &SVector<T, NQ>,
    ) -> Result<SVector<T, NQ>, DynamicsError> {
        let (x, _, _) = chol_m.solve_structured::<NC, NK, ND, 1>(
            j,
            &SVector::zeros(),
            deficiency,
            rows,
            &SVector::zeros(),
            momentum,
        )?;
        Ok(x)
    }
    let momentum = mul(&m, qd);
    let d = L::REDUNDANT_ROWS;
    *qd = if let Some(ends) = mass_tree::<L, NQ, NC, NU>() {
        onto(
            &checked_mass_factor(TreeLdl::new(&m, ends), &m)?,
            &j,
            d,
            &rows,
            &momentum,
        )?
    } else {
        onto(
            &checked_mass_factor(Cholesky::new(&m), &m)?,
            &j,
            d,
            &rows,
            &momentum,
        )?
    };
    Ok(())
}

/// A plastic impact: the velocities after it and what it cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Impact<T: Real, const NQ: usize, const NC: usize, const NK: usize> {
    /// `q̇⁺`: every closure and every held contact row at rest (`J q̇⁺ = 0`, `C q̇⁺ = 0`).
    pub qd_plus: SVector<T, NQ>,
    /// Closure impulses (base frame).
    pub closure_impulses: SVector<T, NC>,
    /// Ground impulses per contact, `(Λ_t, Λ_n)` in the ground's frame.
    pub impulses: SVector<T, NK>,
    /// The slip direction `ŝ` each sliding contact of a spatial leg was resolved with
    /// (unit, on its tangential rows; zero elsewhere and on a planar leg).
    pub slip: SVector<T, NK>,
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
/// (`|Λ_t| > μ Λ_n`, the Euclidean norm of the tangential impulse) is resolved again as
/// sliding, its friction impulse `μ Λ_n` against the slip after the impact, and its mode
/// in `modes` becomes `Slide`; the check runs again after each such change, which moves
/// the other contacts' impulses (one round per contact at most). On a spatial leg that
/// slip direction is the one the slip after the impact takes (a fixed point from the
/// sticking impulse's, then a scan of the circle refined by bisection, contact by
/// contact; where none is consistent, as Coulomb's law on impulses allows, the last one
/// tried is kept); a planar leg's is one of two: against its impulse, flipped in each
/// round where the slip after the impact runs the other way. Every held normal impulse
/// must be non-negative ([`ImpactError::Pulling`] otherwise).
///
/// A sticking impact loses exactly `½ Δq̇ᵀ M Δq̇`. A sliding one loses energy unless the
/// impulse reverses the slip (then Coulomb's law applied to impulses can add energy, a
/// known limit of the model, Stronge 1991); `energy_lost` reports what happened.
#[allow(clippy::too_many_arguments)]
pub fn impact_map<
    L,
    T,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    modes: &mut Modes<NK, ND>,
    ground: &Ground<T, ND>,
    mu: &SVector<T, NK>,
) -> Result<Impact<T, NQ, NC, NK>, ImpactError>
where
    L: ContactModel<NQ, NC, NU, NK, ND>,
    T: Real,
{
    if !(all_finite(q) && all_finite(qd)) {
        return Err(DynamicsError::NonFinite.into());
    }
    let m = L::mass_matrix(q, params);
    let chol_m = checked_mass_factor(Cholesky::new(&m), &m)?;
    let j = L::constraint_jacobian(q, params);
    let jc = L::contact_jacobian(q, params);
    let momentum = mul(&m, qd);
    let solve = |modes: &Modes<NK, ND>, slip: &SVector<T, NK>| {
        let rows = ContactRows::new(ground, &jc, modes, mu, slip);
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
    // A spatial contact already sliding into the impact starts from its slip before it;
    // one at rest along the ground (its speed within rounding, as in `slip_directions`)
    // from none: `consistent_slip` then starts from the slip a frictionless impact leaves.
    let tangential = |k: usize| ND * k..ND * k + ND - 1;
    let mut slip = SVector::<T, NK>::zeros();
    if ND > 2 {
        let c = ground.rows(&jc);
        for k in 0..NK / ND {
            if let ContactMode::Slide { .. } = modes.get(k) {
                let (before, moving) = tangential_velocity::<T, NQ, NK, ND>(&c, qd, k);
                if moving {
                    set_unit(&mut slip, &before, tangential(k));
                }
            }
        }
    }
    let mut sol = solve(modes, &slip)?;
    // A sticking impulse outside the cone slides instead. Resolving one contact as sliding
    // moves the others' impulses (two points of one foot share them), so the check runs
    // again until no sticking impulse leaves its cone: each round turns at least one
    // contact from sticking to sliding, so there are at most as many rounds as contacts.
    let mut first = true;
    for _ in 0..=NK / ND {
        let mut changed = false;
        for k in 0..NK / ND {
            if modes.get(k) == ContactMode::Stick {
                let n = ND * k + ND - 1;
                if tangential_norm::<T, NK, ND>(&sol.contact, k) > mu[ND * k] * sol.contact[n] {
                    // λ_t = −μ ŝ λ_n: the slip runs against the friction impulse.
                    modes.set(
                        k,
                        ContactMode::Slide {
                            forward: ND > 2 || sol.contact[ND * k] < T::zero(),
                        },
                    );
                    set_unit(&mut slip, &-sol.contact, tangential(k));
                    changed = true;
                }
            }
        }
        let sliding = (0..NK / ND).any(|k| matches!(modes.get(k), ContactMode::Slide { .. }));
        // After the first round, only a change asks for another solve.
        if !(changed || (first && ND > 2 && sliding)) {
            break;
        }
        first = false;
        if ND == 2 {
            sol = solve(modes, &slip)?;
            // The slip after the impact must run the way its friction opposes; where it
            // does not (the impulse reversed the slip), the other direction is the
            // consistent one.
            let after = ground.rows(&mul(&jc, &sol.x));
            let mut flipped = false;
            for k in 0..NK / ND {
                if let ContactMode::Slide { forward } = modes.get(k) {
                    let along = if forward {
                        after[ND * k]
                    } else {
                        -after[ND * k]
                    };
                    if along < T::zero() {
                        modes.set(k, ContactMode::Slide { forward: !forward });
                        flipped = true;
                    }
                }
            }
            if flipped {
                sol = solve(modes, &slip)?;
            }
        } else {
            // Each sliding contact's direction is the one the slip after the impact takes
            // (`consistent_slip`), the others' held as they are, until none turns.
            for _ in 0..8 {
                let mut turned = false;
                for k in 0..NK / ND {
                    if !matches!(modes.get(k), ContactMode::Slide { .. }) {
                        continue;
                    }
                    let (t0, t1) = (ND * k, ND * k + 1);
                    let (found, _) = consistent_slip([slip[t0], slip[t1]], |d| {
                        let mut trial = slip;
                        (trial[t0], trial[t1]) = (d[0], d[1]);
                        let x = solve(modes, &trial)?.x;
                        let after = ground.rows(&mul(&jc, &x));
                        Ok::<_, DynamicsError>([after[t0], after[t1]])
                    })?;
                    let turn = (found[0] - slip[t0]).abs().max((found[1] - slip[t1]).abs());
                    turned |= turn > T::default_epsilon().sqrt();
                    (slip[t0], slip[t1]) = (found[0], found[1]);
                }
                if !turned {
                    break;
                }
            }
            sol = solve(modes, &slip)?;
        }
    }
    for k in 0..NK / ND {
        let n = ND * k + ND - 1;
        if modes.get(k).on_ground() && sol.contact[n] < T::zero() {
            return Err(ImpactError::Pulling {
                contact: k,
                normal_impulse: to_f64(sol.contact[n]),
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
        slip: if ND == 2 { SVector::zeros() } else { slip },
        energy_lost,
    })
}
