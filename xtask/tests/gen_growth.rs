//! How `cargo xtask gen`'s time grows with the size of a leg: a serial chain of N links,
//! derived and emitted in a scratch workspace (CasADi from the project's `.venv`).
//! Not part of the suite (it takes minutes); docs/figures.md's table comes from
//! `cargo test -p xtask --test gen_growth -- --ignored --nocapture`.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use xtask::gen::{self, GenOptions};

fn chain(n: usize) -> String {
    let mut s = String::from("gravity = [0.0, -9.81]\n");
    for i in 0..n {
        let parent = if i == 0 {
            "base".to_string()
        } else {
            format!("l{}", i - 1)
        };
        let _ = write!(
            s,
            "\n[[links]]\nname = \"l{i}\"\nparent = \"{parent}\"\nlength = [0.1, 0.0]\nmass = 0.1\ncom = [0.05, 0.01]\ninertia = 1e-4\n"
        );
        if i < 2 {
            s.push_str("actuator = { rotor_inertia = 1e-6, gear_ratio = 10.0 }\n");
        }
    }
    let _ = write!(s, "\n[foot]\nlink = \"l{}\"\n", n - 1);
    s
}

/// Two chains of `n / 2` links hanging side by side from base points 0.1 m apart, joined
/// by a closure at every other link: `n / 4` loops.
fn ladder(n: usize) -> String {
    let m = n / 2;
    let mut s = String::from("gravity = [0.0, -9.81]\n");
    let mut home = Vec::new();
    for (side, origin) in [("a", 0.0), ("b", 0.1)] {
        for i in 0..m {
            let parent = if i == 0 {
                "base".to_string()
            } else {
                format!("{side}{}", i - 1)
            };
            let _ = write!(
                s,
                "\n[[links]]\nname = \"{side}{i}\"\nparent = \"{parent}\"\nlength = [0.1, 0.0]\nmass = 0.1\ncom = [0.05, 0.0]\ninertia = 1e-4\n"
            );
            if i == 0 {
                let _ = write!(
                    s,
                    "origin = [{origin:?}, 0.0]\nactuator = {{ rotor_inertia = 1e-6, gear_ratio = 10.0 }}\n"
                );
            }
            home.push(if i == 0 {
                -std::f64::consts::FRAC_PI_2
            } else {
                0.0
            });
        }
    }
    for k in (1..m).step_by(2) {
        let _ = write!(
            s,
            "\n[[closures]]\nname = \"rung{k}\"\na = {{ link = \"a{k}\", point = [0.1, 0.05] }}\nb = {{ link = \"b{k}\", point = [0.1, -0.05] }}\n"
        );
    }
    let home: Vec<String> = home.iter().map(|x| format!("{x:?}")).collect();
    s = s.replacen(
        "gravity = [0.0, -9.81]\n",
        &format!("gravity = [0.0, -9.81]\nhome = [{}]\n", home.join(", ")),
        1,
    );
    let _ = write!(s, "\n[foot]\nlink = \"a{}\"\n", m - 1);
    s
}

#[test]
#[ignore]
fn generation_time_by_chain_length() {
    let sizes: Vec<usize> = std::env::var("SIZES")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_else(|| vec![2, 4, 8, 16, 24, 32]);
    for (shape, make) in [
        ("one chain", chain as fn(usize) -> String),
        ("two chains, a loop every other link", ladder),
    ] {
        println!("\n{shape}:\n| links | gen (s) | generated Rust (lines) |\n|---|---|---|");
        for &n in &sizes {
            measure(n, &make(n));
        }
    }
}

fn measure(n: usize, spec: &str) {
    let root: PathBuf =
        std::env::temp_dir().join(format!("xtask-growth-{n}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    for sub in [gen::SPECS_DIR, gen::IR_DIR, gen::SRC_DIR] {
        std::fs::create_dir_all(root.join(sub)).unwrap();
    }
    for dir in ["xtask", ".venv"] {
        std::os::unix::fs::symlink(gen::workspace_root().join(dir), root.join(dir)).unwrap();
    }
    std::fs::write(root.join(gen::SPECS_DIR).join("chain.toml"), spec).unwrap();
    let started = Instant::now();
    let result = gen::run(
        &root,
        &GenOptions {
            check: false,
            names: vec![],
        },
    );
    let seconds = started.elapsed().as_secs_f64();
    let lines = std::fs::read_to_string(root.join(gen::SRC_DIR).join("chain.rs"))
        .map_or(0, |t| t.lines().count());
    match result {
        Ok(_) => println!("| {n} | {seconds:.1} | {lines} |"),
        Err(e) => println!("| {n} | failed after {seconds:.1} s: {e} | |"),
    }
    let _ = std::fs::remove_dir_all(&root);
}
