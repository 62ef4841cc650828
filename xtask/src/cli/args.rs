//! The command line of `cargo xtask`, declared once with clap's derive API: `xtask`
//! parses it (so a misspelt flag is refused before anything is built) and the `legs`
//! binary behind `sim` and `eval` parses the same arguments again.
//!
//! Clap's errors are several lines (usage, tips); ours are one line on stderr with exit
//! code 2, so [`parse`] folds them into one.
//!
//! The doc comments are clap's help text, written for a terminal (`<connect>` is MJCF's
//! element, not HTML), so rustdoc's HTML check does not apply to them.
#![allow(rustdoc::invalid_html_tags)]

use std::path::PathBuf;

use clap::error::ErrorKind;
use clap::{Args, Parser, Subcommand, ValueEnum};

use crate::cli::Error;

#[derive(Parser, Debug)]
#[command(
    name = "cargo xtask",
    bin_name = "cargo xtask",
    about = "Closed-chain leg models: generation (spec → CasADi → Rust), simulation, checks",
    allow_negative_numbers = true
)]
pub struct Xtask {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Derive the models (CasADi) and write generated/
    Gen(GenArgs),
    /// Simulate a leg under a controller and write a report
    Sim(SimArgs),
    /// Print every term of a model at one state
    Eval(EvalArgs),
    /// Compare leg designs over their workspaces: singularities, force and speed
    /// capacity, foot inertia, impact mitigation; writes analysis.json, a CSV per grid
    /// and report.html
    Analyze(AnalyzeArgs),
    /// Write the leg for MuJoCo (MJCF, closures as <connect>) or URDF (spanning tree,
    /// closure frames NAME_a / NAME_b)
    Export(ExportArgs),
    /// Criterion benchmarks beside CasADi's C (and Pinocchio), or instruction counts
    Bench(BenchArgs),
    /// The geometries: sizes, mobility, actuated joints
    List,
    /// Write leg-models/specs/NAME.toml, a commented spec to start from
    New(NewArgs),
    /// Write a spatial spec from a MuJoCo MJCF file (bodies, joints, inertias, <connect>
    /// closures, motors, springs), then `cargo xtask gen NAME` generates it
    Import(ImportArgs),
    /// Every check CI runs: formatting, `gen --check`, the workspace tests (snapshots
    /// must be reviewed), the MuJoCo and Pinocchio cross-checks, instruction budgets,
    /// the no_std build, clippy
    Test,
}

