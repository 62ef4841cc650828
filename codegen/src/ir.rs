//! The intermediate representation: straight-line programs in SSA form.
//!
//! A [`Program`] is a function: named inputs (vectors or structs of named scalars), a list
//! of instructions each defining one value (operands refer to earlier values by index), and
//! outputs (scalars, vectors, matrices) listing the value of each entry in column-major
//! order. It knows nothing about legs.

use serde::{Deserialize, Serialize};

/// One straight-line function.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Program {
    pub name: String,
    pub inputs: Vec<Input>,
    pub outputs: Vec<Output>,
    pub instructions: Vec<Instr>,
}

/// A function argument, passed by reference. (No `deny_unknown_fields` here: serde does
/// not support it beside `flatten`; `InputShape` refuses unknown fields itself.)
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Input {
    pub name: String,
    #[serde(flatten)]
    pub shape: InputShape,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum InputShape {
    /// `&SVector<T, len>`; element `i` is read as `name_i`.
    Vector { len: usize },
    /// `&Type<T>`, a struct of scalar fields; element `i` is `name.fields[i]`, and the
    /// `prepared` elements after them are `name.prepared[i − fields]`, parameter-only
    /// values computed once ([`crate::hoist`]).
    Struct {
        #[serde(rename = "type")]
        type_name: String,
        fields: Vec<String>,
        #[serde(default, skip_serializing_if = "is_zero")]
        prepared: usize,
    },
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

impl InputShape {
    pub fn len(&self) -> usize {
        match self {
            InputShape::Vector { len } => *len,
            InputShape::Struct {
                fields, prepared, ..
            } => fields.len() + prepared,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A function result: its entries, column-major, as value indices.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Output {
    pub name: String,
    pub kind: OutputKind,
    pub rows: usize,
    pub cols: usize,
    pub entries: Vec<usize>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OutputKind {
    /// `T` (1×1).
    Scalar,
    /// `SVector<T, rows>` (cols = 1).
    Vector,
    /// `SMatrix<T, rows, cols>`.
    Matrix,
}

/// One instruction; it defines the value whose index is its position in the program.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Instr {
    /// Element `index` of input `input`.
    Input {
        input: usize,
        index: usize,
    },
    /// A constant, emitted so that it round-trips exactly.
    Const(f64),
    Unary(UnaryOp, usize),
    Binary(BinaryOp, usize, usize),
}

macro_rules! ops {
    ($name:ident { $($variant:ident = $text:literal,)* }) => {
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $name { $($variant,)* }

        impl $name {
            pub const ALL: &'static [$name] = &[$($name::$variant,)*];

            pub fn as_str(self) -> &'static str {
                match self { $($name::$variant => $text,)* }
            }

            pub fn from_name(text: &str) -> Option<Self> {
                match text { $($text => Some($name::$variant),)* _ => None }
            }
        }
    };
}

ops!(UnaryOp {
    Neg = "neg",
    Sq = "sq",
    Twice = "twice",
    Inv = "inv",
    Sqrt = "sqrt",
    Sin = "sin",
    Cos = "cos",
    Tan = "tan",
    Asin = "asin",
    Acos = "acos",
    Atan = "atan",
    Sinh = "sinh",
    Cosh = "cosh",
    Tanh = "tanh",
    Exp = "exp",
    Log = "log",
    Abs = "abs",
});

ops!(BinaryOp {
    Add = "add",
    Sub = "sub",
    Mul = "mul",
    Div = "div",
    Pow = "pow",
    Atan2 = "atan2",
    Min = "min",
    Max = "max",
});

/// The wire form of an instruction: `{"op":"mul","args":[3,5]}`,
/// `{"op":"const","value":0.5}`, `{"op":"input","input":0,"index":2}`.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct WireInstr {
    op: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    args: Option<Vec<usize>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    value: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    input: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    index: Option<usize>,
}

impl TryFrom<WireInstr> for Instr {
    type Error = String;

    fn try_from(w: WireInstr) -> Result<Self, String> {
        let only = |ok: bool| {
            if ok {
                Ok(())
            } else {
                Err(format!("instruction `{}` has the wrong fields", w.op))
            }
        };
        match (w.op.as_str(), &w.args) {
            ("input", None) => {
                only(w.value.is_none())?;
                match (w.input, w.index) {
                    (Some(input), Some(index)) => Ok(Instr::Input { input, index }),
                    _ => Err("`input` needs `input` and `index`".into()),
                }
            }
            ("const", None) => {
                only(w.input.is_none() && w.index.is_none())?;
                match w.value {
                    Some(v) if v.is_finite() => Ok(Instr::Const(v)),
                    _ => Err("`const` needs a finite `value`".into()),
                }
            }
            (op, Some(args)) => {
                only(w.value.is_none() && w.input.is_none() && w.index.is_none())?;
                if let Some(u) = UnaryOp::from_name(op) {
                    match args[..] {
                        [a] => Ok(Instr::Unary(u, a)),
                        _ => Err(format!("`{op}` takes 1 operand, got {}", args.len())),
                    }
                } else if let Some(b) = BinaryOp::from_name(op) {
                    match args[..] {
                        [a, c] => Ok(Instr::Binary(b, a, c)),
                        _ => Err(format!("`{op}` takes 2 operands, got {}", args.len())),
                    }
                } else {
                    Err(format!("unknown operation `{op}`"))
                }
            }
            (op, None) => Err(format!("unknown operation `{op}` or missing `args`")),
        }
    }
}

impl From<Instr> for WireInstr {
    fn from(i: Instr) -> Self {
        let mut w = WireInstr {
            op: String::new(),
            args: None,
            value: None,
            input: None,
            index: None,
        };
        match i {
            Instr::Input { input, index } => {
                w.op = "input".into();
                w.input = Some(input);
                w.index = Some(index);
            }
            Instr::Const(v) => {
                w.op = "const".into();
                w.value = Some(v);
            }
            Instr::Unary(op, a) => {
                w.op = op.as_str().into();
                w.args = Some(vec![a]);
            }
            Instr::Binary(op, a, b) => {
                w.op = op.as_str().into();
                w.args = Some(vec![a, b]);
            }
        }
        w
    }
}

impl Serialize for Instr {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        WireInstr::from(*self).serialize(s)
    }
}

impl<'de> Deserialize<'de> for Instr {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Instr::try_from(WireInstr::deserialize(d)?).map_err(serde::de::Error::custom)
    }
}

impl Program {
    /// Which values some output depends on (the others are not emitted).
    pub fn live(&self) -> Vec<bool> {
        let mut live = vec![false; self.instructions.len()];
        for out in &self.outputs {
            for &e in &out.entries {
                live[e] = true;
            }
        }
        for k in (0..live.len()).rev() {
            if live[k] {
                for a in self.instructions[k].operands() {
                    live[a] = true;
                }
            }
        }
        live
    }
}

impl Instr {
    /// The values this instruction reads.
    pub fn operands(&self) -> impl Iterator<Item = usize> {
        let (a, b) = match *self {
            Instr::Input { .. } | Instr::Const(_) => (None, None),
            Instr::Unary(_, a) => (Some(a), None),
            Instr::Binary(_, a, b) => (Some(a), Some(b)),
        };
        a.into_iter().chain(b)
    }
}
