//! The committed generated code is what `codegen` makes from the committed IR (no Python
//! needed), and the committed IR is in its canonical form (floats round-trip exactly).
//! `cargo xtask gen --check` covers the other half: the IR is what CasADi derives today.

use std::collections::BTreeMap;
use std::path::PathBuf;

use leg_tests::workspace_root;
use xtask::gen;

#[test]
fn committed_rust_and_ir_are_fresh() {
    let root = workspace_root();
    let irs = gen::committed_irs(&root).expect("committed IR reads");
    assert!(!irs.is_empty(), "no IR under {}", gen::IR_DIR);
    let mut expected: BTreeMap<PathBuf, String> =
        gen::rust_files(&irs, |_| true).expect("codegen succeeds");
    for ir in &irs {
        expected.insert(
            PathBuf::from(gen::IR_DIR).join(format!("{}.json", ir.model.name)),
            ir.to_text(),
        );
        // CasADi's C comes from CasADi alone (`gen --check` compares it); here: it exists.
        let c = PathBuf::from(gen::CASADI_C_DIR).join(format!("{}.c", ir.model.name));
        let text = std::fs::read_to_string(root.join(&c)).unwrap_or_default();
        assert!(
            text.contains(&format!("{}_dynamics_terms", ir.model.name)),
            "{} is missing",
            c.display()
        );
        expected.insert(c, text);
    }
    let stale = gen::stale_files(&root, &expected);
    assert!(
        stale.is_empty(),
        "generated files differ from what the committed IR makes: {stale:?}\nrun `cargo xtask gen` and commit the result"
    );
}

#[test]
fn every_spec_has_committed_ir_that_names_it() {
    let root = workspace_root();
    let specs = gen::spec_paths(&root).unwrap();
    let irs = gen::committed_irs(&root).unwrap();
    assert_eq!(specs.len(), irs.len());
    for (spec, ir) in specs.iter().zip(&irs) {
        let rel = spec.strip_prefix(&root).unwrap();
        assert_eq!(
            PathBuf::from(&ir.model.spec),
            rel,
            "IR of {} names another spec",
            ir.model.name
        );
        assert_eq!(ir.model.spec_sha256.len(), 64);
    }
}

/// Every Rust example of the documentation is a doctest: a docs file with a ```rust block
/// is included in `tests/src/lib.rs` (as the README is), so that none goes unchecked.
#[test]
fn every_docs_file_with_rust_examples_is_doctested() {
    let root = workspace_root();
    let lib = std::fs::read_to_string(root.join("tests/src/lib.rs")).unwrap();
    assert!(lib.contains("include_str!(\"../../README.md\")"));
    let mut checked = 0;
    for entry in std::fs::read_dir(root.join("docs")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|x| x == "md") {
            let text = std::fs::read_to_string(&path).unwrap();
            if text.contains("```rust") {
                let name = path.file_name().unwrap().to_str().unwrap();
                assert!(
                    lib.contains(&format!("include_str!(\"../../docs/{name}\")")),
                    "docs/{name} has Rust examples that no doctest runs: add it to tests/src/lib.rs"
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 0, "no docs file with Rust examples found");
}