#[derive(Args, Debug)]
pub struct GenArgs {
    /// Regenerate in memory and fail if the committed files differ (names the command
    /// to run)
    #[arg(long)]
    pub check: bool,
    /// Models to regenerate (default: every spec in leg-models/specs/)
    #[arg(value_name = "NAME", conflicts_with = "spec")]
    pub names: Vec<String>,
    /// A spec outside leg-models/specs/ (a user's own crate): generate its model as one
    /// Rust module that depends on `leg-models` only; needs --out
    #[arg(long, value_name = "FILE", requires = "out")]
    pub spec: Option<PathBuf>,
    /// Where the module of --spec goes (with --check: the file to compare with)
    #[arg(long, value_name = "FILE", requires = "spec")]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// The model (a spec in leg-models/specs/)
    pub model: String,
    /// The file format
    #[arg(long, value_enum)]
    pub format: ExportFormat,
    /// Where to write (default: standard output)
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// MuJoCo's MJCF: the spanning tree, closures as equality <connect> constraints
    Mjcf,
    /// URDF: the spanning tree, closure points as fixed frames NAME_a / NAME_b
    Urdf,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Also build and time Pinocchio's pipeline (C++) from each spec
    #[arg(long)]
    pub pinocchio: bool,
    /// Also time a simulated second of each standing, pushed floating robot beside
    /// MuJoCo's `mj_step` at the same 0.5 ms step (the same recorded torques and push)
    #[arg(long)]
    pub mujoco: bool,
    /// Instructions per call of the hot paths (callgrind), against the budgets and
    /// beside CasADi's C, instead of the criterion timings
    #[arg(long, conflicts_with_all = ["pinocchio", "mujoco"])]
    pub instructions: bool,
    /// Rewrite tests/instruction-budgets.json with today's counts
    #[arg(long, conflicts_with_all = ["pinocchio", "mujoco"])]
    pub update_budgets: bool,
    /// Models to time (default: every one); with --pinocchio, Pinocchio's programs are
    /// built and run for these only
    #[arg(value_name = "MODEL", conflicts_with_all = ["instructions", "update_budgets"])]
    pub models: Vec<String>,
}

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The MJCF or URDF file
    pub file: PathBuf,
    /// The leg's name: a plain identifier (lower case, digits, underscores)
    #[arg(long)]
    pub name: String,
    /// Hold the body of the file's free joint as the base (its pose as written); without
    /// it, a file whose top body has a free joint is imported as a floating robot (that
    /// body a link on `joint = "free"`)
    #[arg(long)]
    pub fix_base: bool,
    /// Import one subtree: the body (with its joint) hanging from the base, e.g. one leg
    /// of a robot; closures and motors outside it are left out, each said
    #[arg(long, value_name = "BODY")]
    pub root: Option<String>,
    /// The body that carries the foot point
    #[arg(long, value_name = "BODY")]
    pub foot: String,
    /// The foot point in that body's frame, x,y,z in m (default: its origin)
    #[arg(long, value_name = "X,Y,Z")]
    pub foot_point: Option<String>,
    /// The home pose from this <key> (default: qpos0, the pose as written, where every
    /// <connect> is closed by MuJoCo's rule)
    #[arg(long, value_name = "KEY")]
    pub keyframe: Option<String>,
    /// The home pose, one value per coordinate (rad or m; a ball joint's three angles),
    /// instead of the file's: a URDF's is every joint at 0, where its loops may be open
    #[arg(long, value_name = "Q,...", allow_hyphen_values = true)]
    pub home: Option<String>,
    /// URDF: a loop closure, the point on LINK_A (x,y,z in its frame, default its origin)
    /// held to the point on LINK_B (default: where the first point is in the pose as
    /// written); repeat for each loop
    #[arg(long, value_name = "NAME=LINK_A[:X,Y,Z]/LINK_B[:X,Y,Z]")]
    pub closure: Vec<String>,
    /// URDF: a motor on JOINT with gear ratio GEAR (default 1), beside the file's
    /// transmissions; repeat for each motor
    #[arg(long, value_name = "JOINT[:GEAR]")]
    pub motor: Vec<String>,
    /// A ground contact NAME at the point X,Y,Z of BODY's frame (m), friction 1 (MuJoCo's
    /// default; edit the spec for another); repeat for each contact point
    #[arg(long, value_name = "NAME=BODY:X,Y,Z", allow_hyphen_values = true)]
    pub contact: Vec<String>,
    /// Where to write (default: leg-models/specs/NAME.toml)
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Replace the spec if it exists
    #[arg(long)]
    pub force: bool,
}

#[derive(Args, Debug)]
pub struct NewArgs {
    /// The new model's name: a plain identifier (lower case, digits, underscores)
    pub name: String,
    /// A spatial leg (a five-bar on a hip abduction motor, with a toe contact) instead
    /// of a planar five-bar
    #[arg(long)]
    pub spatial: bool,
}

