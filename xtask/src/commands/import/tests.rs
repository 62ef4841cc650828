//! The importer: names, the freshness of imported specs, and one located error for each
//! thing a spec cannot represent (a small MJCF each, changed in one place).

use std::path::{Path, PathBuf};

use super::*;

fn args(extra: &[&str]) -> ImportArgs {
    #[derive(clap::Parser)]
    struct Words {
        #[command(flatten)]
        args: ImportArgs,
    }
    use clap::Parser;
    Words::try_parse_from(
        ["import", "leg.xml", "--name", "leg", "--foot", "shin"]
            .into_iter()
            .chain(extra.iter().copied()),
    )
    .expect("arguments parse")
    .args
}

/// A small leg: a thigh on a hip hinge with a motor, a shin on a knee, a rod on a ball
/// joint closing to the shin.
const LEG: &str = r#"<mujoco model="small leg">
  <worldbody>
    <body name="thigh" pos="0 0 1">
      <inertial pos="0.1 0 0" mass="1" diaginertia="0.001 0.01 0.01"/>
      <joint name="hip" axis="0 1 0" armature="0.01"/>
      <body name="shin" pos="0.2 0 0">
        <inertial pos="0.1 0 0" mass="0.5" diaginertia="0.001 0.005 0.005"/>
        <joint name="knee" axis="0 1 0" ref="30"/>
      </body>
      <body name="rod" pos="0.02 0 0.03">
        <inertial pos="0.1 0 0" mass="0.1" diaginertia="1e-5 0.001 0.001"/>
        <joint name="rod" type="ball"/>
      </body>
    </body>
  </worldbody>
  <equality>
    <connect body1="rod" body2="shin" anchor="0.25 0 0"/>
  </equality>
  <actuator>
    <motor joint="hip" gear="10"/>
  </actuator>
</mujoco>"#;

fn import_leg(text: &str, extra: &[&str]) -> Result<String, String> {
    import_str(
        Path::new("leg.xml"),
        text,
        &args(extra),
        "cargo xtask import leg.xml",
    )
    .map(|(s, _)| s)
    .map_err(|e| e.to_string())
}

fn refused(text: &str, extra: &[&str], line: u32, words: &str) {
    match import_leg(text, extra) {
        Ok(_) => panic!("imported; expected an error saying {words}"),
        Err(e) => {
            assert!(
                e.contains(&format!("leg.xml:{line}:")) || line == 0,
                "{e}: not at line {line}"
            );
            assert!(e.contains(words), "{e}: does not say `{words}`");
        }
    }
}

#[test]
fn a_source_is_recorded_by_its_path_from_the_root() {
    let root = Path::new("/work/main");
    assert_eq!(
        relative_to(Path::new("/work/main/leg-models/mjcf/a.xml"), root).as_deref(),
        Some("leg-models/mjcf/a.xml")
    );
    assert_eq!(
        relative_to(
            Path::new("/work/mujoco_menagerie/agility_cassie/cassie.xml"),
            root
        )
        .as_deref(),
        Some("../mujoco_menagerie/agility_cassie/cassie.xml")
    );
    // Elsewhere on the machine: no path goes into the spec (its name alone does).
    assert_eq!(
        relative_to(Path::new("/home/me/Downloads/a.xml"), root),
        None
    );
    assert_eq!(relative_to(Path::new("/a.xml"), root), None);
    // Outside the repository is said, inside is not.
    assert!(outside_repository(
        root,
        &root.join("../mujoco_menagerie/c.xml")
    ));
    assert!(!outside_repository(
        root,
        &root.join("leg-models/mjcf/a.xml")
    ));
}

#[test]
fn names_become_identifiers_by_one_rule() {
    assert_eq!(identifier("left-hip-roll"), "left_hip_roll");
    assert_eq!(identifier("Knee.Joint 2"), "knee_joint_2");
    assert_eq!(identifier("2nd"), "n_2nd");
    assert_eq!(identifier("type"), "type_");
    assert_eq!(identifier("foot"), "foot");
}

#[test]
fn the_small_leg_imports_and_its_ref_becomes_home() {
    let spec = import_leg(LEG, &[]).unwrap();
    assert!(spec.contains("name = \"knee\""), "{spec}");
    assert!(spec.contains("joint = \"ball\""));
    // The knee's ref (30°) is its home value; the ball's angles start at zero.
    assert!(
        spec.contains(&format!(
            "home = [0.0, {:?}, 0.0, 0.0, 0.0]",
            30f64.to_radians()
        )),
        "{spec}"
    );
    // armature / gear² is the rotor inertia.
    assert!(
        spec.contains("rotor_inertia = 0.0001, gear_ratio = 10.0"),
        "{spec}"
    );
}

