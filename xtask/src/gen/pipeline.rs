//! `cargo xtask gen`: specs → CasADi → IR → Rust, all in memory first, then written only
//! when every model succeeded (a failed generation leaves every file untouched).

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use codegen::ir::{Input, InputShape, Output, Program};
use serde::Deserialize;

use crate::cli::progress::Progress;
use crate::cli::Error;
use crate::gen::ir_file::{IrFile, ModelInfo, FORMAT};
use crate::gen::model::{self, Model};
use crate::gen::rust_module::{self, Summary};
use crate::gen::spec::Spec;

pub const SPECS_DIR: &str = "leg-models/specs";
pub const IR_DIR: &str = "generated/ir";
pub const SRC_DIR: &str = "generated/src";
/// CasADi's own C code of each derivation, the benchmarks' peer.
pub const CASADI_C_DIR: &str = "generated/casadi";
pub const VENV_DIR: &str = ".venv";
pub const REQUIREMENTS: &str = "xtask/requirements.txt";
const SCRIPT: &str = "xtask/derive.py";

/// The workspace root (the parent of `xtask/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

/// The spec files, sorted by name.
pub fn spec_paths(root: &Path) -> Result<Vec<PathBuf>, String> {
    let dir = root.join(SPECS_DIR);
    let mut out: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map_err(|e| format!("{}: cannot list specs: {e}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    out.sort();
    Ok(out)
}

/// Loads and validates a spec, with its path shown relative to the workspace.
pub fn load_spec(root: &Path, path: &Path) -> Result<Spec, String> {
    let shown = path.strip_prefix(root).unwrap_or(path);
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read: {e}", shown.display()))?;
    Spec::parse(shown, text).map_err(|e| e.to_string())
}

/// What `derive.py` prints.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Derived {
    casadi_version: String,
    spec_sha256: String,
    functions: Vec<DerivedFunction>,
    casadi_c: String,
    home_check: HomeCheck,
}

/// The spec's home pose assembled by the derivation (every joint free, the spec's
/// parameters), and the leg's structure there.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct HomeCheck {
    /// A joint that moves no inertia at home (`M` singular there): a massless link with
    /// nothing massive beyond it.
    massless_joint: Option<usize>,
    /// Revolute closures whose axes point against each other at the assembled home.
    #[serde(default)]
    antiparallel: Vec<usize>,
    /// The largest coordinate of any point of the leg at home (m): the leg's size.
    scale: f64,
    /// `max |φ|` at the home pose as written.
    raw_residual: f64,
    /// The row of `φ` where it is largest there.
    #[serde(default)]
    worst_row: Option<usize>,
    /// `max |φ|` after assembly.
    residual: f64,
    assembled: Vec<f64>,
    /// The largest change of a joint angle during assembly (rad).
    moved: f64,
    rank: usize,
    redundant_rows: Vec<usize>,
    mobility: usize,
}

/// What a home pose may miss by (relative to the leg's size): it is a guess written with a
/// few digits, from which assembly starts.
const HOME_TOLERANCE: f64 = 1e-2;
/// How closely assembly must meet the closures (relative to the leg's size), as the runtime.
const ASSEMBLY_TOLERANCE: f64 = 1000.0 * f64::EPSILON;

