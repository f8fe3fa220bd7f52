//! One equation's right side: parsed once by exmex, its names resolved
//! to slots of the model's value table, and compiled to instructions
//! that read and write that table.

use std::collections::HashMap;
use std::sync::Arc;

use exmex::{Express, FlatEx};

use crate::instruction::{Instruction, run};
use crate::jit::Native;
use crate::ops::{DecimalMatcher, EquationOps, Traced};
use crate::{EquationError, Names};

/// Several right sides compiled into one run over the value table, each
/// writing its value into a slot of its own (see [`Expression::append_to`]):
/// one pass for all the equations of a step. A program may read some
/// slots from a vector beside the table (the states, as the integrator
/// holds them) and give some back in another (their derivatives), without
/// copying them through the table. Once complete, [`Program::compile`]
/// makes machine code of it.
#[derive(Debug, Clone, Default)]
pub(crate) struct Program {
    code: Vec<Instruction>,
    /// The slots read from the vector `x` of [`Program::run_with`], in its
    /// order.
    from_x: Vec<u32>,
    /// The slots given back in its `out`, in its order.
    to_out: Vec<u32>,
    native: Option<Arc<Native>>,
}

impl Program {
    /// An empty program reading `from_x` from a vector beside the table
    /// and giving `to_out` back in another.
    pub(crate) fn with_vectors(from_x: &[usize], to_out: &[usize]) -> Self {
        Self {
            from_x: from_x.iter().map(|&s| slot_index(s)).collect(),
            to_out: to_out.iter().map(|&s| slot_index(s)).collect(),
            ..Self::default()
        }
    }

    /// The program of `code`, reading `from_x` from a vector beside the
    /// table and giving `to_out` back in another; not yet compiled.
    pub(crate) fn from_parts(code: Vec<Instruction>, from_x: &[u32], to_out: &[u32]) -> Self {
        Self {
            code,
            from_x: from_x.to_vec(),
            to_out: to_out.to_vec(),
            native: None,
        }
    }

    /// Its instructions, the slots it reads from `x` and those it gives
    /// back in `out`.
    pub(crate) fn parts(&self) -> (&[Instruction], &[u32], &[u32]) {
        (&self.code, &self.from_x, &self.to_out)
    }

    /// The same program over `lanes` value tables laid end to end, each
    /// `stride` slots long, its vectors holding the lanes one after the
    /// other. Each instruction is followed by its copies for the other
    /// lanes: their chains are independent, so the processor works on them
    /// at once where one record's chain would keep it waiting. Not yet
    /// compiled.
    pub(crate) fn lanes(&self, lanes: usize, stride: usize) -> Self {
        let by = |lane: usize| slot_index(lane * stride);
        let code = self
            .code
            .iter()
            .flat_map(|&i| (0..lanes).map(move |lane| i.shifted(by(lane))))
            .collect();
        let widen = |slots: &[u32]| -> Vec<u32> {
            (0..lanes)
                .flat_map(|lane| slots.iter().map(move |&s| s + by(lane)))
                .collect()
        };
        Self::from_parts(code, &widen(&self.from_x), &widen(&self.to_out))
    }

    /// Compile it to machine code, where Cranelift can build for this
    /// processor (else it stays interpreted, the same values).
    pub(crate) fn compile(&mut self) {
        self.native = Native::compile(&self.code, &self.from_x, &self.to_out).map(Arc::new);
    }

    /// Runs it on the value table (a program without vectors).
    #[inline]
    pub(crate) fn run(&self, values: &mut [f64]) {
        self.run_with(values, &[], &mut []);
    }

    /// Runs it on the value table, its vector slots read from `x` and
    /// given back in `out`.
    #[inline]
    pub(crate) fn run_with(&self, values: &mut [f64], x: &[f64], out: &mut [f64]) {
        match &self.native {
            Some(native) => native.run(values, x, out),
            None => self.interpret(values, x, out),
        }
    }

