//! IR file → the Rust module of one geometry (parameters, the `LegModel` impl and the
//! straight-line functions), and the `generated` crate's `lib.rs` that lists them.
//! The functions themselves come from `codegen`; this layer adds what is about legs.

use codegen::ir::{OutputKind, Program};
use codegen::Error;
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use crate::gen::ir_file::IrFile;

/// One derived term: its function name, arguments, outputs and documentation.
pub struct Term {
    pub name: &'static str,
    pub inputs: &'static [&'static str],
    /// `(name, kind, rows, cols)`.
    pub outputs: Vec<(&'static str, OutputKind, usize, usize)>,
    pub doc: &'static str,
    /// The runtime struct several outputs are returned in (`None`: a tuple).
    pub wrap: Option<&'static str>,
}

/// The terms every model has, in file order, for `nq` joints, `nc` closure rows, `nk`
/// contact rows and points of `nd` coordinates (2 planar, 3 spatial).
pub fn terms(nq: usize, nc: usize, nk: usize, nd: usize, np: usize) -> Vec<Term> {
    use OutputKind::{Matrix, Scalar, Vector};
    const Q: &[&str] = &["q", "p"];
    const QQ: &[&str] = &["q", "qd", "p"];
    const QF: &[&str] = &["q", "qd", "a", "f", "p"];
    let constraint_derivatives = |rows| {
        vec![
            ("force_q", Matrix, nq, nq),
            ("jacobian_q", Matrix, rows, nq),
            ("bias_q", Matrix, rows, nq),
            ("jacobian_rate", Matrix, rows, nq),
        ]
    };
    let t = |name, inputs, outputs, doc| Term {
        name,
        inputs,
        outputs,
        doc,
        wrap: None,
    };
    let wrapped = |wrap, term: Term| Term {
        wrap: Some(wrap),
        ..term
    };
    let m = ("mass_matrix", Matrix, nq, nq);
    let n = ("bias_forces", Vector, nq, 1);
    let j = ("constraint_jacobian", Matrix, nc, nq);
    let b = ("constraint_bias", Vector, nc, 1);
    vec![
        t(
            "mass_matrix",
            Q,
            vec![m],
            "`M(q) = ∂²L/∂q̇²`, with reflected rotor inertia on actuated joints.",
        ),
        t(
            "bias_forces",
            QQ,
            vec![n],
            "`N(q, q̇) = (∂²L/∂q̇∂q) q̇ − ∂L/∂q = C q̇ + G`.",
        ),
        t(
            "gravity_forces",
            Q,
            vec![("gravity_forces", Vector, nq, 1)],
            "`G(q) = ∂V/∂q`.",
        ),
        t(
            "damping_forces",
            &["qd", "p"],
            vec![("damping_forces", Vector, nq, 1)],
            "Viscous joint damping `D q̇`.",
        ),
        t(
            "closure_residual",
            Q,
            vec![("closure_residual", Vector, nc, 1)],
            "`φ(q)`: point a minus point b of each closure.",
        ),
        t("constraint_jacobian", Q, vec![j], "`J(q) = ∂φ/∂q`."),
        t("constraint_bias", QQ, vec![b], "`J̇(q, q̇) q̇`."),
        t(
            "foot_position",
            Q,
            vec![("foot_position", Vector, nd, 1)],
            "The foot point in the base frame.",
        ),
        t(
            "foot_jacobian",
            Q,
            vec![("foot_jacobian", Matrix, nd, nq)],
            "`J_f(q) = ∂(foot)/∂q`.",
        ),
        t(
            "foot_bias",
            QQ,
            vec![("foot_bias", Vector, nd, 1)],
            "`J̇_f(q, q̇) q̇`.",
        ),
        t(
            "kinetic_energy",
            QQ,
            vec![("kinetic_energy", Scalar, 1, 1)],
            "Kinetic energy of links and rotors.",
        ),
        t(
            "potential_energy",
            Q,
            vec![("potential_energy", Scalar, 1, 1)],
            "Potential energy `−Σ m g·c`.",
        ),
        t(
            "joint_positions",
            Q,
            vec![("joint_positions", Matrix, nd, nq)],
            "Joint positions in the base frame, one column per joint.",
        ),
        t(
            "link_tips",
            Q,
            vec![("link_tips", Matrix, nd, nq)],
            "Link tips in the base frame, one column per link.",
        ),
        t(
            "closure_points",
            Q,
            vec![("closure_points", Matrix, nd, np)],
            "Closure points a, b of each closure in the base frame.",
        ),
        t(
            "leg_size",
            Q,
            vec![("leg_size", Scalar, 1, 1)],
            "The leg's size (m): the largest coordinate of any joint or link tip in the base\n\
             frame, which tolerances scale with.",
        ),
        t(
            "contact_positions",
            Q,
            vec![("contact_positions", Vector, nk, 1)],
            "Contact points in the base frame, stacked `(x₀, y₀, x₁, y₁, …)`.",
        ),
        t(
            "contact_jacobian",
            Q,
            vec![("contact_jacobian", Matrix, nk, nq)],
            "`J_c(q) = ∂x_c/∂q`.",
        ),
        t(
            "contact_bias",
            QQ,
            vec![("contact_bias", Vector, nk, 1)],
            "`J̇_c(q, q̇) q̇`.",
        ),
        wrapped(
            "DynamicsTerms",
            t(
                "dynamics_terms",
                QQ,
                vec![m, n, j, b],
                "`M`, `N`, `J` and `J̇ q̇` together, sharing subexpressions.",
            ),
        ),
        t(
            "mass_matrix_derivative",
            &["q", "a", "p"],
            vec![("mass_matrix_derivative", Matrix, nq, nq)],
            "`∂(M a)/∂q` at the accelerations `a`.",
        ),
        t(
            "bias_forces_derivatives",
            QQ,
            vec![
                ("bias_forces_q", Matrix, nq, nq),
                ("bias_forces_qd", Matrix, nq, nq),
            ],
            "`∂N/∂q` and `∂N/∂q̇`.",
        ),
        wrapped(
            "ConstraintDerivatives",
            t(
                "constraint_derivatives",
                QF,
                constraint_derivatives(nc),
                "`∂(Jᵀ f)/∂q`, `∂(J a)/∂q`, `∂(J̇ q̇)/∂q` and `J̇` at the closure forces `f` and the\n\
                 accelerations `a`.",
            ),
        ),
        wrapped(
            "ConstraintDerivatives",
            t(
                "contact_derivatives",
                &["q", "qd", "a", "lambda", "p"],
                constraint_derivatives(nk),
                "`∂(J_cᵀ λ)/∂q`, `∂(J_c a)/∂q`, `∂(J̇_c q̇)/∂q` and `J̇_c` at the contact forces `λ`\n\
                 (base frame) and the accelerations `a`.",
            ),
        ),
        wrapped(
            "DynamicsDerivatives",
            t(
                "dynamics_derivatives",
                QF,
                vec![
                    ("dynamics_q", Matrix, nq, nq),
                    ("dynamics_qd", Matrix, nq, nq),
                    ("constraint_q", Matrix, nc, nq),
                    ("jacobian_rate", Matrix, nc, nq),
                ],
                "`∂(M a + N − Jᵀ f)/∂q`, `∂(N + D q̇)/∂q̇`, `∂(J a + J̇ q̇)/∂q` and `J̇` together, sharing\n\
                 subexpressions: the derivatives the linearized dynamics need (DESIGN.md §3.2).",
            ),
        ),
    ]
}

