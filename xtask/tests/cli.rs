//! The command line: `legs` (behind `cargo xtask sim` and `eval`) and `xtask` itself.
//! Bad input is one line on stderr, exit code 2, and no output file.

use std::path::PathBuf;
use std::process::{Command, Output};

use generated::Minitaur;
use leg_models::nalgebra::SVector;
use leg_models::LegDynamics;
use serde_json::Value;

fn legs(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_legs"))
        .args(args)
        .output()
        .unwrap()
}

fn xtask(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .output()
        .unwrap()
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("legs-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Exit code 2, a one-line error that says `says`, nothing on stdout.
fn refused(out: &Output, says: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    assert!(
        err.starts_with("error: ") && err.trim_end().lines().count() == 1,
        "not one line: {err}"
    );
    assert!(
        err.contains(says),
        "`{}` should say `{says}`",
        err.trim_end()
    );
    assert!(out.stdout.is_empty());
}

#[test]
fn eval_json_has_every_term_and_matches_the_model() {
    let out = legs(&[
        "eval",
        "minitaur",
        "--q",
        "-0.7,-1.25,-2.43,1.25",
        "--qd",
        "0.1,0.2,-0.3,0.4",
        "--u",
        "0.05,-0.02",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "q",
        "qd",
        "u",
        "M",
        "N",
        "G",
        "J",
        "Jdot_qdot",
        "qdd",
        "F",
        "A_tilde",
        "b_tilde",
        "foot",
        "foot_jacobian",
        "kinetic",
        "potential",
        "phi",
    ] {
        assert!(v.get(key).is_some_and(|x| !x.is_null()), "missing {key}");
    }
    let q = SVector::<f64, 4>::from_column_slice(&[-0.7, -1.25, -2.43, 1.25]);
    let p = generated::minitaur::Params::<f64>::default();
    let m = Minitaur::mass_matrix(&q, &p);
    for r in 0..4 {
        for c in 0..4 {
            assert_eq!(
                v["M"][r][c].as_f64().unwrap(),
                m[(r, c)],
                "M is printed exactly, as rows"
            );
        }
    }
    assert_eq!(v["J"].as_array().unwrap().len(), 2);
    assert_eq!(v["foot_jacobian"][0].as_array().unwrap().len(), 4);
}

/// `--derivatives` adds the six derivative matrices as rows; `dqdd_du` against the
/// difference of two evaluations one newton-metre apart (q̈ is linear in u).
#[test]
fn eval_derivatives_adds_the_jacobians() {
    let eval = |u: &str, extra: &[&str]| {
        let mut args = vec![
            "eval",
            "minitaur",
            "--q",
            "-0.7,-1.25,-2.43,1.25",
            "--project",
            "--qd",
            "0.1,0.2,-0.3,0.4",
            "--u",
            u,
            "--json",
        ];
        args.extend_from_slice(extra);
        let out = legs(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice::<Value>(&out.stdout).unwrap()
    };
    let v = eval("0.05,-0.02", &["--derivatives"]);
    for (key, rows, cols) in [
        ("dqdd_dq", 4, 4),
        ("dqdd_dqd", 4, 4),
        ("dqdd_du", 4, 2),
        ("dF_dq", 2, 4),
        ("dF_dqd", 2, 4),
        ("dF_du", 2, 2),
    ] {
        let m = v[key].as_array().unwrap_or_else(|| panic!("{key} missing"));
        assert_eq!(m.len(), rows, "{key} rows");
        assert!(
            m.iter().all(|r| r.as_array().unwrap().len() == cols),
            "{key} columns"
        );
    }
    let shifted = eval("1.05,-0.02", &[]);
    assert!(
        shifted.get("dqdd_dq").is_none(),
        "derivatives only when asked"
    );
    for r in 0..4 {
        let fd = shifted["qdd"][r].as_f64().unwrap() - v["qdd"][r].as_f64().unwrap();
        let d = v["dqdd_du"][r][0].as_f64().unwrap();
        assert!(
            (fd - d).abs() <= 1e-9 * (1.0 + d.abs()),
            "row {r}: {d} vs {fd}"
        );
    }
}

#[test]
fn eval_assemble_solves_the_loop() {
    let out = legs(&[
        "eval",
        "minitaur",
        "--q",
        "-0.75,-2.4",
        "--qd",
        "1,-1",
        "--assemble",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let q: Vec<f64> = v["q"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!((q.len(), q[0], q[2]), (4, -0.75, -2.4));
    let phi = v["phi"].as_array().unwrap();
    assert!(
        phi.iter().all(|x| x.as_f64().unwrap().abs() < 1e-12),
        "{phi:?}"
    );
    let qd: Vec<f64> = v["qd"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!((qd[0], qd[2]), (1.0, -1.0));
}

#[test]
fn eval_refuses_bad_input() {
    refused(&legs(&["eval", "nope", "--q", "1"]), "unknown model `nope`");
    refused(
        &legs(&["eval", "minitaur", "--q", "1,2,3"]),
        "has 3 values, expected 4",
    );
    refused(
        &legs(&["eval", "minitaur", "--q", "1,2", "--assemble", "--qd", "1"]),
        "has 1 value, expected 2",
    );
    refused(
        &legs(&["eval", "minitaur", "--q", "1,x,3,4"]),
        "expected 4 comma-separated numbers",
    );
    refused(
        &legs(&["eval", "minitaur", "--q=1,nan,3,4"]),
        "every value must be finite (not NaN or infinite)",
    );
    refused(
        &legs(&["eval", "minitaur", "--q", "1,2,3,4", "--frob"]),
        "unexpected argument '--frob' found (see `cargo xtask eval --help`)",
    );
    refused(
        &legs(&["eval", "minitaur", "--q", "1,2,3,4", "--jsno"]),
        "tip: a similar argument exists: '--json'",
    );
    refused(
        &legs(&["eval", "minitaur"]),
        "the following required arguments were not provided: --q",
    );
    refused(
        &legs(&["eval", "minitaur", "--q"]),
        "a value is required for '--q",
    );
    refused(
        &legs(&["eval", "minitaur", "--q", "1,2,3,4", "--guess", "1,2,3,4"]),
        "--assemble",
    );
}

#[test]
fn eval_reports_a_singular_state_without_failing() {
    let out = legs(&[
        "eval",
        "minitaur",
        "--q",
        "-1.5707963267948966,0,-1.5707963267948966,0",
        "--json",
    ]);
    assert!(out.status.success());
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(
        v["qdd"].is_null() && v["errors"]["qdd"].as_str().unwrap().contains("singular"),
        "{v}"
    );
}

#[test]
fn sim_writes_csv_summary_and_report() {
    let dir = temp_dir("sim");
    let out = legs(&[
        "sim",
        "two_link",
        "--duration",
        "0.2",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains(dir.to_str().unwrap()),
        "says where it wrote"
    );
    let csv = std::fs::read_to_string(dir.join("trajectory.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert!(header.starts_with("t,q_upper_arm,q_forearm,qd_upper_arm,qd_forearm,u_upper_arm,u_forearm,closure_residual,energy,foot_x,foot_y,ref_x,ref_y,error"), "{header}");
    assert_eq!(csv.lines().count(), 1 + 201);
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["model"], "two_link");
    assert_eq!(summary["controller"], "foot-fl");
    assert!(summary["tracking_error"]["max"].as_f64().unwrap() < 0.01);
    assert!(summary["stopped"].is_null());
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("<svg") && html.contains("id=\"frames\""));
    // Links drawn as bodies, the summary as a table, and why the controller was chosen.
    assert!(html.contains("\"bodies\":[[[[") && html.contains("<table class=\"summary\">"));
    assert_eq!(
        summary["controller_choice"],
        "default: the motors can place the foot"
    );
    // The only URLs are SVG's namespace name, which is never fetched.
    assert_eq!(
        html.matches("http://").count(),
        html.matches("http://www.w3.org/2000/svg").count(),
        "the report names a URL other than SVG's namespace"
    );
    assert!(
        !html.contains("https://") && !html.contains("src=\""),
        "the report must not fetch anything"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn sim_refuses_bad_input_and_writes_nothing() {
    let dir = temp_dir("bad-sim");
    let d = dir.to_str().unwrap();
    refused(&legs(&["sim", "nope", "--out", d]), "unknown model `nope`");
    refused(
        &legs(&["sim", "minitaur", "--controller", "magic", "--out", d]),
        "invalid value 'magic' for '--controller <C>'; possible values: foot-fl, foot-pd, joint-fl, joint-pd, passive",
    );
    refused(
        &legs(&[
            "sim",
            "minitaur",
            "--controller",
            "joint-fl",
            "--trajectory",
            "step",
            "--out",
            d,
        ]),
        "does not suit",
    );
    refused(
        &legs(&["sim", "minitaur", "--dt", "-1", "--out", d]),
        "invalid value '-1' for '--dt <S>': expected a step in (0, 0.05] s",
    );
    refused(
        &legs(&["sim", "minitaur", "--duration", "abc", "--out", d]),
        "invalid value 'abc' for '--duration <S>'",
    );
    // Not one step (issue 29): it ran none and printed "-0.0000 J lost", exit 0.
    for model in ["minitaur", "minitaur_hopper"] {
        refused(
            &legs(&["sim", model, "--duration", "0.0004", "--out", d]),
            "`--duration 0.0004 s` is shorter than one step (`--dt 0.001 s`)",
        );
    }
    refused(
        &legs(&["sim", "minitaur", "--sped", "2", "--out", d]),
        "unexpected argument '--sped' found; tip: a similar argument exists: '--speed'",
    );
    refused(
        &legs(&["sim", "minitaur", "--speed", "0", "--out", d]),
        "--speed 0: under the swing-leg controllers (minitaur) the speed is the spin trajectory's motor speed",
    );
    // A controller that does not apply to the leg is refused with the reason.
    refused(
        &legs(&["sim", "klann_linkage", "--controller", "foot-fl", "--out", d]),
        "controller `foot-fl` does not apply to klann_linkage: the foot has two coordinates but the leg has 1 motor",
    );
    assert!(!dir.exists(), "bad input left {}", dir.display());
}

#[test]
fn a_simulation_that_stops_keeps_its_output() {
    let dir = temp_dir("stops");
    // k_p = 1e9 at dt = 1 ms: the discrete loop diverges within a few steps.
    let out = legs(&[
        "sim",
        "minitaur",
        "--controller",
        "joint-fl",
        "--kp",
        "1e9",
        "--duration",
        "0.5",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("the simulation stopped at t =")
            && err.contains("the output holds everything until then"),
        "{err}"
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    let t = summary["stopped"]["t"].as_f64().unwrap();
    assert!(
        t > 0.0 && t < 0.5 && summary["stopped"]["cause"].is_string(),
        "{summary}"
    );
    let rows = std::fs::read_to_string(dir.join("trajectory.csv"))
        .unwrap()
        .lines()
        .count();
    assert_eq!(rows as u64, 1 + summary["samples"].as_u64().unwrap());
    assert!(rows > 2);
    assert!(dir.join("report.html").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn export_writes_mjcf_and_urdf_and_refuses_bad_input() {
    let dir = temp_dir("export");
    let file = dir.join("minitaur.urdf");
    let out = xtask(&[
        "export",
        "minitaur",
        "--format",
        "urdf",
        "--out",
        file.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let urdf = std::fs::read_to_string(&file).unwrap();
    for frame in [
        "<link name=\"toe.a\"/>",
        "<link name=\"toe.b\"/>",
        "<link name=\"foot.point\"/>",
        "<mass value=\"0.05\"/>",
    ] {
        assert!(urdf.contains(frame), "{frame} missing");
    }
    let out = xtask(&["export", "atrias", "--format", "mjcf"]);
    let mjcf = String::from_utf8(out.stdout).unwrap();
    assert!(mjcf.contains("<connect name=\"shin_pin\" site1=\"shin_pin.a\" site2=\"shin_pin.b\""));
    assert!(
        mjcf.contains("mass=\"0.4438\"")
            && mjcf.contains("<motor name=\"thigh\" joint=\"thigh\" gear=\"1\"/>")
    );
    // The home keyframe, in MuJoCo's qpos order (bodies depth first: atrias lists its
    // links in that order).
    let home = generated::Atrias::HOME
        .iter()
        .map(|x| format!("{x:?}"))
        .collect::<Vec<_>>()
        .join(" ");
    assert!(
        mjcf.contains(&format!("<key name=\"home\" qpos=\"{home}\"/>")),
        "no home keyframe {home}"
    );
    let armature = format!("armature=\"{:?}\"", 1.2e-4 * 50.0 * 50.0);
    assert!(
        mjcf.contains(&armature),
        "reflected rotor inertia I·N² as {armature}"
    );
    let bad = dir.join("bad.xml");
    let b = bad.to_str().unwrap();
    refused(
        &xtask(&["export", "nope", "--format", "mjcf", "--out", b]),
        "unknown model `nope`",
    );
    refused(
        &xtask(&["export", "minitaur", "--format", "obj", "--out", b]),
        "invalid value 'obj' for '--format <FORMAT>'; possible values: mjcf, urdf",
    );
    refused(
        &xtask(&["export", "minitaur", "--out", b]),
        "the following required arguments were not provided: --format",
    );
    refused(
        &xtask(&["export", "minitaur", "atrias", "--format", "mjcf"]),
        "unexpected argument 'atrias' found",
    );
    assert!(!bad.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `new NAME --spatial` writes a spatial template whose home pose `gen` assembles (one
/// redundant closure row found), as `new NAME` does for the planar one; the file is
/// removed after.
#[test]
fn new_writes_templates_gen_takes() {
    let root = xtask::gen::workspace_root();
    let dir = temp_dir("new");
    std::fs::create_dir_all(&dir).unwrap();
    for (flag, says) in [
        (
            Some("--spatial"),
            "rank J 2 of 3 closure rows, redundant rows [2]",
        ),
        (None, "rank J 2 of 2 closure rows"),
    ] {
        let name = format!(
            "zz_new_{}_{}",
            flag.map_or("planar", |_| "spatial"),
            std::process::id()
        );
        let mut args = vec!["new", name.as_str()];
        args.extend(flag);
        let out = xtask(&args);
        let spec = root.join("leg-models/specs").join(format!("{name}.toml"));
        let generated = dir.join(format!("{name}.rs"));
        let gen = xtask(&[
            "gen",
            "--spec",
            spec.to_str().unwrap(),
            "--out",
            generated.to_str().unwrap(),
        ]);
        let _ = std::fs::remove_file(&spec);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            gen.status.success(),
            "{}",
            String::from_utf8_lossy(&gen.stderr)
        );
        let text = String::from_utf8_lossy(&gen.stdout);
        assert!(text.contains(says), "{text}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn list_new_and_unknown_commands() {
    let out = xtask(&["list"]);
    let text = String::from_utf8(out.stdout).unwrap();
    for m in ["atrias", "digit", "five_bar_offset", "minitaur", "two_link"] {
        assert!(text.contains(m), "{text}");
    }
    assert!(text.contains("upper_a, upper_b"));
    // A spatial leg's dimension and its contacts by name.
    let ankle = text
        .lines()
        .find(|l| l.starts_with("ankle_rod_leg "))
        .expect("listed");
    let cells: Vec<&str> = ankle.split_whitespace().collect();
    assert_eq!(cells[1], "3", "{ankle}");
    assert!(ankle.ends_with("heel, toe"), "{ankle}");
    refused(&xtask(&["new", "Bad-Name"]), "not a plain identifier");
    refused(&xtask(&["new", "minitaur"]), "exists already");
    refused(
        &xtask(&["frobnicate"]),
        "unrecognized subcommand 'frobnicate'",
    );
    refused(
        &xtask(&["exprot", "minitaur"]),
        "tip: a similar subcommand exists: 'export'",
    );
    refused(&xtask(&[]), "no command given");
    refused(
        &xtask(&["gen", "--frob"]),
        "unexpected argument '--frob' found",
    );
    refused(
        &xtask(&["gen", "--chek"]),
        "tip: a similar argument exists: '--check'",
    );
    refused(&xtask(&["gen", "nope"]), "unknown model `nope`");
}

#[test]
fn every_subcommand_has_help_and_both_value_forms_work() {
    for cmd in [
        "gen", "sim", "eval", "export", "bench", "list", "new", "test",
    ] {
        let out = xtask(&[cmd, "--help"]);
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && text.contains(&format!("Usage: cargo xtask {cmd}")),
            "`{cmd} --help`: {text}"
        );
    }
    let out = legs(&["sim", "--help"]);
    assert!(out.status.success() && String::from_utf8_lossy(&out.stdout).contains("--controller"));
    // `--flag=value` and `--flag value`, negative numbers included.
    let spaced = legs(&["eval", "minitaur", "--q", "-0.2,1.4,0.3,-1.4", "--json"]);
    let joined = legs(&["eval", "minitaur", "--q=-0.2,1.4,0.3,-1.4", "--json"]);
    assert!(
        spaced.status.success(),
        "{}",
        String::from_utf8_lossy(&spaced.stderr)
    );
    assert_eq!(spaced.stdout, joined.stdout);
}

/// A leg with contacts runs on the ground: `sim minitaur_hopper` hops (under the Minitaur
/// motors' 3.5 N m), writes the events and draws the ground; a swing-leg controller, a
/// forward speed for a body on a vertical rail, and an unknown contact are refused with
/// the reason.
#[test]
fn sim_hops_a_leg_with_contacts() {
    let dir = temp_dir("hop");
    let d = dir.to_str().unwrap();
    let out = legs(&[
        "sim",
        "minitaur_hopper",
        "--duration",
        "3",
        "--torque-limit",
        "3.5",
        "--out",
        d,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["controller"], "hop");
    assert!(summary["hops"].as_u64().unwrap() >= 6, "{summary}");
    assert!(
        summary["apex_error_after_five_hops_m"]["max"]
            .as_f64()
            .unwrap()
            < 5e-3,
        "{summary}"
    );
    assert_eq!(summary["events"]["slips"], 0);
    let events = std::fs::read_to_string(dir.join("events.csv")).unwrap();
    assert!(events.starts_with("t,kind,contact,impulse_t,impulse_n,energy_lost\n"));
    assert!(
        events
            .lines()
            .any(|l| l.contains(",Touchdown,toe_contact,")),
        "{events}"
    );
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(
        html.contains("\"ground\":[0.0,1.0,0.0]"),
        "the ground is drawn"
    );
    std::fs::remove_dir_all(&dir).unwrap();
    let bad = temp_dir("bad-hop");
    let b = bad.to_str().unwrap();
    refused(
        &legs(&[
            "sim",
            "minitaur_hopper",
            "--controller",
            "foot-fl",
            "--out",
            b,
        ]),
        "minitaur_hopper has contacts",
    );
    refused(
        &legs(&["sim", "minitaur_hopper", "--apex", "-1", "--out", b]),
        "--apex -1: at or below the standing height",
    );
    refused(
        &legs(&["sim", "minitaur_hopper", "--kp", "50", "--out", b]),
        "minitaur_hopper has contacts: `--kp` sets the swing-leg controllers' stiffness",
    );
    refused(
        &legs(&["sim", "minitaur_hopper", "--speed", "fast", "--out", b]),
        "invalid value 'fast' for '--speed <V>': not a number: expected",
    );
    refused(
        &legs(&["sim", "minitaur_hopper", "--speed", "0.5", "--out", b]),
        "--speed: minitaur_hopper: a forward speed needs a body that moves along the ground",
    );
    // Ignored without a word under a passive drop (issue 29).
    for flag in ["--apex", "--speed"] {
        refused(
            &legs(&[
                "sim",
                "atrias_hopper",
                "--controller",
                "passive",
                flag,
                "0.5",
                "--out",
                b,
            ]),
            &format!("{flag} sets the hopping controller's"),
        );
    }
    refused(
        &legs(&[
            "eval",
            "minitaur_hopper",
            "--q",
            "0.3,-0.7,-1.25,-2.43,1.25",
            "--impact",
            "heel",
        ]),
        "unknown contact `heel` (contacts of minitaur_hopper: toe_contact)",
    );
    assert!(!bad.exists(), "bad input left {}", bad.display());
}

/// `sim --serve`: the hopping controller answers each state line with the motors'
/// torques (the MuJoCo closed loop), and a malformed line with an error line, going on.
#[test]
fn sim_serve_answers_torques_for_states() {
    use std::io::Write;
    let mut child = Command::new(env!("CARGO_BIN_EXE_legs"))
        .args(["sim", "minitaur_hopper", "--serve"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // In flight at the home pose raised 3 cm, then on the ground; then a short line.
    let home = "0.29 -0.7076 -1.253 -2.434 1.253";
    let rest = "0 0 0 0 0";
    let lines = format!("0 {home} {rest} 0 0\n0.001 {home} {rest} 1 0\n0.002 1 2 3\n");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(lines.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let answers: Vec<&str> = text.lines().collect();
    assert_eq!(answers.len(), 3, "{text}");
    for a in &answers[..2] {
        let u: Vec<f64> = a.split_whitespace().map(|x| x.parse().unwrap()).collect();
        assert_eq!(u.len(), 2, "{a}");
        assert!(u.iter().all(|x| x.is_finite()), "{a}");
    }
    assert_eq!(answers[2], "error: 4 numbers, expected 13");
}

/// `sim ROBOT --serve` answers the balance QP's torques line by line (the MuJoCo push
/// run's loop): at the state `sim` stands the robot in (its trajectory's first row) the
/// answer is that row's torques, the command `sim` itself applied (to the QP solver's
/// tolerance); a line of another
/// width or of words gets `error: …`, and the server answers the next line.
#[test]
fn sim_serve_answers_a_robots_balance_torques() {
    use std::io::Write;
    let d = temp_dir("robot-serve");
    let out = legs(&[
        "sim",
        "minitaur_quadruped",
        "--duration",
        "0.002",
        "--push",
        "0,0,0",
        "--out",
        d.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(d.join("trajectory.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let first: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    let pick = |keep: &dyn Fn(&str) -> bool| -> Vec<&str> {
        header
            .iter()
            .zip(&first)
            .filter(|(h, _)| keep(h))
            .map(|(_, v)| *v)
            .collect()
    };
    let state = pick(&|h| h.starts_with("body_") || h.starts_with("q_") || h.starts_with("v_"));
    assert_eq!(state.len(), 7 + 2 * 22);
    let applied: Vec<f64> = pick(&|h| h.starts_with("u_"))
        .iter()
        .map(|x| x.parse().unwrap())
        .collect();
    let mut child = Command::new(env!("CARGO_BIN_EXE_legs"))
        .args(["sim", "minitaur_quadruped", "--serve"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let line = state.join(" ");
    let lines = format!("{line}\n1 2 3\nnot numbers\n{line}\n");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(lines.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let answers: Vec<&str> = text.lines().collect();
    assert_eq!(answers.len(), 4, "{text}");
    for a in [answers[0], answers[3]] {
        let u: Vec<f64> = a.split_whitespace().map(|x| x.parse().unwrap()).collect();
        assert_eq!(u.len(), applied.len(), "{a}");
        let scale = applied.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (mine, theirs) in u.iter().zip(&applied) {
            // The same QP at the same state, to its interior-point solver's stopping
            // tolerance (Clarabel's 1e-8; the state read back differs at rounding).
            assert!(
                (mine - theirs).abs() <= 1e-6 * scale,
                "served {u:?}, sim applied {applied:?}"
            );
        }
    }
    assert_eq!(answers[1], "error: 3 numbers, expected 51");
    assert!(answers[2].starts_with("error: "), "{}", answers[2]);
    let _ = std::fs::remove_dir_all(d);
}

/// `eval --impact`: the impact map at a state, against its own identities (the toe at
/// rest after it, the energy lost equal to ½ Δq̇ᵀ M Δq̇, a pushing normal impulse).
#[test]
fn eval_prints_the_impact_map() {
    let out = legs(&[
        "eval",
        "minitaur_hopper",
        "--q",
        "0.2499991,-0.7076,-1.253,-2.434,1.253",
        "--project",
        "--qd=-1,0,0,0,0",
        "--impact",
        "toe_contact",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let imp = &v["impact"];
    let vec = |x: &Value| -> Vec<f64> {
        x.as_array()
            .unwrap()
            .iter()
            .map(|e| e.as_f64().unwrap())
            .collect()
    };
    let (qd, qd_plus) = (vec(&v["qd"]), vec(&imp["qd_plus"]));
    let m: Vec<Vec<f64>> = v["M"].as_array().unwrap().iter().map(vec).collect();
    let dq: Vec<f64> = qd_plus.iter().zip(&qd).map(|(a, b)| a - b).collect();
    let half_dmd: f64 = 0.5
        * (0..5)
            .map(|i| (0..5).map(|j| dq[i] * m[i][j] * dq[j]).sum::<f64>())
            .sum::<f64>();
    let lost = imp["energy_lost"].as_f64().unwrap();
    assert!(
        (lost - half_dmd).abs() < 1e-12 * lost,
        "{lost} vs {half_dmd}"
    );
    assert!(vec(&imp["impulses"])[1] > 0.0);
    assert_eq!(imp["mode_after"], "stick");
    assert!(v.get("warnings").is_none(), "{v}");
    // Away from the ground the map is computed as asked, and said so.
    let raised = legs(&[
        "eval",
        "minitaur_hopper",
        "--q",
        "0.26,-0.7076,-1.253,-2.434,1.253",
        "--project",
        "--qd=-1,0,0,0,0",
        "--impact",
        "toe_contact",
        "--json",
    ]);
    let w: Value = serde_json::from_slice(&raised.stdout).unwrap();
    let said = w["warnings"]["impact"].as_str().unwrap_or_default();
    assert!(
        said.contains("contact `toe_contact` is") && said.contains("from the ground"),
        "{w}"
    );
}

#[test]
fn analyze_writes_the_table_the_grids_and_the_report() {
    let dir = temp_dir("analyze");
    let d = dir.to_str().unwrap();
    let out = legs(&[
        "analyze",
        "minitaur",
        "klann_linkage",
        "--nodes",
        "40",
        "--torque-limit",
        "2",
        "--out",
        d,
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("minitaur") && stdout.contains("workspace (cm²)"),
        "{stdout}"
    );
    // The one-motor linkage says why it has no polygon, and still gets what applies.
    assert!(
        stdout.contains("klann_linkage: ") && stdout.contains("1 motor"),
        "{stdout}"
    );
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("analysis.json")).unwrap()).unwrap();
    let designs = json["designs"].as_array().unwrap();
    assert_eq!(designs.len(), 2);
    let m = &designs[0]["table"];
    // Minitaur's coaxial five-bar: an annulus from 0.1 to 0.3 m, to the 40-node grid.
    let area = m["workspace_area_m2"].as_f64().unwrap();
    let annulus = std::f64::consts::PI * (0.09 - 0.01);
    assert!((area - annulus).abs() < 0.1 * annulus, "{area}");
    assert!(m["vertical_force_n"].as_f64().unwrap() > 0.0);
    assert_eq!(designs[0]["torque_limit"], serde_json::json!([2.0, 2.0]));
    assert!(designs[1]["table"]["workspace_area_m2"].is_null());
    assert!(designs[1]["not_computed"]["workspace_area_m2"]
        .as_str()
        .unwrap()
        .contains("1 motor"));
    // Its workspace is the foot's path over a turn of the crank.
    assert_eq!(designs[1]["foot_path"]["full_turn"], Value::Bool(true));
    assert!(designs[1]["foot_path"]["length_m"].as_f64().unwrap() > 0.0);
    let csv = std::fs::read_to_string(dir.join("minitaur.csv")).unwrap();
    assert!(csv.starts_with("x,y,state,q_upper_a"));
    assert_eq!(csv.lines().count(), 1 + 40 * 40);
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("<canvas") || html.contains("createElement('canvas')"));
    assert!(!html.contains("http://") && !html.contains("https://"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `analyze` on spatial legs: the measures at stance in 3-D (the force polytope, the speed
/// zonotope, 3 × 3 inertias), the workspace in a slice through the stance foot (its area
/// against the closed form of revolute_knee_leg's annulus), the CSV's nodes in space, and
/// the reasons where a measure does not apply (a leg its motors do not determine).
#[test]
fn analyze_takes_a_spatial_leg() {
    let dir = temp_dir("analyze-spatial");
    let d = dir.to_str().unwrap();
    let out = legs(&[
        "analyze",
        "revolute_knee_leg",
        "rssr_linkage",
        "minitaur",
        "--nodes",
        "80",
        "--out",
        d,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("rssr_linkage: ") && stdout.contains("1 motor"),
        "{stdout}"
    );
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("analysis.json")).unwrap()).unwrap();
    let designs = json["designs"].as_array().unwrap();
    let knee = &designs[0];
    // The thigh (0.2 m) and shin (0.25 m) sweep an annulus in the sagittal slice through the
    // foot: π (0.45² − max(0.05², y₀² − 0.06²)) (analysis_spatial.rs).
    let area = knee["table"]["workspace_area_m2"].as_f64().unwrap();
    let y0 = knee["stance"]["foot"][1].as_f64().unwrap();
    let annulus = std::f64::consts::PI * (0.45f64.powi(2) - 0.05f64.powi(2).max(y0 * y0 - 0.0036));
    assert!(
        (area - annulus).abs() < 0.01 * annulus,
        "{area} against {annulus}"
    );
    assert_eq!(
        knee["grid"]["slice"]["axes"],
        serde_json::json!([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    );
    assert_eq!(knee["stance"]["foot"].as_array().unwrap().len(), 3);
    assert_eq!(
        knee["stance"]["inverse_inertia_free"]
            .as_array()
            .unwrap()
            .len(),
        3
    );
    assert!(knee["stance"]["force_polytope_n"].as_array().unwrap().len() >= 8);
    assert!(knee["stance"]["force_polytope_volume_n3"].as_f64().unwrap() > 0.0);
    assert!(
        knee["stance"]["speed_zonotope_volume_m3_s3"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    for key in [
        "vertical_force_n",
        "vertical_speed_m_s",
        "condition",
        "impact_mitigation",
    ] {
        assert!(knee["table"][key].as_f64().is_some(), "{key}: {knee}");
    }
    // The CSV's nodes are points in space, on the slice's plane through the foot.
    let csv = std::fs::read_to_string(dir.join("revolute_knee_leg.csv")).unwrap();
    assert!(csv.starts_with("x,y,z,state,q_abduction"), "{}", &csv[..80]);
    assert_eq!(csv.lines().count(), 1 + 80 * 80);
    let foot_y = knee["stance"]["foot"][1].as_f64().unwrap();
    for line in csv.lines().skip(1).take(200) {
        let y: f64 = line.split(',').nth(1).unwrap().parse().unwrap();
        assert!((y - foot_y).abs() < 1e-12, "{line}");
    }
    // One motor: no polytope, no slice; the foot's inertia still.
    let rssr = &designs[1];
    assert!(rssr["table"]["workspace_area_m2"].is_null());
    assert!(rssr["not_computed"]["workspace_area_m2"]
        .as_str()
        .unwrap()
        .contains("1 motor"));
    assert!(rssr["table"]["effective_mass_kg"].as_f64().unwrap() > 0.0);
    // The planar leg beside it is unchanged: its grid in its own plane.
    assert!(designs[2]["grid"]["slice"].is_null());
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(
        html.contains("\"axes\":[\"x\",\"z\"]"),
        "the slice's axes label its maps"
    );
    // A frontal slice, and the volume; a slice of a planar leg is refused by name.
    let out = legs(&[
        "analyze",
        "revolute_knee_leg",
        "--slice",
        "yz",
        "--nodes",
        "40",
        "--volume",
        "16",
        "--out",
        d,
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("workspace volume (cm³)"), "{stdout}");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("analysis.json")).unwrap()).unwrap();
    assert_eq!(
        json["designs"][0]["grid"]["slice"]["axes"],
        serde_json::json!([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    );
    // The shell of radii 0.05 and 0.45 m swept by the abduction (analysis_spatial.rs), to
    // a coarse 16³ grid.
    let volume = json["designs"][0]["table"]["workspace_volume_m3"]
        .as_f64()
        .unwrap();
    let shell = 4.0 * std::f64::consts::PI / 3.0 * (0.45f64.powi(3) - 0.05f64.powi(3));
    assert!(
        (volume - shell).abs() < 0.15 * shell,
        "{volume} against {shell}"
    );
    assert_eq!(json["designs"][0]["volume"]["nodes_per_side"], 16);
    let _ = std::fs::remove_dir_all(&dir);
    refused(
        &legs(&["analyze", "minitaur", "--slice", "xz", "--out", d]),
        "`--slice` is for spatial legs: `minitaur` is planar",
    );
    refused(
        &legs(&["analyze", "revolute_knee_leg", "--slice", "xq", "--out", d]),
        "--slice",
    );
    refused(
        &legs(&["analyze", "atrias", "--volume", "10", "--out", d]),
        "`--volume` is for spatial legs: `atrias` is planar",
    );
    refused(
        &legs(&[
            "analyze",
            "revolute_knee_leg",
            "--volume",
            "101",
            "--out",
            d,
        ]),
        "--volume",
    );
    assert!(!dir.exists());
}

#[test]
fn analyze_sweeps_a_parameter() {
    let dir = temp_dir("analyze-sweep");
    let d = dir.to_str().unwrap();
    let out = legs(&[
        "analyze",
        "minitaur",
        "--sweep",
        "lower_a_length_x=0.16:0.24:3",
        "--set",
        "lower_b_length_x=0.2",
        "--nodes",
        "30",
        "--out",
        d,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("analysis.json")).unwrap()).unwrap();
    let designs = json["designs"].as_array().unwrap();
    assert_eq!(designs.len(), 3);
    let lengths: Vec<f64> = designs
        .iter()
        .map(|d| d["parameters"]["lower_a_length_x"].as_f64().unwrap())
        .collect();
    assert_eq!(lengths, [0.16, 0.2, 0.24]);
    for d in designs {
        assert_eq!(d["parameters"]["lower_b_length_x"].as_f64(), Some(0.2));
    }
    // The home pose assembles only at the spec's length (the toe's closure holds only
    // there): the others say so, and the middle design has its grid.
    assert!(designs[1]["table"]["workspace_area_m2"].as_f64().unwrap() > 0.0);
    for k in [0, 2] {
        let d = &designs[k];
        assert!(
            d["error"].as_str().is_some() || d["table"]["workspace_area_m2"].as_f64().is_some(),
            "{d}"
        );
    }
    assert!(dir.join("report.html").exists());
    // A rerun into the same folder with other designs leaves only its own CSVs: the
    // earlier run's stayed beside them (the new user's trial). A file of the user's stays.
    let csvs = |dir: &std::path::Path| {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .filter(|n| n.ends_with(".csv"))
            .collect();
        v.sort();
        v
    };
    let before = csvs(&dir);
    assert!(!before.is_empty());
    std::fs::write(dir.join("mine.csv"), "kept").unwrap();
    let out = legs(&[
        "analyze",
        "minitaur",
        "--sweep",
        "lower_b_length_x=0.19:0.21:2",
        "--nodes",
        "10",
        "--out",
        d,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("analysis.json")).unwrap()).unwrap();
    let mut named: Vec<String> = json["designs"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|d| d["grid"]["csv"].as_str().map(str::to_string))
        .collect();
    named.push("mine.csv".into());
    named.sort();
    assert_eq!(csvs(&dir), named, "earlier: {before:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--branches`: one design per assembly branch at the home motor angles, each with its
/// own stance (same motors, another foot) and grid file.
#[test]
fn analyze_compares_the_assembly_branches() {
    let dir = temp_dir("analyze-branches");
    let d = dir.to_str().unwrap();
    let out = legs(&[
        "analyze",
        "minitaur",
        "--branches",
        "--nodes",
        "30",
        "--out",
        d,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("analysis.json")).unwrap()).unwrap();
    let designs = json["designs"].as_array().unwrap();
    let labels: Vec<&str> = designs
        .iter()
        .map(|d| d["label"].as_str().unwrap())
        .collect();
    assert_eq!(labels, ["minitaur branch 1 (home)", "minitaur branch 2"]);
    let q = |k: usize| -> Vec<f64> {
        designs[k]["stance"]["q"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (home, other) = (q(0), q(1));
    // Minitaur's motors are joints 0 and 2.
    assert_eq!((home[0], home[2]), (other[0], other[2]));
    assert!((home[1] - other[1]).abs() > 0.1, "{home:?} {other:?}");
    for d in designs {
        assert!(d["table"]["workspace_area_m2"].as_f64().unwrap() > 0.0);
    }
    assert!(dir.join("minitaur_branch_2.csv").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn analyze_refuses_bad_input_and_writes_nothing() {
    let dir = temp_dir("analyze-bad");
    let d = dir.to_str().unwrap();
    let long_set = format!("{}=0.2", "x".repeat(4998));
    let long_name = format!("{}=0.2", "y".repeat(2000));
    for (args, says) in [
        (
            vec!["analyze", "minitaurr", "--out", d],
            "unknown model `minitaurr`",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "--set",
                "lower_a_lenght_x=0.2",
                "--out",
                d,
            ],
            "did you mean `lower_a_length_x`",
        ),
        // Limits that overflow the polygons (issue 29, class 5): read as "unbounded".
        (
            vec!["analyze", "minitaur", "--torque-limit", "1e308", "--out", d],
            "`--torque-limit`: 1e308 is beyond 1e9: a torque limit must be in (0, 1e9]",
        ),
        (
            vec!["analyze", "minitaur", "--speed-limit", "2,1e308", "--out", d],
            "`--speed-limit`: 1e308 is beyond 1e9",
        ),
        // Sweeps that make no designs (issue 29): values that overflow, values one label.
        (
            vec!["analyze", "minitaur", "--sweep", "lower_a_length_x=-1e308:1e308:3", "--out", d],
            "`--sweep`: parameter `lower_a_length_x` must be at most 1e6 in magnitude",
        ),
        (
            vec!["analyze", "minitaur", "--sweep", "lower_a_length_x=0.2:0.2000000000001:3", "--out", d],
            "3 values from 0.2 to 0.2000000000001 are not distinct at 12 significant digits",
        ),
        // A hostile name is echoed escaped and short (issue 29): `refused` checks one line.
        (
            vec![
                "analyze",
                "minitaur",
                "--set",
                "bad\nname\u{2028}\u{1b}[31mredxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx=0.2",
                "--out",
                d,
            ],
            "argument `bad\\nname\\u{2028}\\u{1b}[31mredxxxxxxxxxx…` holds a control character",
        ),
        (
            vec!["analyze", "minitaur", "--set", "bad\u{2028}name=0.2", "--out", d],
            "argument `bad\\u{2028}name=0.2` holds a control character",
        ),
        (
            vec!["analyze", "minitaur", "--set", &long_set, "--out", d],
            "argument `xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx…` has 5002 characters, more than 4096",
        ),
        (
            vec!["analyze", "minitaur", "--set", &long_name, "--out", d],
            "has no parameter `yyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyy…`",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "--set",
                "lower_a_length_x",
                "--out",
                d,
            ],
            "NAME=VALUE",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "--sweep",
                "lower_a_length_x=0.1:0.2",
                "--out",
                d,
            ],
            "NAME=FROM:TO:N",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "atrias",
                "--sweep",
                "gravity_y=-9:-10:3",
                "--out",
                d,
            ],
            "give one model",
        ),
        (
            vec!["analyze", "minitaur", "--torque-limit", "1,2,3", "--out", d],
            "give one limit or 2",
        ),
        (
            vec!["analyze", "minitaur", "--torque-limit", "-1", "--out", d],
            "positive",
        ),
        (
            vec!["analyze", "minitaur", "--motor-range", "1:-1", "--out", d],
            "LO < HI",
        ),
        (
            vec!["analyze", "minitaur", "--nodes", "1", "--out", d],
            "2..=2000",
        ),
        (
            vec!["analyze", "minitaur", "--set", "foo=1", "--out", d],
            "its parameters: ",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "--set",
                "upper_a_mass=-1",
                "--out",
                d,
            ],
            "`upper_a_mass` is a mass, an inertia or a damping and cannot be negative",
        ),
        // The spec's rules at run time too (from the new user's trial): they were accepted.
        (
            vec!["analyze", "minitaur", "--set", "upper_a_gear_ratio=0", "--out", d],
            "`upper_a_gear_ratio` is a gear ratio and must be positive, got 0",
        ),
        (
            vec!["analyze", "minitaur", "--set", "upper_a_damping=-1", "--out", d],
            "`upper_a_damping` is a mass, an inertia or a damping and cannot be negative",
        ),
        (
            vec!["analyze", "minitaur", "--set", "lower_a_mass=1e308", "--out", d],
            "`lower_a_mass` must be at most 1e6 in magnitude",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "--sweep",
                "upper_a_mass=-0.1:0.1:3",
                "--out",
                d,
            ],
            "cannot be negative",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "--set",
                "lower_a_length_x=0.22",
                "--sweep",
                "lower_a_length_x=0.16:0.26:3",
                "--out",
                d,
            ],
            "is both set (`--set`) and swept (`--sweep`)",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "--nodes",
                "2000",
                "--sweep",
                "lower_a_length_x=0.16:0.26:3",
                "--out",
                d,
            ],
            "12.0 million grid nodes",
        ),
        (
            vec!["analyze", "minitaur", "atrias", "minitaur", "--out", d],
            "`minitaur` is given twice",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "--branches",
                "--sweep",
                "lower_a_length_x=0.16:0.26:3",
                "--out",
                d,
            ],
            "do not go together",
        ),
        (
            vec![
                "analyze",
                "minitaur",
                "atrias",
                "digit",
                "--branches",
                "--nodes",
                "1800",
                "--out",
                d,
            ],
            "`minitaur` has 2 branches",
        ),
        (vec!["analyze", "--out", d], "MODEL"),
    ] {
        let out = legs(&args);
        refused(&out, says);
    }
    assert!(!dir.exists(), "a refused analysis wrote {}", dir.display());
}

/// Issue 29, class 6: one target in the way (a folder where a file goes) left the other files
/// written. Now every target is checked before the work starts and the files are moved into
/// place together: the folder is left exactly as it was.
#[test]
fn output_is_written_whole_or_not_at_all() {
    let cases: [(&[&str], &str); 4] = [
        (&["analyze", "minitaur", "--nodes", "12"], "analysis.json"),
        (&["analyze", "minitaur", "--nodes", "12"], "report.html"),
        (&["sim", "minitaur", "--duration", "0.01"], "summary.json"),
        (
            &["sim", "minitaur_hopper", "--duration", "0.01"],
            "events.csv",
        ),
    ];
    for (i, (args, blocked)) in cases.iter().enumerate() {
        let dir = temp_dir(&format!("whole-{i}"));
        std::fs::create_dir_all(dir.join(blocked)).unwrap();
        // A file from an earlier run, which must survive untouched.
        std::fs::write(dir.join("earlier.txt"), "kept").unwrap();
        let mut full = args.to_vec();
        full.extend(["--out", dir.to_str().unwrap()]);
        let out = legs(&full);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(
            err.contains(&format!("{blocked}: exists and is not a file"))
                && err.trim_end().lines().count() == 1,
            "{args:?}: {err}"
        );
        let mut left: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        let mut expected = vec![blocked.to_string(), "earlier.txt".to_string()];
        expected.sort();
        assert_eq!(left, expected, "{args:?} wrote into {}", dir.display());
        assert!(std::fs::read_dir(dir.join(blocked))
            .unwrap()
            .next()
            .is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }
    // The output folder itself in the way: a file where the folder goes.
    let dir = temp_dir("whole-file");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("not-a-folder");
    std::fs::write(&file, "x").unwrap();
    let out = legs(&[
        "sim",
        "minitaur",
        "--duration",
        "0.01",
        "--out",
        file.join("sub").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("not-a-folder: exists and is not a folder"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "x");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 29, class 11: rates of 1e200 left `N`, `Jdot_qdot` and `kinetic` as `null` with
/// no word, and an impact at 1e160 reported success with `energy_lost: null`. Every term
/// that is not a number now has an entry in `errors` that says overflow and names it.
#[test]
fn eval_names_every_term_that_overflows() {
    let cases: [&[&str]; 2] = [
        &[
            "eval",
            "minitaur",
            "--assemble",
            "--q",
            "-0.6,-2.5",
            "--qd",
            "1e200,1e200",
            "--derivatives",
            "--json",
        ],
        &[
            "eval",
            "minitaur_hopper",
            "--q",
            "0.3,-0.7,-1.25,-2.43,1.25",
            "--qd",
            "0,-1e160,0,0,0",
            "--impact",
            "toe_contact",
            "--json",
        ],
    ];
    for args in cases {
        let out = legs(args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: Value = serde_json::from_slice(&out.stdout).unwrap();
        let errors = v["errors"].as_object().expect("an errors entry");
        for (key, value) in v.as_object().unwrap() {
            if !value.is_null() {
                continue;
            }
            let by = match key.as_str() {
                "F" => "qdd",
                "b_tilde" => "A_tilde",
                k if k.starts_with("dqdd_") || k.starts_with("dF_") => "derivatives",
                k => k,
            };
            let why = errors.get(by).and_then(Value::as_str).unwrap_or_default();
            assert!(
                why.contains("overflow"),
                "{args:?}: `{key}` is null and `errors.{by}` says `{why}`"
            );
        }
    }
    // The impact's energy is named.
    let v: Value = serde_json::from_slice(&legs(cases[1]).stdout).unwrap();
    assert!(v["impact"].is_null());
    assert!(
        v["errors"]["impact"].as_str().unwrap().contains("overflow"),
        "{}",
        v["errors"]
    );
}

/// Issue 29, class 5: a gear ratio of 1e-200 made a default speed limit of 1e202 rad/s and
/// left dashes with no reason. The design says which limit and why; every dash of every
/// design has its reason.
#[test]
fn analyze_says_why_for_every_dash() {
    let dir = temp_dir("analyze-dash");
    let out = legs(&[
        "analyze",
        "minitaur",
        "--set",
        "upper_a_gear_ratio=1e-200",
        "--nodes",
        "12",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("analysis.json")).unwrap()).unwrap();
    let error = v["designs"][0]["error"].as_str().unwrap_or_default();
    assert!(
        error.contains(
            "the speed limit of motor 1 (upper_a) is 1.000e202 rad/s, from its gear ratio 1e-200"
        ),
        "{error}"
    );
    let _ = std::fs::remove_dir_all(&dir);
    // Every null in a table has its reason, on designs of every kind of leg.
    let out = legs(&[
        "analyze",
        "minitaur",
        "klann_linkage",
        "minitaur_pinned_toe",
        "two_link",
        "--nodes",
        "12",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("analysis.json")).unwrap()).unwrap();
    for d in v["designs"].as_array().unwrap() {
        for (key, value) in d["table"].as_object().unwrap() {
            if value.is_null() {
                assert!(
                    d["not_computed"][key].is_string(),
                    "{}: `{key}` has no reason",
                    d["label"]
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 29, part 4: hostile command lines for the hopper's `sim` and for `eval --impact`
/// and `--derivatives`, as a table: each is refused with exit code 2 and one line that
/// says what and where, and writes nothing.
#[test]
fn hostile_command_lines_for_the_hopper_and_eval() {
    let dir = temp_dir("hostile");
    let d = dir.to_str().unwrap();
    let q = "0.3,-0.7,-1.25,-2.43,1.25";
    let esc = "a\u{1b}[31mb";
    let rows: &[(&[&str], &str)] = &[
        (
            &["sim", "minitaur_hopper", "--apex", "1e308", "--out", d],
            "invalid value '1e308' for '--apex <H>'",
        ),
        (
            &["sim", "minitaur_hopper", "--apex", "nan", "--out", d],
            "invalid value 'nan' for '--apex <H>'",
        ),
        (
            &["sim", "minitaur_hopper", "--dt", "0", "--out", d],
            "expected a step in (0, 0.05] s",
        ),
        // A tiny step was echoed with 300 digits.
        (
            &["sim", "minitaur_hopper", "--dt", "1e-300", "--out", d],
            "3 s at dt = 1e-300 s is more than 5 million steps",
        ),
        (
            &["sim", "minitaur_hopper", "--duration", "inf", "--out", d],
            "expected a duration in (0, 600] s",
        ),
        (
            &["sim", "minitaur_hopper", "--torque-limit", "-1", "--out", d],
            "invalid value '-1' for '--torque-limit <N>'",
        ),
        (
            &[
                "sim",
                "minitaur_hopper",
                "--torque-limit",
                "nan",
                "--out",
                d,
            ],
            "expected a positive number of N m",
        ),
        (
            &["sim", "atrias_hopper", "--speed", "1e308", "--out", d],
            "expected a speed of at most 1000",
        ),
        (
            &["sim", "minitaur_hopper", "--trajectory", "spin", "--out", d],
            "`spin` is for legs in the air",
        ),
        (
            &[
                "sim",
                "minitaur_hopper",
                "--controller",
                "passive",
                "--apex",
                "0.4",
                "--out",
                d,
            ],
            "--apex sets the hopping controller's apex height",
        ),
        (
            &["sim", "minitaur_hopper", "--out", esc],
            "holds a control character",
        ),
        // Settings that mean nothing for the leg were ignored without a word (the new user's trial).
        (
            &["sim", "minitaur", "--apex", "0.3", "--out", d],
            "--apex is the hopping controller's apex height; minitaur has no contacts",
        ),
        (
            &[
                "sim",
                "minitaur",
                "--controller",
                "foot-fl",
                "--speed",
                "5",
                "--out",
                d,
            ],
            "--speed sets the spin trajectory's motor speed; the `step` trajectory has none",
        ),
        (
            &[
                "sim",
                "minitaur",
                "--controller",
                "passive",
                "--kp",
                "100",
                "--out",
                d,
            ],
            "--kp sets a controller's stiffness; with --controller passive there is none",
        ),
        // A record over the budget was refused only when the run began, leaving empty files.
        (
            &[
                "sim",
                "minitaur",
                "--duration",
                "600",
                "--dt",
                "0.00013",
                "--every",
                "10",
                "--out",
                d,
            ],
            "more than the budget of 512 MiB",
        ),
        (
            &[
                "sim",
                "minitaur_hopper",
                "--duration",
                "600",
                "--dt",
                "0.00013",
                "--every",
                "10",
                "--out",
                d,
            ],
            "more than the budget of 512 MiB",
        ),
        // A trajectory.csv of a gigabyte was written without a word (the new user's trial).
        (
            &[
                "sim",
                "minitaur",
                "--duration",
                "500",
                "--dt",
                "1e-4",
                "--out",
                d,
            ],
            "writes 5000002 rows to trajectory.csv, more than the file's limit of 1000000: pass --every 6 or more",
        ),
        (
            &["sim", "minitaur", "--every", "0", "--out", d],
            "invalid value '0' for '--every <N>'",
        ),
        // A gain of 1e308 was taken, and the run failed at t = 0 with an empty summary.
        (
            &["sim", "minitaur", "--kp", "1e308", "--out", d],
            "expected a positive stiffness of at most 1e9 1/s²",
        ),
        (
            &["eval", "minitaur_hopper", "--q", q, "--impact"],
            "a value is required for '--impact <CONTACT>'",
        ),
        (
            &[
                "eval",
                "minitaur_hopper",
                "--q",
                q,
                "--impact",
                "toe_contact",
                "--impact",
                "toe_contact",
            ],
            "cannot be used multiple times",
        ),
        (
            &["eval", "minitaur", "--q", "0,0,0,0", "--impact", "toe"],
            "minitaur has no contact points",
        ),
        (
            &["eval", "minitaur_hopper", "--q", q, "--impact", esc],
            "holds a control character",
        ),
        (
            &[
                "eval",
                "minitaur_hopper",
                "--q",
                q,
                "--impact",
                "heel\u{2028}x",
            ],
            "holds a control character",
        ),
        (
            &[
                "eval",
                "minitaur_hopper",
                "--q",
                q,
                "--derivatives",
                "--qd",
                "1e400,0,0,0,0",
            ],
            "`--qd 1e400,0,0,0,0`: every value must be finite",
        ),
        (
            &[
                "eval",
                "minitaur_hopper",
                "--q",
                "0.3,-0.7,-1.25,-2.43,1.25,1",
                "--derivatives",
            ],
            "`--q` has 6 values, expected 5",
        ),
        (
            &[
                "eval",
                "minitaur_hopper",
                "--q",
                q,
                "--u",
                "1,2,3",
                "--derivatives",
            ],
            "`--u` has 3 values, expected 2",
        ),
        (
            &["eval", "minitaur_hopper", "--q", q, "--derivatives=yes"],
            "unexpected value 'yes' for '--derivatives'",
        ),
        (
            &[
                "eval",
                "minitaur_hopper",
                "--q",
                q,
                "--impact",
                "toe_contact",
                "--assemble",
            ],
            "`--q` has 5 values, expected 2 (actuated angles with --assemble)",
        ),
        (
            &[
                "eval",
                "minitaur_hopper",
                "--q",
                q,
                "--impact",
                "toe_contact",
                "--u",
                "nan,0",
            ],
            "`--u nan,0`: every value must be finite",
        ),
    ];
    for (args, says) in rows {
        let out = legs(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.starts_with("error: ") && err.trim_end().lines().count() == 1 && err.len() < 400,
            "{args:?}: not one short line: {err}"
        );
        assert!(
            err.contains(says),
            "{args:?}: `{}` should say `{says}`",
            err.trim_end()
        );
        assert!(out.stdout.is_empty(), "{args:?}");
    }
    assert!(!dir.exists(), "hostile input left {}", dir.display());
    eprintln!("{} hostile command lines refused", rows.len());
}

/// A spatial leg in `eval` (every coordinate, three per ball joint) and the MJCF export;
/// what applies to planar legs only is refused by name.
#[test]
fn eval_and_export_take_a_spatial_leg() {
    let out = legs(&[
        "eval",
        "rssr_linkage",
        "--q",
        "0.3,-0.0135,0.3281,0.0348,0.1693",
        "--project",
        "--json",
        "--derivatives",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["ball_joints"], serde_json::json!([1]));
    assert_eq!(v["joints"][1], "coupler.x");
    assert_eq!(v["M"].as_array().unwrap().len(), 5);
    assert_eq!(v["dqdd_dq"].as_array().unwrap().len(), 5);
    let phi: Vec<f64> = serde_json::from_value(v["phi"].clone()).unwrap();
    assert!(phi.iter().all(|x| x.abs() < 1e-12), "{phi:?}");
    refused(
        &legs(&["eval", "rssr_linkage", "--q", "0.3", "--assemble"]),
        "--assemble: rssr_linkage is a spatial leg",
    );
    refused(&legs(&["eval", "rssr_linkage", "--q", "0.3,0,0"]), "--q");
    let out = xtask(&["export", "rssr_linkage", "--format", "mjcf"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("type=\"ball\"") && text.contains("<connect"),
        "{text}"
    );
    // URDF: a ball joint as three continuous joints named for its angles.
    let out = xtask(&["export", "rssr_linkage", "--format", "urdf"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for joint in ["coupler.x", "coupler.y", "coupler.z"] {
        assert!(
            text.contains(&format!("<joint name=\"{joint}\" type=\"continuous\">")),
            "{joint}: {text}"
        );
    }
}

/// `sim` on spatial legs: foot-space control of a foot with three coordinates where three
/// motors determine the leg, joint space with the reason where they do not; the outputs
/// carry the third coordinate and the report draws the leg in 3-D.
#[test]
fn sim_takes_a_spatial_leg() {
    let dir = temp_dir("sim-spatial");
    let out = legs(&[
        "sim",
        "abducted_five_bar",
        "--duration",
        "0.3",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = dir.clone();
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["controller"], "foot-fl");
    assert!(summary["max_closure_residual_m"].as_f64().unwrap() < 1e-12);
    // The loop's force rows and the foot in x, y and z.
    let csv = std::fs::read_to_string(run.join("trajectory.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    for column in ["F_0_z", "foot_z", "ref_z", "q_abduction"] {
        assert!(header.split(',').any(|c| c == column), "{column}: {header}");
    }
    let html = std::fs::read_to_string(run.join("report.html")).unwrap();
    assert!(html.contains("drag it to turn the view"));
    assert!(html.contains("a brown square of its plane"));
    // One motor cannot place a foot in space: joint space, saying why.
    let out = legs(&[
        "sim",
        "rssr_linkage",
        "--duration",
        "0.1",
        "--out",
        dir.join("rssr").to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("rssr/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["controller"], "joint-fl");
    assert!(
        summary["controller_choice"]
            .as_str()
            .unwrap()
            .contains("the foot has three coordinates but the leg has 1 motor"),
        "{}",
        summary["controller_choice"]
    );
    refused(
        &legs(&["sim", "rssr_linkage", "--controller", "foot-pd"]),
        "foot-space control needs at least three",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A CSV's rows as maps from the header's names to the cells.
fn csv_rows(text: &str) -> Vec<std::collections::HashMap<String, String>> {
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(str::to_string))
                .collect()
        })
        .collect()
}

/// `sim` of a spatial leg with contacts runs it on its ground under the swing-leg
/// controllers: the five-bar's step cycle dips 1 cm under the floor (5 mm under the toe at
/// home), so the toe lands, presses and lifts off again each cycle. Checked from the
/// written trajectory, not the summary's own figures: the toe never below the floor, the
/// normal force never pulling, the tangential force inside the cone |λ_t| ≤ μ λ_n while it
/// sticks and on it while it slides, the toe still while it sticks, the loop closed. A
/// block resting on the ground with its motors off stays put, pressed by its weight.
#[test]
fn sim_runs_a_spatial_leg_with_contacts_on_its_ground() {
    let dir = temp_dir("sim-ground");
    let out = legs(&[
        "sim",
        "abducted_five_bar",
        "--duration",
        "1",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["controller"], "foot-fl");
    assert!(
        summary["events"]["touchdowns"].as_u64().unwrap() >= 2,
        "{summary}"
    );
    assert!(
        summary["events"]["liftoffs"].as_u64().unwrap() >= 2,
        "{summary}"
    );
    let events = std::fs::read_to_string(dir.join("events.csv")).unwrap();
    assert!(events.contains(",Touchdown,toe_contact,"), "{events}");
    // One landing per 0.5 s cycle, answered by the controller: no liftoff at a landing's
    // instant (with the step's torques a braking controller pulled the toe off again).
    let listed = csv_rows(&events);
    let at = |kind: &str| -> Vec<f64> {
        listed
            .iter()
            .filter(|e| e["kind"] == kind)
            .map(|e| e["t"].parse().unwrap())
            .collect()
    };
    let (landings, liftoffs) = (at("Touchdown"), at("Liftoff"));
    assert_eq!(landings.len(), 2, "{events}");
    assert!(
        liftoffs
            .iter()
            .all(|l| landings.iter().all(|t| (l - t).abs() > 1e-6)),
        "{events}"
    );
    // A torque step at a step's start may push a contact out of its mode's bounds (a
    // stick out of the cone, a normal force below zero): the mode changes at that instant,
    // and the row before the change holds the old mode's forces (the run's own summary
    // leaves those rows out the same way).
    let switches: Vec<f64> = csv_rows(&events)
        .iter()
        .map(|e| e["t"].parse().unwrap())
        .collect();
    let rows: Vec<_> = csv_rows(&std::fs::read_to_string(dir.join("trajectory.csv")).unwrap())
        .into_iter()
        .filter(|r| {
            let t: f64 = r["t"].parse().unwrap();
            !switches.iter().any(|s| (s - t).abs() < 1e-9)
        })
        .collect();
    let v = |r: &std::collections::HashMap<String, String>, c: &str| -> f64 {
        r[c].parse().unwrap_or_else(|_| panic!("{c}: {}", r[c]))
    };
    // The spec: the floor 0.25 m under the hip along +z, μ 0.8; the foot is the toe.
    let (floor, mu) = (-0.25, 0.8);
    let mut stance = 0;
    let mut stuck_at: Option<(f64, f64)> = None;
    for r in &rows {
        assert!(v(r, "foot_z") >= floor - 1e-9, "toe under the floor: {r:?}");
        assert!(v(r, "closure_residual") < 1e-12);
        let mode = r["mode_toe_contact"].as_str();
        let (t1, t2, n) = (
            v(r, "lambda_t1_toe_contact"),
            v(r, "lambda_t2_toe_contact"),
            v(r, "lambda_n_toe_contact"),
        );
        match mode {
            "flight" => {
                assert_eq!((t1, t2, n), (0.0, 0.0, 0.0));
                stuck_at = None;
            }
            _ => {
                stance += 1;
                assert!(n >= -1e-9, "pulling on the ground: {r:?}");
                assert!((v(r, "foot_z") - floor).abs() < 1e-9, "{r:?}");
                let bound = mu * n;
                if mode == "slide" {
                    assert!(
                        (t1.hypot(t2) - bound).abs() <= 1e-9 * bound.max(1.0),
                        "{r:?}"
                    );
                    stuck_at = None;
                } else {
                    assert!(t1.hypot(t2) <= bound * (1.0 + 1e-9), "{r:?}");
                    let xy = (v(r, "foot_x"), v(r, "foot_y"));
                    if let Some(at) = stuck_at {
                        assert!((xy.0 - at.0).hypot(xy.1 - at.1) < 1e-9, "{r:?}");
                    }
                    stuck_at = Some(xy);
                }
            }
        }
    }
    assert!(stance > 100, "{stance} rows in stance");
    // While it slides, friction opposes the slip: against the toe's displacement to the
    // next row (both sliding, no event between), in whatever direction it slides. The
    // force opposes the velocity at the row; the displacement over 1 ms turns with it, by
    // up to 27° where the slip starts.
    let mut cosines = Vec::new();
    for w in rows.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if a["mode_toe_contact"] != "slide" || b["mode_toe_contact"] != "slide" {
            continue;
        }
        let (ta, tb): (f64, f64) = (a["t"].parse().unwrap(), b["t"].parse().unwrap());
        if switches.iter().any(|s| *s > ta - 1e-9 && *s < tb + 1e-9) {
            continue;
        }
        let step = (
            v(b, "foot_x") - v(a, "foot_x"),
            v(b, "foot_y") - v(a, "foot_y"),
        );
        let force = (v(a, "lambda_t1_toe_contact"), v(a, "lambda_t2_toe_contact"));
        let cos =
            (step.0 * force.0 + step.1 * force.1) / (step.0.hypot(step.1) * force.0.hypot(force.1));
        assert!(
            cos < -0.5,
            "friction not against the slip at {ta}: cos {cos}"
        );
        cosines.push(cos);
    }
    let aligned = cosines.iter().filter(|c| **c < -0.99).count();
    assert!(
        cosines.len() > 10 && aligned * 10 >= cosines.len() * 9,
        "{aligned} of {} sliding steps with friction within 8° of against the slip",
        cosines.len()
    );
    assert!(summary["max_friction_cone_ratio"].as_f64().unwrap() <= 1.0 + 1e-9);
    assert!(summary["max_contact_residual_m"].as_f64().unwrap() < 1e-12);

    // At rest on the ground, motors off: it stays, its weight on the ground.
    let rest = dir.join("rest");
    let out = legs(&[
        "sim",
        "sliding_mass",
        "--controller",
        "passive",
        "--duration",
        "0.2",
        "--out",
        rest.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows = csv_rows(&std::fs::read_to_string(rest.join("trajectory.csv")).unwrap());
    for r in &rows {
        assert_eq!(r["mode_bottom"], "stick");
        // The block's 2 kg under 9.81 m/s².
        assert!((v(r, "lambda_n_bottom") - 2.0 * 9.81).abs() < 1e-9, "{r:?}");
        assert!(v(r, "lambda_t1_bottom").abs() < 1e-9 && v(r, "lambda_t2_bottom").abs() < 1e-9);
        assert!(v(r, "q_slide_x").abs() < 1e-12 && v(r, "q_block").abs() < 1e-12);
    }
    // The hopping controller's flag means nothing here: refused, with the reason.
    refused(
        &legs(&["sim", "sliding_mass", "--apex", "0.3"]),
        "has no body that hops",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `import`: a spec from an MJCF file; bad input is one line, exit 2, and nothing written.
#[test]
fn import_writes_a_spec_gen_takes_and_refuses_bad_input() {
    let dir = temp_dir("import");
    std::fs::create_dir_all(&dir).unwrap();
    let root = xtask::gen::workspace_root();
    let source = root.join("leg-models/mjcf/achilles_leg.xml");
    let out_spec = dir.join("leg.toml");
    let (src, spec) = (source.to_str().unwrap(), out_spec.to_str().unwrap());
    let base = [
        "import",
        src,
        "--name",
        "leg",
        "--fix-base",
        "--root",
        "hip-roll",
        "--foot",
        "foot",
        "--out",
        spec,
    ];
    let out = xtask(&base);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("8 links (10 coordinates), 2 closures, 4 motors"),
        "{stdout}"
    );
    assert!(stdout.contains("note: connect `tail_hip-roll`"), "{stdout}");
    let text = std::fs::read_to_string(&out_spec).unwrap();
    let parsed = xtask::gen::spec::Spec::parse(&out_spec, text).unwrap();
    assert!(xtask::gen::model::build(&parsed).is_ok());
    // Kept unless --force.
    refused(&xtask(&base), "exists already");
    let fresh = dir.join("other.toml");
    let other = fresh.to_str().unwrap();
    let with = |from: &str, to: &str| -> Vec<String> {
        base.iter()
            .map(|a| {
                if *a == spec {
                    other.to_string()
                } else {
                    a.to_string()
                }
            })
            .map(|a| if a == from { to.to_string() } else { a })
            .collect()
    };
    for (args, says) in [
        (
            with("leg", "Leg"),
            "--name: `Leg` is not a plain identifier",
        ),
        (with("hip-roll", "thigh"), "--root thigh: no body"),
        (with("foot", "heel"), "--foot heel: no body"),
        (with(src, "missing.xml"), "cannot read missing.xml"),
        (
            base.iter()
                .filter(|a| **a != "--fix-base")
                .map(|a| {
                    if *a == spec {
                        other.to_string()
                    } else {
                        a.to_string()
                    }
                })
                .collect(),
            "import one leg with --fix-base --root",
        ),
    ] {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(&xtask(&args), says);
        assert!(!fresh.exists(), "{args:?} wrote a spec");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `eval --impact` on a spatial leg: the 2 kg block of `sliding_mass` (μ 0.5) landing at
/// v = (1, 0.5, −0.3) m/s. Written out: the normal impulse m v_n = 0.6 N s stops the fall;
/// sticking would need m |v_t| = 2.24 N s > μ Λ_n = 0.3 N s, so it slides, friction μ Λ_n
/// against the slip: v_t keeps 1 − μ v_n / |v_t| of itself, along the same direction, and
/// the energy lost is ½ m (|v|² − |v_t⁺|²).
#[test]
fn eval_lands_a_spatial_contact() {
    let out = legs(&[
        "eval",
        "sliding_mass",
        "--q",
        "0,0,0",
        "--qd",
        "1,0.5,-0.3",
        "--impact",
        "bottom",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let impact = &v["impact"];
    assert_eq!(impact["mode_after"], "slide");
    let (m, mu, vt, vn) = (2.0, 0.5, (1.0f64, 0.5f64), 0.3);
    let speed = vt.0.hypot(vt.1);
    let keep = 1.0 - mu * vn / speed;
    let got = |key: &str, i: usize| impact[key][i].as_f64().unwrap();
    let close = |a: f64, b: f64| assert!((a - b).abs() < 1e-12, "{a} vs {b}: {impact}");
    close(got("qd_plus", 0), keep * vt.0);
    close(got("qd_plus", 1), keep * vt.1);
    close(got("qd_plus", 2), 0.0);
    close(got("impulses", 2), m * vn);
    // The ground's frame on level ground: t₁ = x, t₂ = y.
    close(got("impulses", 0), -mu * m * vn * vt.0 / speed);
    close(got("impulses", 1), -mu * m * vn * vt.1 / speed);
    close(got("slip_direction", 0), vt.0 / speed);
    close(got("slip_direction", 1), vt.1 / speed);
    let lost = 0.5 * m * (speed * speed + vn * vn - (keep * speed).powi(2));
    close(impact["energy_lost"].as_f64().unwrap(), lost);
    let contact = &v["contacts"][0];
    assert_eq!(contact["name"], "bottom");
    assert_eq!(contact["gap"].as_f64().unwrap(), 0.0);
    assert_eq!(contact["tangential"].as_array().unwrap().len(), 2);
}

/// `eval` of a spatial leg says what `--q` holds (a ball joint's three angles named where
/// the leg has one) and why `--assemble` does not apply; `--impact` names a contact the
/// leg has.
#[test]
fn eval_of_a_spatial_leg_says_what_it_takes() {
    refused(
        &legs(&["eval", "cassie_leg", "--q", "0.1"]),
        "expected 13 (joint values, one per joint and three angles for the ball joint `left_achilles_rod`)",
    );
    let out = legs(&["eval", "abducted_five_bar", "--q", "0.1"]);
    refused(&out, "expected 5 (joint values, one per joint)");
    assert!(!String::from_utf8_lossy(&out.stderr).contains("ball"));
    let q = ["0.1"; 13].join(",");
    refused(
        &legs(&["eval", "cassie_leg", "--q", &q, "--impact", "foot"]),
        "--impact foot: cassie_leg has no contact points",
    );
    refused(
        &legs(&["eval", "sliding_mass", "--q", "0,0,0", "--impact", "toe"]),
        "--impact: unknown contact `toe` (contacts of sliding_mass: bottom)",
    );
    refused(
        &legs(&["eval", "cassie_leg", "--q", &q, "--assemble"]),
        "--assemble: cassie_leg is a spatial leg; its assembly from the motors' angles is planar only for now",
    );
}

/// `sim ROBOT --feet free`: pushed harder than held feet can take (the held run of this
/// push stops where a foot would slip or lift), the quadruped's feet lift, slip and land
/// and the run goes to its end. Checked from the written trajectory and the spec's own
/// numbers: at rest every foot sticks and the feet carry the weight; in every row each
/// foot's force is in its friction cone and pushes, a foot in flight has none, the loops
/// stay closed; some foot leaves the ground and some slides; the default step is 0.5 ms.
/// `--feet` on a leg, and an unknown kind of feet, are refused.
#[test]
fn sim_lets_a_robots_feet_lift_slip_and_land() {
    use generated::MinitaurQuadruped as Q;
    use leg_models::Parameters;
    let d = temp_dir("robot-free");
    let out = legs(&[
        "sim",
        "minitaur_quadruped",
        "--feet",
        "free",
        "--duration",
        "1",
        "--push",
        "0,60,0",
        "--out",
        d.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let p = <Q as LegDynamics<22, 12, 8>>::Params::<f64>::default();
    let names = <<Q as LegDynamics<22, 12, 8>>::Params<f64> as Parameters<f64>>::NAMES;
    let mass: f64 = (0..names.len())
        .filter(|&i| names[i].ends_with("_mass"))
        .map(|i| p.get(i).unwrap())
        .sum();
    let mu = leg_models::dynamics::contact::spec_friction::<Q, f64, 22, 12, 8, 12, 3>();
    let rows = csv_rows(&std::fs::read_to_string(d.join("trajectory.csv")).unwrap());
    assert_eq!(rows.len(), 2000, "1 s at the default 0.5 ms");
    let num = |r: &std::collections::HashMap<String, String>, c: &str| -> f64 {
        r.get(c)
            .unwrap_or_else(|| panic!("no column {c}"))
            .parse()
            .unwrap()
    };
    let contacts = <Q as leg_models::ContactModel<22, 12, 8, 12, 3>>::CONTACT_NAMES;
    let (mut flight, mut slide) = (0, 0);
    for r in &rows {
        let t = num(r, "t");
        let mut carried = 0.0;
        for (k, c) in contacts.iter().enumerate() {
            let (fx, fy, fz) = (
                num(r, &format!("F_{c}_x")),
                num(r, &format!("F_{c}_y")),
                num(r, &format!("F_{c}_z")),
            );
            carried += fz;
            let mode = r[&format!("mode_{c}")].as_str();
            match mode {
                "flight" => {
                    flight += 1;
                    assert!(
                        fx.abs().max(fy.abs()).max(fz.abs()) < 1e-9,
                        "t = {t}: {c} in flight with a force"
                    );
                }
                "stick" | "slide" => {
                    slide += usize::from(mode == "slide");
                    assert!(
                        fz > 0.0,
                        "t = {t}: {c} on the ground without a push ({fz} N)"
                    );
                    assert!(
                        fx.hypot(fy) <= mu[3 * k + 2] * fz * (1.0 + 1e-9),
                        "t = {t}: {c} outside its cone"
                    );
                }
                other => panic!("t = {t}: {c}: mode {other:?}"),
            }
            if t < 0.5 {
                assert_eq!(mode, "stick", "t = {t}: {c} before the push");
            }
        }
        if t < 0.5 {
            assert!(
                (carried - mass * 9.81).abs() < 1e-4 * mass * 9.81,
                "t = {t}: the feet carry {carried} N of the weight {} N",
                mass * 9.81
            );
        }
        assert!(num(r, "closure_residual") < 1e-12, "t = {t}");
    }
    assert!(
        flight > 0 && slide > 0,
        "no foot left the ground ({flight}) or slid ({slide})"
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["feet_free"], true);
    assert_eq!(summary["dt_s"].as_f64(), Some(5e-4));
    assert!(summary["stopped"].is_null());
    let in_flight: u64 = summary["feet"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["steps_in_flight"].as_u64().unwrap())
        .sum();
    assert_eq!(in_flight as usize, flight);
    refused(
        &legs(&["sim", "minitaur", "--feet", "free"]),
        "is a leg on a fixed base",
    );
    refused(
        &legs(&["sim", "minitaur_quadruped", "--feet", "loose"]),
        "free",
    );
    let _ = std::fs::remove_dir_all(d);
}

/// `sim` of a floating robot stands it under the balance QP and pushes its body. Checked
/// from the written trajectory and the spec's own numbers, not the summary's figures: at
/// rest the ground forces carry the weight (the spec's link masses); every foot's force
/// pushes and stays in its friction cone (the spec's μ) in every row; the push is in the
/// rows of its window only; the loops stay closed and the feet on the ground; the body's
/// quaternion stays unit and the body comes back where it stood. A push too strong for
/// held feet stops the run where a foot would slip or lift, keeping what it computed; the
/// flags of a leg's run and a malformed push are refused, a robot that cannot stand says
/// why.
#[test]
fn sim_stands_a_floating_robot_and_pushes_it() {
    use generated::MinitaurQuadruped as Q;
    use leg_models::Parameters;
    let d = temp_dir("robot");
    let out = legs(&[
        "sim",
        "minitaur_quadruped",
        "--duration",
        "1.5",
        "--push",
        "0,8,0",
        "--out",
        d.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let p = <Q as LegDynamics<22, 12, 8>>::Params::<f64>::default();
    let names = <<Q as LegDynamics<22, 12, 8>>::Params<f64> as Parameters<f64>>::NAMES;
    let mass: f64 = (0..names.len())
        .filter(|&i| names[i].ends_with("_mass"))
        .map(|i| p.get(i).unwrap())
        .sum();
    let mu = leg_models::dynamics::contact::spec_friction::<Q, f64, 22, 12, 8, 12, 3>();
    let rows = csv_rows(&std::fs::read_to_string(d.join("trajectory.csv")).unwrap());
    assert_eq!(rows.len(), 1500);
    let num = |r: &std::collections::HashMap<String, String>, c: &str| -> f64 {
        r.get(c)
            .unwrap_or_else(|| panic!("no column {c}"))
            .parse()
            .unwrap()
    };
    let contacts = <Q as leg_models::ContactModel<22, 12, 8, 12, 3>>::CONTACT_NAMES;
    assert_eq!(contacts.len(), 4);
    let first = &rows[0];
    let carried: f64 = contacts
        .iter()
        .map(|c| num(first, &format!("F_{c}_z")))
        .sum();
    assert!(
        (carried - mass * 9.81).abs() < 1e-9 * mass * 9.81,
        "at rest the feet carry {carried} N, the weight is {} N",
        mass * 9.81
    );
    for r in &rows {
        let t = num(r, "t");
        for (k, c) in contacts.iter().enumerate() {
            let (fx, fy, fz) = (
                num(r, &format!("F_{c}_x")),
                num(r, &format!("F_{c}_y")),
                num(r, &format!("F_{c}_z")),
            );
            // The ground is the world's z = 0 plane.
            assert!(fz > 0.0, "t = {t}: {c} pulls ({fz} N)");
            assert!(
                fx.hypot(fy) <= mu[3 * k + 2] * fz,
                "t = {t}: {c} outside its cone"
            );
        }
        assert!([0.0, 8.0].contains(&num(r, "push_y")), "t = {t}");
        assert_eq!(num(r, "push_x"), 0.0);
        assert!(num(r, "closure_residual") < 1e-12, "t = {t}");
        assert!(num(r, "contact_height") < 1e-12, "t = {t}");
        let quaternion = ["w", "x", "y", "z"]
            .iter()
            .map(|a| num(r, &format!("body_q{a}")).powi(2))
            .sum::<f64>();
        assert!((quaternion - 1.0).abs() < 1e-12, "t = {t}");
    }
    // 0.1 s at 1 ms from 0.5 s: a hundred rows, the first at 0.5 s.
    let pushed: Vec<f64> = rows
        .iter()
        .filter(|r| num(r, "push_y") != 0.0)
        .map(|r| num(r, "t"))
        .collect();
    assert_eq!(pushed.len(), 100);
    assert!((pushed[0] - 0.5).abs() < 1e-9 && (pushed[99] - 0.599).abs() < 1e-9);
    let last = rows.last().unwrap();
    let moved: Vec<f64> = ["x", "y", "z"]
        .iter()
        .map(|a| num(last, &format!("body_{a}")) - num(first, &format!("body_{a}")))
        .collect();
    let during = rows
        .iter()
        .map(|r| (num(r, "body_y") - num(first, "body_y")).abs())
        .fold(0.0, f64::max);
    assert!(during > 1e-4, "the push moved the body only {during} m");
    assert!(moved.iter().all(|m| m.abs() < 1e-3), "not back: {moved:?}");
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["recovered"], true);
    assert!(std::fs::read_to_string(d.join("report.html"))
        .unwrap()
        .contains("standing under the balance QP"));

    // Too strong for held feet: stopped where a foot would slip or lift, its rows kept.
    let strong = temp_dir("robot-strong");
    let out = legs(&[
        "sim",
        "minitaur_quadruped",
        "--duration",
        "1",
        "--push",
        "0,80,0",
        "--out",
        strong.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("would slip") || err.contains("would lift off"),
        "{err}"
    );
    let kept = csv_rows(&std::fs::read_to_string(strong.join("trajectory.csv")).unwrap());
    let end = num(kept.last().unwrap(), "t");
    assert!((0.5..0.99).contains(&end), "stopped at {end}");
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(strong.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["stopped"]["t_s"].as_f64(), Some(end));
    assert_eq!(summary["recovered"], false);
    assert!(strong.join("report.html").exists());

    for (args, says) in [
        (vec!["--kp", "3"], "--kp is for a leg"),
        (vec!["--push", "1,2"], "expected 3"),
        (
            vec!["--push", "1,x,2"],
            "expected 3 comma-separated numbers",
        ),
        (vec!["--push-at", "-1"], "a time in [0, 600] s"),
        (vec!["--push-at", "4"], "not before the run's end"),
        (vec!["--push-for", "0.0001"], "shorter than one step"),
    ] {
        let mut a = vec!["sim", "minitaur_quadruped", "--out", "/nonexistent/never"];
        a.extend(args);
        refused(&legs(&a), says);
    }
    for flag in [["--push", "1,0,0"], ["--push-at", "0.2"]] {
        refused(
            &legs(&["sim", "minitaur", flag[0], flag[1]]),
            "is a leg on a fixed base",
        );
    }
    let arm = temp_dir("robot-arm");
    let out = legs(&["sim", "floating_arm", "--out", arm.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("fewer than three contact points"));
    assert!(!arm.exists());
    for dir in [d, strong] {
        let _ = std::fs::remove_dir_all(dir);
    }
}
