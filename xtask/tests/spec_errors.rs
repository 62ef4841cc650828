//! Bad specs fail with the file, line, column and field; spec text never reaches
//! generated code; a failed generation writes nothing.

use std::path::{Path, PathBuf};

use xtask::gen::model;
use xtask::gen::spec::{Spec, SpecError};
use xtask::gen::{self, GenOptions};

const VALID: &str = r#"# a small five-bar
gravity = [0.0, -9.81]

[[links]]
name = "upper_a"
parent = "base"
length = [0.1, 0.0]
mass = 0.05
com = [0.05, 0.0]
inertia = 4e-5
actuator = { rotor_inertia = 0.0, gear_ratio = 1.0 }

[[links]]
name = "lower_a"
parent = "upper_a"
length = [0.2, 0.0]
mass = 0.05
com = [0.1, 0.0]
inertia = 1.6e-4

[[links]]
name = "upper_b"
parent = "base"
origin = [0.05, 0.0]
length = [0.1, 0.0]
mass = 0.05
com = [0.05, 0.0]
inertia = 4e-5
actuator = { rotor_inertia = 0.0, gear_ratio = 1.0 }

[[links]]
name = "lower_b"
parent = "upper_b"
length = [0.2, 0.0]
mass = 0.05
com = [0.1, 0.0]
inertia = 1.6e-4

[[closures]]
name = "toe"
a = { link = "lower_a" }
b = { link = "lower_b" }

[foot]
link = "lower_a"
"#;

fn parse(text: &str) -> Result<Spec, SpecError> {
    Spec::parse(Path::new("leg-models/specs/leg.toml"), text.to_string())
}

/// Replaces the `nth` (0-based) occurrence of `from` in the valid spec.
fn edit(from: &str, to: &str, nth: usize) -> String {
    let (i, _) = VALID
        .match_indices(from)
        .nth(nth)
        .unwrap_or_else(|| panic!("`{from}` #{nth} not in spec"));
    format!("{}{}{}", &VALID[..i], to, &VALID[i + from.len()..])
}

/// 1-based line and column of the `nth` occurrence of `needle` in `text`.
fn pos(text: &str, needle: &str, nth: usize) -> (usize, usize) {
    let (i, _) = text.match_indices(needle).nth(nth).unwrap();
    xtask::gen::spec::line_column(text, i)
}

fn expect_error(text: &str, at: (usize, usize), field: &str, says: &str) {
    let e = parse(text).expect_err("spec should be refused");
    assert_eq!(e.file, PathBuf::from("leg-models/specs/leg.toml"));
    assert_eq!((e.line, e.column), at, "position of: {e}");
    assert_eq!(e.field, field, "field of: {e}");
    assert!(e.message.contains(says), "`{e}` should say `{says}`");
    let shown = e.to_string();
    assert!(
        shown.starts_with(&format!(
            "leg-models/specs/leg.toml:{}:{}: {field}: ",
            at.0, at.1
        )),
        "{shown}"
    );
}

#[test]
fn the_valid_spec_parses() {
    let spec = parse(VALID).unwrap();
    assert_eq!(spec.name, "leg");
    let m = model::build(&spec).unwrap();
    assert_eq!(m.actuated, vec![0, 2]);
    assert_eq!(m.links[2].origin, ["upper_b_origin_x", "upper_b_origin_y"]);
    // A child joint sits at its parent's tip unless the spec says otherwise.
    assert_eq!(m.links[1].origin, m.links[0].length);
    let p = m
        .params
        .iter()
        .find(|p| p.name == "upper_b_origin_x")
        .unwrap();
    assert_eq!(p.default, 0.05);
}

#[test]
fn syntax_error() {
    let text = edit("mass = 0.05", "mass = ", 1);
    let at = pos(&text, "mass = \n", 0);
    expect_error(&text, (at.0, at.1 + 7), "links[1].mass", "");
}

/// A missing `]` was blamed on the next key (`links[0].name`, a line below): the error
/// points at the array left open.
#[test]
fn unclosed_array() {
    let text = edit("length = [0.2, 0.0]", "length = [0.2, 0.0 # no bracket", 0);
    let at = pos(&text, "[0.2, 0.0 #", 0);
    expect_error(
        &text,
        at,
        "links[1].length",
        "this array is not closed: a `]` is missing",
    );
}

#[test]
fn unknown_parent() {
    let text = edit("parent = \"upper_a\"", "parent = \"uper_a\"", 0);
    let (l, c) = pos(&text, "\"uper_a\"", 0);
    expect_error(&text, (l, c), "links[1].parent", "unknown parent `uper_a`");
}

#[test]
fn parent_defined_below() {
    let text = edit("parent = \"upper_a\"", "parent = \"lower_b\"", 0);
    let (l, c) = pos(&text, "\"lower_b\"", 0);
    expect_error(&text, (l, c), "links[1].parent", "defined below");
}

#[test]
fn missing_field() {
    let text = edit("mass = 0.05\n", "", 2);
    let e = parse(&text).unwrap_err();
    assert!(e.message.contains("missing field `mass`"), "{e}");
    assert_eq!(e.field, "links[2].mass", "{e}");
    // The error points into the third link's table.
    let third = pos(&text, "name = \"upper_b\"", 0).0;
    assert!(e.line >= third - 1 && e.line <= third + 6, "{e}");
}

#[test]
fn negative_mass() {
    let text = edit("mass = 0.05", "mass = -0.05", 3);
    let (l, c) = pos(&text, "-0.05", 0);
    expect_error(
        &text,
        (l, c),
        "links[3].mass",
        "must not be negative, got -0.05",
    );
}

#[test]
fn negative_mass_with_a_source_note() {
    let text = edit(
        "mass = 0.05",
        "mass = { value = -1.0, source = \"a datasheet\" }",
        0,
    );
    let (l, c) = pos(&text, "{ value = -1.0", 0);
    expect_error(&text, (l, c), "links[0].mass", "must not be negative");
}

#[test]
fn zero_gear_ratio() {
    let text = edit("gear_ratio = 1.0", "gear_ratio = 0", 1);
    let (l, c) = pos(&text, "gear_ratio = 0 }", 0);
    expect_error(
        &text,
        (l, c + 13),
        "links[2].actuator.gear_ratio",
        "must be positive",
    );
}