/// `cargo xtask sim`.
#[derive(Args, Debug, Clone)]
#[command(
    allow_negative_numbers = true,
    after_help = "writes trajectory.csv, summary.json and report.html (open it in a browser)"
)]
pub struct SimArgs {
    /// The model (default: minitaur)
    pub model: Option<String>,
    /// Default: foot-fl where the motors can place the foot (two or more motors that
    /// determine the leg), else joint-fl on the motors, else passive; the summary says why
    #[arg(long, value_enum, value_name = "C")]
    pub controller: Option<ControllerArg>,
    /// Default: step for foot controllers, sine for joint controllers (spin with one
    /// motor), hold for passive
    #[arg(long, value_enum, value_name = "T")]
    pub trajectory: Option<TrajectoryArg>,
    /// Motor speed of the spin trajectory in rad/s (1 turn/s by default); on a leg whose
    /// body moves along the ground, the forward hopping speed in m/s (default: hop in place)
    #[arg(long, value_name = "V",
          value_parser = number("a speed of at most 1000 (rad/s, or m/s on the ground)", |x| x.abs() <= 1000.0))]
    pub speed: Option<f64>,
    /// Simulated time in s
    #[arg(long, value_name = "S", default_value_t = 3.0,
          value_parser = number("a duration in (0, 600] s", |x| x > 0.0 && x <= 600.0))]
    pub duration: f64,
    /// Step in s; torques are updated once per step (default 0.001; 0.0005 with
    /// `--feet free`, whose first-order step needs it on Cassie)
    #[arg(long, value_name = "S",
          value_parser = number("a step in (0, 0.05] s", |x| x > 0.0 && x <= 0.05))]
    pub dt: Option<f64>,
    /// Stiffness of the error dynamics in 1/s² (default 400 foot, 100 joint); k_d = 2√k_p;
    /// PD gains are scaled by the leg's inertia at home
    #[arg(long, value_name = "K",
          value_parser = number("a positive stiffness of at most 1e9 1/s²", |x| x > 0.0 && x <= 1e9))]
    pub kp: Option<f64>,
    /// Motor limit in N m (default none); saturations are counted
    #[arg(long, value_name = "N", value_parser = number("a positive number of N m", |x| x > 0.0))]
    pub torque_limit: Option<f64>,
    /// Where to write (default target/sim/MODEL)
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Write every N-th sample to trajectory.csv (the first and last always); the file
    /// holds at most a million rows, so a longer run needs a larger N
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u64).range(1..=1_000_000_000))]
    pub every: u64,
    /// On a leg with contacts: the commanded apex height of the body in m (default the
    /// home pose's height + 5 cm); the leg hops to it
    #[arg(long, value_name = "H", value_parser = number("a height in m", |x| x.abs() <= 1e3))]
    pub apex: Option<f64>,
    /// On a floating robot (it stands under the balance QP): the push on its body, a force
    /// `FX,FY,FZ` in N in the world (z up, the robot standing at the origin facing +x);
    /// default 5 % of its weight sideways (+y); `0,0,0` for none
    #[arg(long, value_name = "FX,FY,FZ", allow_hyphen_values = true, value_parser = numbers_text)]
    pub push: Option<String>,
    /// On a floating robot: when the push starts, in s (default 0.5)
    #[arg(long, value_name = "S",
          value_parser = number("a time in [0, 600] s", |x| (0.0..=600.0).contains(&x)))]
    pub push_at: Option<f64>,
    /// On a floating robot: how long the push lasts, in s (default 0.1)
    #[arg(long, value_name = "S",
          value_parser = number("a duration in (0, 600] s", |x| x > 0.0 && x <= 600.0))]
    pub push_for: Option<f64>,
    /// On a floating robot: `held` keeps every contact on the ground where it stands (RK4;
    /// the run stops where a foot would lift or slip), `free` lets every foot lift, slip
    /// and land (time stepping, each step's contact modes from one complementarity
    /// solve); default held
    #[arg(long, value_enum, value_name = "F")]
    pub feet: Option<FeetArg>,
    /// On a leg with contacts: serve the hopping controller's torques on stdin/stdout
    /// instead of simulating (one line `t q… q̇… (on_ground anchor)…` in, one line of
    /// torques out), for the MuJoCo cross-check's closed loop
    #[arg(long, hide = true)]
    pub serve: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ControllerArg {
    /// Feedback linearization of the foot position
    FootFl,
    /// PD on the foot position with gravity compensation
    FootPd,
    /// Feedback linearization of the motor angles
    JointFl,
    /// PD on the motor angles with gravity compensation
    JointPd,
    /// No torque
    Passive,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FeetArg {
    /// Every contact held where it stands (the run stops where one would lift or slip)
    Held,
    /// Every foot free to lift, slip and land
    Free,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TrajectoryArg {
    /// An ellipse under the hip, 6 cm × 3 cm at 2 Hz (foot controllers)
    Step,
    /// 0.1 rad, 1 Hz sinusoids around the home pose (joint controllers)
    Sine,
    /// The motors turning at --speed (joint controllers)
    Spin,
    /// A minimum-jerk move (joint controllers)
    MinJerk,
    /// Hold the start
    Hold,
}

/// `cargo xtask eval`.
#[derive(Args, Debug, Clone)]
#[command(allow_negative_numbers = true)]
pub struct EvalArgs {
    /// The model
    pub model: String,
    /// Joint angles (rad), one per joint, comma-separated; with --assemble, the actuated
    /// angles only
    #[arg(
        long,
        value_name = "Q1,Q2,…",
        allow_hyphen_values = true,
        required = true,
        value_parser = numbers_text
    )]
    pub q: String,
    /// Joint rates (rad/s), default zero; with --assemble, the actuated rates only
    #[arg(long, value_name = "QD1,…", allow_hyphen_values = true, value_parser = numbers_text)]
    pub qd: Option<String>,
    /// Motor torques (N m), one per actuated joint, default zero
    #[arg(long, value_name = "U1,…", allow_hyphen_values = true, value_parser = numbers_text)]
    pub u: Option<String>,
    /// Solve the loops for the passive joints first: by default following the assembly
    /// branch of the spec's home pose while the motors move from their home angles to
    /// --q (an error says where that branch ends); with --guess, from that pose
    #[arg(long, conflicts_with = "project")]
    pub assemble: bool,
    /// Move --q onto the closures first with every joint free (the smallest
    /// correction), and --qd onto their velocity constraints: for a pose written
    /// roughly, or a leg whose motors over-determine it (where --assemble does not apply)
    #[arg(long)]
    pub project: bool,
    /// With --assemble: a starting pose, one angle per joint (rad); it picks the
    /// assembly mode
    #[arg(
        long,
        value_name = "Q1,…",
        allow_hyphen_values = true,
        requires = "assemble",
        value_parser = numbers_text
    )]
    pub guess: Option<String>,
    /// The plastic impact of this contact point (a `[[contacts]]` name) landing at this
    /// state with the others in the air: `impact` holds qd_plus, impulses (the ground's,
    /// tangential and normal), closure_impulses, energy_lost and the mode after (stick or
    /// slide)
    #[arg(long, value_name = "CONTACT")]
    pub impact: Option<String>,
    /// Every contact point held where it is (sticking): `stance` holds that forward
    /// dynamics' qdd, closure forces F and contact forces (per contact, the ground's
    /// frame: tangential, then normal); with --project, --qd is also moved onto the held
    /// contacts (their velocities zero)
    #[arg(long)]
    pub stance: bool,
    /// Also the derivatives of forward dynamics: dqdd_dq, dqdd_dqd, dqdd_du, dF_dq,
    /// dF_dqd, dF_du (arrays of rows), exact, from the generated directional terms
    #[arg(long)]
    pub derivatives: bool,
    /// One JSON object: q, qd, u, M, N, G, J, Jdot_qdot, qdd, F, A_tilde, b_tilde, foot,
    /// foot_jacobian, kinetic, potential, phi, contacts (positions, gaps), impact, stance
    /// (matrices as arrays of rows), and with --derivatives the six derivatives; a term
    /// that cannot be computed at this state is null, and `errors` says why
    #[arg(long)]
    pub json: bool,
}

