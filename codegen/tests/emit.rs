//! Codegen of small hand-written IR fixtures (one per operation kind and shape case):
//! snapshots of what is emitted, assertions on its structure, the refusal of malformed
//! programs, exact constants, and the freshness of `compiled/programs.rs`, which
//! `compiled.rs` compiles and evaluates.

use std::path::{Path, PathBuf};

use codegen::ir::{Instr, Program};
use proc_macro2::{TokenStream, TokenTree};

const FIXTURES: &[&str] = &[
    "unary",
    "binary",
    "constants",
    "struct_input",
    "shapes",
    "dead_code",
];

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests")
}

fn fixture(name: &str) -> Program {
    let text =
        std::fs::read_to_string(dir().join("fixtures").join(format!("{name}.json"))).unwrap();
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("fixture {name}: {e}"))
}

fn emit(p: &Program) -> TokenStream {
    codegen::emit_function(p, "Fixture.").unwrap_or_else(|e| panic!("{e}"))
}

fn pretty(tokens: TokenStream) -> String {
    codegen::format_file(&[], tokens).unwrap()
}

#[test]
fn fixtures_snapshot() {
    insta::glob!("fixtures", "*.json", |path| {
        let program: Program =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        insta::assert_snapshot!(pretty(emit(&program)));
    });
}

