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
            "its body's only joint",
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

// URDF.

fn value(params: &[gen::model::Param], name: &str) -> f64 {
    params
        .iter()
        .find(|p| p.name == name)
        .expect("a parameter")
        .default
}

/// World poses at `q = 0` of a spatial model's links, `(joint point, rotation)`, as
/// derive_spatial.py places them: `p_i = p_parent + R_parent origin_i`, `R_i = R_parent O_i`.
fn world_frames(m: &gen::model::Model) -> Vec<(Vec3, Mat3)> {
    let v = |names: &[String]| -> Vec3 {
        let mut out = [0.0; 3];
        for (o, n) in out.iter_mut().zip(names) {
            *o = value(&m.params, n);
        }
        out
    };
    let mut out: Vec<(Vec3, Mat3)> = Vec::new();
    for l in &m.links {
        let o = l.orientation.unwrap_or(linalg::IDENTITY);
        let (p, r) = match l.parent {
            None => ([0.0; 3], linalg::IDENTITY),
            Some(k) => out[k],
        };
        out.push((
            linalg::add(p, linalg::mat_vec(&r, v(&l.origin))),
            linalg::mat_mul(&r, &o),
        ));
    }
    out
}

fn world_point(m: &gen::model::Model, frames: &[(Vec3, Mat3)], p: &gen::model::Point) -> Vec3 {
    let at: Vec3 = std::array::from_fn(|i| p.point.get(i).map_or(0.0, |n| value(&m.params, n)));
    match p.link {
        None => at,
        Some(k) => linalg::add(frames[k].0, linalg::mat_vec(&frames[k].1, at)),
    }
}

fn close(a: Vec3, b: Vec3, what: &str) {
    for i in 0..3 {
        assert!((a[i] - b[i]).abs() < 1e-12, "{what}: {a:?} against {b:?}");
    }
}

#[test]
fn a_urdf_export_imports_back_to_the_same_leg() {
    // abducted_five_bar written as URDF by our exporter (checked against Pinocchio in
    // `cargo xtask test`), read back with its loop named on the command line.
    let root = gen::workspace_root();
    let spec =
        gen::load_spec(&root, &root.join("leg-models/specs/abducted_five_bar.toml")).unwrap();
    let original = gen::model::build(&spec).unwrap();
    let urdf = crate::commands::export::spatial::urdf(&original);
    let mut a = args(&[
        "--closure",
        "toe=toe.a/toe.b:0,0,0",
        "--foot-point",
        "0.2,0,0",
    ]);
    a.foot = "lower_a".into();
    a.file = "leg.urdf".into();
    let (text, lines) = import_str(
        Path::new("leg.urdf"),
        &urdf,
        &a,
        "cargo xtask import leg.urdf",
    )
    .unwrap();
    assert!(
        lines[0].starts_with("5 links (5 coordinates), 1 closures, 3 motors"),
        "{lines:?}"
    );
    let imported =
        gen::model::build(&spec::Spec::parse(Path::new("leg.toml"), text.clone()).unwrap())
            .unwrap();
    assert_eq!(imported.links.len(), original.links.len(), "{text}");
    let (fo, fi) = (world_frames(&original), world_frames(&imported));
    for (k, (lo, li)) in original.links.iter().zip(&imported.links).enumerate() {
        assert_eq!(identifier(&lo.name), li.name);
        assert_eq!(lo.joint, li.joint);
        close(fo[k].0, fi[k].0, &format!("{}: joint point", lo.name));
        let axis = |l: &gen::model::Link, r: &Mat3| {
            linalg::mat_vec(r, std::array::from_fn(|i| l.axis.as_ref().unwrap()[i]))
        };
        close(
            axis(lo, &fo[k].1),
            axis(li, &fi[k].1),
            &format!("{}: axis", lo.name),
        );
        assert!(
            (value(&original.params, &lo.mass) - value(&imported.params, &li.mass)).abs() < 1e-15
        );
        let com = |m: &gen::model::Model, f: &[(Vec3, Mat3)], l: &gen::model::Link| {
            world_point(
                m,
                f,
                &gen::model::Point {
                    link: Some(k),
                    point: l.com.clone(),
                },
            )
        };
        close(
            com(&original, &fo, lo),
            com(&imported, &fi, li),
            &format!("{}: centre of mass", lo.name),
        );
        // Motors: the gear and the rotor inertia (Drake's tag in our export).
        let rotor = |m: &gen::model::Model, l: &gen::model::Link| {
            l.rotor
                .as_ref()
                .map(|[i, n]| (value(&m.params, i), value(&m.params, n)))
        };
        match (rotor(&original, lo), rotor(&imported, li)) {
            (None, None) => {}
            (Some(a), Some(b)) => assert!((a.0 - b.0).abs() < 1e-15 && a.1 == b.1, "{a:?} {b:?}"),
            (a, b) => panic!("{}: motor {a:?} against {b:?}", lo.name),
        }
    }
    // The loop's points are the same (the file's closure frames, `toe.b`'s origin named
    // on the command line: at q = 0 the loop is open), and the foot is the same point.
    let (c0, c1) = (&original.closures[0], &imported.closures[0]);
    close(
        world_point(&original, &fo, &c0.a),
        world_point(&imported, &fi, &c1.a),
        "closure a",
    );
    close(
        world_point(&original, &fo, &c0.b),
        world_point(&imported, &fi, &c1.b),
        "closure b",
    );
    close(
        world_point(&original, &fo, &original.foot),
        world_point(&imported, &fi, &imported.foot),
        "foot",
    );
    // The home pose of a URDF is every joint at 0, and its header says how it was made.
    assert!(
        text.starts_with("# Imported by `cargo xtask import leg.urdf"),
        "{text}"
    );
}