    /// Runs it by the interpreter, compiled or not: what the compiled
    /// code is tested against. It writes `x` into the table's slots too.
    pub(crate) fn interpret(&self, values: &mut [f64], x: &[f64], out: &mut [f64]) {
        for (&slot, &v) in self.from_x.iter().zip(x) {
            values[slot as usize] = v;
        }
        run(&self.code, values);
        for (v, &slot) in out.iter_mut().zip(&self.to_out) {
            *v = values[slot as usize];
        }
    }

    /// Whether it runs as machine code.
    #[cfg(test)]
    pub(crate) fn is_native(&self) -> bool {
        self.native.is_some()
    }
}

/// The value table's layout beyond its named slots: the numbers the
/// equations write (one slot each, set once per record) and each
/// instruction's result.
#[derive(Debug, Clone, Default)]
pub(crate) struct Table {
    len: usize,
    numbers: Vec<(usize, f64)>,
}

impl Table {
    /// A table whose first `named` slots are the model's names.
    pub(crate) fn new(named: usize) -> Self {
        Self {
            len: named,
            numbers: Vec::new(),
        }
    }

    /// A table of this layout: zeros, with its numbers written.
    pub(crate) fn values(&self) -> Vec<f64> {
        let mut values = vec![0.0; self.len];
        for &(slot, number) in &self.numbers {
            values[slot] = number;
        }
        values
    }

    /// Its length: one past the last slot.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// A slot of its own for a value.
    pub(crate) fn fresh(&mut self) -> usize {
        self.len += 1;
        self.len - 1
    }

    /// The slot holding `number` (one per distinct number).
    pub(crate) fn number(&mut self, number: f64) -> usize {
        if let Some(&(slot, _)) = self
            .numbers
            .iter()
            .find(|(_, n)| n.to_bits() == number.to_bits())
        {
            return slot;
        }
        let slot = self.fresh();
        self.numbers.push((slot, number));
        slot
    }
}

/// A compiled right side: its instructions (those that read only what is
/// fixed through a record apart, once [`Expression::hoist`] has split
/// them), the slot of its value, and the named slots it reads.
#[derive(Debug, Clone)]
pub(crate) struct Expression {
    code: Vec<Instruction>,
    per_record: Vec<Instruction>,
    result: usize,
    reads: Vec<usize>,
}

impl Expression {
    /// Parse `text`, the right side of the equation called `key`, resolve
    /// its names among `names` (those `allowed` for this kind of
    /// equation; a known name that is not allowed says why), and compile
    /// it into `table`'s slots.
    pub(crate) fn compile(
        key: &str,
        text: &str,
        names: &Names,
        allowed: impl Fn(usize) -> Result<(), String>,
        table: &mut Table,
    ) -> Result<Self, EquationError> {
        let error = |position: Option<usize>, message: String| EquationError {
            equation: key.to_string(),
            position,
            message,
        };
        if text.trim().is_empty() {
            return Err(error(None, "the equation is empty".into()));
        }
        let (thens, elses) = branch_words(text);
        if thens != elses {
            return Err(error(
                None,
                format!(
                    "{thens} `then` and {elses} `else`: every `if CONDITION then VALUE` needs \
                     its `else OTHER`"
                ),
            ));
        }
        let operators = operator_count(text);
        if operators > MAX_OPERATORS {
            return Err(error(
                None,
                format!(
                    "{operators} operators in one equation, at most {MAX_OPERATORS}: exmex's \
                     parse takes time that grows with their square and its tree is walked \
                     recursively; split it into named parts with `define` (each part its own \
                     equation, the sum of the parts in this one)"
                ),
            ));
        }
        if let Some(at) = negated_power(text) {
            return Err(error(
                Some(at),
                "a minus sign before a power: exmex reads -x^2 as (-x)^2, not -(x^2) as \
                 mathematics does; write -(x^2) or (-x)^2, whichever is meant"
                    .into(),
            ));
        }
        let flat = FlatEx::<Traced, EquationOps, DecimalMatcher>::parse(text)
            .map_err(|e| error(position_of(text, e.msg()), syntax_message(e.msg())))?;
        let mut slots = Vec::with_capacity(flat.var_names().len());
        for name in flat.var_names() {
            let slot = names.slot(name).ok_or_else(|| {
                error(
                    text.find(name.as_str()),
                    format!("unknown name `{name}`; known: {}", names.known()),
                )
            })?;
            allowed(slot).map_err(|why| error(text.find(name.as_str()), why))?;
            slots.push(slot);
        }
        let variables: Vec<Traced> = slots.iter().map(|&s| Traced::Slot(s)).collect();
        // The variables are exactly the expression's, in its order: exmex
        // only fails on a count that differs.
        let tree = flat
            .eval(&variables)
            .map_err(|e| error(None, syntax_message(e.msg())))?;
        let mut code = Vec::new();
        let result = lower(&tree, table, &mut code, &mut HashMap::new());
        slots.sort_unstable();
        slots.dedup();
        Ok(Self {
            code,
            per_record: Vec::new(),
            result,
            reads: slots,
        })
    }