#[test]
fn every_fixture_is_compiled() {
    let mut names: Vec<String> = std::fs::read_dir(dir().join("fixtures"))
        .unwrap()
        .flatten()
        .map(|e| e.path().file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let mut listed: Vec<&str> = FIXTURES.to_vec();
    listed.sort();
    assert_eq!(names, listed, "add new fixtures to FIXTURES");
}

fn idents(tokens: TokenStream, out: &mut Vec<String>) {
    for t in tokens {
        match t {
            TokenTree::Ident(i) => out.push(i.to_string()),
            TokenTree::Group(g) => idents(g.stream(), out),
            _ => {}
        }
    }
}

#[test]
fn emitted_code_has_no_loops_allocation_unsafe_or_panics() {
    for name in FIXTURES {
        let mut ids = Vec::new();
        idents(emit(&fixture(name)), &mut ids);
        for bad in [
            "for", "while", "loop", "unsafe", "unwrap", "expect", "panic", "Vec", "Box", "vec",
            "if", "match",
        ] {
            assert!(!ids.iter().any(|i| i == bad), "{name} emits `{bad}`");
        }
        let text = pretty(emit(&fixture(name)));
        // The only indexing is the constant `[0]` of destructuring a vector input.
        for (i, _) in text.match_indices(".data.0[") {
            assert!(
                text[i..].starts_with(".data.0[0]"),
                "{name}: indexing other than .data.0[0]"
            );
        }
    }
}

#[test]
fn dead_values_are_not_emitted_and_unused_inputs_are_marked() {
    let text = pretty(emit(&fixture("dead_code")));
    assert!(!text.contains("sin"), "dead `sin` emitted:\n{text}");
    assert!(text.contains("let [x_0, _] = x.data.0[0];"), "{text}");
    let text = pretty(emit(&fixture("struct_input")));
    assert!(
        text.contains("_qd: &SVector<T, 3>"),
        "unused input not marked:\n{text}"
    );
    assert!(text.contains("let [_, q_1, _] = q.data.0[0];"), "{text}");
    assert!(text.contains("p.mass * p.length"), "{text}");
    assert!(!text.contains("unused"), "{text}");
}

/// Several outputs returned in a struct are the tuple's values, in order, as its fields
/// named as the outputs; the function returns the struct's type.
#[test]
fn outputs_returned_in_a_struct_are_the_tuples_values_by_name() {
    let p = fixture("shapes");
    let tail = |tokens: TokenStream| {
        let f: syn::ItemFn = syn::parse2(tokens).unwrap();
        let Some(syn::Stmt::Expr(e, None)) = f.block.stmts.last().cloned() else {
            panic!("the result is the function's tail expression")
        };
        (f.sig.output, e)
    };
    let (tuple_ret, tuple) = tail(emit(&p));
    // `return_type` (what the generated trait methods declare) is what is emitted.
    let declared = |ret: &syn::ReturnType| match ret {
        syn::ReturnType::Type(_, ty) => quote::quote!(#ty).to_string(),
        syn::ReturnType::Default => panic!("a return type"),
    };
    assert_eq!(
        declared(&tuple_ret),
        codegen::return_type(&p, None).to_string()
    );
    let wrap = (quote::quote!(Shapes<T, 2>), quote::quote!(Shapes));
    let (ret, wrapped) = tail(codegen::emit_function_returning(&p, "", Some(wrap)).unwrap());
    assert_eq!(
        quote::quote!(#ret).to_string(),
        quote::quote!(-> Shapes<T, 2>).to_string()
    );
    assert_eq!(
        declared(&ret),
        codegen::return_type(&p, Some(&quote::quote!(Shapes<T, 2>))).to_string()
    );
    let (syn::Expr::Tuple(tuple), syn::Expr::Struct(wrapped)) = (tuple, wrapped) else {
        panic!("a tuple, then a struct")
    };
    let path = &wrapped.path;
    assert_eq!(quote::quote!(#path).to_string(), "Shapes");
    let names: Vec<String> = wrapped
        .fields
        .iter()
        .map(|f| match &f.member {
            syn::Member::Named(id) => id.to_string(),
            syn::Member::Unnamed(_) => panic!("fields are named"),
        })
        .collect();
    let outputs: Vec<&str> = p.outputs.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, outputs);
    for (field, element) in wrapped.fields.iter().zip(&tuple.elems) {
        let value = &field.expr;
        assert_eq!(
            quote::quote!(#value).to_string(),
            quote::quote!(#element).to_string()
        );
    }
    // One output is returned as it is, wrap or not.
    let mut one = p.clone();
    one.outputs.truncate(1);
    let (one_ret, _) = tail(emit(&one));
    assert_eq!(
        declared(&one_ret),
        codegen::return_type(&one, Some(&quote::quote!(Shapes<T, 2>))).to_string()
    );
    let wrap = (quote::quote!(Shapes<T, 2>), quote::quote!(Shapes));
    assert_eq!(
        codegen::emit_function_returning(&one, "", Some(wrap))
            .unwrap()
            .to_string(),
        codegen::emit_function(&one, "").unwrap().to_string()
    );
}

#[test]
fn values_are_numbered_in_emission_order() {
    let text = pretty(emit(&fixture("binary")));
    for (k, op) in ["+", "-", "*", "/"].iter().enumerate() {
        assert!(
            text.contains(&format!("let v{k} = x_0 {op} x_1;")),
            "{text}"
        );
    }
}

#[test]
fn constants_round_trip_exactly() {
    let p = fixture("constants");
    let text = pretty(emit(&p));
    let lits: Vec<f64> = text
        .match_indices("T::lit(")
        .map(|(i, _)| {
            let rest = &text[i + 7..];
            rest[..rest.find(')').unwrap()]
                .replace(' ', "")
                .parse::<f64>()
                .unwrap()
        })
        .collect();
    let consts: Vec<f64> = p
        .instructions
        .iter()
        .filter_map(|i| {
            if let Instr::Const(c) = i {
                Some(*c)
            } else {
                None
            }
        })
        .collect();
    assert!(lits.len() >= consts.len(), "{text}");
    for c in consts {
        assert!(
            lits.iter().any(|l| l.to_bits() == c.to_bits()),
            "{c:e} not emitted exactly:\n{text}"
        );
    }
}

#[test]
fn ir_json_round_trips() {
    for name in FIXTURES {
        let p = fixture(name);
        let text = serde_json::to_string(&p).unwrap();
        assert_eq!(serde_json::from_str::<Program>(&text).unwrap(), p);
    }
}

#[test]
fn emission_is_deterministic() {
    for name in FIXTURES {
        assert_eq!(pretty(emit(&fixture(name))), pretty(emit(&fixture(name))));
    }
}

fn refused(json: &str) -> String {
    match serde_json::from_str::<Program>(json) {
        Err(e) => e.to_string(),
        Ok(p) => codegen::emit_function(&p, "").unwrap_err().to_string(),
    }
}

#[test]
fn malformed_programs_are_refused_with_the_reason() {
    let base = |instrs: &str, outputs: &str| {
        format!(
            r#"{{"name":"f","inputs":[{{"name":"x","kind":"vector","len":1}}],"outputs":{outputs},"instructions":{instrs}}}"#
        )
    };
    let out1 = r#"[{"name":"y","kind":"scalar","rows":1,"cols":1,"entries":[0]}]"#;
    let cases = [
        (
            base(r#"[{"op":"sin","args":[0]}]"#, out1),
            "not defined before",
        ),
        (
            base(r#"[{"op":"input","input":0,"index":1}]"#, out1),
            "out of range",
        ),
        (
            base(r#"[{"op":"input","input":3,"index":0}]"#, out1),
            "missing input",
        ),
        (
            base(r#"[{"op":"frobnicate","args":[0]}]"#, out1),
            "unknown operation `frobnicate`",
        ),
        (
            base(r#"[{"op":"sin","args":[0,0]}]"#, out1),
            "takes 1 operand",
        ),
        (
            base(r#"[{"op":"const","value":1.0,"args":[0]}]"#, out1),
            "wrong fields",
        ),
        (
            base(
                r#"[{"op":"input","input":0,"index":0}]"#,
                r#"[{"name":"y","kind":"vector","rows":2,"cols":1,"entries":[0]}]"#,
            ),
            "lists 1 entries",
        ),
        (
            base(
                r#"[{"op":"input","input":0,"index":0}]"#,
                r#"[{"name":"y","kind":"scalar","rows":2,"cols":1,"entries":[0,0]}]"#,
            ),
            "is Scalar but 2×1",
        ),
        (
            base(
                r#"[{"op":"input","input":0,"index":0}]"#,
                r#"[{"name":"y","kind":"scalar","rows":1,"cols":1,"entries":[5]}]"#,
            ),
            "missing value 5",
        ),
        (
            r#"{"name":"f; drop","inputs":[],"outputs":[],"instructions":[]}"#.to_string(),
            "not a plain Rust identifier",
        ),
        (
            r#"{"name":"fn","inputs":[],"outputs":[],"instructions":[]}"#.to_string(),
            "not a plain Rust identifier",
        ),
    ];
    for (json, expected) in cases {
        let msg = refused(&json);
        assert!(
            msg.contains(expected),
            "{json}\n→ {msg}\n(expected it to say `{expected}`)"
        );
    }
}

/// What `compiled/programs.rs` must contain: every fixture, in one compiled module.
fn programs_source() -> String {
    let functions: Vec<TokenStream> = FIXTURES.iter().map(|n| emit(&fixture(n))).collect();
    let tokens = quote::quote! {
        #![cfg_attr(rustfmt, rustfmt::skip)]
        use super::{Arithmetic, FixtureParams};
        use nalgebra::{ArrayStorage, SMatrix, SVector};
        #(#functions)*
    };
    codegen::format_file(
        &["@generated by codegen/tests/emit.rs from codegen/tests/fixtures/*.json (UPDATE_EXPECT=1 to rewrite). Do not edit.".into()],
        tokens,
    )
    .unwrap()
}

#[test]
fn compiled_programs_are_fresh() {
    let path = dir().join("compiled").join("programs.rs");
    let expected = programs_source();
    if std::env::var_os("UPDATE_EXPECT").is_some() {
        std::fs::write(&path, &expected).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == expected,
        "{} is stale: run `UPDATE_EXPECT=1 cargo test -p codegen --test emit`",
        path.display()
    );
}