#[test]
fn closure_naming_a_missing_link() {
    let text = edit(
        "b = { link = \"lower_b\" }",
        "b = { link = \"lower_c\" }",
        0,
    );
    let (l, c) = pos(&text, "\"lower_c\"", 0);
    expect_error(
        &text,
        (l, c),
        "closures[0].b.link",
        "unknown link `lower_c`",
    );
}

#[test]
fn closure_on_one_link() {
    let text = edit(
        "b = { link = \"lower_b\" }",
        "b = { link = \"lower_a\" }",
        0,
    );
    let (l, c) = pos(&text, "\"lower_a\" }", 1);
    expect_error(&text, (l, c), "closures[0].b.link", "two different links");
}

#[test]
fn foot_on_a_missing_link() {
    let text = edit("link = \"lower_a\"\n", "link = \"shin\"\n", 0);
    let (l, c) = pos(&text, "\"shin\"", 0);
    expect_error(&text, (l, c), "foot.link", "unknown link `shin`");
}

#[test]
fn names_that_are_not_plain_identifiers() {
    for bad in [
        "Upper-A",
        "upper a",
        "fn",
        "1st",
        "_x",
        "ünter",
        "a\\\"; panic!(\\\"",
        "base",
    ] {
        let text = edit("name = \"upper_b\"", &format!("name = \"{bad}\""), 0);
        let (l, c) = pos(&text, "name = \"", 2);
        let e = parse(&text).expect_err(bad);
        assert_eq!((e.line, e.column), (l, c + 7), "{e}");
        assert_eq!(e.field, "links[2].name");
    }
}

#[test]
fn duplicate_names() {
    let text = edit("name = \"toe\"", "name = \"lower_b\"", 0);
    let (l, c) = pos(&text, "\"lower_b\"", 1);
    let (first, _) = pos(&text, "\"lower_b\"", 0);
    expect_error(
        &text,
        (l, c),
        "closures[0].name",
        &format!("duplicate name `lower_b` (first given as links[3].name, line {first})"),
    );
    let text = edit("name = \"lower_b\"", "name = \"lower_a\"", 0);
    let (l, c) = pos(&text, "\"lower_a\"", 1);
    expect_error(&text, (l, c), "links[3].name", "duplicate name `lower_a`");
}

#[test]
fn unknown_field_and_wrong_type() {
    let text = edit("inertia = 4e-5", "inertia = 4e-5\ninertai = 1.0", 0);
    let e = parse(&text).unwrap_err();
    assert!(e.message.contains("unknown field `inertai`"), "{e}");
    assert_eq!(e.field, "links[0].inertai", "{e}");
    assert_eq!(e.line, pos(&text, "inertai", 0).0);
    let text = edit("com = [0.1, 0.0]", "com = \"middle\"", 0);
    let (l, c) = pos(&text, "\"middle\"", 0);
    expect_error(&text, (l, c), "links[1].com", "a 2-vector");
    let text = edit("com = [0.1, 0.0]", "com = [0.1, 0.0, 0.3]", 0);
    let e = parse(&text).unwrap_err();
    assert_eq!(e.field, "links[1].com", "{e}");
}

#[test]
fn a_file_name_that_is_not_an_identifier() {
    let e = Spec::parse(Path::new("specs/Five-Bar.toml"), VALID.to_string()).unwrap_err();
    assert_eq!(e.field, "(file name)");
    assert!(e.message.contains("`Five-Bar`"));
}

#[test]
fn spec_text_never_reaches_what_is_generated() {
    let evil = "\\\"); } panic!(\\\"pwned\\\"); /*";
    let text = format!(
        "description = \"{evil}\"\n{}",
        edit(
            "mass = 0.05",
            &format!("mass = {{ value = 0.05, source = \"{evil}\" }}"),
            0
        )
    );
    let spec = parse(&text).unwrap();
    let m = model::build(&spec).unwrap();
    for p in &m.params {
        assert!(
            !p.doc.contains("pwned") && !p.name.contains("pwned"),
            "{p:?}"
        );
    }
    for l in &m.links {
        assert!(!l.name.contains("pwned"));
    }
}

/// A temporary workspace holding specs and generated files.
struct TempRoot(PathBuf);