/// The terms of [`leg_models::LegModel`] (a leg's points, in its dimension); the others
/// but the contacts' are [`leg_models::LegDynamics`]'s.
const POINT_TERMS: &[&str] = &[
    "foot_position",
    "foot_jacobian",
    "foot_bias",
    "joint_positions",
    "link_tips",
    "closure_points",
];

/// `two_link` → `TwoLink`.
pub fn type_name(model: &str) -> String {
    model
        .split('_')
        .filter(|s| !s.is_empty())
        .map(|s| {
            let mut c = s.chars();
            c.next()
                .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                .unwrap_or_default()
        })
        .collect()
}

/// Checks the IR holds exactly the expected terms with the expected shapes.
pub fn check_terms(ir: &IrFile) -> Result<(), Error> {
    let nq = ir.model.joints.len();
    let (nc, nk, nd) = (
        ir.model.closure_rows(),
        ir.model.contact_rows(),
        ir.model.dimension,
    );
    if nd != 2 && nd != 3 {
        return Err(Error {
            context: format!("IR of `{}`", ir.model.name),
            message: format!("dimension {nd} (a leg is planar, 2, or spatial, 3)"),
        });
    }
    let expected = terms(nq, nc, nk, nd, ir.model.closure_points());
    let fail = |m: String| Error {
        context: format!("IR of `{}`", ir.model.name),
        message: m,
    };
    if ir.functions.len() != expected.len() {
        return Err(fail(format!(
            "{} functions, expected {}",
            ir.functions.len(),
            expected.len()
        )));
    }
    for (f, t) in ir.functions.iter().zip(&expected) {
        let inputs: Vec<&str> = f.inputs.iter().map(|i| i.name.as_str()).collect();
        let outputs: Vec<_> = f
            .outputs
            .iter()
            .map(|o| (o.name.as_str(), o.kind, o.rows, o.cols))
            .collect();
        if f.name != t.name || inputs != t.inputs || outputs != t.outputs {
            return Err(fail(format!(
                "function `{}` does not have the signature of `{}`",
                f.name, t.name
            )));
        }
    }
    Ok(())
}