/// A home pose that does not assemble is a spec error at `home`.
fn check_home(spec: &Spec, model: &Model, check: &HomeCheck) -> Result<(), String> {
    let (line, column, field) = match &spec.file.home {
        Some(h) => {
            let (l, c) = crate::gen::spec::line_column(&spec.text, h.span().start);
            (l, c, "home")
        }
        None => (1, 1, "home (not given: all zeros)"),
    };
    let error = |message: String| {
        crate::gen::spec::SpecError {
            file: spec.path.clone(),
            line,
            column,
            field: field.into(),
            message,
        }
        .to_string()
    };
    let scale = check.scale;
    let assembled = check.residual <= ASSEMBLY_TOLERANCE * scale;
    let pose = check
        .assembled
        .iter()
        .map(|x| format!("{x:.4}"))
        .collect::<Vec<_>>()
        .join(", ");
    if check.raw_residual > HOME_TOLERANCE * scale || !assembled {
        let hint = if assembled {
            format!(" (the nearest assembled pose is [{pose}])")
        } else {
            format!(
                " (assembly from it stops at residual {:.3e} m)",
                check.residual
            )
        };
        // The closure that row belongs to, by name: the one to look at first.
        let widest = check
            .worst_row
            .and_then(|row| {
                let mut first = 0;
                model.closures.iter().find(|c| {
                    first += c.rows(model.dimension);
                    row < first
                })
            })
            .map_or(String::new(), |c| {
                format!("; closure `{}` is open widest", c.name)
            });
        return Err(error(format!(
            "the home pose does not assemble: closure residual {:.3e} m, more than {} of the leg's size {:.3} m{widest}{hint}",
            check.raw_residual, HOME_TOLERANCE, scale
        )));
    }
    if let Some(&k) = check.antiparallel.first() {
        let c = spec.file.closures[k].get_ref();
        let at = c
            .axis_b
            .as_ref()
            .or(c.axis.as_ref())
            .expect("a revolute closure");
        let (line, column) = crate::gen::spec::line_column(&spec.text, at.span().start);
        return Err(crate::gen::spec::SpecError {
            file: spec.path.clone(),
            line,
            column,
            field: format!("closures[{k}].axis_b"),
            message: format!(
                "closure `{}`: link b's axis points against link a's at the assembled home (the same hinge line, but the exports place their second points along each axis): turn axis_b around",
                c.name.get_ref()
            ),
        }
        .to_string());
    }
    if check.mobility == 0 {
        if let Some(c) = spec.file.closures.first() {
            let name = &c.get_ref().name;
            let (line, column) = crate::gen::spec::line_column(&spec.text, name.span().start);
            return Err(crate::gen::spec::SpecError {
                file: spec.path.clone(),
                line,
                column,
                field: "closures".into(),
                message: format!(
                    "the closures leave the leg no motion: rank J = {} = the number of joints at home, so every joint is fixed (remove a closure or add a link)",
                    check.rank
                ),
            }
            .to_string());
        }
    }
    if let Some(j) = check.massless_joint {
        let j = model.links[j].spec_link;
        let link = spec.file.links[j].get_ref();
        let (line, column) = crate::gen::spec::line_column(&spec.text, link.mass.span().start);
        return Err(crate::gen::spec::SpecError {
            file: spec.path.clone(),
            line,
            column,
            field: format!("links[{j}].mass"),
            message: format!(
                "the mass matrix is singular at home: the joint of `{}` moves no mass or inertia (give the link mass or inertia, or hang a massive link from it)",
                link.name.get_ref()
            ),
        }
        .to_string());
    }
    if check.moved > 0.2 {
        return Err(error(format!(
            "the home pose is far from assembled: assembly moves a joint by {:.3} rad (the nearest assembled pose is [{pose}])",
            check.moved
        )));
    }
    Ok(())
}