const URDF: &str = r#"<robot name="two">
  <link name="base"/>
  <link name="thigh">
    <inertial><origin xyz="0.1 0 0" rpy="0 0 1.5707963267948966"/><mass value="1"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.0105"/></inertial>
  </link>
  <joint name="hip" type="revolute">
    <parent link="base"/><child link="thigh"/>
    <origin xyz="0 0 1" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="10"/>
    <dynamics damping="0.1"/>
  </joint>
  <link name="shin"><inertial><mass value="0.5"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3"/></inertial></link>
  <joint name="knee" type="continuous">
    <parent link="thigh"/><child link="shin"/>
    <origin xyz="0.2 0 0"/><axis xyz="0 1 0"/>
  </joint>
  <transmission name="t"><joint name="hip"/><actuator name="m"><mechanicalReduction>10</mechanicalReduction></actuator></transmission>
</robot>"#;

fn import_urdf(text: &str, extra: &[&str]) -> Result<String, String> {
    let mut a = args(extra);
    a.file = "leg.urdf".into();
    import_str(
        Path::new("leg.urdf"),
        text,
        &a,
        "cargo xtask import leg.urdf",
    )
    .map(|(s, _)| s)
    .map_err(|e| e.to_string())
}

#[test]
fn a_urdf_gives_its_joints_limits_damping_inertias_and_transmissions() {
    let text = import_urdf(URDF, &["--motor", "knee:2"]).unwrap();
    let m = gen::model::build(&spec::Spec::parse(Path::new("leg.toml"), text.clone()).unwrap())
        .unwrap();
    assert_eq!(m.links.len(), 2);
    assert_eq!(m.actuated, [0, 1], "{text}");
    // The thigh's inertia, written in a frame turned 90° about z: xx and yy swap.
    let gen::model::Inertia::Spatial(i) = &m.links[0].inertia else {
        panic!()
    };
    let get = |k: usize| i[k].as_ref().map_or(0.0, |n| value(&m.params, n));
    assert!(
        (get(0) - 0.01).abs() < 1e-15
            && (get(1) - 0.001).abs() < 1e-15
            && (get(2) - 0.0105).abs() < 1e-15,
        "{text}"
    );
    assert!(text.contains("damping = 0.1"), "{text}");
    assert!(
        text.contains("gear_ratio = 10.0") && text.contains("gear_ratio = 2.0"),
        "{text}"
    );
}

#[test]
fn a_urdf_refuses_what_a_spec_cannot_hold_at_its_line() {
    let edit = |from: &str, to: &str| URDF.replacen(from, to, 1);
    let at = |text: &str, extra: &[&str], line: u32, words: &str| {
        let e = import_urdf(text, extra).unwrap_err();
        assert!(
            line == 0 || e.contains(&format!("leg.urdf:{line}:")),
            "{e}: not at line {line}"
        );
        assert!(e.contains(words), "{e}: does not say `{words}`");
    };
    at(
        &edit("type=\"continuous\"", "type=\"floating\""),
        &[],
        14,
        "floating",
    );
    at(
        &edit(
            "<dynamics damping=\"0.1\"/>",
            "<dynamics damping=\"0.1\" friction=\"0.5\"/>",
        ),
        &[],
        11,
        "friction",
    );
    at(
        &edit(
            "<axis xyz=\"0 1 0\"/>\n  </joint>",
            "<axis xyz=\"0 1 0\"/><mimic joint=\"hip\"/>\n  </joint>",
        ),
        &[],
        16,
        "mimic",
    );
    at(
        &edit("<child link=\"shin\"/>", "<child link=\"thigh\"/>"),
        &[],
        14,
        "carried by joint `hip` already",
    );
    at(
        URDF,
        &["--closure", "c=thigh/nowhere"],
        0,
        "no link `nowhere`",
    );
    at(URDF, &["--closure", "c=thigh"], 0, "not NAME=LINK_A");
    at(URDF, &["--motor", "hip"], 0, "has a motor already");
    at(
        URDF,
        &["--motor", "ankle"],
        0,
        "no revolute, continuous or prismatic joint `ankle`",
    );
    at(URDF, &["--fix-base"], 0, "root link is the base already");
    at(URDF, &["--keyframe", "home"], 0, "no keyframes");
    at(LEG, &["--closure", "c=a/b"], 0, "--closure is for URDF");
}

