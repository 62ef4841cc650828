//! Property tests of spec validation: every spec in `leg-models/specs/`, edited at random
//! as a user might get it wrong (a number made NaN, negative, zero or huge; a key removed,
//! renamed or duplicated; a name changed to a reserved word, to another name or to odd
//! characters; a line deleted), either validates and builds, or fails with a located,
//! one-line error. Never a panic.
//!
//! Cases per spec: 100 by default; a long campaign sets `LEGS_SPEC_MUTATIONS`, e.g.
//! `LEGS_SPEC_MUTATIONS=10000 cargo test --release -p xtask --test spec_mutations`.

use std::path::Path;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestRunner};
use xtask::gen;
use xtask::gen::model;
use xtask::gen::spec::{Spec, SpecError};

/// A fixed seed (1 unless `LEGS_PROPTEST_SEED` says otherwise), so that a run can be
/// repeated and the counts the test asserts do not depend on luck.
fn seed() -> RngSeed {
    RngSeed::Fixed(
        std::env::var("LEGS_PROPTEST_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(1),
    )
}

fn cases() -> u32 {
    std::env::var("LEGS_SPEC_MUTATIONS")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(100)
}

#[derive(Clone, Debug)]
enum Mutation {
    /// The `k`-th number becomes this text.
    Number(usize, &'static str),
    /// Line `k` is deleted.
    DeleteLine(usize),
    /// Line `k` is written twice.
    DuplicateLine(usize),
    /// The key of line `k` gets a letter more.
    RenameKey(usize),
    /// The `k`-th quoted string becomes this text.
    Name(usize, &'static str),
}

fn mutation() -> impl Strategy<Value = Vec<Mutation>> {
    let one = prop_oneof![
        (
            0..200usize,
            prop::sample::select(vec![
                "nan", "-1.0", "0.0", "1e308", "inf", "-inf", "-0.0", "1e-320", "\"x\"", "[]",
                "{}",
            ])
        )
            .prop_map(|(k, v)| Mutation::Number(k, v)),
        (0..200usize).prop_map(Mutation::DeleteLine),
        (0..200usize).prop_map(Mutation::DuplicateLine),
        (0..200usize).prop_map(Mutation::RenameKey),
        (
            0..60usize,
            prop::sample::select(vec![
                "base",
                "foot",
                "fn",
                "self",
                "a-b",
                "é",
                "a\\nb",
                "",
                "x_a",
                "Upper",
                "toe_frame",
                "lower_a",
                "upper_a",
                "thigh",
                "a b",
                "\\u0000",
            ])
        )
            .prop_map(|(k, v)| Mutation::Name(k, v)),
    ];
    prop::collection::vec(one, 1..4)
}

/// The byte ranges of the numbers (plain TOML numbers) in `text`.
fn numbers(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        // Skip comments and strings.
        if b[i] == b'#' {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += 1;
            }
            i += 1;
            continue;
        }
        let starts =
            b[i].is_ascii_digit() || (b[i] == b'-' && b.get(i + 1).is_some_and(u8::is_ascii_digit));
        let after_word = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        if starts && !after_word {
            let s = i;
            i += 1;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b"._-+".contains(&b[i])) {
                i += 1;
            }
            out.push((s, i));
            continue;
        }
        i += 1;
    }
    out
}

/// The byte ranges of the insides of the quoted strings in `text` (outside comments).
fn strings(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'#' {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        if b[i] == b'"' {
            let s = i + 1;
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += 1;
            }
            out.push((s, i.min(b.len())));
        }
        i += 1;
    }
    out
}

fn apply(text: &str, m: &Mutation) -> String {
    let replace = |ranges: Vec<(usize, usize)>, k: usize, with: &str| match ranges
        .get(k % ranges.len().max(1))
    {
        Some(&(s, e)) => format!("{}{with}{}", &text[..s], &text[e..]),
        None => text.to_string(),
    };
    let lines: Vec<&str> = text.lines().collect();
    let line = |k: usize| k % lines.len().max(1);
    match *m {
        Mutation::Number(k, v) => replace(numbers(text), k, v),
        Mutation::Name(k, v) => replace(strings(text), k, v),
        Mutation::DeleteLine(k) => {
            let mut l = lines.clone();
            if !l.is_empty() {
                l.remove(line(k));
            }
            l.join("\n")
        }
        Mutation::DuplicateLine(k) => {
            let mut l = lines.clone();
            if !l.is_empty() {
                let i = line(k);
                l.insert(i, lines[i]);
            }
            l.join("\n")
        }
        Mutation::RenameKey(k) => {
            let mut l: Vec<String> = lines.iter().map(|s| s.to_string()).collect();
            if let Some(s) = l.get_mut(line(k)) {
                if let Some(eq) = s.find('=') {
                    s.insert(eq.saturating_sub(1).min(s.len()), 'z');
                }
            }
            l.join("\n")
        }
    }
}

/// A located error: the file, a line and column inside the text, a field, one line.
fn located(e: &SpecError, path: &Path, text: &str) -> Result<(), TestCaseError> {
    let shown = e.to_string();
    prop_assert_eq!(&e.file, path);
    prop_assert!(
        e.line >= 1 && e.line <= text.lines().count().max(1) + 1,
        "line of {}",
        shown
    );
    prop_assert!(e.column >= 1, "column of {}", shown);
    prop_assert!(!e.field.is_empty(), "field of {}", shown);
    prop_assert!(
        !shown.contains('\n') && !shown.contains('\r'),
        "not one line: {:?}",
        shown
    );
    Ok(())
}

#[test]
fn edited_specs_validate_or_fail_located() {
    let root = gen::workspace_root();
    let mut checked = 0;
    for spec_path in gen::spec_paths(&root).unwrap() {
        let rel = spec_path.strip_prefix(&root).unwrap().to_path_buf();
        let original = std::fs::read_to_string(&spec_path).unwrap();
        let mut runner = TestRunner::new(Config {
            cases: cases(),
            failure_persistence: None,
            rng_seed: seed(),
            ..Config::default()
        });
        // How many edited specs were accepted and refused: both must happen, or the edits
        // test nothing.
        let outcomes = std::cell::Cell::new((0u32, 0u32));
        let result = runner.run(&mutation(), |ms| {
            let text = ms.iter().fold(original.clone(), |t, m| apply(&t, m));
            let (ok, refused) = outcomes.get();
            match Spec::parse(&rel, text.clone()).map(|spec| model::build(&spec)) {
                Err(e) | Ok(Err(e)) => {
                    located(&e, &rel, &text)?;
                    outcomes.set((ok, refused + 1));
                }
                Ok(Ok(_)) => outcomes.set((ok + 1, refused)),
            }
            Ok(())
        });
        if let Err(e) = result {
            panic!("{}: {e}", rel.display());
        }
        let (ok, refused) = outcomes.get();
        assert!(
            ok > 0 && refused > cases() / 4,
            "{}: {ok} edited specs accepted, {refused} refused",
            rel.display()
        );
        checked += 1;
    }
    assert!(checked >= 5, "only {checked} specs");
}
