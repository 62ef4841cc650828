//! Snapshots of the generated Rust of each built-in geometry: any change to the generated
//! code shows as a diff to accept with `cargo insta review`.

use leg_tests::workspace_root;
use xtask::gen;

#[test]
fn generated_models() {
    let irs = gen::committed_irs(&workspace_root()).expect("committed IR reads");
    for ir in &irs {
        let source = xtask::rust_module::model_source(ir).expect("codegen succeeds");
        insta::assert_snapshot!(format!("model_{}", ir.model.name), source);
    }
}