/// How the leg's mobility at home compares with its motors, for people.
pub fn actuation_note(mobility: usize, motors: usize) -> &'static str {
    match mobility.cmp(&motors) {
        std::cmp::Ordering::Equal => "fully actuated",
        std::cmp::Ordering::Greater => "under-actuated",
        std::cmp::Ordering::Less => "over-actuated",
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DerivedFunction {
    name: String,
    inputs: Vec<String>,
    outputs: Vec<Output>,
    instructions: Vec<codegen::ir::Instr>,
}

/// Sets up (once) the virtual environment with the pinned CasADi; returns its python.
pub fn python(root: &Path) -> Result<PathBuf, String> {
    let venv = root.join(VENV_DIR);
    let py = venv.join("bin").join("python");
    let requirements = std::fs::read_to_string(root.join(REQUIREMENTS))
        .map_err(|e| format!("{REQUIREMENTS}: {e}"))?;
    let stamp = venv.join("requirements.installed");
    if py.exists() && std::fs::read_to_string(&stamp).ok().as_deref() == Some(requirements.as_str())
    {
        return Ok(py);
    }
    eprintln!("setting up {VENV_DIR}/ with {REQUIREMENTS} (first run only)…");
    let run = |cmd: &mut Command, shown: &str| -> Result<(), String> {
        let status = cmd.current_dir(root).status().map_err(|e| {
            format!("cannot run `{shown}`: {e}; is python3 (3.9 or later, with venv) installed?")
        })?;
        if status.success() {
            Ok(())
        } else {
            Err(format!("`{shown}` failed ({status}); run it by hand to see why, then `cargo xtask gen` again"))
        }
    };
    if !py.exists() {
        run(
            Command::new("python3").args(["-m", "venv", VENV_DIR]),
            &format!("python3 -m venv {VENV_DIR}"),
        )?;
    }
    run(
        Command::new(&py).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "-r",
            REQUIREMENTS,
        ]),
        &format!("{VENV_DIR}/bin/python -m pip install -r {REQUIREMENTS}"),
    )?;
    std::fs::write(&stamp, requirements).map_err(|e| format!("{}: {e}", stamp.display()))?;
    Ok(py)
}

