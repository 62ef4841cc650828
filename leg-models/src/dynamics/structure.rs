//! What a leg is as a mechanism, and which methods apply to it: its mobility (degrees of
//! freedom of the closed chain, `NQ − rank J`) against its motors, and the closure rows
//! that repeat the others. Properties, never names, decide what applies to a leg.

use core::fmt;

use nalgebra::SMatrix;

use crate::dynamics::forward::rcond_floor;
use crate::model::contract::{LegDynamics, Real};
use crate::model::linalg::PivotedLdlt;
pub use crate::model::linalg::{factors_along_the_tree, mass_factor_operations, subtree_ends};

/// How a leg's motors compare with its degrees of freedom.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Actuation {
    /// As many motors as degrees of freedom: the motor angles determine the leg.
    Full,
    /// Fewer motors than degrees of freedom (a passive ankle): the passive joints move on
    /// their own; the motors' own accelerations can still be commanded.
    Under,
    /// More motors than degrees of freedom: the motors fight through the closures.
    Over,
}

/// The counts that decide which methods apply to a leg.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Structure {
    /// `NQ`.
    pub joints: usize,
    /// `NC`.
    pub closure_rows: usize,
    /// Closure rows implied by the others ([`LegDynamics::REDUNDANT_ROWS`]).
    pub redundant_rows: usize,
    /// `NQ − rank J` ([`LegDynamics::MOBILITY`]).
    pub mobility: usize,
    /// `NU`.
    pub motors: usize,
    /// The foot's coordinates: 2 on a planar leg, 3 on a spatial one
    /// ([`LegDynamics::DIMENSION`]).
    pub dimension: usize,
}

/// Why a method does not apply to a leg; named when a controller or reduction is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NotApplicable {
    /// The motors do not determine the passive joints, so the null-space form `q̇ = G θ̇`
    /// and everything built on it (foot control, the foot inverse) do not exist.
    UnderActuated {
        /// The leg's degrees of freedom.
        mobility: usize,
        /// Its motors, fewer.
        motors: usize,
    },
    /// The motors over-determine the leg: there is no reduction to the motor angles.
    OverActuated {
        /// The leg's degrees of freedom.
        mobility: usize,
        /// Its motors, more.
        motors: usize,
    },
    /// The foot has two coordinates in the plane, three in space; fewer motors cannot
    /// place it.
    FootNeedsMotors {
        /// The leg's motors, fewer than the foot's coordinates.
        motors: usize,
        /// The foot's coordinates.
        dimension: usize,
    },
}

