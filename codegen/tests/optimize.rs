//! The exact simplifications: fewer instructions, and bit-identical results for every
//! input (NaN, infinities and signed zeros included), checked by interpreting both
//! programs.

use codegen::ir::{BinaryOp, Input, InputShape, Instr, Output, OutputKind, Program, UnaryOp};
use codegen::optimize::optimize;

fn eval(p: &Program, x: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = Vec::with_capacity(p.instructions.len());
    for i in &p.instructions {
        let r = match *i {
            Instr::Input { index, .. } => x[index],
            Instr::Const(c) => c,
            Instr::Unary(op, a) => {
                let a = v[a];
                match op {
                    UnaryOp::Neg => -a,
                    UnaryOp::Sq => a * a,
                    UnaryOp::Twice => a + a,
                    UnaryOp::Sin => a.sin(),
                    UnaryOp::Cos => a.cos(),
                    _ => unimplemented!("not in these programs"),
                }
            }
            Instr::Binary(op, a, b) => {
                let (a, b) = (v[a], v[b]);
                match op {
                    BinaryOp::Add => a + b,
                    BinaryOp::Sub => a - b,
                    BinaryOp::Mul => a * b,
                    BinaryOp::Div => a / b,
                    _ => unimplemented!("not in these programs"),
                }
            }
        };
        v.push(r);
    }
    p.outputs[0].entries.iter().map(|&e| v[e]).collect()
}

fn program(instructions: Vec<Instr>, entries: Vec<usize>) -> Program {
    Program {
        name: "f".into(),
        inputs: vec![Input {
            name: "x".into(),
            shape: InputShape::Vector { len: 2 },
        }],
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

#[test]
fn simplifications_are_exact_and_remove_instructions() {
    use BinaryOp::*;
    use Instr::*;
    let p = program(
        vec![
            Input { input: 0, index: 0 }, // 0: x
            Input { input: 0, index: 1 }, // 1: y
            Const(1.0),                   // 2
            Const(-1.0),                  // 3
            Const(2.0),                   // 4
            Const(0.0),                   // 5
            Binary(Mul, 0, 2),            // 6: x·1
            Binary(Mul, 3, 0),            // 7: (−1)·x
            Binary(Div, 0, 4),            // 8: x/2
            Binary(Sub, 0, 5),            // 9: x − 0
            Unary(UnaryOp::Neg, 1),       // 10: −y
            Binary(Add, 0, 10),           // 11: x + (−y)
            Binary(Sub, 0, 10),           // 12: x − (−y)
            Binary(Add, 1, 0),            // 13: y + x (= x + y, one value)
            Binary(Mul, 4, 4),            // 14: 2·2 folded
            Unary(UnaryOp::Neg, 10),      // 15: −(−y)
            Binary(Add, 0, 5),            // 16: x + 0, kept (−0 + 0 = +0)
            Binary(Mul, 0, 5),            // 17: x·0, kept (NaN·0 = NaN)
        ],
        (6..18).collect(),
    );
    let o = optimize(&p);
    o.validate().unwrap();
    let count = |p: &Program| {
        p.instructions
            .iter()
            .filter(|i| matches!(i, Unary(..) | Binary(..)))
            .count()
    };
    assert!(count(&o) < count(&p), "{} → {}", count(&p), count(&o));
    let specials = [
        0.0,
        -0.0,
        1.5,
        -2.25,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e-310,
        -3e300,
    ];
    for &x in &specials {
        for &y in &specials {
            let (a, b) = (eval(&p, &[x, y]), eval(&o, &[x, y]));
            for (k, (u, v)) in a.iter().zip(&b).enumerate() {
                assert!(
                    u.to_bits() == v.to_bits() || (u.is_nan() && v.is_nan()),
                    "entry {k} at ({x}, {y}): {u} vs {v}"
                );
            }
        }
    }
}