/// `cargo xtask analyze`.
#[derive(Args, Debug, Clone)]
#[command(
    allow_negative_numbers = true,
    after_help = "writes analysis.json, one CSV per design's grid and report.html (open it in a browser)"
)]
pub struct AnalyzeArgs {
    /// The models to compare (specs in leg-models/specs/)
    #[arg(required = true, value_name = "MODEL")]
    pub models: Vec<String>,
    /// Change a parameter before analysing (`lower_a_length_x=0.22`); repeat for more;
    /// applies to every model given
    #[arg(long = "set", value_name = "NAME=VALUE", allow_hyphen_values = true)]
    pub sets: Vec<String>,
    /// Sweep a parameter over N designs from FROM to TO (inclusive), analysed in
    /// parallel; one model only. NAME may list parameters that move together
    /// (`lower_a_length_x,lower_b_length_x=0.16:0.26:6`)
    #[arg(long, value_name = "NAME=FROM:TO:N", allow_hyphen_values = true)]
    pub sweep: Option<String>,
    /// Joint torque limits in N m (after the gearbox): one value for every motor or one
    /// per motor, comma-separated (default: 1 N m at the motor times its gear ratio)
    #[arg(long, value_name = "N[,N…]", value_parser = numbers_text)]
    pub torque_limit: Option<String>,
    /// Joint speed limits in rad/s (after the gearbox): one value or one per motor
    /// (default: 100 rad/s at the motor over its gear ratio)
    #[arg(long, value_name = "W[,W…]", value_parser = numbers_text)]
    pub speed_limit: Option<String>,
    /// Mass of the body the hip is on for the impact mitigation factor, kg (default ten
    /// times the leg's mass); a leg with body joints of its own uses its own body
    #[arg(long, value_name = "KG",
          value_parser = number("a mass in (0, 1e6] kg", |x| x > 0.0 && x <= 1e6))]
    pub body_mass: Option<f64>,
    /// Analyse every assembly branch at the home pose's motor angles, each a design
    /// (default: the home pose's branch only); not with --sweep
    #[arg(long)]
    pub branches: bool,
    /// Motor angle range of the workspace, rad, for every motor (default: no limit)
    #[arg(long, value_name = "LO:HI", allow_hyphen_values = true)]
    pub motor_range: Option<String>,
    /// Grid nodes per side
    #[arg(long, value_name = "N", default_value_t = 200,
          value_parser = clap::value_parser!(u32).range(2..=2000))]
    pub nodes: u32,
    /// The plane a spatial leg's workspace grid lies in, through its stance foot: `xz`
    /// (sagittal, the default), `yz` (frontal) or `xy` (transverse); not for a planar leg
    #[arg(long, value_name = "PLANE", value_parser = ["xz", "yz", "xy"])]
    pub slice: Option<String>,
    /// Also measure a spatial leg's workspace as a volume: the continuation over a cube of
    /// N³ foot positions around the hip (N from 2 to 100; no measures at the nodes)
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(2..=100))]
    pub volume: Option<u32>,
    /// Where to write (default target/analyze)
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// A list of numbers may start with a minus sign, but a flag where the list should be
/// (`--q --json`) is a missing value, not a list. The numbers are checked against the
/// model's sizes where the model is known (`cli::numbers`).
fn numbers_text(text: &str) -> Result<String, String> {
    if text.starts_with("--") {
        Err(format!(
            "expected comma-separated numbers, got the flag `{text}` (is the value missing?)"
        ))
    } else {
        Ok(text.to_string())
    }
}