impl TempRoot {
    fn new(tag: &str) -> TempRoot {
        let dir = std::env::temp_dir().join(format!("xtask-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for sub in [gen::SPECS_DIR, gen::IR_DIR, gen::SRC_DIR] {
            std::fs::create_dir_all(dir.join(sub)).unwrap();
        }
        TempRoot(dir)
    }

    fn write(&self, rel: &str, text: &str) {
        std::fs::write(self.0.join(rel), text).unwrap();
    }

    fn listing(&self) -> Vec<(PathBuf, String)> {
        let mut out = Vec::new();
        for sub in [gen::SPECS_DIR, gen::IR_DIR, gen::SRC_DIR] {
            let mut entries: Vec<_> = std::fs::read_dir(self.0.join(sub))
                .unwrap()
                .flatten()
                .map(|e| e.path())
                .collect();
            entries.sort();
            for p in entries {
                let text = std::fs::read_to_string(&p).unwrap();
                out.push((p, text));
            }
        }
        out
    }
}

impl Drop for TempRoot {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn a_failed_generation_leaves_every_file_untouched() {
    let root = TempRoot::new("failed-gen");
    root.write("leg-models/specs/good.toml", VALID);
    root.write(
        "leg-models/specs/bad.toml",
        &edit("mass = 0.05", "mass = -1.0", 0),
    );
    root.write("generated/ir/good.json", "committed IR");
    root.write("generated/src/good.rs", "// committed code");
    root.write("generated/src/lib.rs", "// committed lib");
    let before = root.listing();
    let err = gen::run(
        &root.0,
        &GenOptions {
            check: false,
            names: vec![],
        },
    )
    .unwrap_err();
    assert!(
        err.is_usage(),
        "bad input must be a usage error (exit 2): {err}"
    );
    let err = err.to_string();
    assert!(
        err.contains("leg-models/specs/bad.toml:") && err.contains("links[0].mass"),
        "{err}"
    );
    assert_eq!(root.listing(), before, "a failed generation changed files");
    // Unknown model names are refused before anything runs, too.
    let err = gen::run(
        &root.0,
        &GenOptions {
            check: false,
            names: vec!["nope".into()],
        },
    )
    .unwrap_err();
    assert!(
        err.is_usage(),
        "bad input must be a usage error (exit 2): {err}"
    );
    let err = err.to_string();
    assert!(
        err.contains("unknown model `nope`") && err.contains("good"),
        "{err}"
    );
    assert_eq!(root.listing(), before);
}

#[test]
fn home_pose_with_the_wrong_number_of_angles() {
    let text = edit(
        "gravity = [0.0, -9.81]\n",
        "gravity = [0.0, -9.81]\nhome = [0.1, 0.2, 0.3]\n",
        0,
    );
    let (l, c) = pos(&text, "[0.1, 0.2, 0.3]", 0);
    expect_error(&text, (l, c), "home", "lists 3 joint values for 4 links");
    let text = edit(
        "gravity = [0.0, -9.81]\n",
        "gravity = [0.0, -9.81]\nhome = [0.1, 0.2, 0.3, 0.4]\n",
        0,
    );
    let m = model::build(&parse(&text).unwrap()).unwrap();
    assert_eq!(m.home, vec![0.1, 0.2, 0.3, 0.4]);
    assert_eq!(
        model::build(&parse(VALID).unwrap()).unwrap().home,
        vec![0.0; 4]
    );
}

/// No name a user may choose is reserved by the exports (issue 30): a link named `foot`,
/// a link named like a closure point's frame (`toe_a`) and a contact named like a frame's
/// joint build, and the exports' names stay distinct within each kind.
#[test]
fn names_a_user_chooses_do_not_clash_with_the_exports() {
    let text = edit("name = \"upper_b\"", "name = \"toe_a\"", 0)
        .replace("parent = \"upper_b\"", "parent = \"toe_a\"")
        .replace("lower_b", "foot")
        + "\n[[contacts]]\nname = \"foot_frame\"\nlink = \"lower_a\"\nfriction = 0.8\n";
    let m = model::build(&parse(&text).unwrap()).unwrap();
    // The names the elements defined at `indent` spaces hold (a URDF transmission's
    // `<joint name=…>` refers to a joint: it sits deeper).
    let names = |xml: &str, element: &str, indent: Option<usize>| -> Vec<String> {
        let open = format!("<{element} name=\"");
        xml.lines()
            .filter(|line| indent.is_none_or(|n| line.len() - line.trim_start().len() == n))
            .filter_map(|line| line.trim_start().strip_prefix(open.as_str()))
            .map(|rest| rest[..rest.find('"').unwrap()].to_string())
            .collect()
    };
    let distinct = |v: &[String], what: &str| {
        let mut s = v.to_vec();
        s.sort();
        s.dedup();
        assert_eq!(s.len(), v.len(), "{what} names clash: {v:?}");
    };
    let urdf = xtask::commands::export::urdf(&m);
    let links = names(&urdf, "link", Some(2));
    for n in [
        "foot",
        "toe_a",
        "foot.point",
        "toe.a",
        "toe.b",
        "foot_frame.point",
    ] {
        assert!(
            links.contains(&n.to_string()),
            "URDF link `{n}` in {links:?}"
        );
    }
    distinct(&links, "URDF link");
    distinct(&names(&urdf, "joint", Some(2)), "URDF joint");
    let mjcf = xtask::commands::export::mjcf(&m);
    let sites = names(&mjcf, "site", None);
    for n in ["foot.point", "toe.a", "toe.b", "foot_frame.point"] {
        assert!(
            sites.contains(&n.to_string()),
            "MJCF site `{n}` in {sites:?}"
        );
    }
    distinct(&sites, "MJCF site");
    distinct(&names(&mjcf, "body", None), "MJCF body");
    distinct(&names(&mjcf, "geom", None), "MJCF geom");
    // `base` stays a keyword: it is what a first link's `parent` names.
    let text = VALID.replace("lower_b", "base");
    let (l, c) = pos(&text, "\"base\"", 2);
    expect_error(&text, (l, c), "links[3].name", "`base` is reserved");
}

/// Runs the derivation (CasADi, from the project's Python environment): a home pose that
/// does not assemble is a spec error located at `home`, and nothing is written.
#[test]
fn a_home_pose_that_does_not_assemble_is_located() {
    // Every link along x: the two branches end 5 cm apart on a 0.35 m leg.
    let text = edit(
        "gravity = [0.0, -9.81]\n",
        "gravity = [0.0, -9.81]\nhome = [0.0, 0.0, 0.0, 0.0]\n",
        0,
    );
    let root = scratch("bad-home", &text);
    let before = root.listing();
    let err = generate(&root).unwrap_err();
    assert!(
        err.is_usage(),
        "bad input must be a usage error (exit 2): {err}"
    );
    let err = err.to_string();
    let (l, c) = pos(&text, "[0.0, 0.0, 0.0, 0.0]", 0);
    assert!(
        err.starts_with(&format!("leg-models/specs/leg.toml:{l}:{c}: home: the home pose does not assemble: closure residual 5.000e-2 m")),
        "{err}"
    );
    // The closure open there, by name.
    assert!(err.contains("closure `toe` is open widest"), "{err}");
    assert_eq!(root.listing(), before, "a failed generation changed files");
}

/// With two closures, the one open widest is named, not the first: `ankle_rod_leg` (a
/// five-bar's toe and an ankle rod) with its rod written 3 cm too long, the five-bar left
/// as it is.
#[test]
fn of_two_closures_the_one_open_widest_is_named() {
    let spec =
        std::fs::read_to_string(gen::workspace_root().join("leg-models/specs/ankle_rod_leg.toml"))
            .unwrap();
    let text = spec.replace("distance = 0.1019", "distance = 0.1319");
    assert_ne!(text, spec, "the rod's length is in the spec");
    let root = scratch("two-closures", &text);
    let before = root.listing();
    let err = generate(&root).unwrap_err().to_string();
    assert!(
        err.contains("home: the home pose does not assemble"),
        "{err}"
    );
    assert!(err.contains("closure `ankle_rod` is open widest"), "{err}");
    assert_eq!(root.listing(), before, "a failed generation changed files");
}

/// Runs the derivation: `list` gives a spec that `gen` would refuse its own error (not
/// advice to run `gen`), and a spec that does not validate its message under the table,
/// which stays narrow.
#[test]
fn list_says_what_gen_would_say() {
    let bad_home = edit(
        "gravity = [0.0, -9.81]\n",
        "gravity = [0.0, -9.81]\nhome = [0.0, 0.0, 0.0, 0.0]\n",
        0,
    );
    let root = scratch("list", &bad_home);
    let broken = edit(
        "mass = 0.05",
        &format!("mass = -0.05 # {}", "x".repeat(300)),
        0,
    );
    root.write("leg-models/specs/broken.toml", &broken);
    let two_link =
        std::fs::read_to_string(gen::workspace_root().join("leg-models/specs/two_link.toml"))
            .unwrap();
    root.write("leg-models/specs/fine.toml", &two_link);
    let before = root.listing();
    let text = xtask::commands::list::table(&root.0).unwrap();
    let (table, notes) = text.split_once("\n\n").expect("messages under the table");
    assert!(table.lines().all(|l| l.chars().count() < 120), "{table}");
    assert!(
        notes.contains("leg: `cargo xtask gen leg` fails: leg-models/specs/leg.toml:")
            && notes.contains("the home pose does not assemble"),
        "{notes}"
    );
    assert!(
        notes.contains("broken: leg-models/specs/broken.toml:"),
        "{notes}"
    );
    assert!(
        notes
            .contains("fine: not generated yet; `cargo xtask gen fine` will say: fine: mobility 2 (rank J 0 of 0 closure rows), 2 motors: fully actuated"),
        "{notes}"
    );
    assert_eq!(root.listing(), before, "list wrote files");
}

#[test]
fn a_leg_without_a_motor() {
    let text = VALID.replace("actuator = { rotor_inertia = 0.0, gear_ratio = 1.0 }\n", "");
    let (l, c) = pos(&text, "\"upper_a\"", 0);
    expect_error(
        &text,
        (l, c),
        "links",
        "no link has an `actuator`: a leg needs at least one motor",
    );
}

#[test]
fn a_leg_with_no_size() {
    let text = VALID
        .replace("[0.1, 0.0]", "[0.0, 0.0]")
        .replace("[0.2, 0.0]", "[0.0, 0.0]")
        .replace("[0.05, 0.0]", "[0.0, 0.0]");
    let (l, c) = pos(&text, "[0.0, 0.0]", 0);
    expect_error(&text, (l, c), "links[0].length", "the leg has no size");
    // One offset anywhere gives it a size.
    let text = text.replacen("origin = [0.0, 0.0]", "origin = [0.05, 0.0]", 1);
    assert!(parse(&text).is_ok());
}

#[test]
fn two_names_that_make_one_parameter() {
    // `upper_a` has a motor (`upper_a_rotor_inertia`); a link `upper_a_rotor` has an
    // inertia (`upper_a_rotor_inertia`).
    let extra = "[[links]]\nname = \"upper_a_rotor\"\nparent = \"base\"\nlength = [0.1, 0.0]\nmass = 0.05\ncom = [0.05, 0.0]\ninertia = 4e-5\n\n[[closures]]";
    let text = VALID.replacen("[[closures]]", extra, 1);
    let e = model::build(&parse(&text).unwrap()).unwrap_err();
    let (l, c) = pos(&text, "\"upper_a_rotor\"", 0);
    assert_eq!(
        (e.line, e.column, e.field.as_str()),
        (l, c, "links[4].name"),
        "{e}"
    );
    let (first, _) = pos(&text, "\"upper_a\"", 0);
    assert!(
        e.message.contains(&format!(
            "this name and links[0].name (line {first}) would both make the parameter `upper_a_rotor_inertia`"
        )),
        "{e}"
    );
}

#[test]
fn spec_text_in_an_error_is_escaped_and_short() {
    let text = edit("name = \"toe\"", "name = \"to\\ne\"", 0);
    let e = parse(&text).unwrap_err();
    let shown = e.to_string();
    assert!(
        !shown.contains('\n') && shown.contains("`to\\ne`"),
        "{shown}"
    );
    let long = "x".repeat(300);
    let text = edit("parent = \"upper_a\"", &format!("parent = \"{long}\""), 0);
    let shown = parse(&text).unwrap_err().to_string();
    assert!(shown.contains(&format!("`{}…`", "x".repeat(40))), "{shown}");
    assert!(shown.len() < 300, "{shown}");
}

/// Runs the derivation (CasADi): closures that fix every joint are a spec error located at
/// the closures, and nothing is written.
#[test]
fn closures_that_leave_no_motion_are_located() {
    // Two links from base points 0.1 m apart whose tips meet: a rigid triangle.
    let text = r#"gravity = [0.0, -9.81]
home = [1.0471975511965976, 2.0943951023931957]

[[links]]
name = "left"
parent = "base"
length = [0.1, 0.0]
mass = 0.05
com = [0.05, 0.0]
inertia = 4e-5
actuator = { rotor_inertia = 0.0, gear_ratio = 1.0 }

[[links]]
name = "right"
parent = "base"
origin = [0.1, 0.0]
length = [0.1, 0.0]
mass = 0.05
com = [0.05, 0.0]
inertia = 4e-5

[[closures]]
name = "apex"
a = { link = "left" }
b = { link = "right" }

[foot]
link = "left"
"#;
    let root = scratch("no-motion", text);
    let before = root.listing();
    let err = generate(&root).unwrap_err();
    assert!(err.is_usage(), "{err}");
    let (l, c) = pos(text, "\"apex\"", 0);
    assert!(
        err.to_string().starts_with(&format!(
            "leg-models/specs/leg.toml:{l}:{c}: closures: the closures leave the leg no motion: rank J = 2"
        )),
        "{err}"
    );
    assert_eq!(root.listing(), before, "a failed generation changed files");
}

#[test]
fn a_spec_larger_than_the_limit_is_refused_up_front() {
    let n = xtask::gen::spec::MAX_LINKS + 1;
    let mut text = String::from("gravity = [0.0, -9.81]\n");
    for i in 0..n {
        let parent = if i == 0 {
            "base".to_string()
        } else {
            format!("l{}", i - 1)
        };
        text.push_str(&format!(
            "\n[[links]]\nname = \"l{i}\"\nparent = \"{parent}\"\nlength = [0.1, 0.0]\nmass = 0.1\ncom = [0.05, 0.0]\ninertia = 1e-4\nactuator = {{ rotor_inertia = 0.0, gear_ratio = 1.0 }}\n"
        ));
    }
    text.push_str(&format!("\n[foot]\nlink = \"l{}\"\n", n - 1));
    let at = pos(&text, &format!("\"l{}\"", n - 1), 0);
    expect_error(
        &text,
        at,
        &format!("links[{}]", n - 1),
        &format!("a spec may have at most {} links, this one has {n}", n - 1),
    );
}

/// A scratch workspace whose one spec is `text`, with the project's derivation script and
/// Python environment.
fn scratch(tag: &str, text: &str) -> TempRoot {
    let root = TempRoot::new(tag);
    for dir in ["xtask", ".venv"] {
        let from = gen::workspace_root().join(dir);
        std::os::unix::fs::symlink(&from, root.0.join(dir)).unwrap();
    }
    root.write("leg-models/specs/leg.toml", text);
    root
}

fn generate(root: &TempRoot) -> Result<String, xtask::cli::Error> {
    gen::run(
        &root.0,
        &GenOptions {
            check: false,
            names: vec![],
        },
    )
}

/// Runs the derivation (CasADi): a closure whose points can never meet (the branches are
/// too short to reach each other) is located at `home`, and nothing is written.
#[test]
fn a_closure_that_can_never_meet_is_located() {
    // The lower links shortened to 2 cm and the motors 0.3 m apart: the toes stay at least
    // 6 cm apart (0.3 − 2 × 0.12) in any pose.
    let text = VALID
        .replace("length = [0.2, 0.0]", "length = [0.02, 0.0]")
        .replace("com = [0.1, 0.0]", "com = [0.01, 0.0]")
        .replace(
            "gravity = [0.0, -9.81]\n",
            "gravity = [0.0, -9.81]\nhome = [-1.0, 0.5, -2.0, -0.5]\n",
        )
        .replace("origin = [0.05, 0.0]", "origin = [0.3, 0.0]");
    let root = scratch("never-meet", &text);
    let before = root.listing();
    let err = generate(&root).unwrap_err();
    assert!(err.is_usage(), "{err}");
    let (l, c) = pos(&text, "[-1.0, 0.5, -2.0, -0.5]", 0);
    assert!(
        err.to_string().starts_with(&format!(
            "leg-models/specs/leg.toml:{l}:{c}: home: the home pose does not assemble"
        )),
        "{err}"
    );
    assert_eq!(root.listing(), before, "a failed generation changed files");
}

/// Runs the derivation (CasADi): a closed chain with every joint driven generates, and
/// `gen` says it is over-actuated and what that means.
#[test]
fn an_over_actuated_leg_is_reported() {
    let motor = "inertia = 1.6e-4\n";
    let text = VALID.replace(
        motor,
        "inertia = 1.6e-4\nactuator = { rotor_inertia = 0.0, gear_ratio = 1.0 }\n",
    );
    let text = text.replace(
        "gravity = [0.0, -9.81]\n",
        "gravity = [0.0, -9.81]\nhome = [-0.6437, -1.2057, -2.4979, 1.2057]\n",
    );
    let root = scratch("over-actuated", &text);
    let report = generate(&root).expect("an over-actuated leg is legal");
    assert!(
        report.contains("leg: mobility 2 (rank J 2 of 2 closure rows), 4 motors: over-actuated (4 motors for 2 degrees of freedom"),
        "{report}"
    );
}

#[test]
fn a_number_too_large_to_derive_with() {
    let text = edit("mass = 0.05", "mass = 1e308", 0);
    let (l, c) = pos(&text, "1e308", 0);
    expect_error(
        &text,
        (l, c),
        "links[0].mass",
        "must be at most 1e6 in magnitude, got 1e308",
    );
}

/// The valid spec with `extra` appended (springs, contacts, ground).
fn with(extra: &str) -> String {
    format!("{VALID}\n{extra}")
}

#[test]
fn joint_kinds_and_axes_are_checked() {
    let text = edit(
        "parent = \"upper_a\"",
        "parent = \"upper_a\"\njoint = \"prismatic\"",
        0,
    );
    let at = pos(&text, "\"prismatic\"", 0);
    expect_error(
        &text,
        at,
        "links[1].axis",
        "a prismatic joint needs the `axis`",
    );
    let text = edit(
        "parent = \"upper_a\"",
        "parent = \"upper_a\"\njoint = \"prismatic\"\naxis = [0.0, 0.0]",
        0,
    );
    let at = pos(&text, "[0.0, 0.0]", 0);
    expect_error(&text, at, "links[1].axis", "must not be zero");
    let text = edit(
        "parent = \"upper_a\"",
        "parent = \"upper_a\"\naxis = [1.0, 0.0]",
        0,
    );
    let at = pos(&text, "[1.0, 0.0]", 0);
    expect_error(
        &text,
        at,
        "links[1].axis",
        "only a prismatic joint has an axis",
    );
    let text = edit(
        "parent = \"upper_a\"",
        "parent = \"upper_a\"\njoint = \"helical\"",
        0,
    );
    let e = parse(&text).unwrap_err();
    assert_eq!(e.field, "links[1].joint", "{e}");
    assert!(e.message.contains("unknown variant `helical`"), "{e}");
    assert!(
        e.message.contains("`revolute`, `prismatic`") || e.message.contains("revolute"),
        "{e}"
    );
}

#[test]
fn springs_contacts_and_ground_are_checked() {
    let text = with("[[springs]]\nname = \"s\"\na = \"knee\"\nstiffness = 10.0\n");
    let at = pos(&text, "\"knee\"", 0);
    expect_error(&text, at, "springs[0].a", "unknown link `knee`");
    let text =
        with("[[springs]]\nname = \"s\"\na = \"lower_a\"\nb = \"lower_a\"\nstiffness = 10.0\n");
    let at = pos(&text, "\"lower_a\"\nstiffness", 0);
    expect_error(&text, at, "springs[0].b", "two different joints");
    let text = with("[[springs]]\nname = \"s\"\na = \"lower_a\"\nstiffness = -1.0\n");
    let at = pos(&text, "-1.0", 0);
    expect_error(&text, at, "springs[0].stiffness", "must be positive");
    let text = with("[[springs]]\nname = \"toe\"\na = \"lower_a\"\nstiffness = 1.0\n");
    let at = pos(&text, "\"toe\"", 1);
    expect_error(&text, at, "springs[0].name", "duplicate name `toe`");
    let text = with("[[contacts]]\nname = \"sole\"\nlink = \"shin\"\nfriction = 0.8\n");
    let at = pos(&text, "\"shin\"", 0);
    expect_error(&text, at, "contacts[0].link", "unknown link `shin`");
    let text = with("[[contacts]]\nname = \"sole\"\nlink = \"lower_a\"\nfriction = -0.1\n");
    let at = pos(&text, "-0.1", 0);
    expect_error(&text, at, "contacts[0].friction", "must not be negative");
    let text = with("[[contacts]]\nname = \"sole\"\nlink = \"lower_a\"\n");
    let e = parse(&text).unwrap_err();
    assert!(
        e.field.starts_with("contacts[0]") && e.message.contains("friction"),
        "{e}"
    );
    let text = with("[[contacts]]\nname = \"base\"\nlink = \"lower_a\"\nfriction = 0.8\n");
    let at = pos(&text, "\"base\"", 2);
    expect_error(&text, at, "contacts[0].name", "reserved");
    let text = with("[ground]\nnormal = [0.0, 0.0]\n");
    let at = pos(&text, "[0.0, 0.0]\n", 0);
    expect_error(&text, at, "ground.normal", "must not be zero");
    let text = with("[ground]\noffset = 1e9\n");
    let at = pos(&text, "1e9", 0);
    expect_error(&text, at, "ground.offset", "at most");
}

/// Runs the derivation (CasADi): a massless link with nothing beyond it makes `M`
/// singular, located at its mass; massless links that carry a body generate.
#[test]
fn a_massless_link_that_moves_nothing_is_located() {
    let text = edit(
        "mass = 0.05\ncom = [0.1, 0.0]\ninertia = 1.6e-4",
        "mass = 0.0\ncom = [0.1, 0.0]\ninertia = 0.0",
        1,
    )
    .replace(
        "gravity = [0.0, -9.81]\n",
        "gravity = [0.0, -9.81]\nhome = [-0.6437, -1.2057, -2.4979, 1.2057]\n",
    );
    // lower_b massless but closed to lower_a: its joint still moves nothing by itself,
    // M (of the open tree) is singular.
    let root = scratch("massless", &text);
    let before = root.listing();
    let err = generate(&root).unwrap_err();
    assert!(err.is_usage(), "{err}");
    let (l, c) = pos(&text, "mass = 0.0\n", 0);
    assert!(
        err.to_string().starts_with(&format!(
            "leg-models/specs/leg.toml:{l}:{}: links[3].mass: the mass matrix is singular at home: the joint of `lower_b` moves no mass",
            c + "mass = ".len()
        )),
        "{err}"
    );
    assert_eq!(root.listing(), before, "a failed generation changed files");
}

/// Runs the derivation (CasADi): a spec that does not validate blocks `gen` of another
/// leg only when it is selected: `gen leg` generates `leg` and notes the other; `gen`
/// of everything (and `--check`) refuses at the broken spec.
#[test]
fn a_broken_spec_does_not_block_generating_another() {
    let text = VALID.replace(
        "gravity = [0.0, -9.81]\n",
        "gravity = [0.0, -9.81]\nhome = [-0.6437, -1.2057, -2.4979, 1.2057]\n",
    );
    let root = scratch("broken-other", &text);
    root.write(
        "leg-models/specs/other.toml",
        "gravity = [0.0, -9.81]\n[[links]]\nname = \"x\"\n",
    );
    let one = gen::run(
        &root.0,
        &GenOptions {
            check: false,
            names: vec!["leg".into()],
        },
    )
    .expect("`leg` generates beside a broken spec");
    assert!(
        one.contains("note: other was not regenerated: its spec does not validate (leg-models/specs/other.toml:"),
        "{one}"
    );
    assert!(root.0.join(gen::SRC_DIR).join("leg.rs").exists());
    let all = generate(&root).unwrap_err();
    assert!(
        all.is_usage() && all.to_string().contains("other.toml"),
        "{all}"
    );
}

/// The built-in spatial test leg's text, edited.
fn spatial_edit(from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(
        gen::workspace_root().join("leg-models/specs/abducted_five_bar.toml"),
    )
    .unwrap();
    assert!(text.contains(from), "{from}");
    text.replacen(from, to, 1)
}

fn refused(text: &str, field: &str, says: &str) {
    let e = parse(text).unwrap_err();
    assert_eq!(e.field, field, "{e}");
    assert!(e.message.contains(says), "{e}");
    assert!(e.line > 0, "{e}");
}

#[test]
fn spatial_specs_refuse_what_does_not_fit_their_dimension() {
    // The spatial leg itself validates and builds a 3-D model.
    let text = spatial_edit("", "");
    let spec = parse(&text).unwrap();
    let m = model::build(&spec).unwrap();
    assert_eq!(m.dimension, 3);
    assert_eq!(m.gravity.len(), 3);
    // A 2-vector on a spatial leg, a 3-vector on a planar one: named with the dimension.
    refused(
        &spatial_edit("origin = [0.0, 0.04, 0.0]", "origin = [0.0, 0.04]"),
        "links[1].origin",
        "the leg is spatial",
    );
    refused(
        &VALID.replacen("origin = [0.05, 0.0]", "origin = [0.05, 0.0, 0.0]", 1),
        "links[2].origin",
        "the leg is planar",
    );
    refused(
        &spatial_edit(
            "gravity = [0.0, 0.0, -9.81]",
            "gravity = [0.0, 0.0, -9.81, 0.0]",
        ),
        "gravity",
        "4 entries",
    );
    // Inertia tensors a rigid body cannot have; a planar inertia on a spatial link.
    refused(
        &spatial_edit(
            "inertia = [1.0e-6, 4.1666666666666665e-5, 4.1666666666666665e-5]",
            "inertia = [1.0e-6, 1.0e-6, 4.1666666666666665e-5]",
        ),
        "links[1].inertia",
        "no rigid body has it",
    );
    refused(
        &spatial_edit(
            "inertia = [1.0e-6, 4.1666666666666665e-5, 4.1666666666666665e-5]",
            "inertia = [1.0, 1.0, 1.0, 2.0, 0.0, 0.0]",
        ),
        "links[1].inertia",
        "not positive semi-definite",
    );
    refused(
        &spatial_edit(
            "inertia = [1.0e-6, 4.1666666666666665e-5, 4.1666666666666665e-5]",
            "inertia = 4e-5",
        ),
        "links[1].inertia",
        "has 1 entries",
    );
    // Orientation: a quaternion, spatial only, not zero.
    refused(
        &spatial_edit(
            "orientation = [0.9887710779360422, 0.0, -0.14943813247359922, 0.0]",
            "orientation = [0.0, 0.0, 0.0, 0.0]",
        ),
        "links[4].orientation",
        "must not be zero",
    );
    refused(
        &spatial_edit(
            "orientation = [0.9887710779360422, 0.0, -0.14943813247359922, 0.0]",
            "orientation = [1.0, 0.0, 0.0]",
        ),
        "links[4].orientation",
        "quaternion",
    );
    refused(
        &VALID.replacen(
            "inertia = 4e-5\n",
            "inertia = 4e-5\norientation = [1.0, 0.0, 0.0, 0.0]\n",
            1,
        ),
        "links[0].orientation",
        "only a spatial leg",
    );
    refused(
        &spatial_edit("axis = [1.0, 0.0, 0.0]", "axis = [0.0, 0.0, 0.0]"),
        "links[0].axis",
        "must not be zero",
    );
    // A spatial contact's point and the ground's normal have three coordinates (the leg
    // has its toe contact and a floor 0.25 m under the hip).
    refused(
        &spatial_edit(
            "link = \"lower_a\"\nfriction",
            "link = \"lower_a\"\npoint = [0.2, 0.0]\nfriction",
        ),
        "contacts[0].point",
        "the leg is spatial",
    );
    refused(
        &spatial_edit("offset = -0.25", "normal = [0.0, 1.0]\noffset = -0.25"),
        "ground.normal",
        "the leg is spatial",
    );
    // Accepted with three: the ground's normal normalized, +z by default.
    let m = model::build(&parse(&text).unwrap()).unwrap();
    assert_eq!(m.ground_normal, [0.0, 0.0, 1.0]);
    assert_eq!(m.ground_offset, -0.25);
    assert_eq!(m.contacts.len(), 1);
    let tilted = spatial_edit("offset = -0.25", "normal = [0.0, 3.0, 4.0]\noffset = -0.2");
    let m = model::build(&parse(&tilted).unwrap()).unwrap();
    assert_eq!(m.ground_normal, [0.0, 0.6, 0.8]);
    assert_eq!(m.ground_offset, -0.2);
}

/// The RSSR test leg's text (a ball joint in its loop), edited.
fn ball_edit(from: &str, to: &str) -> String {
    let text =
        std::fs::read_to_string(gen::workspace_root().join("leg-models/specs/rssr_linkage.toml"))
            .unwrap();
    assert!(text.contains(from), "{from}");
    text.replacen(from, to, 1)
}

#[test]
fn ball_joints_are_refused_where_they_do_not_fit() {
    // The leg itself: three coordinates for its ball joint, named `<link>.x/.y/.z`.
    let m = model::build(&parse(&ball_edit("", "")).unwrap()).unwrap();
    assert_eq!(
        m.joint_names(),
        ["crank", "coupler.x", "coupler.y", "coupler.z", "rocker"]
    );
    assert_eq!(m.home.len(), 5);
    refused(
        &ball_edit(
            "joint = \"ball\"\n",
            "joint = \"ball\"\naxis = [1.0, 0.0, 0.0]\n",
        ),
        "links[1].axis",
        "a ball joint has no axis",
    );
    refused(
        &ball_edit(
            "joint = \"ball\"\n",
            "joint = \"ball\"\nactuator = { rotor_inertia = 1e-5, gear_ratio = 1.0 }\n",
        ),
        "links[1].actuator",
        "a motor drives one axis",
    );
    refused(
        &format!(
            "{}\n[[springs]]\nname = \"twist\"\na = \"coupler\"\nstiffness = 1.0\n",
            ball_edit("", "")
        ),
        "springs[0].a",
        "a ball joint has three",
    );
    refused(
        &ball_edit(
            "home = [0.3, -0.0135, 0.3281, 0.0348, 0.1693]",
            "home = [0.3, -0.0135, 0.1693]",
        ),
        "home",
        "3 joint values for 5 coordinates (3 links, three angles per ball joint)",
    );
    refused(
        &VALID.replacen("inertia = 4e-5\n", "inertia = 4e-5\njoint = \"ball\"\n", 1),
        "links[0].joint",
        "only a spatial leg",
    );
}

/// The floating test robot's text (a body on a free joint), edited.
fn free_edit(from: &str, to: &str) -> String {
    let text =
        std::fs::read_to_string(gen::workspace_root().join("leg-models/specs/floating_arm.toml"))
            .unwrap();
    assert!(text.contains(from), "{from}");
    text.replacen(from, to, 1)
}

#[test]
fn free_joints_are_a_floating_robots_body_and_refused_elsewhere() {
    // Six coordinates: the translation `<link>.tx/.ty/.tz`, then a ball joint's angles.
    let m = model::build(&parse(&free_edit("", "")).unwrap()).unwrap();
    assert_eq!(
        m.joint_names(),
        ["body.tx", "body.ty", "body.tz", "body.x", "body.y", "body.z", "hip", "thigh", "shin"]
    );
    assert_eq!(
        m.links.iter().map(|l| l.joint).collect::<Vec<_>>(),
        [
            "prismatic",
            "prismatic",
            "prismatic",
            "revolute",
            "revolute",
            "revolute",
            "revolute",
            "revolute",
            "revolute"
        ]
    );
    // Only the body carries mass; its five stages are frames.
    assert_eq!(m.links.iter().filter(|l| l.massless).count(), 5);
    let free = "joint = \"free\"\n";
    for (extra, field, message) in [
        (
            "axis = [1.0, 0.0, 0.0]\n",
            "links[0].axis",
            "a free joint has no axis",
        ),
        (
            "actuator = { rotor_inertia = 1e-5, gear_ratio = 1.0 }\n",
            "links[0].actuator",
            "carries no motor",
        ),
        ("damping = 0.1\n", "links[0].damping", "no damping"),
        (
            "origin = [0.0, 0.0, 0.5]\n",
            "links[0].origin",
            "the body's state",
        ),
        (
            "orientation = [1.0, 0.0, 0.0, 0.0]\n",
            "links[0].orientation",
            "the body's state",
        ),
    ] {
        refused(&free_edit(free, &format!("{free}{extra}")), field, message);
    }
    // Not first, or another link on the base.
    refused(
        &free_edit(
            "parent = \"body\"\norigin = [0.12",
            "parent = \"base\"\norigin = [0.12",
        ),
        "links[1].parent",
        "every link hangs from its body `body`",
    );
    refused(
        &ball_edit("joint = \"ball\"\n", "joint = \"free\"\n"),
        "links[1].joint",
        "list it first",
    );
    refused(
        &format!(
            "{}\n[[springs]]\nname = \"sway\"\na = \"body\"\nstiffness = 1.0\n",
            free_edit("", "")
        ),
        "springs[0].a",
        "a free joint has six",
    );
    refused(
        &format!(
            "{}\n[[closures]]\nname = \"tether\"\na = {{ link = \"shin\" }}\nb = {{ link = \"base\", point = [0.0, 0.0, 0.0] }}\n",
            free_edit("", "")
        ),
        "closures[0].b.link",
        "no point fixed in the world",
    );
    refused(
        &free_edit(
            "home = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3, -0.6, 1.1]",
            "home = [0.3, -0.6, 1.1]",
        ),
        "home",
        "3 joint values for 9 coordinates (4 links, six coordinates for the free joint)",
    );
    refused(
        &format!("{}\n[ground]\noffset = -1.0\n", free_edit("", "")),
        "ground",
        "the world's, given at run time",
    );
    refused(
        &free_edit(
            "home = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3",
            "home = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.3",
        ),
        "home",
        "the chart's centre: zeros",
    );
    refused(
        &VALID.replacen("inertia = 4e-5\n", "inertia = 4e-5\njoint = \"free\"\n", 1),
        "links[0].joint",
        "only a spatial robot",
    );
}

/// A distance (rod) closure: one row, its length a parameter; refused on a planar leg and
/// with a length that is not positive.
#[test]
fn distance_closures_are_one_row_and_refused_where_they_do_not_fit() {
    let rssr = |extra: &str| {
        ball_edit(
            "b = { link = \"rocker\" }\n",
            &format!("b = {{ link = \"rocker\" }}\n{extra}"),
        )
    };
    let m = model::build(&parse(&rssr("distance = 0.1\n")).unwrap()).unwrap();
    assert_eq!(m.closure_rows(), 1);
    assert!(m
        .params
        .iter()
        .any(|p| p.name == "joint_distance" && p.default == 0.1));
    refused(
        &rssr("distance = 0.0\n"),
        "closures[0].distance",
        "must be positive",
    );
    refused(
        &rssr("distance = -0.2\n"),
        "closures[0].distance",
        "must be positive",
    );
    refused(
        &VALID.replacen("[[closures]]\n", "[[closures]]\ndistance = 0.1\n", 1),
        "closures[0].distance",
        "for spatial legs for now",
    );
}

/// The revolute-closure test leg's text, edited.
fn revolute_edit(from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(
        gen::workspace_root().join("leg-models/specs/revolute_knee_leg.toml"),
    )
    .unwrap();
    assert!(text.contains(from), "{from}");
    text.replacen(from, to, 1)
}

#[test]
fn revolute_closures_are_refused_where_they_do_not_fit() {
    // The leg itself: five rows, its axes unit and b's perpendicular pair.
    let m = model::build(&parse(&revolute_edit("", "")).unwrap()).unwrap();
    assert_eq!(m.closure_rows(), 5);
    let r = m.closures[0].revolute.as_ref().unwrap();
    assert_eq!(r.a, [0.0, 0.0, 1.0]);
    let b = r.axis_b();
    assert!(
        (b[1] - 1.0).abs() < 1e-15 && b[0].abs() < 1e-15 && b[2].abs() < 1e-15,
        "{b:?}"
    );
    let dot = |x: [f64; 3], y: [f64; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
    assert!(dot(r.u, b).abs() < 1e-15 && dot(r.w, b).abs() < 1e-15 && dot(r.u, r.w).abs() < 1e-15);
    // Not both a rod and a hinge; axis_b only with axis; no zero or 2-vector axis.
    refused(
        &revolute_edit(
            "axis_b = [0.0, 1.0, 0.0]",
            "axis_b = [0.0, 1.0, 0.0]\ndistance = 0.1",
        ),
        "closures[0].distance",
        "not both",
    );
    refused(
        &revolute_edit("axis = [0.0, 0.0, 1.0]\naxis_b", "axis_b"),
        "closures[0].axis_b",
        "give `axis`",
    );
    refused(
        &revolute_edit(
            "axis = [0.0, 0.0, 1.0]\naxis_b",
            "axis = [0.0, 0.0, 0.0]\naxis_b",
        ),
        "closures[0].axis",
        "must not be zero",
    );
    refused(
        &revolute_edit(
            "axis = [0.0, 0.0, 1.0]\naxis_b",
            "axis = [0.0, 1.0]\naxis_b",
        ),
        "closures[0].axis",
        "the leg is spatial",
    );
    // On a planar leg a closure is a pin already.
    let planar =
        std::fs::read_to_string(gen::workspace_root().join("leg-models/specs/minitaur.toml"))
            .unwrap();
    let at = planar.find("[[closures]]").unwrap();
    let end = planar[at..].find("\n\n").map_or(planar.len(), |e| at + e);
    let text = format!("{}\naxis = [0.0, 1.0]{}", &planar[..end], &planar[end..]);
    refused(&text, "closures[0].axis", "planar leg");
}

/// Runs the derivation: a revolute closure whose axes point against each other at the
/// assembled home is refused at `axis_b` (its rows vanish there too, but the exports
/// place their second points along each axis), and nothing is written.
#[test]
fn a_revolute_closure_with_antiparallel_axes_is_located() {
    let text = revolute_edit("axis_b = [0.0, 1.0, 0.0]", "axis_b = [0.0, -1.0, 0.0]");
    let root = scratch("antiparallel", &text);
    let before = root.listing();
    let err = generate(&root).unwrap_err();
    assert!(
        err.is_usage(),
        "bad input must be a usage error (exit 2): {err}"
    );
    let err = err.to_string();
    let line = text[..text.find("axis_b = [0.0, -1.0").unwrap()]
        .lines()
        .count()
        + 1;
    assert!(
        err.starts_with(&format!("leg-models/specs/leg.toml:{line}:10: closures[0].axis_b: closure `knee_link`: link b's axis points against link a's")),
        "{err}"
    );
    assert_eq!(root.listing(), before, "a failed generation changed files");
}
