//! Snapshots of the generated Rust of each geometry: any change to the generated code
//! shows as a diff to accept with `cargo insta review`. (`insta::glob!` checks every
//! model and reports all differences at once.)

use xtask::gen::ir_file::IrFile;

#[test]
fn generated_models() {
    insta::glob!("../../generated/ir", "*.json", |path| {
        let ir = IrFile::parse(&std::fs::read_to_string(path).unwrap()).unwrap();
        let source = xtask::gen::rust_module::model_source(&ir).expect("codegen succeeds");
        insta::assert_snapshot!(source);
    });
}