#[test]
fn a_urdf_inertia_written_in_a_turned_frame_is_turned_into_the_link_frame() {
    // A full tensor in the frame of <inertial><origin rpy>, against R I Rᵀ with R written
    // out here in closed form (URDF's rpy: R = R_z(yaw) R_y(pitch) R_x(roll)).
    let (r, p, y) = (0.3_f64, -0.4_f64, 0.7_f64);
    let local = [
        [0.005, 0.0003, -0.0002],
        [0.0003, 0.006, 0.0001],
        [-0.0002, 0.0001, 0.004],
    ];
    let text = URDF.replacen(
        r#"<origin xyz="0.1 0 0" rpy="0 0 1.5707963267948966"/><mass value="1"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.0105"/>"#,
        &format!(
            r#"<origin xyz="0.1 0 0" rpy="{r} {p} {y}"/><mass value="1"/>
      <inertia ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}"/>"#,
            local[0][0], local[0][1], local[0][2], local[1][1], local[1][2], local[2][2]
        ),
        1,
    );
    assert_ne!(text, URDF);
    let spec_text = import_urdf(&text, &[]).unwrap();
    let m =
        gen::model::build(&spec::Spec::parse(Path::new("leg.toml"), spec_text.clone()).unwrap())
            .unwrap();
    let (cr, sr, cp, sp, cy, sy) = (r.cos(), r.sin(), p.cos(), p.sin(), y.cos(), y.sin());
    let rot = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ];
    let expected = |i: usize, j: usize| {
        let mut s = 0.0;
        for a in 0..3 {
            for b in 0..3 {
                s += rot[i][a] * local[a][b] * rot[j][b];
            }
        }
        s
    };
    let gen::model::Inertia::Spatial(entries) = &m.links[0].inertia else {
        panic!("a spatial inertia")
    };
    let get = |k: usize| entries[k].as_ref().map_or(0.0, |n| value(&m.params, n));
    for (k, (i, j)) in [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
        .into_iter()
        .enumerate()
    {
        assert!(
            (get(k) - expected(i, j)).abs() < 1e-15,
            "I[{i}][{j}]: {} against {}\n{spec_text}",
            get(k),
            expected(i, j)
        );
    }
}

#[test]
fn a_urdf_link_the_tree_does_not_reach_is_refused() {
    // Two links that carry each other, apart from the tree.
    let text = URDF.replacen(
        "  <transmission",
        r#"  <link name="p"/><link name="r"/>
  <joint name="pr" type="fixed"><parent link="p"/><child link="r"/></joint>
  <joint name="rp" type="fixed"><parent link="r"/><child link="p"/></joint>
  <transmission"#,
        1,
    );
    let e = import_urdf(&text, &[]).unwrap_err();
    assert!(e.contains("is not reached from the root `base`"), "{e}");
}

/// A file whose top body floats, imported without --fix-base: that body is the spec's
/// first link on a free joint (no origin, orientation or motor), everything else hangs
/// from it, home starts with the chart's six zeros, gravity is the world's, and the
/// body's pose is said, not lost. The spec validates and builds.
#[test]
fn a_floating_file_imports_as_a_robot() {
    let floating = LEG.replace(
        "<worldbody>\n    <body name=\"thigh\" pos=\"0 0 1\">",
        "<worldbody>\n  <body name=\"pelvis\" pos=\"0 0 0.9\" quat=\"0.9950041652780258 0 0.09983341664682815 0\">\n    <freejoint/>\n    <inertial pos=\"0.01 0 0.02\" mass=\"5\" diaginertia=\"0.05 0.04 0.03\"/>\n    <body name=\"thigh\" pos=\"0 0 1\">",
    )
    .replace("  </worldbody>", "  </body>\n  </worldbody>");
    let spec = import_leg(&floating, &[]).unwrap();
    assert!(
        spec.contains("name = \"pelvis\"\nparent = \"base\"\njoint = \"free\"\nlength"),
        "{spec}"
    );
    assert!(
        spec.contains("`pelvis` floats: its pose (0.0, 0.0, 0.9, 0.995"),
        "{spec}"
    );
    assert!(spec.contains("gravity = [0.0, 0.0, -9.81]"), "{spec}");
    let parsed = gen::spec::Spec::parse(Path::new("leg-models/specs/leg.toml"), spec.clone())
        .unwrap_or_else(|e| panic!("{e}\n{spec}"));
    let m = gen::model::build(&parsed).unwrap();
    let names = m.joint_names();
    assert_eq!(
        names[..7],
        [
            "pelvis.tx",
            "pelvis.ty",
            "pelvis.tz",
            "pelvis.x",
            "pelvis.y",
            "pelvis.z",
            "hip"
        ]
    );
    assert_eq!(m.home[..6], [0.0; 6]);
    // The thigh hangs from the pelvis where the file puts it: 1 m up its frame.
    assert!(
        spec.contains("name = \"hip\"\nparent = \"pelvis\""),
        "{spec}"
    );
    // A floating file cut to one leg needs the body held.
    refused(
        &floating,
        &["--root", "thigh"],
        0,
        "import one leg with --fix-base --root",
    );
}
