//! `LegDynamics::mass_tree_factor`: the mass matrix's `Lᵀ D L` along the spec's tree,
//! written out for the model's coordinates (RobCoGen's unrolled `JSIM::computeL()`, as an
//! `L D Lᵀ` without square roots). It repeats `leg_models::linalg::factor_along_tree`'s
//! operations in the same order, so the two agree to the bit, with every index a constant:
//! no loops over stretches of run-time length, no index checks, and the sums of different
//! entries free to overlap.

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

/// One past the last coordinate of each coordinate's subtree, where `parents` lists the
/// coordinates depth first (parents first, every subtree contiguous); `None` otherwise.
/// The runtime's `SubtreeEnds::of`, which decides the same for the factor's caller.
pub fn subtree_ends(parents: &[Option<usize>]) -> Option<Vec<usize>> {
    let n = parents.len();
    let mut ends = vec![0; n];
    for k in (0..n).rev() {
        if ends[k] == 0 {
            ends[k] = k + 1;
        }
        if let Some(p) = parents[k] {
            if p >= k {
                return None;
            }
            ends[p] = ends[p].max(ends[k]);
        }
    }
    let contiguous =
        (0..n).all(|k| (k + 1..ends[k]).all(|j| matches!(parents[j], Some(p) if p >= k)));
    contiguous.then_some(ends)
}

/// The trait method, for the tree `parents`. Where the coordinates are not depth first
/// the runtime factors `M` densely and never calls it; it then writes NaN pivots, which
/// `TreeLdl::with_factor` refuses.
pub fn mass_tree_factor(parents: &[Option<usize>]) -> TokenStream {
    // Not forced inline: a robot's factor is a thousand lines, called once a solve.
    let signature = quote! {
        #[inline]
        fn mass_tree_factor<T: Arithmetic>(
            l: &mut SMatrix<T, NQ, NQ>,
            d: &mut SVector<T, NQ>,
            inv_d: &mut SVector<T, NQ>,
        )
    };
    let Some(ends) = subtree_ends(parents) else {
        return quote! {
            #signature {
                let _ = l;
                d.fill(T::lit(f64::NAN));
                inv_d.fill(T::lit(f64::NAN));
            }
        };
    };
    let n = parents.len();
    let lit = Literal::usize_unsuffixed;
    let entry = |j: usize, i: usize| format_ident!("l_{}_{}", j, i);
    let pivot = |i: usize| format_ident!("d_{}", i);
    let inverse = |i: usize| format_ident!("inv_{}", i);
    let mut body = Vec::new();
    for i in (0..n).rev() {
        let mut pivot_terms = Vec::new();
        for j in (i + 1..ends[i]).rev() {
            // Lⱼᵢ Dⱼ = Aᵢⱼ − Σ_{k below j} Lₖᵢ Dₖ Lₖⱼ, the sum from the top of j's subtree.
            let s = format_ident!("s_{}_{}", j, i);
            let terms = (j + 1..ends[j]).map(|k| {
                let (lki, dk, lkj) = (entry(k, i), pivot(k), entry(k, j));
                quote!(- #lki * #dk * #lkj)
            });
            let (li, lj, lji, inv_j) = (lit(i), lit(j), entry(j, i), inverse(j));
            body.push(quote! {
                let #s = l[(#li, #lj)] #(#terms)*;
                let #lji = #s * #inv_j;
            });
            pivot_terms.push(quote!(- #lji * #s));
        }
        let (li, di, inv_i) = (lit(i), pivot(i), inverse(i));
        body.push(quote! {
            let #di = l[(#li, #li)] #(#pivot_terms)*;
            let #inv_i = T::lit(1.0) / #di;
        });
    }
    for (i, &end) in ends.iter().enumerate() {
        for j in i + 1..end {
            let (li, lj, lji) = (lit(i), lit(j), entry(j, i));
            body.push(quote!(l[(#lj, #li)] = #lji;));
        }
        let (li, di, inv_i) = (lit(i), pivot(i), inverse(i));
        body.push(quote! {
            d[#li] = #di;
            inv_d[#li] = #inv_i;
        });
    }
    quote! {
        #signature {
            #(#body)*
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_of_depth_first_trees_and_refusals() {
        // Two branches under a body of two coordinates: 0 → 1 → {2 → 3, 4}.
        let tree = [None, Some(0), Some(1), Some(2), Some(1)];
        assert_eq!(subtree_ends(&tree), Some(vec![5, 5, 4, 4, 5]));
        // A parent after its child, and a subtree split by another branch.
        assert_eq!(subtree_ends(&[Some(1), None]), None);
        assert_eq!(subtree_ends(&[None, Some(0), None, Some(1)]), None);
    }

    #[test]
    fn factor_of_a_small_tree_reads_only_its_branches() {
        // 0 → {1, 2}: the two leaves are independent, so L₂₁ is never formed and the
        // root's pivot takes both of its children's entries, the deeper (2) first.
        let code = mass_tree_factor(&[None, Some(0), Some(0)])
            .to_string()
            .replace(' ', "");
        for line in [
            "lets_2_0=l[(0,2)];",
            "letl_2_0=s_2_0*inv_2;",
            "letd_0=l[(0,0)]-l_2_0*s_2_0-l_1_0*s_1_0;",
            "letinv_0=T::lit(1.0)/d_0;",
            "l[(2,0)]=l_2_0;",
            "inv_d[1]=inv_1;",
        ] {
            assert!(code.contains(line), "{line} not in {code}");
        }
        assert!(!code.contains("l_2_1"), "{code}");
        // A chain: the deepest entry enters its ancestors' sums, D weighted.
        let chain = mass_tree_factor(&[None, Some(0), Some(1)])
            .to_string()
            .replace(' ', "");
        assert!(
            chain.contains("lets_1_0=l[(0,1)]-l_2_0*d_2*l_2_1;"),
            "{chain}"
        );
    }

    #[test]
    fn coordinates_out_of_depth_first_order_get_nan_pivots() {
        let code = mass_tree_factor(&[None, Some(0), None, Some(1)]).to_string();
        assert!(code.contains("NAN"), "{code}");
    }
}