    /// The named slots this expression reads.
    pub(crate) fn reads(&self) -> &[usize] {
        &self.reads
    }

    /// Set apart the instructions that read only slots `fixed` through a
    /// record (or numbers, or results of such instructions): they run
    /// once per record, by [`Expression::prepare`], instead of at every
    /// evaluation. Slots below `named` are the model's names.
    pub(crate) fn hoist(&mut self, named: usize, fixed: impl Fn(usize) -> bool) {
        let mut varying: Vec<usize> = Vec::new();
        let (mut per_record, mut code) = (Vec::new(), Vec::new());
        for &instruction in &self.code {
            let (operands, to) = instruction.slots();
            let is_fixed = operands.iter().all(|&s| {
                let s = s as usize;
                if s < named {
                    fixed(s)
                } else {
                    !varying.contains(&s)
                }
            });
            if is_fixed {
                per_record.push(instruction);
            } else {
                varying.push(to as usize);
                code.push(instruction);
            }
        }
        self.per_record.extend(per_record);
        self.code = code;
    }

    /// Run the instructions set apart by [`Expression::hoist`]: once a
    /// record, after the fixed slots are written.
    pub(crate) fn prepare(&self, values: &mut [f64]) {
        run(&self.per_record, values);
    }

    /// Append to `program` the instructions that evaluate it at every
    /// step, its value then written into `slot` (its last instruction
    /// retargeted, or a copy where it has none of its own).
    pub(crate) fn append_to(&self, program: &mut Program, slot: usize) {
        let slot = slot_index(slot);
        match self.code.split_last() {
            Some((last, rest)) if last.slots().1 as usize == self.result => {
                program.code.extend_from_slice(rest);
                program.code.push(last.writing(slot));
            }
            _ => {
                program.code.extend_from_slice(&self.code);
                program
                    .code
                    .push(Instruction::Copy([slot_index(self.result), slot]));
            }
        }
    }

    /// Its value with the table `values`, whose slots of instruction
    /// results it writes.
    #[inline]
    pub(crate) fn eval(&self, values: &mut [f64]) -> f64 {
        run(&self.code, values);
        values[self.result]
    }
}

/// Instructions computing `tree` appended to `code`; the slot holding its
/// value. A part met twice in the tree is computed once (`seen`).
fn lower(
    tree: &Traced,
    table: &mut Table,
    code: &mut Vec<Instruction>,
    seen: &mut HashMap<Instruction, usize>,
) -> usize {
    let instruction = match tree {
        Traced::Number(number) => return table.number(*number),
        Traced::Slot(slot) => return *slot,
        Traced::Unary(f, x) => Instruction::Unary(*f, [slot_index(lower(x, table, code, seen)), 0]),
        Traced::Binary(f, a, b) => {
            let a = slot_index(lower(a, table, code, seen));
            let b = slot_index(lower(b, table, code, seen));
            Instruction::binary(*f, [a, b, 0])
        }
    };
    if let Some(&slot) = seen.get(&instruction) {
        return slot;
    }
    let to = table.fresh();
    seen.insert(instruction, to);
    code.push(instruction.writing(slot_index(to)));
    to
}

