//! With the `peers` feature: compiles CasADi's C code of every model (generated/casadi/)
//! at -O3 and declares its functions to Rust, for the benchmarks.

fn main() {
    #[cfg(feature = "peers")]
    peers::build();
}

#[cfg(feature = "peers")]
mod peers {
    use std::fmt::Write;
    use std::path::PathBuf;

    pub fn build() {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../generated/casadi");
        println!("cargo:rerun-if-changed={}", dir.display());
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .expect("generated/casadi exists (cargo xtask gen)")
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|x| x == "c"))
            .collect();
        files.sort();
        let mut build = cc::Build::new();
        build.opt_level(3).flag("-O3").warnings(false);
        let mut decls = String::from("extern \"C\" {\n");
        let mut table = String::from("/// CasADi's C functions by model: the Lagrange form's and the closed form's fused terms and\n/// forward dynamics, and `jacobian` of the closed form's forward dynamics.\npub const CASADI_C: &[(&str, Peers)] = &[\n");
        for f in &files {
            println!("cargo:rerun-if-changed={}", f.display());
            build.file(f);
            let name = f.file_stem().unwrap().to_str().unwrap();
            let text = std::fs::read_to_string(f).unwrap();
            // A spatial leg's file has the fused terms only (derive.py says why).
            let has = |what: &str| text.contains(&format!("int {name}_{what}("));
            let mut declared = |what: &str| -> String {
                if has(what) {
                    let _ = writeln!(decls, "    fn {name}_{what}(arg: *const *const f64, res: *const *mut f64, iw: *mut i64, w: *mut f64, mem: i32) -> i32;");
                    format!("Some({name}_{what})")
                } else {
                    "None".to_string()
                }
            };
            let terms = declared("dynamics_terms");
            let forward = declared("forward_dynamics");
            let closed_terms = declared("closed_dynamics_terms");
            let closed_forward = declared("closed_forward_dynamics");
            let derivatives = declared("closed_forward_dynamics_derivatives");
            let strip = |s: &str| {
                s.trim_start_matches("Some(")
                    .trim_end_matches(')')
                    .to_string()
            };
            let _ = writeln!(
                table,
                "    (\"{name}\", Peers {{ lagrange: Pair {{ terms: {}, forward_dynamics: {forward} }}, closed: Pair {{ terms: {}, forward_dynamics: {closed_forward} }}, derivatives: {derivatives} }}),",
                strip(&terms),
                strip(&closed_terms)
            );
        }
        decls.push_str("}\n");
        table.push_str("];\n");
        build.compile("casadi_peers");
        let out = PathBuf::from(std::env::var("OUT_DIR").unwrap()).join("casadi_peers.rs");
        std::fs::write(out, format!("{decls}\n{table}")).unwrap();
    }
}