fn lit(n: usize) -> Literal {
    Literal::usize_unsuffixed(n)
}

/// The header line of every generated file.
pub fn header(ir: &IrFile) -> String {
    format!(
        "@generated by `cargo xtask gen` from {} (sha256 {}) with CasADi {}. Do not edit.",
        ir.model.spec, ir.model.spec_sha256, ir.model.casadi_version
    )
}

/// The Rust module of one geometry.
pub fn model_source(ir: &IrFile) -> Result<String, Error> {
    check_terms(ir)?;
    let info = &ir.model;
    let ctx = format!("model `{}`", info.name);
    codegen::ident(&ctx, &info.name)?;
    let (nq, nc, nu, nk, nd) = (
        info.joints.len(),
        info.closure_rows(),
        info.actuated.len(),
        info.contact_rows(),
        info.dimension,
    );
    let ty = codegen::ident(&ctx, &type_name(&info.name))?;
    let name = &info.name;
    let joints = info
        .joints
        .iter()
        .map(|j| {
            // A ball joint's angles are `<link>.x`, `.y`, `.z`, a free joint's translation
            // `<link>.tx`, `.ty`, `.tz`: names a spec cannot choose.
            let link = match j.rsplit_once('.') {
                Some((link, "x" | "y" | "z" | "tx" | "ty" | "tz")) => link,
                _ => j,
            };
            codegen::ident(&ctx, link).map(|_| j)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let actuated = info.actuated.iter().map(|&a| lit(a));
    if info.home.len() != nq || !info.home.iter().all(|h| h.is_finite()) {
        return Err(Error {
            context: ctx.clone(),
            message: format!("home pose needs {nq} finite angles"),
        });
    }
    let home = info.home.iter().map(|&h| codegen::f64_literal(h));
    if info.redundant_rows.iter().any(|&r| r >= nc) || info.mobility > nq {
        return Err(Error {
            context: ctx.clone(),
            message: format!(
                "redundant rows {:?} or mobility {} out of range",
                info.redundant_rows, info.mobility
            ),
        });
    }
    if info.joint_kinds.len() != nq
        || info.parents.len() != nq
        || info
            .parents
            .iter()
            .enumerate()
            .any(|(i, p)| p.is_some_and(|p| p >= i))
        || info.contact_friction.len() != info.contacts.len()
        || !info.contact_friction.iter().all(|m| m.is_finite())
        || info.ground_normal.len() != nd
        || !info.ground_normal.iter().all(|v| v.is_finite())
        || !info.ground_offset.is_finite()
    {
        return Err(Error {
            context: ctx.clone(),
            message: "joint kinds, parents, contact friction or ground do not match the model"
                .into(),
        });
    }
    let kinds = info
        .joint_kinds
        .iter()
        .map(|k| match k.as_str() {
            "revolute" => Ok(quote!(JointKind::Revolute)),
            "prismatic" => Ok(quote!(JointKind::Prismatic)),
            other => Err(Error {
                context: ctx.clone(),
                message: format!("unknown joint kind `{other}`"),
            }),
        })
        .collect::<Result<Vec<_>, _>>()?;
    let parents = info.parents.iter().map(|p| match p {
        Some(p) => {
            let p = lit(*p);
            quote!(Some(#p))
        }
        None => quote!(None),
    });
    // Each spring's stiffness and rest are the parameters `{name}_stiffness`, `{name}_rest`.
    let param_index = |name: String| {
        info.params
            .iter()
            .position(|p| p.name == name)
            .map(lit)
            .ok_or_else(|| Error {
                context: ctx.clone(),
                message: format!("no parameter `{name}`"),
            })
    };
    let springs = info
        .springs
        .iter()
        .map(|s| {
            if s.a >= nq || s.b.is_some_and(|b| b >= nq) {
                return Err(Error {
                    context: ctx.clone(),
                    message: format!("spring `{}` names a joint out of range", s.name),
                });
            }
            let name = &s.name;
            let a = lit(s.a);
            let b = match s.b {
                Some(b) => {
                    let b = lit(b);
                    quote!(Some(#b))
                }
                None => quote!(None),
            };
            let k = param_index(format!("{name}_stiffness"))?;
            let r = param_index(format!("{name}_rest"))?;
            Ok(quote!(leg_models::Spring { name: #name, a: #a, b: #b, stiffness: #k, rest: #r }))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let contact_names = &info.contacts;
    for c in contact_names {
        codegen::ident(&ctx, c)?;
    }
    let friction = info
        .contact_friction
        .iter()
        .map(|&m| codegen::f64_literal(m));
    let normal = info.ground_normal.iter().map(|&v| codegen::f64_literal(v));
    let offset = codegen::f64_literal(info.ground_offset);
    let redundant = lit(info.redundant_rows.len());
    let mobility = lit(info.mobility);
    // Only a leg with ball joints says so: the trait's default is none.
    let ball_joints = if info.ball_joints.iter().any(|&b| b + 2 >= nq) {
        return Err(Error {
            context: ctx.clone(),
            message: format!(
                "ball joints {:?} beyond the {nq} coordinates",
                info.ball_joints
            ),
        });
    } else if info.ball_joints.is_empty() {
        quote!()
    } else {
        let b = info.ball_joints.iter().map(|&b| lit(b));
        quote!(const BALL_JOINTS: &'static [usize] = &[#(#b),*];)
    };
    // Only a floating robot says so: the trait's default is a fixed base.
    let free_joint = match info.free_joint {
        Some(f) if f + 5 >= nq => {
            return Err(Error {
                context: ctx.clone(),
                message: format!("a free joint at {f} beyond the {nq} coordinates"),
            })
        }
        Some(f) => {
            let f = lit(f);
            quote!(const FREE_JOINT: Option<usize> = Some(#f);)
        }
        None => quote!(),
    };
    // The trait's default is the planar leg's 2.
    let dimension = if nd == 3 {
        quote!(
            const DIMENSION: usize = 3;
        )
    } else {
        quote!()
    };
    let distance_closures = if info.distance_closures.is_empty() {
        quote!()
    } else {
        let d = info.distance_closures.iter().map(|&k| lit(k));
        quote!(const DISTANCE_CLOSURES: &'static [usize] = &[#(#d),*];)
    };
    let revolute_closures = if info.revolute_closures.is_empty() {
        quote!()
    } else {
        let r = info.revolute_closures.iter().map(|&k| lit(k));
        quote!(const REVOLUTE_CLOSURES: &'static [usize] = &[#(#r),*];)
    };
    let chart_states = lit(2 * info.mobility);
    let chart_doc = format!(
        " The chart of the constraint manifold: {} coordinates (the mobility), {} states.",
        info.mobility,
        2 * info.mobility
    );

    let mut fields = Vec::new();
    let mut defaults = Vec::new();
    let mut param_names = Vec::new();
    let mut getters = Vec::new();
    let mut setters = Vec::new();
    for p in &info.params {
        let id = codegen::ident(&ctx, &p.name)?;
        // Units are written `[m]`: escaped, so rustdoc does not read them as links.
        let doc = format!(" {}", p.doc.replace('[', "\\[").replace(']', "\\]"));
        fields.push(quote!(#[doc = #doc] pub #id: T));
        if !p.default.is_finite() {
            return Err(Error {
                context: ctx,
                message: format!("parameter `{}` has no finite default", p.name),
            });
        }
        let v = codegen::scalar_literal(p.default);
        defaults.push(quote!(#id: #v));
        let i = lit(param_names.len());
        getters.push(quote!(#i => Some(self.values.#id)));
        setters.push(quote!(#i => self.values.#id = value));
        param_names.push(p.name.clone());
    }

    // Parameter-only work is done once per parameter set (`Params::new`), not per call.
    let hoisted = codegen::hoist::hoist(&ir.functions, "p", "ParamValues");
    // A field `prepare` does not read (a floating robot's gravity) is set without preparing:
    // a floating robot writes its chart's gravity every call. Matched by name, so the
    // setters' order (the spec's) need not be the struct's; a name not found re-prepares.
    let read_fields: &[String] = match &hoisted.prepare.inputs[0].shape {
        codegen::ir::InputShape::Struct { fields, .. } => fields,
        _ => &[],
    };
    let reads: Vec<bool> = param_names
        .iter()
        .map(|name| {
            read_fields
                .iter()
                .position(|f| f == name)
                .is_none_or(|k| hoisted.reads[k])
        })
        .collect();
    let n_params = lit(param_names.len());
    let prepared = lit(hoisted.prepare.outputs[0].rows);
    let mut functions = vec![codegen::emit_function(
        &hoisted.prepare,
        "The parameter-only quantities the terms read (products of masses, lengths and\n\
         centres of mass, inertias about the joints, …), computed once per parameter set\n\
         by [`Params::new`].",
    )?];
    let mut methods = Vec::new();
    let mut point_methods = Vec::new();
    let mut contact_methods = Vec::new();
    for (f, t) in hoisted
        .programs
        .iter()
        .zip(terms(nq, nc, nk, nd, info.closure_points()))
    {
        functions.push(codegen::emit_function_returning(
            f,
            t.doc,
            wrap_type(f, nq, t.wrap),
        )?);
        if f.name.starts_with("contact_") {
            contact_methods.push(trait_method(f, nq, t.wrap));
        } else if POINT_TERMS.contains(&f.name.as_str()) {
            point_methods.push(trait_method(f, nq, t.wrap));
        } else {
            methods.push(trait_method(f, nq, t.wrap));
        }
    }

    let doc =
        format!(
        " The `{name}` leg: {nq} joints, {} closure(s), actuated joints {:?}. Generated from `{}`.",
        info.closures.len(),
        info.actuated.iter().map(|&a| &info.joints[a]).collect::<Vec<_>>(),
        info.spec
    );
    let (lq, lc, lu, lk) = (lit(nq), lit(nc), lit(nu), lit(nk));
    // A planar leg is the runtime's `Leg` with its contacts; a spatial leg implements
    // `LegModel` and `ContactModel` with three coordinates per point.
    let spatial = nd == 3;
    let nd_lit = lit(nd);
    let lp = lit(info.closure_points());
    // Planar modules keep their words (their snapshots unchanged).
    let nc_doc = if spatial {
        " Number of closure rows (three per point closure, one per rod)."
    } else {
        " Number of closure rows (two per closure)."
    };
    let imports = quote! {
        use leg_models::{
            Arithmetic, ConstraintDerivatives, ContactModel, DynamicsDerivatives, DynamicsTerms,
            JointKind, LegDynamics, LegModel, Parameters,
        };
    };
    let aliases = if spatial {
        quote! {
            /// Number of coordinates of a point: the leg is spatial.
            pub const ND: usize = 3;
            /// Number of closure points (two per closure).
            pub const NP: usize = #lp;

            /// This leg with its parameters in `f64`, the runtime's entry point:
            /// `Leg::default()` holds the spec's values. A spatial leg has the methods of
            /// every leg (terms, assembly, dynamics, derivatives, simulation, joint-space
            /// control, linearization and LQR) and its contacts' (three rows each); its
            /// foot is this module's `foot_position`.
            pub type Leg = leg_models::Leg<#ty, f64, NQ, NC, NU, NK>;

            /// This leg computing in `f32` (e.g. on a microcontroller).
            pub type LegF32 = leg_models::Leg<#ty, f32, NQ, NC, NU, NK>;
        }
    } else {
        quote! {
            /// This leg with its parameters in `f64`, the runtime's entry point:
            /// `Leg::default()` holds the spec's values. Code generic over the scalar writes
            /// `leg_models::Leg<Model, T, NQ, NC, NU, NK>` with this module's sizes.
            pub type Leg = leg_models::Leg<#ty, f64, NQ, NC, NU, NK>;

            /// This leg computing in `f32` (e.g. on a microcontroller).
            pub type LegF32 = leg_models::Leg<#ty, f32, NQ, NC, NU, NK>;
        }
    };
    let leg_sizes = if spatial {
        quote!(NQ, NC, NU, ND, NP)
    } else {
        quote!(NQ, NC, NU)
    };
    let (contact_sizes, nk_doc) = if spatial {
        (
            quote!(NQ, NC, NU, NK, ND),
            " Number of contact rows (three per contact point).",
        )
    } else {
        (
            quote!(NQ, NC, NU, NK),
            " Number of contact rows (two per contact point).",
        )
    };
    let contact_impl = quote! {
        impl ContactModel<#contact_sizes> for #ty {
            const CONTACT_NAMES: &'static [&'static str] = &[#(#contact_names),*];
            const CONTACT_FRICTION: &'static [f64] = &[#(#friction),*];
            const GROUND_NORMAL: [f64; #nd_lit] = [#(#normal),*];
            const GROUND_OFFSET: f64 = #offset;
            #(#contact_methods)*
        }
    };
    let tokens = quote! {
        #![doc = #doc]
        // prettyplease formats generated code, so that formatting cannot drift.
        #![cfg_attr(rustfmt, rustfmt::skip)]
        // `eq_op`: value numbering can make `x − x` of two equal values, which stays (it is
        // NaN, not 0, for a non-finite x: the simplifications keep every bit).
        #![allow(
            clippy::approx_constant,
            clippy::eq_op,
            clippy::excessive_precision,
            clippy::let_and_return,
            clippy::too_many_lines
        )]

        use leg_models::nalgebra::{ArrayStorage, SMatrix, SVector};
        #imports

        /// Number of joints.
        pub const NQ: usize = #lq;
        #[doc = #nc_doc]
        pub const NC: usize = #lc;
        /// Number of actuated joints.
        pub const NU: usize = #lu;
        #[doc = #nk_doc]
        pub const NK: usize = #lk;

        #[doc = #doc]
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
        pub struct #ty;

        #aliases

        #[doc = #chart_doc]
        impl leg_models::ChartSize<#mobility, #chart_states> for #ty {}

        /// The physical quantities of the spec; `Default` holds its values.
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct ParamValues<T> {
            #(#fields,)*
        }

        impl<T: Arithmetic> Default for ParamValues<T> {
            fn default() -> Self {
                Self { #(#defaults,)* }
            }
        }

        /// Physical parameters, ready for evaluation: the values (read as fields through
        /// `Deref`, `p.gravity_y`) and the parameter-only quantities every term reads,
        /// computed once when a value changes instead of in every call. `Default` holds
        /// the spec's values; change them at run time, without regenerating, with
        /// [`Params::update`], [`Parameters::set`] or [`Parameters::set_many`].
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct Params<T> {
            values: ParamValues<T>,
            prepared: [T; #prepared],
        }

        impl<T: Arithmetic> Params<T> {
            /// Parameters of these values.
            pub fn new(values: ParamValues<T>) -> Self {
                Self { prepared: prepare(&values).data.0[0], values }
            }

            /// The values.
            pub fn values(&self) -> &ParamValues<T> {
                &self.values
            }

            /// Changes values, then prepares once: `p.update(|v| v.gravity_y = -1.62)`.
            pub fn update(&mut self, change: impl FnOnce(&mut ParamValues<T>)) {
                change(&mut self.values);
                self.prepare_again();
            }

            /// The prepared quantities of the present values, in place.
            fn prepare_again(&mut self) {
                self.prepared = prepare(&self.values).data.0[0];
            }
        }

        impl<T> core::ops::Deref for Params<T> {
            type Target = ParamValues<T>;
            fn deref(&self) -> &ParamValues<T> {
                &self.values
            }
        }

        impl<T: Arithmetic> From<ParamValues<T>> for Params<T> {
            fn from(values: ParamValues<T>) -> Self {
                Self::new(values)
            }
        }

        impl<T: Arithmetic> Default for Params<T> {
            fn default() -> Self {
                Self::new(ParamValues::default())
            }
        }

        /// Which parameters (in [`Parameters::NAMES`] order) `prepare` reads: setting any
        /// other leaves the prepared quantities as they are.
        const PREPARE_READS: [bool; #n_params] = [#(#reads),*];

        impl<T: Arithmetic> Parameters<T> for Params<T> {
            const NAMES: &'static [&'static str] = &[#(#param_names),*];
            fn get(&self, i: usize) -> Option<T> {
                match i {
                    #(#getters,)*
                    _ => None,
                }
            }
            fn set_many(&mut self, changes: &[(usize, T)]) -> bool {
                if changes.iter().any(|c| c.0 >= Self::NAMES.len()) {
                    return false;
                }
                let mut stale = false;
                for &(i, value) in changes {
                    match i {
                        #(#setters,)*
                        _ => {}
                    }
                    stale |= PREPARE_READS[i];
                }
                if stale {
                    self.prepare_again();
                }
                true
            }
        }

        impl LegDynamics<NQ, NC, NU> for #ty {
            const NAME: &'static str = #name;
            const JOINT_NAMES: [&'static str; NQ] = [#(#joints),*];
            const JOINT_KINDS: [JointKind; NQ] = [#(#kinds),*];
            const PARENTS: [Option<usize>; NQ] = [#(#parents),*];
            const SPRINGS: &'static [leg_models::Spring] = &[#(#springs),*];
            const ACTUATED: [usize; NU] = [#(#actuated),*];
            const HOME: [f64; NQ] = [#(#home),*];
            const REDUNDANT_ROWS: usize = #redundant;
            const MOBILITY: usize = #mobility;
            #ball_joints
            #free_joint
            #dimension
            #distance_closures
            #revolute_closures
            type Params<T: Arithmetic> = Params<T>;
            #(#methods)*
        }

        impl LegModel<#leg_sizes> for #ty {
            #(#point_methods)*
        }

        #contact_impl

        #(#functions)*
    };
    codegen::format_file(&[header(ir)], tokens)
}

/// The runtime struct `wrap` a term of several outputs returns: its type `Wrap<T, NQ,
/// rows>` (rows those of its last output) and its name; `None` for a term of one
/// output, or not wrapped.
fn wrap_type(f: &Program, nq: usize, wrap: Option<&str>) -> Option<(TokenStream, TokenStream)> {
    let wrap = wrap.filter(|_| f.outputs.len() > 1)?;
    let st = format_ident!("{}", wrap);
    let (lq, rows) = (lit(nq), lit(f.outputs.last().map_or(0, |o| o.rows)));
    Some((quote!(#st<T, #lq, #rows>), quote!(#st)))
}

/// The trait method that forwards to the generated function `f`, returning what it
/// returns: one output as it is; several in the runtime's struct `wrap` (built by `f`
/// itself, [`wrap_type`]), or as a tuple without one.
fn trait_method(f: &Program, nq: usize, wrap: Option<&str>) -> TokenStream {
    let name = format_ident!("{}", f.name);
    let args: Vec<_> = f
        .inputs
        .iter()
        .map(|i| {
            let id = format_ident!("{}", i.name);
            let len = lit(i.shape.len());
            if i.name == "p" {
                quote!(#id: &Params<T>)
            } else {
                quote!(#id: &SVector<T, #len>)
            }
        })
        .collect();
    let pass: Vec<_> = f
        .inputs
        .iter()
        .map(|i| format_ident!("{}", i.name))
        .collect();
    // `f` returns what the method does (a wrapped struct built in the caller's place):
    // nothing is moved here.
    let ret = codegen::return_type(f, wrap_type(f, nq, wrap).map(|(ty, _)| ty).as_ref());
    // Inlined so the forward adds no call: without it, a small model's method stayed a
    // separate function and its terms' shared sines were computed twice (two_link's
    // derivatives, 585 -> 837 instructions).
    quote! {
        #[inline]
        fn #name<T: Arithmetic>(#(#args),*) -> #ret {
            #name(#(#pass),*)
        }
    }
}

/// Size and name facts `lib.rs` needs of each model.
pub struct Summary {
    pub name: String,
    pub nq: usize,
    pub nc: usize,
    pub nu: usize,
    pub nk: usize,
    /// Closure points, two per closure.
    pub np: usize,
    pub spatial: bool,
    /// A robot whose body floats (a free joint).
    pub floating: bool,
}

impl Summary {
    pub fn of(ir: &IrFile) -> Summary {
        Summary {
            name: ir.model.name.clone(),
            nq: ir.model.joints.len(),
            nc: ir.model.closure_rows(),
            nu: ir.model.actuated.len(),
            nk: ir.model.contact_rows(),
            np: ir.model.closure_points(),
            spatial: ir.model.dimension == 3,
            floating: ir.model.free_joint.is_some(),
        }
    }
}

/// The `generated` crate's `lib.rs`: one module per model and `for_each_model!`.
pub fn lib_source(models: &[Summary]) -> Result<String, Error> {
    let mut mods = Vec::new();
    let mut calls = Vec::new();
    let mut spatial_calls = Vec::new();
    let mut floating_calls = Vec::new();
    for m in models {
        let module = codegen::ident("lib.rs", &m.name)?;
        let ty = codegen::ident("lib.rs", &type_name(&m.name))?;
        let (q, c, u, k) = (lit(m.nq), lit(m.nc), lit(m.nu), lit(m.nk));
        mods.push(quote! {
            pub mod #module;
            pub use #module::#ty;
        });
        if m.floating {
            let p = lit(m.np);
            floating_calls
                .push(quote!($callback!(#module, $crate::#module::#ty, #q, #c, #u, #p, #k);));
        } else if m.spatial {
            let p = lit(m.np);
            spatial_calls
                .push(quote!($callback!(#module, $crate::#module::#ty, #q, #c, #u, #p, #k);));
        } else {
            calls.push(quote!($callback!(#module, $crate::#module::#ty, #q, #c, #u, #k);));
        }
    }
    let tokens = quote! {
        //! Generated leg models, one module per spec in `leg-models/specs/`. Each implements
        //! [`leg_models::LegModel`]. Regenerate with `cargo xtask gen`; never edit by hand.
        #![cfg_attr(not(feature = "std"), no_std)]
        #![warn(missing_docs)]
        #![cfg_attr(rustfmt, rustfmt::skip)]

        #(#mods)*

        /// Calls `$callback!(module, Type, NQ, NC, NU, NK)` once for every generated planar
        /// model, so tests and tools cover a new geometry without naming it.
        #[macro_export]
        macro_rules! for_each_model {
            ($callback:ident) => {
                #(#calls)*
            };
        }

        /// Calls `$callback!(module, Type, NQ, NC, NU, NP, NK)` once for every generated
        /// spatial model (`LegModel<NQ, NC, NU, 3, NP>`: three coordinates per point, `NP`
        /// closure points; `ContactModel<NQ, NC, NU, NK, 3>`: three rows per contact).
        #[macro_export]
        macro_rules! for_each_spatial_model {
            ($callback:ident) => {
                #(#spatial_calls)*
            };
        }

        /// Calls `$callback!(module, Type, NQ, NC, NU, NP, NK)` once for every generated
        /// floating robot: a spatial model whose first link is a free joint
        /// (`LegDynamics::FREE_JOINT`), driven through `leg_models::robot`. Its size
        /// constants are a spatial model's.
        #[macro_export]
        macro_rules! for_each_floating_model {
            ($callback:ident) => {
                #(#floating_calls)*
            };
        }
    };
    codegen::format_file(
        &["@generated by `cargo xtask gen` from leg-models/specs/*.toml. Do not edit.".into()],
        tokens,
    )
}
