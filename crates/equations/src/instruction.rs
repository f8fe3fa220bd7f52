//! The instructions equations compile to: a function of slots of the
//! model's value table written into another, and the
//! interpreter that runs them.

use crate::ops::{Binary, Unary};

/// One step of a compiled right side: a function of slots of the value
/// table (`a`, `b`), written into another (`to`). The four arithmetic
/// operators have steps of their own so that the commonest instructions
/// take one dispatch, not two.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Instruction {
    Add([u32; 3]),
    Sub([u32; 3]),
    Mul([u32; 3]),
    Div([u32; 3]),
    Unary(Unary, [u32; 2]),
    Binary(Binary, [u32; 3]),
    Copy([u32; 2]),
}

impl Instruction {
    /// The instruction computing `f(a, b)` into `to`.
    pub(crate) fn binary(f: Binary, [a, b, to]: [u32; 3]) -> Self {
        match f {
            Binary::Add => Self::Add([a, b, to]),
            Binary::Sub => Self::Sub([a, b, to]),
            Binary::Mul => Self::Mul([a, b, to]),
            Binary::Div => Self::Div([a, b, to]),
            f => Self::Binary(f, [a, b, to]),
        }
    }

    /// The same instruction writing into `to`.
    pub(crate) fn writing(self, to: u32) -> Self {
        match self {
            Self::Add([a, b, _]) => Self::Add([a, b, to]),
            Self::Sub([a, b, _]) => Self::Sub([a, b, to]),
            Self::Mul([a, b, _]) => Self::Mul([a, b, to]),
            Self::Div([a, b, _]) => Self::Div([a, b, to]),
            Self::Unary(f, [x, _]) => Self::Unary(f, [x, to]),
            Self::Binary(f, [a, b, _]) => Self::Binary(f, [a, b, to]),
            Self::Copy([x, _]) => Self::Copy([x, to]),
        }
    }

    /// The same instruction on slots `by` further on (another lane's
    /// table, laid after the first).
    pub(crate) fn shifted(self, by: u32) -> Self {
        match self {
            Self::Add([a, b, to]) => Self::Add([a + by, b + by, to + by]),
            Self::Sub([a, b, to]) => Self::Sub([a + by, b + by, to + by]),
            Self::Mul([a, b, to]) => Self::Mul([a + by, b + by, to + by]),
            Self::Div([a, b, to]) => Self::Div([a + by, b + by, to + by]),
            Self::Unary(f, [x, to]) => Self::Unary(f, [x + by, to + by]),
            Self::Binary(f, [a, b, to]) => Self::Binary(f, [a + by, b + by, to + by]),
            Self::Copy([x, to]) => Self::Copy([x + by, to + by]),
        }
    }

    /// The slots it reads and the one it writes.
    pub(crate) fn slots(self) -> ([u32; 2], u32) {
        match self {
            Self::Add([a, b, to])
            | Self::Sub([a, b, to])
            | Self::Mul([a, b, to])
            | Self::Div([a, b, to])
            | Self::Binary(_, [a, b, to]) => ([a, b], to),
            Self::Unary(_, [x, to]) | Self::Copy([x, to]) => ([x, x], to),
        }
    }
}

/// Runs `code` on the value table.
#[inline]
pub(crate) fn run(code: &[Instruction], values: &mut [f64]) {
    for instruction in code {
        let (slot, value) = match *instruction {
            Instruction::Add([a, b, to]) => (to, values[a as usize] + values[b as usize]),
            Instruction::Sub([a, b, to]) => (to, values[a as usize] - values[b as usize]),
            Instruction::Mul([a, b, to]) => (to, values[a as usize] * values[b as usize]),
            Instruction::Div([a, b, to]) => (to, values[a as usize] / values[b as usize]),
            Instruction::Unary(f, [x, to]) => (to, f.apply(values[x as usize])),
            Instruction::Binary(f, [a, b, to]) => {
                (to, f.apply(values[a as usize], values[b as usize]))
            }
            Instruction::Copy([x, to]) => (to, values[x as usize]),
        };
        values[slot as usize] = value;
    }
}
