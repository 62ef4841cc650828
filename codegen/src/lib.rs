//! IR → Rust: straight-line programs to straight-line Rust functions.
//!
//! The emitted functions are generic over a scalar `T: Arithmetic` (the caller brings `Arithmetic`,
//! `SVector`, `SMatrix` and `ArrayStorage` into scope), take vector inputs as
//! `&SVector<T, n>` (destructured, so there is no indexing and no panic path) and struct
//! inputs as `&Type<T>` (read as fields), and return `T`, `SVector` or `SMatrix` values
//! built from their column-major entries. Constants are written as `T::lit(x)` with `x`
//! the shortest `f64` literal that round-trips. Output is deterministic byte for byte:
//! tokens are built with `quote`, checked with `syn::parse2` and formatted with
//! `prettyplease`.

pub mod hoist;
pub mod ir;
pub mod optimize;

use std::collections::{HashMap, HashSet};
use std::fmt;

use ir::{BinaryOp, Input, InputShape, Instr, OutputKind, Program, UnaryOp};
use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};

/// Why a program cannot be turned into Rust.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Error {
    /// The function (or file) concerned.
    pub context: String,
    pub message: String,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.context, self.message)
    }
}

impl std::error::Error for Error {}

fn err(context: &str, message: impl Into<String>) -> Error {
    Error {
        context: context.to_string(),
        message: message.into(),
    }
}

/// Parses `text` as a plain Rust identifier (not a keyword, not raw).
pub fn ident(context: &str, text: &str) -> Result<Ident, Error> {
    let plain = !text.is_empty()
        && text.is_ascii()
        && !text.starts_with(|c: char| c.is_ascii_digit())
        && text.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    match syn::parse_str::<Ident>(text) {
        Ok(id) if plain && text != "_" => Ok(id),
        _ => Err(err(
            context,
            format!("`{text}` is not a plain Rust identifier"),
        )),
    }
}

/// The value a program name refers to, as Rust tokens.
enum Value {
    /// A let-bound local or a destructured vector element.
    Local(Ident),
    /// A struct field read in place: `p.mass`.
    Field(Ident, Ident),
    /// A prepared parameter-only value: `p.prepared[3]`.
    Prepared(Ident, usize),
    Const(f64),
}

