//! Hoisting parameter-only work: what moves into `prepare`, what stays, that two
//! functions share one prepared value, and that the results are the same bits (both
//! forms interpreted).

use codegen::hoist::hoist;
use codegen::ir::{BinaryOp, Input, InputShape, Instr, Output, OutputKind, Program, UnaryOp};

const FIELDS: [&str; 3] = ["mass", "length", "inertia"];

/// Interprets `prog` with `x` the state vector and `p` the parameter struct's elements
/// (fields, then prepared values).
fn eval(prog: &Program, x: &[f64], p: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = Vec::new();
    for i in &prog.instructions {
        let r = match *i {
            Instr::Input { input, index } => match &prog.inputs[input].shape {
                InputShape::Vector { .. } => x[index],
                InputShape::Struct { .. } => p[index],
            },
            Instr::Const(c) => c,
            Instr::Unary(UnaryOp::Sin, a) => v[a].sin(),
            Instr::Unary(UnaryOp::Cos, a) => v[a].cos(),
            Instr::Unary(UnaryOp::Neg, a) => -v[a],
            Instr::Binary(op, a, b) => match op {
                BinaryOp::Add => v[a] + v[b],
                BinaryOp::Sub => v[a] - v[b],
                BinaryOp::Mul => v[a] * v[b],
                _ => unimplemented!("not in these programs"),
            },
            Instr::Unary(..) => unimplemented!("not in these programs"),
        };
        v.push(r);
    }
    prog.outputs
        .iter()
        .flat_map(|o| o.entries.iter().map(|&e| v[e]))
        .collect()
}

fn program(name: &str, instructions: Vec<Instr>, entries: Vec<usize>) -> Program {
    Program {
        name: name.into(),
        inputs: vec![
            Input {
                name: "q".into(),
                shape: InputShape::Vector { len: 1 },
            },
            Input {
                name: "p".into(),
                shape: InputShape::Struct {
                    type_name: "Params".into(),
                    fields: FIELDS.iter().map(|f| f.to_string()).collect(),
                    prepared: 0,
                },
            },
        ],
        outputs: vec![Output {
            name: "y".into(),
            kind: OutputKind::Vector,
            rows: entries.len(),
            cols: 1,
            entries,
        }],
        instructions,
    }
}

use BinaryOp::{Add, Mul};
use Instr::{Binary, Input as In, Unary};

/// `y = [m l cos q + I + m l², m l sin q]` and `z = [m l]`.
fn programs() -> Vec<Program> {
    let first = program(
        "first",
        vec![
            In { input: 0, index: 0 }, // 0 q
            In { input: 1, index: 0 }, // 1 m
            In { input: 1, index: 1 }, // 2 l
            In { input: 1, index: 2 }, // 3 I
            Binary(Mul, 1, 2),         // 4 m l (parameters only)
            Unary(UnaryOp::Cos, 0),    // 5
            Binary(Mul, 4, 5),         // 6 m l cos q
            Binary(Mul, 4, 2),         // 7 m l²
            Binary(Add, 3, 7),         // 8 I + m l² (parameters only)
            Binary(Add, 6, 8),         // 9
            Unary(UnaryOp::Sin, 0),    // 10
            Binary(Mul, 10, 4),        // 11
        ],
        vec![9, 11],
    );
    let second = program(
        "second",
        vec![
            In { input: 1, index: 1 }, // 0 l
            In { input: 1, index: 0 }, // 1 m
            Binary(Mul, 1, 0),         // 2 m l, the same value as `first`'s
        ],
        vec![2],
    );
    vec![first, second]
}