/// A slot as an instruction stores it: a model of more than 4 billion
/// values is not one a record could simulate.
pub(crate) fn slot_index(slot: usize) -> u32 {
    u32::try_from(slot).unwrap_or(u32::MAX)
}

/// Where `text` puts a unary minus before an operand raised to a power
/// (`-x^2`, `2 * -f(x)^3`, `-(a + b)^2`), which exmex evaluates as
/// `(-x)^2`: unary operators bind tighter than binary ones there
/// (exmex's documentation). A unary minus is one at the start, or after
/// an opening parenthesis, a comma or another operator.
/// The most operators one equation may hold: the parse's time grows with
/// their square (docs/performance.md) and the expression tree is
/// walked recursively, so a generated equation of any length is refused
/// by its size rather than left to exhaust the time or the stack.
pub(crate) const MAX_OPERATORS: usize = 10_000;

/// The operators and function arguments of `text`: each of `+ - * / ^ ,`
/// and each opening parenthesis (a call or a group).
fn operator_count(text: &str) -> usize {
    text.bytes()
        .filter(|b| matches!(b, b'+' | b'-' | b'*' | b'/' | b'^' | b',' | b'('))
        .count()
}

fn negated_power(text: &str) -> Option<usize> {
    let chars: Vec<(usize, char)> = text
        .char_indices()
        .filter(|(_, c)| !c.is_whitespace())
        .collect();
    let is_name = |c: char| c.is_alphanumeric() || c == '_' || c == '.';
    let mut k = 0;
    while k < chars.len() {
        let (at, c) = chars[k];
        let unary = c == '-'
            && (k == 0
                || matches!(
                    chars[k - 1].1,
                    '(' | ',' | '+' | '-' | '*' | '/' | '^' | '<' | '>' | '='
                ));
        if !unary {
            k += 1;
            continue;
        }
        // The operand: a name or number, a call, or a parenthesized group.
        let mut j = k + 1;
        while j < chars.len() && is_name(chars[j].1) {
            j += 1;
        }
        if j < chars.len() && chars[j].1 == '(' {
            let mut depth = 0usize;
            while j < chars.len() {
                match chars[j].1 {
                    '(' => depth += 1,
                    ')' => depth -= 1,
                    _ => {}
                }
                j += 1;
                if depth == 0 {
                    break;
                }
            }
        }
        if j > k + 1 && j < chars.len() && chars[j].1 == '^' {
            return Some(at);
        }
        k += 1;
    }
    None
}

/// How many `then` and `else` words `text` holds.
fn branch_words(text: &str) -> (usize, usize) {
    let words = text.split(|c: char| !(c.is_alphanumeric() || c == '_'));
    words.fold((0, 0), |(t, e), w| match w {
        "then" => (t + 1, e),
        "else" => (t, e + 1),
        _ => (t, e),
    })
}

/// Where in `text` exmex's `message` points: the rest it could not parse
/// or a position it names.
fn position_of(text: &str, message: &str) -> Option<usize> {
    if let Some(rest) = message.strip_prefix("don't know how to parse ") {
        return text
            .rfind(rest.trim())
            .or(Some(text.len() - rest.len().min(text.len())));
    }
    if let Some(i) = message.find("position ") {
        let digits: String = message[i + 9..]
            .chars()
            .take_while(char::is_ascii_digit)
            .collect();
        return digits.parse().ok();
    }
    None
}

/// exmex's message, as a user reads it.
fn syntax_message(message: &str) -> String {
    format!("cannot parse it: {message}")
}