fn derive(root: &Path, py: &Path, model: &Model) -> Result<Derived, String> {
    let mut child = Command::new(py)
        .arg(root.join(SCRIPT))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", py.display()))?;
    let input = serde_json::to_vec(model).expect("model serializes");
    child
        .stdin
        .take()
        .expect("piped")
        .write_all(&input)
        .map_err(|e| format!("derivation of `{}`: {e}", model.name))?;
    let out = child
        .wait_with_output()
        .map_err(|e| format!("derivation of `{}`: {e}", model.name))?;
    if !out.status.success() {
        return Err(format!(
            "derivation of `{}` failed ({}):\n{}",
            model.name,
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("derivation of `{}` printed unreadable IR: {e}", model.name))
}

/// Puts the derivation's programs together with what the model is.
fn assemble(spec: &Spec, model: &Model, derived: Derived) -> IrFile {
    let structure = &derived.home_check;
    let (redundant_rows, mobility) = (structure.redundant_rows.clone(), structure.mobility);
    let n = model.links.len();
    let fields: Vec<String> = model.params.iter().map(|p| p.name.clone()).collect();
    let functions = derived
        .functions
        .into_iter()
        .map(|f| Program {
            name: f.name,
            inputs: f
                .inputs
                .into_iter()
                .map(|name| {
                    let shape = if name == "p" {
                        InputShape::Struct {
                            type_name: "Params".into(),
                            fields: fields.clone(),
                            prepared: 0,
                        }
                    } else {
                        // Closure forces `f` and contact forces `lambda` have a row each;
                        // every other vector (q, q̇, accelerations `a`) a joint each.
                        let len = match name.as_str() {
                            "f" => model.closure_rows(),
                            "lambda" => model.dimension * model.contacts.len(),
                            _ => n,
                        };
                        InputShape::Vector { len }
                    };
                    Input { name, shape }
                })
                .collect(),
            outputs: f.outputs,
            instructions: f.instructions,
        })
        .collect();
    IrFile {
        format: FORMAT,
        model: ModelInfo {
            name: model.name.clone(),
            spec: spec.path.display().to_string(),
            spec_sha256: derived.spec_sha256,
            casadi_version: derived.casadi_version,
            joints: model.joint_names(),
            actuated: model.actuated.clone(),
            home: model.home.clone(),
            closures: model.closures.iter().map(|c| c.name.clone()).collect(),
            distance_closures: model
                .closures
                .iter()
                .enumerate()
                .filter(|(_, c)| c.distance.is_some())
                .map(|(k, _)| k)
                .collect(),
            revolute_closures: model
                .closures
                .iter()
                .enumerate()
                .filter(|(_, c)| c.revolute.is_some())
                .map(|(k, _)| k)
                .collect(),
            redundant_rows,
            mobility,
            params: model.params.clone(),
            joint_kinds: model.links.iter().map(|l| l.joint.to_string()).collect(),
            parents: model.links.iter().map(|l| l.parent).collect(),
            springs: model
                .springs
                .iter()
                .map(|s| crate::gen::ir_file::SpringInfo {
                    name: s.name.clone(),
                    a: s.a,
                    b: s.b,
                })
                .collect(),
            contacts: model.contacts.iter().map(|c| c.name.clone()).collect(),
            contact_friction: model.contacts.iter().map(|c| c.friction).collect(),
            ground_normal: model.ground_normal.clone(),
            ground_offset: model.ground_offset,
            dimension: model.dimension,
            // The angles of a ball joint, and of a free joint after its translation.
            ball_joints: model
                .links
                .iter()
                .enumerate()
                .filter(|(i, l)| {
                    l.massless
                        && l.joint == "revolute"
                        && (*i == 0
                            || model.links[i - 1].spec_link != l.spec_link
                            || model.links[i - 1].joint != "revolute")
                })
                .map(|(i, _)| i)
                .collect(),
            free_joint: model
                .links
                .iter()
                .position(|l| l.spec_kind == crate::gen::spec::JointKind::Free),
        },
        functions,
    }
}

/// The generated crate's files, by path relative to the root: the module of each model `emit` selects (`gen NAME`
/// emits NAME's alone; the others' are as their IR left them) and `lib.rs`, which lists
/// every model.
pub fn rust_files(
    irs: &[IrFile],
    emit: impl Fn(&str) -> bool,
) -> Result<BTreeMap<PathBuf, String>, String> {
    let mut files = BTreeMap::new();
    for ir in irs.iter().filter(|ir| emit(&ir.model.name)) {
        let src = rust_module::model_source(ir).map_err(|e| e.to_string())?;
        files.insert(
            Path::new(SRC_DIR).join(format!("{}.rs", ir.model.name)),
            src,
        );
    }
    let summaries: Vec<Summary> = irs.iter().map(Summary::of).collect();
    let lib = rust_module::lib_source(&summaries).map_err(|e| e.to_string())?;
    files.insert(Path::new(SRC_DIR).join("lib.rs"), lib);
    Ok(files)
}

/// Reads every committed IR file.
/// The committed IR of `name`, or `None` when it has not been generated yet.
pub fn committed_ir(root: &Path, name: &str) -> Result<Option<IrFile>, String> {
    let path = Path::new(IR_DIR).join(format!("{name}.json"));
    match std::fs::read_to_string(root.join(&path)) {
        Ok(text) => IrFile::parse(&text)
            .map(Some)
            .map_err(|e| format!("{}: {e}", path.display())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(format!("{}: {e}", path.display())),
    }
}

pub fn committed_irs(root: &Path) -> Result<Vec<IrFile>, String> {
    let mut out = Vec::new();
    for spec in spec_paths(root)? {
        let name = spec
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default();
        let path = Path::new(IR_DIR).join(format!("{name}.json"));
        let text = std::fs::read_to_string(root.join(&path))
            .map_err(|e| format!("{}: {e} (run `cargo xtask gen`)", path.display()))?;
        out.push(IrFile::parse(&text).map_err(|e| format!("{}: {e}", path.display()))?);
    }
    Ok(out)
}

/// Files under `generated/` that no spec accounts for.
fn orphans(root: &Path, expected: &BTreeMap<PathBuf, String>) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for (dir, ext) in [(IR_DIR, "json"), (SRC_DIR, "rs"), (CASADI_C_DIR, "c")] {
        let Ok(entries) = std::fs::read_dir(root.join(dir)) else {
            continue;
        };
        for e in entries.flatten() {
            let rel = Path::new(dir).join(e.file_name());
            if rel.extension().is_some_and(|x| x == ext) && !expected.contains_key(&rel) {
                out.push(rel);
            }
        }
    }
    out.sort();
    out
}

/// Files whose committed content differs from `expected` (missing ones included), and
/// orphans.
pub fn stale_files(root: &Path, expected: &BTreeMap<PathBuf, String>) -> Vec<PathBuf> {
    let mut stale: Vec<PathBuf> = expected
        .iter()
        .filter(|(path, text)| {
            std::fs::read_to_string(root.join(path)).ok().as_deref() != Some(text.as_str())
        })
        .map(|(p, _)| p.clone())
        .collect();
    stale.extend(orphans(root, expected));
    stale
}

pub struct GenOptions {
    pub check: bool,
    /// Models to regenerate; empty means all.
    pub names: Vec<String>,
}

/// Derives one spec: its IR (checked), CasADi's C of the same derivation, and the line
/// `gen` prints about it (mobility, motors, redundant rows).
fn derive_spec(root: &Path, py: &Path, spec: &Spec) -> Result<(IrFile, String, String), Error> {
    let model = model::build(spec).map_err(|e| Error::Usage(e.to_string()))?;
    let mut derived = derive(root, py, &model).map_err(Error::Failed)?;
    check_home(spec, &model, &derived.home_check).map_err(Error::Usage)?;
    let h = &derived.home_check;
    let motors = model.actuated.len();
    let note = format!(
        "{}: mobility {} (rank J {} of {} closure rows{}), {} motor{}: {}",
        spec.name,
        h.mobility,
        h.rank,
        model.closure_rows(),
        if h.redundant_rows.is_empty() {
            String::new()
        } else {
            format!(", redundant rows {:?}", h.redundant_rows)
        },
        motors,
        if motors == 1 { "" } else { "s" },
        match actuation_note(h.mobility, motors) {
            // Legal, and worth a word: the motors can fight each other.
            "over-actuated" => format!(
                "over-actuated ({motors} motors for {} degrees of freedom: they can load each other through the closures, and joint-space control does not apply)",
                h.mobility
            ),
            note => note.to_string(),
        }
    );
    let casadi_c = std::mem::take(&mut derived.casadi_c);
    let ir = assemble(spec, &model, derived);
    rust_module::check_terms(&ir).map_err(|e| Error::Failed(e.to_string()))?;
    Ok((ir, casadi_c, note))
}

/// What `gen` would say of a spec that has no generated code yet: the line it prints
/// (mobility and motors) or the spec's own error (a home pose that does not assemble, a
/// massless joint), from the same derivation, in memory; nothing is written.
pub fn dry_run(root: &Path, spec: &Spec) -> Result<String, Error> {
    let py = python(root).map_err(Error::Failed)?;
    derive_spec(root, &py, spec).map(|(_, _, note)| note)
}

/// The module a generated file is in a user's crate: its file's stem (`src/legs/hopper.rs`
/// is `mod hopper;`), or its folder's name for a `mod.rs`.
fn module_name(out: &Path) -> String {
    let stem = out.file_stem().and_then(|s| s.to_str()).unwrap_or("model");
    if stem == "mod" {
        out.parent()
            .and_then(|p| p.file_name())
            .and_then(|s| s.to_str())
            .unwrap_or(stem)
            .to_string()
    } else {
        stem.to_string()
    }
}

/// Generates the model of a spec that lives outside `leg-models/specs/` (a user's own
/// crate) as one module at `out`: the same derivation and checks as `run`, and the module
/// needs only the `leg-models` crate (`mod my_leg;` in the user's crate). With `check`,
/// writes nothing and fails if `out` differs. A failure writes nothing.
pub fn standalone(root: &Path, spec_path: &Path, out: &Path, check: bool) -> Result<String, Error> {
    let started = std::time::Instant::now();
    // The module's header names the spec: one spelling of its path (relative to the
    // repository when inside it, else absolute), so `--check` does not depend on how the
    // path was typed.
    let spec_path = &spec_path
        .canonicalize()
        .map_err(|e| Error::Usage(format!("{}: cannot read: {e}", spec_path.display())))?;
    let spec = load_spec(root, spec_path).map_err(Error::Usage)?;
    // A path that cannot be written is found before the derivation, not after it.
    if !check {
        crate::cli::check_target(out).map_err(Error::Usage)?;
    }
    let py = python(root).map_err(Error::Failed)?;
    let (ir, _casadi_c, note) = derive_spec(root, &py, &spec)?;
    let src = rust_module::model_source(&ir).map_err(|e| Error::Failed(e.to_string()))?;
    let shown = out.display();
    if check {
        let committed = std::fs::read_to_string(out).unwrap_or_default();
        if committed != src {
            return Err(Error::Failed(format!(
                "{shown} is stale: run `cargo xtask gen --spec {} --out {shown}`",
                spec_path.display()
            )));
        }
        return Ok(format!("{shown} is up to date"));
    }
    crate::cli::write_atomic(out, &src).map_err(Error::Failed)?;
    Ok(format!(
        "{note}\ngenerated {} into {shown} in {:.1} s; in your crate: `mod {};` beside a dependency on leg-models",
        spec.name,
        started.elapsed().as_secs_f64(),
        module_name(out)
    ))
}

/// Runs the generation; returns a report for the user. A bad spec or an unknown name is
/// a usage error (the input's fault, exit code 2); anything else is a failure.
pub fn run(root: &Path, opts: &GenOptions) -> Result<String, Error> {
    let started = std::time::Instant::now();
    let paths = spec_paths(root).map_err(Error::Failed)?;
    let known: Vec<String> = paths
        .iter()
        .filter_map(|p| p.file_stem().and_then(|s| s.to_str()).map(String::from))
        .collect();
    for n in &opts.names {
        if !known.contains(n) {
            return Err(Error::usage(format!(
                "unknown model `{n}` (specs in {SPECS_DIR}/: {})",
                known.join(", ")
            )));
        }
    }
    let selected = |name: &str| opts.names.is_empty() || opts.names.iter().any(|n| n == name);

    // Everything is computed before anything is written. A spec that is not selected and
    // does not validate blocks nothing: its committed code (if any) is kept, and a note
    // says so.
    let mut specs = Vec::new();
    let mut kept_notes = Vec::new();
    let mut kept_irs = Vec::new();
    for p in &paths {
        let name = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
        match load_spec(root, p) {
            Ok(spec) => specs.push(spec),
            Err(e) if selected(name) => return Err(Error::Usage(e)),
            Err(e) => {
                let kept = committed_ir(root, name).map_err(Error::Failed)?;
                kept_notes.push(format!(
                    "note: {name} was not regenerated: its spec does not validate ({e}); {}",
                    if kept.is_some() {
                        "its committed code is kept"
                    } else {
                        "it has no generated code"
                    }
                ));
                kept_irs.extend(kept);
            }
        }
    }
    let py = python(root).map_err(Error::Failed)?;
    let mut irs = Vec::new();
    let mut files = BTreeMap::new();
    let mut notes = Vec::new();
    let mut progress = Progress::ticking(
        specs.iter().filter(|s| selected(&s.name)).count() as u64,
        "deriving",
    );
    for spec in &specs {
        let ir = if selected(&spec.name) {
            progress.message(format!("deriving {} with CasADi", spec.name));
            let (ir, casadi_c, note) = derive_spec(root, &py, spec)?;
            progress.set(notes.len() as u64 + 1);
            notes.push(note);
            files.insert(
                Path::new(CASADI_C_DIR).join(format!("{}.c", spec.name)),
                casadi_c,
            );
            files.insert(
                Path::new(IR_DIR).join(format!("{}.json", spec.name)),
                ir.to_text(),
            );
            ir
        } else {
            let path = Path::new(IR_DIR).join(format!("{}.json", spec.name));
            let text = std::fs::read_to_string(root.join(&path)).map_err(|e| {
                Error::Failed(format!(
                    "{}: {e} (run `cargo xtask gen {}`)",
                    path.display(),
                    spec.name
                ))
            })?;
            IrFile::parse(&text).map_err(|e| Error::Failed(format!("{}: {e}", path.display())))?
        };
        irs.push(ir);
    }
    drop(progress);
    irs.extend(kept_irs);
    irs.sort_by(|a, b| a.model.name.cmp(&b.model.name));
    notes.extend(kept_notes);
    files.extend(rust_files(&irs, selected).map_err(Error::Failed)?);
    let names: Vec<&str> = specs
        .iter()
        .map(|s| s.name.as_str())
        .filter(|n| selected(n))
        .collect();

    if opts.check {
        let mut expected = files;
        if !opts.names.is_empty() {
            // Only the selected models' files are compared.
            expected.retain(|p, _| {
                p.file_stem()
                    .and_then(|s| s.to_str())
                    .is_some_and(|s| selected(s) || s == "lib")
            });
        }
        let mut stale = stale_files(root, &expected);
        if !opts.names.is_empty() {
            stale.retain(|p| expected.contains_key(p));
        }
        if stale.is_empty() {
            return Ok(format!(
                "generated code is up to date ({}; {:.1} s)\n{}",
                names.join(", "),
                started.elapsed().as_secs_f64(),
                notes.join("\n")
            ));
        }
        let list: Vec<String> = stale.iter().map(|p| format!("  {}", p.display())).collect();
        return Err(Error::Failed(format!(
            "generated files are stale or missing:\n{}\nrun `cargo xtask gen` and commit the result",
            list.join("\n")
        )));
    }

    let mut written = Vec::new();
    for (path, text) in &files {
        let full = root.join(path);
        if std::fs::read_to_string(&full).ok().as_deref() == Some(text.as_str()) {
            continue;
        }
        crate::cli::write_atomic(&full, text).map_err(Error::Failed)?;
        written.push(path.display().to_string());
    }
    if opts.names.is_empty() {
        for orphan in orphans(root, &files) {
            std::fs::remove_file(root.join(&orphan))
                .map_err(|e| Error::Failed(format!("{}: {e}", orphan.display())))?;
            written.push(format!("{} (removed)", orphan.display()));
        }
    }
    Ok(format!(
        "{}\ngenerated {} in {:.1} s; {}",
        notes.join("\n"),
        names.join(", "),
        started.elapsed().as_secs_f64(),
        if written.is_empty() {
            "no file changed".to_string()
        } else {
            format!("changed: {}", written.join(", "))
        }
    ))
}

/// The models there are specs for.
pub fn model_names(root: &Path) -> Result<Vec<String>, String> {
    Ok(spec_paths(root)?
        .iter()
        .filter_map(|p| p.file_stem().and_then(|s| s.to_str()).map(String::from))
        .collect())
}

/// The planar legs among [`model_names`] (a spec whose gravity has two entries): what the
/// exports, their cross-checks and the benchmarks take for now.
pub fn planar_model_names(root: &Path) -> Result<Vec<String>, String> {
    model_names_of_dimension(root, 2)
}

/// The spatial legs' names (their exports and cross-checks differ from the planar ones').
pub fn spatial_model_names(root: &Path) -> Result<Vec<String>, String> {
    model_names_of_dimension(root, 3)
}

fn model_names_of_dimension(root: &Path, dimension: usize) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    for (path, name) in spec_paths(root)?.iter().zip(model_names(root)?) {
        let spec = load_spec(root, path)?;
        if spec.file.gravity.get_ref().value.len() == dimension {
            out.push(name);
        }
    }
    Ok(out)
}

pub fn check_model(name: &str, known: &[String]) -> Result<(), Error> {
    if known.iter().any(|k| k == name) {
        Ok(())
    } else {
        Err(Error::usage(format!(
            "unknown model `{name}` (expected one of: {})",
            known.join(", ")
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_module_hint_names_the_file_written_not_the_spec() {
        assert_eq!(module_name(Path::new("src/legs/hopper.rs")), "hopper");
        assert_eq!(module_name(Path::new("src/my_leg/mod.rs")), "my_leg");
        assert_eq!(module_name(Path::new("leg.rs")), "leg");
    }
}