#[test]
fn what_a_spec_cannot_represent_is_a_located_error() {
    let cases: &[(&str, &str, i32, &str)] = &[
        (
            "</worldbody>",
            "</worldbody><tendon><fixed name=\"t\"><joint joint=\"hip\" coef=\"1\"/></fixed></tendon>",
            0,
            "tendons are not imported",
        ),
        (
            "<connect body1=\"rod\" body2=\"shin\" anchor=\"0.25 0 0\"/>",
            "<weld body1=\"rod\" body2=\"shin\"/>",
            0,
            "<weld> equalities are not representable",
        ),
        (
            "<joint name=\"knee\" axis=\"0 1 0\" ref=\"30\"/>",
            "<joint name=\"knee\" axis=\"0 1 0\"/><joint name=\"knee2\"/>",
            0,
            "has 2 joints",
        ),
        (
            "<joint name=\"knee\" axis=\"0 1 0\" ref=\"30\"/>",
            "<joint name=\"knee\" axis=\"0 1 0\" armature=\"0.1\"/>",
            0,
            "armature on a joint without a motor",
        ),
        (
            "<inertial pos=\"0.1 0 0\" mass=\"0.5\" diaginertia=\"0.001 0.005 0.005\"/>",
            "<geom type=\"capsule\" size=\"0.02\" fromto=\"0 0 0 0.2 0 0\"/>",
            -1,
            "has no <inertial>",
        ),
        (
            "<motor joint=\"hip\" gear=\"10\"/>",
            "<motor joint=\"rod\" gear=\"10\"/>",
            0,
            "a motor on a ball joint",
        ),
        (
            "<motor joint=\"hip\" gear=\"10\"/>",
            "<motor joint=\"hip\" gear=\"-10\"/>",
            0,
            "a gear ratio is positive",
        ),
        (
            "<motor joint=\"hip\" gear=\"10\"/>",
            "<position joint=\"hip\" kp=\"10\"/>",
            0,
            "<position> actuators are not representable",
        ),
        (
            "<motor joint=\"hip\" gear=\"10\"/>",
            "<motor joint=\"ankle\" gear=\"10\"/>",
            0,
            "no such joint",
        ),
        (
            "body2=\"shin\"",
            "body2=\"calf\"",
            0,
            "no such body",
        ),
        (
            "<body name=\"thigh\" pos=\"0 0 1\">",
            "<body name=\"thigh\" pos=\"0 0 1\" quat=\"0 0 0 0\">",
            0,
            "a zero quaternion",
        ),
        (
            "<body name=\"thigh\" pos=\"0 0 1\">",
            "<body name=\"thigh\" pos=\"0 0 x\">",
            0,
            "is not a finite number",
        ),
        (
            "<body name=\"thigh\" pos=\"0 0 1\">",
            "<body name=\"thigh\" pos=\"0 0 1\"><freejoint/>",
            0,
            "give --fix-base",
        ),
        (
            "<body name=\"thigh\" pos=\"0 0 1\">",
            "<frame/><body name=\"thigh\" pos=\"0 0 1\">",
            0,
            "<frame> is not read",
        ),
        (
            "<joint name=\"knee\" axis=\"0 1 0\" ref=\"30\"/>",
            "<joint name=\"Hip\" axis=\"0 1 0\"/>",
            0,
            "both become `hip`",
        ),
        ("<mujoco model", "<mujoco  model", 0, ""),
    ];
    for (from, to, offset, words) in cases {
        let at = LEG.find(from).expect("the case's text is in the leg");
        // The error's line: the changed line's, or the one before (the body of a geom).
        let line = (LEG[..at].matches('\n').count() as i32 + 1 + offset) as u32;
        let text = LEG.replacen(from, to, 1);
        if words.is_empty() {
            assert!(import_leg(&text, &[]).is_ok());
        } else {
            refused(&text, &[], line, words);
        }
    }
}

#[test]
fn command_line_errors_name_the_flag() {
    let bad: &[(&[&str], &str)] = &[
        (&["--root", "calf"], "--root calf: no body"),
        (&["--fix-base"], "--fix-base: leg.xml has no free joint"),
        (&["--keyframe", "stand"], "--keyframe stand: no key"),
        (&["--foot-point", "1,2"], "--foot-point"),
    ];
    for (extra, words) in bad {
        let e = import_leg(LEG, extra).expect_err("refused");
        assert!(e.contains(words), "{e}: does not say {words}");
    }
    let mut a = args(&[]);
    a.foot = "heel".into();
    let e = import_str(Path::new("leg.xml"), LEG, &a, "c")
        .unwrap_err()
        .to_string();
    assert!(e.contains("--foot heel: no body"), "{e}");
}

#[test]
fn imported_specs_are_what_importing_their_files_gives() {
    let root: PathBuf = crate::gen::workspace_root();
    let n = check_imported(&root).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        n >= 1,
        "no imported spec in leg-models/specs (achilles_leg is one)"
    );
}