impl fmt::Display for NotApplicable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = |n: usize| if n == 1 { "" } else { "s" };
        match *self {
            NotApplicable::UnderActuated { mobility, motors } => write!(
                f,
                "the leg has {mobility} degree{} of freedom but {motors} motor{}: the motors do not determine the passive joints",
                s(mobility),
                s(motors)
            ),
            NotApplicable::OverActuated { mobility, motors } => write!(
                f,
                "the leg has {mobility} degree{} of freedom but {motors} motors: the motors over-determine it, so there is no reduction to the motor angles",
                s(mobility)
            ),
            NotApplicable::FootNeedsMotors { motors, dimension } => {
                let n = match dimension {
                    2 => "two",
                    3 => "three",
                    _ => "its",
                };
                write!(
                    f,
                    "the foot has {n} coordinates but the leg has {motors} motor{}: foot-space control needs at least {n}",
                    s(motors)
                )
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for NotApplicable {}

impl Structure {
    /// The structure of leg `L`.
    pub fn of<L, const NQ: usize, const NC: usize, const NU: usize>() -> Structure
    where
        L: LegDynamics<NQ, NC, NU>,
    {
        Structure {
            joints: NQ,
            closure_rows: NC,
            redundant_rows: L::REDUNDANT_ROWS,
            mobility: L::MOBILITY,
            motors: NU,
            dimension: L::DIMENSION,
        }
    }

    /// How the motors compare with the mobility.
    pub fn actuation(&self) -> Actuation {
        match self.mobility.cmp(&self.motors) {
            core::cmp::Ordering::Equal => Actuation::Full,
            core::cmp::Ordering::Greater => Actuation::Under,
            core::cmp::Ordering::Less => Actuation::Over,
        }
    }

    /// The Schur reduction `Ã θ̈ = b̃ + u` (and joint-space control of the motors) exists
    /// unless the motors over-determine the leg.
    pub fn joint_space(&self) -> Result<(), NotApplicable> {
        match self.actuation() {
            Actuation::Over => Err(NotApplicable::OverActuated {
                mobility: self.mobility,
                motors: self.motors,
            }),
            _ => Ok(()),
        }
    }

    /// The motor angles determine the leg (`q̇ = G θ̇`): the null-space form applies.
    pub fn motors_determine_the_leg(&self) -> Result<(), NotApplicable> {
        match self.actuation() {
            Actuation::Full => Ok(()),
            Actuation::Under => Err(NotApplicable::UnderActuated {
                mobility: self.mobility,
                motors: self.motors,
            }),
            Actuation::Over => Err(NotApplicable::OverActuated {
                mobility: self.mobility,
                motors: self.motors,
            }),
        }
    }

    /// The motors can place the foot: at least as many as its coordinates (two in the
    /// plane, three in space), and they determine the leg.
    /// (At a given pose the foot Jacobian may still lose rank: a typed error there.)
    pub fn foot_space(&self) -> Result<(), NotApplicable> {
        if self.motors < self.dimension {
            return Err(NotApplicable::FootNeedsMotors {
                motors: self.motors,
                dimension: self.dimension,
            });
        }
        self.motors_determine_the_leg()
    }
}

/// Factors a matrix built from the closure rows (`J X Jᵀ`, `J Jᵀ + μ I`), allowing as
/// many negligible pivots as the leg has redundant rows ([`LegDynamics::REDUNDANT_ROWS`]
/// counts them; the pivots choose which, since that depends on the configuration).
pub(crate) fn factor_closure_rows<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    s: &SMatrix<T, NC, NC>,
) -> Option<PivotedLdlt<T, NC>>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    PivotedLdlt::new(s, L::REDUNDANT_ROWS, rcond_floor::<T>())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Depth-first order found and refused; the choice by operations: a body carrying
    /// two three-link legs is factored along the tree, a chain and a small leg densely.
    #[test]
    fn chooses_the_tree_factor_by_operations() {
        assert_eq!(subtree_ends(&[None, Some(0), Some(0), Some(1)]), None); // 3 is 1's, after 2
        assert_eq!(subtree_ends(&[None, Some(1), None]), None); // parent after child
        assert_eq!(
            subtree_ends(&[None, Some(0), Some(1), None]),
            Some([3, 3, 3, 4])
        );
        let chain = [None, Some(0), Some(1), Some(2), Some(3), Some(4)];
        let (dense, tree) = mass_factor_operations(&chain);
        assert_eq!(dense, 36 + 35);
        assert!(!factors_along_the_tree(&chain), "{dense} {tree:?}");
        // A body (a chain of six) carrying four legs of two two-link branches each, as
        // Minitaur's quadruped: 665 multiply–adds along the tree, 2255 dense.
        let mut quadruped = [None; 22];
        for (k, p) in quadruped.iter_mut().enumerate().skip(1) {
            *p = Some(if k >= 6 && k % 2 == 0 { 5 } else { k - 1 });
        }
        assert_eq!(mass_factor_operations(&quadruped), (2255, Some(665)));
        assert!(factors_along_the_tree(&quadruped));
        // The same body carrying two three-link chains: 319 against 430 does not pay, nor
        // does a small leg's tree however sparse (a five-bar: 6 against 26).
        let mut two_chains = [None; 12];
        for (k, p) in two_chains.iter_mut().enumerate().skip(1) {
            *p = Some(if k == 9 { 5 } else { k - 1 });
        }
        assert_eq!(mass_factor_operations(&two_chains), (430, Some(319)));
        assert!(!factors_along_the_tree(&two_chains));
        assert!(!factors_along_the_tree(&[None, Some(1), None]));
        let five_bar = [None, Some(0), None, Some(2)];
        assert_eq!(mass_factor_operations(&five_bar), (26, Some(6)));
        assert!(!factors_along_the_tree(&five_bar));
    }
}
