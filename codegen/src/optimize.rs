//! Exact simplifications of a straight-line program before it is emitted: constant
//! folding, value numbering (commutative operands ordered, so `a + b` and `b + a` are one
//! value), and rewrites that give the same bits for every input, NaN and signed zero
//! included: `x·1 → x`, `x·(−1) → −x`, `x/1 → x`, `x/2ᵏ → x·2⁻ᵏ`, `x − 0 → x`,
//! `x + (−y) → x − y`, `x − (−y) → x + y`, `−(−x) → x`. Nothing that could change a
//! result (`x + 0`, `x·0`, reassociation) is done. Dead values are dropped at emission.

use std::collections::HashMap;

use crate::ir::{BinaryOp, Instr, Program, UnaryOp};

#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum Key {
    Input(usize, usize),
    Const(u64),
    Unary(UnaryOp, usize),
    Binary(BinaryOp, usize, usize),
}

fn fold_unary(op: UnaryOp, a: f64) -> f64 {
    match op {
        UnaryOp::Neg => -a,
        UnaryOp::Sq => a * a,
        UnaryOp::Twice => a + a,
        UnaryOp::Inv => 1.0 / a,
        UnaryOp::Sqrt => a.sqrt(),
        UnaryOp::Sin => a.sin(),
        UnaryOp::Cos => a.cos(),
        UnaryOp::Tan => a.tan(),
        UnaryOp::Asin => a.asin(),
        UnaryOp::Acos => a.acos(),
        UnaryOp::Atan => a.atan(),
        UnaryOp::Sinh => a.sinh(),
        UnaryOp::Cosh => a.cosh(),
        UnaryOp::Tanh => a.tanh(),
        UnaryOp::Exp => a.exp(),
        UnaryOp::Log => a.ln(),
        UnaryOp::Abs => a.abs(),
    }
}

fn fold_binary(op: BinaryOp, a: f64, b: f64) -> f64 {
    match op {
        BinaryOp::Add => a + b,
        BinaryOp::Sub => a - b,
        BinaryOp::Mul => a * b,
        BinaryOp::Div => a / b,
        BinaryOp::Pow => a.powf(b),
        BinaryOp::Atan2 => a.atan2(b),
        BinaryOp::Min => a.min(b),
        BinaryOp::Max => a.max(b),
    }
}

/// `1/c` when it is exact (c a power of two, normal, and so is its inverse).
fn exact_inverse(c: f64) -> Option<f64> {
    let inv = 1.0 / c;
    let pow2 = |x: f64| x.is_normal() && (x.to_bits() & ((1u64 << 52) - 1)) == 0;
    (pow2(c) && pow2(inv)).then_some(inv)
}

struct Builder {
    out: Vec<Instr>,
    seen: HashMap<Key, usize>,
}

impl Builder {
    fn value(&self, id: usize) -> Instr {
        self.out[id]
    }

    fn constant(&self, id: usize) -> Option<f64> {
        match self.out[id] {
            Instr::Const(c) => Some(c),
            _ => None,
        }
    }

    fn push(&mut self, instr: Instr) -> usize {
        let key = match instr {
            Instr::Input { input, index } => Key::Input(input, index),
            Instr::Const(c) => Key::Const(c.to_bits()),
            Instr::Unary(op, a) => Key::Unary(op, a),
            Instr::Binary(op, a, b) => Key::Binary(op, a, b),
        };
        if let Some(&id) = self.seen.get(&key) {
            return id;
        }
        self.out.push(instr);
        let id = self.out.len() - 1;
        self.seen.insert(key, id);
        id
    }

    fn unary(&mut self, op: UnaryOp, a: usize) -> usize {
        if let Some(c) = self.constant(a) {
            let v = fold_unary(op, c);
            if v.is_finite() {
                return self.push(Instr::Const(v));
            }
        }
        if let (UnaryOp::Neg, Instr::Unary(UnaryOp::Neg, x)) = (op, self.value(a)) {
            return x;
        }
        self.push(Instr::Unary(op, a))
    }

    fn binary(&mut self, op: BinaryOp, a: usize, b: usize) -> usize {
        if let (Some(x), Some(y)) = (self.constant(a), self.constant(b)) {
            let v = fold_binary(op, x, y);
            if v.is_finite() {
                return self.push(Instr::Const(v));
            }
        }
        let (ca, cb) = (self.constant(a), self.constant(b));
        match op {
            BinaryOp::Mul => {
                if cb == Some(1.0) {
                    return a;
                }
                if ca == Some(1.0) {
                    return b;
                }
                if cb == Some(-1.0) {
                    return self.unary(UnaryOp::Neg, a);
                }
                if ca == Some(-1.0) {
                    return self.unary(UnaryOp::Neg, b);
                }
            }
            BinaryOp::Div => {
                if cb == Some(1.0) {
                    return a;
                }
                if let Some(inv) = cb.and_then(exact_inverse) {
                    let c = self.push(Instr::Const(inv));
                    return self.binary(BinaryOp::Mul, a, c);
                }
            }
            BinaryOp::Sub => {
                if cb.is_some_and(|c| c == 0.0 && c.is_sign_positive()) {
                    return a;
                }
                if let Instr::Unary(UnaryOp::Neg, y) = self.value(b) {
                    return self.binary(BinaryOp::Add, a, y);
                }
            }
            BinaryOp::Add => {
                if let Instr::Unary(UnaryOp::Neg, y) = self.value(b) {
                    return self.binary(BinaryOp::Sub, a, y);
                }
                if let Instr::Unary(UnaryOp::Neg, y) = self.value(a) {
                    return self.binary(BinaryOp::Sub, b, y);
                }
            }
            _ => {}
        }
        // Addition and multiplication commute exactly: one order, one value.
        let (a, b) = match op {
            BinaryOp::Add | BinaryOp::Mul if b < a => (b, a),
            _ => (a, b),
        };
        self.push(Instr::Binary(op, a, b))
    }
}

/// The program with the exact simplifications applied; outputs are unchanged in value.
pub fn optimize(p: &Program) -> Program {
    let mut b = Builder {
        out: Vec::with_capacity(p.instructions.len()),
        seen: HashMap::new(),
    };
    let mut map = Vec::with_capacity(p.instructions.len());
    for instr in &p.instructions {
        let id = match *instr {
            Instr::Input { .. } | Instr::Const(_) => b.push(*instr),
            Instr::Unary(op, a) => b.unary(op, map[a]),
            Instr::Binary(op, x, y) => b.binary(op, map[x], map[y]),
        };
        map.push(id);
    }
    let mut out = p.clone();
    out.instructions = b.out;
    for o in &mut out.outputs {
        for e in &mut o.entries {
            *e = map[*e];
        }
    }
    out
}
