//! Parameter-only work moved out of the per-state functions.
//!
//! A value computed from the parameter struct and constants alone (a mass times a length,
//! an inertia about a joint, `m c·l` of two links) is the same at every state. Such values
//! that per-state code reads are computed once, by one `prepare` program over the
//! parameter struct's fields, shared by every function of a model (value-numbered, so a
//! quantity two functions need is one entry), and read back as `p.prepared[k]`. What is
//! left in each function depends on the state. Only values that are computed (not plain
//! field reads or constants) are hoisted; the results are the same bits.

use crate::ir::{Input, InputShape, Instr, Output, OutputKind, Program};
use crate::optimize::optimize;

/// Programs with their parameter-only values moved into one `prepare` program.
pub struct Hoisted {
    /// `prepare(values) -> SVector<T, n>`: every hoisted value, from the parameter struct's
    /// fields alone (its one input, renamed `values` of type `values_type`).
    pub prepare: Program,
    /// The programs, each reading hoisted value `k` as element `fields + k` of its parameter
    /// input (`InputShape::Struct::prepared` says how many there are).
    pub programs: Vec<Program>,
    /// Which of the struct's fields `prepare` reads: changing any other field leaves the
    /// prepared values as they are (a floating robot's gravity, which only multiplies
    /// state-dependent terms, is one of those; a planar leg's usually is not).
    pub reads: Vec<bool>,
}

/// Which fields of its one struct input the live code of `prog` reads.
fn fields_read(prog: &Program, fields: usize) -> Vec<bool> {
    let mut reads = vec![false; fields];
    for (instr, live) in prog.instructions.iter().zip(prog.live()) {
        if let (Instr::Input { index, .. }, true) = (instr, live) {
            reads[*index] = true;
        }
    }
    reads
}

/// Which values of `prog` come from its input `param` and constants alone.
fn parameter_only(prog: &Program, param: usize) -> Vec<bool> {
    let mut only = Vec::with_capacity(prog.instructions.len());
    for instr in &prog.instructions {
        let v = match *instr {
            Instr::Input { input, .. } => input == param,
            Instr::Const(_) => true,
            _ => instr.operands().all(|a| only[a]),
        };
        only.push(v);
    }
    only
}

/// Hoists the parameter-only values of `programs` that read the struct input named
/// `param` (programs without it are returned optimized and otherwise unchanged).
pub fn hoist(programs: &[Program], param: &str, values_type: &str) -> Hoisted {
    let programs: Vec<Program> = programs.iter().map(optimize).collect();
    let fields = programs
        .iter()
        .flat_map(|p| &p.inputs)
        .find_map(|i| match &i.shape {
            InputShape::Struct { fields, .. } if i.name == param => Some(fields.clone()),
            _ => None,
        })
        .unwrap_or_default();

    // One program holding every program's parameter-only values; each frontier value
    // (hoisted: read by state-dependent code or an output) becomes one of its outputs.
    let mut all = Vec::new();
    let mut frontier_of: Vec<Vec<(usize, usize)>> = Vec::new(); // (value in program, entry)
    let mut entries = Vec::new();
    for prog in &programs {
        let mut hoisted = Vec::new();
        let Some(pi) = prog.inputs.iter().position(|i| i.name == param) else {
            frontier_of.push(hoisted);
            continue;
        };
        let only = parameter_only(prog, pi);
        let live = prog.live();
        let computed = |k: usize| {
            only[k] && !matches!(prog.instructions[k], Instr::Input { .. } | Instr::Const(_))
        };
        let mut frontier = vec![false; prog.instructions.len()];
        for (k, instr) in prog.instructions.iter().enumerate() {
            if live[k] && !only[k] {
                for a in instr.operands() {
                    frontier[a] |= computed(a);
                }
            }
        }
        for out in &prog.outputs {
            for &e in &out.entries {
                frontier[e] |= computed(e);
            }
        }
        let mut map = vec![usize::MAX; prog.instructions.len()];
        for (k, instr) in prog.instructions.iter().enumerate() {
            if !only[k] {
                continue;
            }
            let copied = match *instr {
                Instr::Input { index, .. } => Instr::Input { input: 0, index },
                Instr::Const(c) => Instr::Const(c),
                Instr::Unary(op, a) => Instr::Unary(op, map[a]),
                Instr::Binary(op, a, b) => Instr::Binary(op, map[a], map[b]),
            };
            all.push(copied);
            map[k] = all.len() - 1;
            if frontier[k] {
                hoisted.push((k, entries.len()));
                entries.push(map[k]);
            }
        }
        frontier_of.push(hoisted);
    }
    let combined = optimize(&Program {
        name: "prepare".into(),
        inputs: vec![Input {
            name: "values".into(),
            shape: InputShape::Struct {
                type_name: values_type.into(),
                fields: fields.clone(),
                prepared: 0,
            },
        }],
        outputs: vec![Output {
            name: "prepared".into(),
            kind: OutputKind::Vector,
            rows: entries.len(),
            cols: 1,
            entries: entries.clone(),
        }],
        instructions: all,
    });
    // Value numbering made equal quantities one value: one slot each, in first-use order.
    let mut slots: Vec<usize> = Vec::new();
    let mut slot_of_value = std::collections::HashMap::new();
    let slot_of: Vec<usize> = combined.outputs[0]
        .entries
        .iter()
        .map(|&v| {
            *slot_of_value.entry(v).or_insert_with(|| {
                slots.push(v);
                slots.len() - 1
            })
        })
        .collect();
    let mut prepare = combined;
    prepare.outputs[0].entries = slots.clone();
    prepare.outputs[0].rows = slots.len();

    let programs = programs
        .into_iter()
        .zip(frontier_of)
        .map(|(mut prog, hoisted)| {
            let Some(pi) = prog.inputs.iter().position(|i| i.name == param) else {
                return prog;
            };
            for (k, entry) in hoisted {
                prog.instructions[k] = Instr::Input {
                    input: pi,
                    index: fields.len() + slot_of[entry],
                };
            }
            if let InputShape::Struct { prepared, .. } = &mut prog.inputs[pi].shape {
                *prepared = slots.len();
            }
            prog
        })
        .collect();
    let reads = fields_read(&prepare, fields.len());
    Hoisted {
        prepare,
        programs,
        reads,
    }
}