/// A value parser for a finite number that satisfies `ok`; `expected` says what it must be.
fn number(
    expected: &'static str,
    ok: fn(f64) -> bool,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |text: &str| match text.parse::<f64>() {
        Ok(x) if x.is_finite() && ok(x) => Ok(x),
        Ok(_) => Err(format!("expected {expected}")),
        Err(_) => Err(format!("not a number: expected {expected}")),
    }
}

/// What [`parse`] found: arguments to run, or help that was printed.
pub enum Parsed<T> {
    Run(T),
    Printed,
}

/// The longest argument taken (a path, a list of numbers, a sweep).
pub const MAX_ARGUMENT: usize = 4096;

/// Parses `args` (without the program name). `--help` prints and gives `Printed`; a bad
/// argument is a one-line usage error (exit code 2) that keeps clap's tip (the flag or
/// command it probably meant) and points at `--help`.
pub fn parse<T: Parser>(args: &[String]) -> Result<Parsed<T>, Error> {
    // No argument of ours holds a newline, a line separator or another control character;
    // one that does is refused before clap echoes it, and shown escaped and short.
    let breaks_a_line = |c: char| c.is_control() || matches!(c, '\u{2028}' | '\u{2029}');
    if let Some(bad) = args.iter().find(|a| a.chars().any(breaks_a_line)) {
        return Err(Error::usage(format!(
            "argument `{}` holds a control character (see `cargo xtask --help`)",
            crate::cli::shown(bad)
        )));
    }
    // Nor is one of them long: clap would echo it whole.
    if let Some(bad) = args.iter().find(|a| a.chars().count() > MAX_ARGUMENT) {
        return Err(Error::usage(format!(
            "argument `{}` has {} characters, more than {MAX_ARGUMENT}",
            crate::cli::shown(bad),
            bad.chars().count()
        )));
    }
    let argv = std::iter::once("cargo xtask".to_string()).chain(args.iter().cloned());
    match T::try_parse_from(argv) {
        Ok(t) => Ok(Parsed::Run(t)),
        Err(e) => match e.kind() {
            ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
                print!("{}", e.render());
                Ok(Parsed::Printed)
            }
            ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
                Err(Error::usage("no command given (see `cargo xtask --help`)"))
            }
            _ => Err(Error::usage(one_line(&e.render().to_string(), args))),
        },
    }
}

/// Clap's message, its tips, and where to read more, on one line.
fn one_line(rendered: &str, args: &[String]) -> String {
    let mut text = String::new();
    for line in rendered.lines().map(str::trim) {
        if line.is_empty()
            || line.starts_with("Usage:")
            || line.starts_with("For more information")
            // Clap's advice for positional values that look like flags: ours never are.
            || line.starts_with("tip: to pass")
        {
            continue;
        }
        let line = line.strip_prefix("error: ").unwrap_or(line);
        let line = match line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            Some(inner) => inner,
            None => line,
        };
        if !text.is_empty() {
            text.push_str(if text.ends_with(':') { " " } else { "; " });
        }
        text.push_str(line);
    }
    // The subcommand's own help, where there is one.
    let help = match args.first().map(String::as_str) {
        Some(c) if !c.starts_with('-') && known_command(c) => format!("cargo xtask {c} --help"),
        _ => "cargo xtask --help".to_string(),
    };
    text.push_str(&format!(" (see `{help}`)"));
    text
}