#[test]
fn parameter_only_values_move_to_prepare_once() {
    let h = hoist(&programs(), "p", "Values");
    // m l and I + m l² (m l², read only by I + m l², is not read per state).
    assert_eq!(h.prepare.outputs[0].rows, 2, "{:?}", h.prepare);
    assert!(matches!(
        &h.prepare.inputs[0].shape,
        InputShape::Struct { type_name, prepared: 0, .. } if type_name == "Values"
    ));
    for prog in &h.programs {
        let InputShape::Struct { prepared, .. } = &prog.inputs[1].shape else {
            panic!("the parameter input stays a struct")
        };
        assert_eq!(*prepared, 2);
    }
    // What is left (what the outputs need; the rest is not emitted) reads the prepared
    // values and computes no product of parameters.
    let first = &h.programs[0];
    let mut live = vec![false; first.instructions.len()];
    for &e in &first.outputs[0].entries {
        live[e] = true;
    }
    for k in (0..live.len()).rev() {
        if live[k] {
            first.instructions[k]
                .operands()
                .for_each(|a| live[a] = true);
        }
    }
    for (k, instr) in first.instructions.iter().enumerate() {
        if !live[k] {
            continue;
        }
        if let Instr::Binary(_, a, b) = *instr {
            let param = |v: usize| {
                matches!(
                    first.instructions[v],
                    Instr::Input { input: 1, .. } | Instr::Const(_)
                )
            };
            assert!(!(param(a) && param(b)), "{instr:?} is parameter-only");
        }
    }
    // Both functions read m l from the same slot.
    let slot_read =
        |prog: &Program, entry: usize| prog.instructions[prog.outputs[0].entries[entry]];
    assert_eq!(
        slot_read(&h.programs[1], 0),
        Instr::Input { input: 1, index: 3 }
    );
    assert!(h.programs[0]
        .instructions
        .contains(&Instr::Input { input: 1, index: 3 }));
}

#[test]
fn hoisted_programs_give_the_same_bits() {
    let originals = programs();
    let h = hoist(&originals, "p", "Values");
    for (q, values) in [
        (0.3, [1.5, 0.25, 0.01]),
        (-2.0, [0.0, -0.0, 3.0]),
        (f64::NAN, [1.0, f64::INFINITY, 2.0]),
    ] {
        let mut p = values.to_vec();
        p.extend(eval(&h.prepare, &[], &values));
        for (before, after) in originals.iter().zip(&h.programs) {
            let (a, b) = (eval(before, &[q], &values), eval(after, &[q], &p));
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a), bits(&b), "{}", before.name);
        }
    }
}

#[test]
fn programs_without_parameters_are_unchanged() {
    let mut prog = program(
        "state_only",
        vec![In { input: 0, index: 0 }, Unary(UnaryOp::Sin, 0)],
        vec![1],
    );
    prog.inputs.truncate(1);
    let h = hoist(std::slice::from_ref(&prog), "p", "Values");
    assert_eq!(h.programs[0], prog);
    assert_eq!(h.prepare.outputs[0].rows, 0);
}

#[test]
fn prepare_reads_only_the_fields_of_hoisted_values() {
    // Every field is in a hoisted value of `programs()`.
    assert_eq!(hoist(&programs(), "p", "Values").reads, [true; 3]);
    // `y = [I sin q, m l]`: I multiplies a state-dependent value only, so changing it
    // leaves the prepared values as they are.
    let prog = program(
        "inertia_per_state",
        vec![
            In { input: 0, index: 0 }, // 0 q
            In { input: 1, index: 0 }, // 1 m
            In { input: 1, index: 1 }, // 2 l
            In { input: 1, index: 2 }, // 3 I
            Unary(UnaryOp::Sin, 0),    // 4
            Binary(Mul, 3, 4),         // 5 I sin q
            Binary(Mul, 1, 2),         // 6 m l (parameters only)
        ],
        vec![5, 6],
    );
    let h = hoist(&[prog], "p", "Values");
    assert_eq!(h.reads, [true, true, false]);
    // The prepared values indeed do not depend on I.
    let with = |inertia: f64| eval(&h.prepare, &[], &[1.5, 0.25, inertia]);
    assert_eq!(with(0.01), with(7.0));
}