impl Value {
    fn tokens(&self) -> TokenStream {
        match self {
            Value::Local(id) => quote!(#id),
            Value::Field(s, f) => quote!(#s.#f),
            Value::Prepared(s, k) => {
                let k = Literal::usize_unsuffixed(*k);
                quote!(#s.prepared[#k])
            }
            Value::Const(v) => scalar_literal(*v),
        }
    }
}

/// A constant of generated code: `T::lit(x)`, with `x` from [`f64_literal`].
pub fn scalar_literal(v: f64) -> TokenStream {
    let x = f64_literal(v);
    quote!(T::lit(#x))
}

/// The shortest `f64` literal that parses back to exactly `v` (sign included, `-0.0`
/// too). `v` must be finite.
pub fn f64_literal(v: f64) -> TokenStream {
    // `{:?}` is the shortest round-trip form and switches to exponent notation for very
    // large or small magnitudes; it always has a `.` or an `e`, so it is a float literal.
    let text = format!("{:?}", v.abs());
    let lit = text
        .parse::<Literal>()
        .unwrap_or_else(|_| Literal::f64_unsuffixed(v.abs()));
    if v.is_sign_negative() {
        quote!(-#lit)
    } else {
        quote!(#lit)
    }
}

impl Program {
    /// Checks the program is well formed: operands refer to earlier values, inputs and
    /// outputs are in range, shapes are consistent, names are identifiers.
    pub fn validate(&self) -> Result<(), Error> {
        let ctx = self.name.as_str();
        ident(ctx, &self.name)?;
        let mut names = HashSet::new();
        for input in &self.inputs {
            ident(ctx, &input.name)?;
            if !names.insert(input.name.as_str()) {
                return Err(err(ctx, format!("duplicate input `{}`", input.name)));
            }
            if let InputShape::Struct {
                type_name, fields, ..
            } = &input.shape
            {
                ident(ctx, type_name)?;
                let mut seen = HashSet::new();
                for f in fields {
                    ident(ctx, f)?;
                    if !seen.insert(f) {
                        return Err(err(
                            ctx,
                            format!("duplicate field `{f}` in `{}`", input.name),
                        ));
                    }
                }
            }
        }
        for (k, instr) in self.instructions.iter().enumerate() {
            if let Instr::Input { input, index } = *instr {
                let Some(inp) = self.inputs.get(input) else {
                    return Err(err(ctx, format!("value {k} reads missing input {input}")));
                };
                if index >= inp.shape.len() {
                    return Err(err(
                        ctx,
                        format!("value {k} reads `{}`[{index}], out of range", inp.name),
                    ));
                }
            }
            if let Some(bad) = instr.operands().find(|&a| a >= k) {
                return Err(err(
                    ctx,
                    format!("value {k} reads value {bad}, not defined before it"),
                ));
            }
        }
        let mut names = HashSet::new();
        for out in &self.outputs {
            ident(ctx, &out.name)?;
            if !names.insert(out.name.as_str()) {
                return Err(err(ctx, format!("duplicate output `{}`", out.name)));
            }
            let shape_ok = match out.kind {
                OutputKind::Scalar => out.rows == 1 && out.cols == 1,
                OutputKind::Vector => out.cols == 1,
                OutputKind::Matrix => true,
            };
            if !shape_ok {
                return Err(err(
                    ctx,
                    format!(
                        "output `{}` is {:?} but {}×{}",
                        out.name, out.kind, out.rows, out.cols
                    ),
                ));
            }
            if out.entries.len() != out.rows * out.cols {
                return Err(err(
                    ctx,
                    format!(
                        "output `{}` is {}×{} but lists {} entries",
                        out.name,
                        out.rows,
                        out.cols,
                        out.entries.len()
                    ),
                ));
            }
            if let Some(bad) = out.entries.iter().find(|&&e| e >= self.instructions.len()) {
                return Err(err(
                    ctx,
                    format!("output `{}` reads missing value {bad}", out.name),
                ));
            }
        }
        if self.outputs.is_empty() {
            return Err(err(ctx, "no outputs"));
        }
        Ok(())
    }
}

fn input_type(input: &Input) -> TokenStream {
    match &input.shape {
        InputShape::Vector { len } => {
            let len = Literal::usize_unsuffixed(*len);
            quote!(SVector<T, #len>)
        }
        InputShape::Struct { type_name, .. } => {
            let ty = Ident::new(type_name, Span::call_site());
            quote!(#ty<T>)
        }
    }
}

/// The Rust type a function emitted from `prog` returns: one output as it is, several in
/// the struct type `wrap` when given, or as a tuple.
pub fn return_type(prog: &Program, wrap: Option<&TokenStream>) -> TokenStream {
    let mut types = prog
        .outputs
        .iter()
        .map(|o| output_type(o.kind, o.rows, o.cols));
    match (prog.outputs.len(), wrap) {
        (1, _) => types.next().expect("one output"),
        (_, Some(ty)) => ty.clone(),
        (_, None) => quote!((#(#types),*)),
    }
}

fn output_type(kind: OutputKind, rows: usize, cols: usize) -> TokenStream {
    let (r, c) = (
        Literal::usize_unsuffixed(rows),
        Literal::usize_unsuffixed(cols),
    );
    match kind {
        OutputKind::Scalar => quote!(T),
        OutputKind::Vector => quote!(SVector<T, #r>),
        OutputKind::Matrix => quote!(SMatrix<T, #r, #c>),
    }
}

/// Emits `prog` as `pub fn name<T: Arithmetic>(inputs…) -> outputs { … }` with `doc` as its
/// documentation. Values no output needs are not emitted.
pub fn emit_function(prog: &Program, doc: &str) -> Result<TokenStream, Error> {
    emit_function_returning(prog, doc, None)
}

/// [`emit_function`], several outputs returned in the struct `wrap` (its type, and its
/// name as an expression; its fields named as the outputs) instead of a tuple: built in the caller's place, where a tuple
/// moved into the struct afterwards was a copy of every output (a 32-coordinate mass
/// matrix is 8 KB).
pub fn emit_function_returning(
    prog: &Program,
    doc: &str,
    wrap: Option<(TokenStream, TokenStream)>,
) -> Result<TokenStream, Error> {
    prog.validate()?;
    let prog = &optimize::optimize(prog);
    let n = prog.instructions.len();

    // Liveness: only values some output depends on are emitted.
    let live = prog.live();

    // Name every value: vector elements `q_0`, struct fields `p.mass`, constants inline,
    // computed values `v{k}`.
    let mut used_elems: Vec<Vec<Option<Ident>>> = prog
        .inputs
        .iter()
        .map(|i| vec![None; i.shape.len()])
        .collect();
    let mut values = Vec::with_capacity(n);
    let mut computed = 0usize;
    for (k, instr) in prog.instructions.iter().enumerate() {
        let v = match *instr {
            Instr::Input { input, index } => {
                let inp = &prog.inputs[input];
                let arg = format_ident!("{}", inp.name);
                match &inp.shape {
                    InputShape::Vector { .. } => {
                        let id = format_ident!("{}_{}", inp.name, index);
                        if live[k] {
                            used_elems[input][index] = Some(id.clone());
                        }
                        Value::Local(id)
                    }
                    InputShape::Struct { fields, .. } => match fields.get(index) {
                        Some(field) => Value::Field(arg, format_ident!("{}", field)),
                        None => Value::Prepared(arg, index - fields.len()),
                    },
                }
            }
            Instr::Const(c) => Value::Const(c),
            _ => {
                // Computed values are numbered in the order they are emitted.
                let id = format_ident!("v{}", computed);
                if live[k] {
                    computed += 1;
                }
                Value::Local(id)
            }
        };
        values.push(v);
    }

    // Arguments: unused ones are prefixed with `_`; used vectors are destructured.
    let mut args = Vec::new();
    let mut body = Vec::new();
    for (i, input) in prog.inputs.iter().enumerate() {
        let ty = input_type(input);
        let used =
            prog.instructions.iter().enumerate().any(|(k, ins)| {
                live[k] && matches!(ins, Instr::Input { input, .. } if *input == i)
            });
        let name = if used {
            format_ident!("{}", input.name)
        } else {
            format_ident!("_{}", input.name)
        };
        args.push(quote!(#name: &#ty));
        if used && matches!(input.shape, InputShape::Vector { .. }) {
            let pats = used_elems[i].iter().map(|e| match e {
                Some(id) => quote!(#id),
                None => quote!(_),
            });
            body.push(quote!(let [#(#pats),*] = #name.data.0[0];));
        }
    }

    // `sin` and `cos` of one value become one `Arithmetic::sincos` (one argument reduction),
    // emitted where the first of the two was.
    let mut sin_of = HashMap::new();
    let mut cos_of = HashMap::new();
    for (k, instr) in prog.instructions.iter().enumerate() {
        match *instr {
            Instr::Unary(UnaryOp::Sin, a) if live[k] => {
                sin_of.insert(a, k);
            }
            Instr::Unary(UnaryOp::Cos, a) if live[k] => {
                cos_of.insert(a, k);
            }
            _ => {}
        }
    }
    for (k, instr) in prog.instructions.iter().enumerate() {
        if !live[k] {
            continue;
        }
        if let Instr::Unary(UnaryOp::Sin | UnaryOp::Cos, a) = *instr {
            if let (Some(&s), Some(&c)) = (sin_of.get(&a), cos_of.get(&a)) {
                if k == s.min(c) {
                    let (Value::Local(vs), Value::Local(vc)) = (&values[s], &values[c]) else {
                        unreachable!("computed values are locals")
                    };
                    let arg = values[a].tokens();
                    body.push(quote!(let (#vs, #vc) = #arg.sincos();));
                }
                continue;
            }
        }
        let rhs = match *instr {
            Instr::Input { .. } | Instr::Const(_) => continue,
            Instr::Unary(op, a) => unary(op, values[a].tokens()),
            Instr::Binary(op, a, b) => binary(op, values[a].tokens(), values[b].tokens()),
        };
        let Value::Local(lhs) = &values[k] else {
            unreachable!("computed values are locals")
        };
        body.push(quote!(let #lhs = #rhs;));
    }

    let ret = return_type(prog, wrap.as_ref().map(|(ty, _)| ty));
    let mut results = Vec::new();
    for out in &prog.outputs {
        let value = if out.kind == OutputKind::Scalar {
            values[out.entries[0]].tokens()
        } else {
            let columns = out
                .entries
                .chunks(out.rows.max(1))
                .take(out.cols)
                .map(|col| {
                    let entries = col.iter().map(|&e| values[e].tokens());
                    quote!([#(#entries),*])
                });
            let columns: Vec<_> = if out.rows == 0 {
                (0..out.cols).map(|_| quote!([])).collect()
            } else {
                columns.collect()
            };
            // The dimensions come from the storage; the return type pins the scalar.
            quote!(SMatrix::from_data(ArrayStorage([#(#columns),*])))
        };
        results.push(value);
    }
    let result = match wrap {
        _ if results.len() == 1 => results.remove(0),
        Some((_, st)) => {
            let fields = prog.outputs.iter().map(|o| format_ident!("{}", o.name));
            quote!(#st { #(#fields: #results),* })
        }
        None => quote!((#(#results),*)),
    };

    let name = format_ident!("{}", prog.name);
    let doc_lines = doc.lines().map(|l| {
        let l = format!(" {l}");
        quote!(#[doc = #l])
    });
    Ok(quote! {
        #(#doc_lines)*
        pub fn #name<T: Arithmetic>(#(#args),*) -> #ret {
            #(#body)*
            #result
        }
    })
}

fn unary(op: UnaryOp, a: TokenStream) -> TokenStream {
    match op {
        UnaryOp::Neg => quote!(-#a),
        UnaryOp::Sq => quote!(#a * #a),
        UnaryOp::Twice => quote!(#a + #a),
        UnaryOp::Inv => quote!(T::lit(1.0) / #a),
        UnaryOp::Sqrt => quote!(#a.sqrt()),
        UnaryOp::Sin => quote!(#a.sin()),
        UnaryOp::Cos => quote!(#a.cos()),
        UnaryOp::Tan => quote!(#a.tan()),
        UnaryOp::Asin => quote!(#a.asin()),
        UnaryOp::Acos => quote!(#a.acos()),
        UnaryOp::Atan => quote!(#a.atan()),
        UnaryOp::Sinh => quote!(#a.sinh()),
        UnaryOp::Cosh => quote!(#a.cosh()),
        UnaryOp::Tanh => quote!(#a.tanh()),
        UnaryOp::Exp => quote!(#a.exp()),
        UnaryOp::Log => quote!(#a.ln()),
        UnaryOp::Abs => quote!(#a.abs()),
    }
}

fn binary(op: BinaryOp, a: TokenStream, b: TokenStream) -> TokenStream {
    match op {
        BinaryOp::Add => quote!(#a + #b),
        BinaryOp::Sub => quote!(#a - #b),
        BinaryOp::Mul => quote!(#a * #b),
        BinaryOp::Div => quote!(#a / #b),
        BinaryOp::Pow => quote!(#a.powf(#b)),
        BinaryOp::Atan2 => quote!(#a.atan2(#b)),
        BinaryOp::Min => quote!(#a.min(#b)),
        BinaryOp::Max => quote!(#a.max(#b)),
    }
}

/// Checks `tokens` parse as a Rust file and formats them with prettyplease, behind the
/// `header` comment lines (written as `// line`).
pub fn format_file(header: &[String], tokens: TokenStream) -> Result<String, Error> {
    let file: syn::File =
        syn::parse2(tokens).map_err(|e| err("generated file", format!("does not parse: {e}")))?;
    let mut out = String::new();
    for line in header {
        out.push_str("// ");
        out.push_str(line);
        out.push('\n');
    }
    out.push_str(&prettyplease::unparse(&file));
    Ok(out)
}