fn known_command(name: &str) -> bool {
    use clap::CommandFactory;
    Xtask::command()
        .get_subcommands()
        .any(|c| c.get_name() == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(a: &[&str]) -> Vec<String> {
        a.iter().map(|s| s.to_string()).collect()
    }

    fn refused(a: &[&str]) -> String {
        match parse::<Xtask>(&args(a)) {
            Err(Error::Usage(m)) => m,
            Err(Error::Failed(m)) => panic!("{a:?}: a failure, not a usage error: {m}"),
            Ok(_) => panic!("{a:?} was accepted"),
        }
    }

    fn sim(a: &[&str]) -> SimArgs {
        match parse::<Xtask>(&args(a)) {
            Ok(Parsed::Run(Xtask {
                command: Command::Sim(s),
            })) => s,
            _ => panic!("{a:?} is not a sim command"),
        }
    }

    #[test]
    fn both_value_forms_and_negative_numbers() {
        let a = sim(&["sim", "atrias", "--dt=0.002", "--speed", "-3", "--kp", "50"]);
        assert_eq!(a.model.as_deref(), Some("atrias"));
        assert_eq!((a.dt, a.speed, a.kp), (Some(0.002), Some(-3.0), Some(50.0)));
        assert_eq!(a.duration, 3.0);
        let Ok(Parsed::Run(Xtask {
            command: Command::Eval(e),
        })) = parse::<Xtask>(&args(&[
            "eval",
            "minitaur",
            "--q",
            "-0.1,0.2",
            "--assemble",
        ]))
        else {
            panic!("eval not parsed");
        };
        assert_eq!((e.q.as_str(), e.assemble), ("-0.1,0.2", true));
    }

    #[test]
    fn a_misspelt_flag_or_command_gets_a_suggestion_on_one_line() {
        let m = refused(&["sim", "--sped", "2"]);
        assert!(m.contains("--sped") && m.contains("--speed"), "{m}");
        assert!(m.ends_with("(see `cargo xtask sim --help`)"), "{m}");
        assert!(!m.contains('\n'));
        let m = refused(&["sim", "--controller", "foot-f"]);
        assert!(m.contains("foot-f") && m.contains("foot-fl"), "{m}");
        let m = refused(&["exprot"]);
        assert!(m.contains("exprot") && m.contains("export"), "{m}");
        assert!(m.ends_with("(see `cargo xtask --help`)"), "{m}");
    }

    #[test]
    fn values_are_checked_with_what_is_expected() {
        let m = refused(&["sim", "--dt", "-1"]);
        assert!(
            m.contains("-1") && m.contains("expected a step in (0, 0.05] s"),
            "{m}"
        );
        let m = refused(&["sim", "--duration", "nan"]);
        assert!(m.contains("expected a duration"), "{m}");
        let m = refused(&["eval", "minitaur", "--q", "1,2,3,4", "--guess", "1,2,3,4"]);
        assert!(m.contains("--assemble"), "{m}");
        let m = refused(&["bench", "--pinocchio", "--instructions"]);
        assert!(m.contains("cannot be used with"), "{m}");
        let m = refused(&["bench", "--mujoco", "--update-budgets"]);
        assert!(m.contains("cannot be used with"), "{m}");
        let m = refused(&["eval", "minitaur", "--q", "--json"]);
        assert!(m.contains("got the flag `--json`"), "{m}");
        let m = refused(&["export", "minitaur"]);
        assert!(m.contains("--format"), "{m}");
    }

    #[test]
    fn input_cannot_break_the_line() {
        let m = refused(&["gen", "--a\nb"]);
        assert!(!m.contains('\n') && m.contains("\\n"), "{m}");
    }

    #[test]
    fn every_subcommand_has_help() {
        use clap::CommandFactory;
        Xtask::command().debug_assert();
        for c in Xtask::command().get_subcommands() {
            assert!(c.get_about().is_some(), "`{}` has no help", c.get_name());
        }
    }
}
