//! The functions an equation may call: exmex's defaults for floats
//! (arithmetic, powers, sqrt, exp, logarithms, trigonometric and
//! hyperbolic functions, abs, min, max, atan2) and what an engineer's
//! model needs beside them: `sign`, a saturation `sat(x, limit)`,
//! comparisons (1 where true, else 0) and a piecewise
//! `if CONDITION then VALUE else OTHER`.
//!
//! exmex parses; it does not evaluate a record. Its
//! operators here act on [`Traced`] values: evaluating a parsed equation
//! once on them gives the equation's tree in exmex's own reading
//! (priorities, unary minus), which the expression module compiles to
//! instructions over the value table. The arithmetic itself is
//! [`Unary::apply`] and [`Binary::apply`], the one place each function is
//! defined.

use std::str::FromStr;

use exmex::{BinOp, MakeOperators, MatchLiteral, Operator};

/// What `then` gives where its condition is false: a NaN whose bits no
/// arithmetic produces, which `else` replaces by its right side. An
/// equation never sees it: a `then` without an `else` is refused at load.
const NO_BRANCH: u64 = 0x7ff8_0000_0b1a_7c4e;

fn no_branch() -> f64 {
    f64::from_bits(NO_BRANCH)
}

/// Whether a value is a `then` whose condition failed with no `else`.
pub(crate) fn lacks_branch(x: f64) -> bool {
    x.to_bits() == NO_BRANCH
}

/// Priorities below exmex's `+` (0): comparisons bind tighter than
/// `then`, `then` tighter than `else`, so that
/// `if x < 0 then -1 else x > 1 then 1 else x` reads as it would aloud.
const COMPARISON: i64 = -10;
const THEN: i64 = -20;
const ELSE: i64 = -30;

fn truth(holds: bool) -> f64 {
    if holds { 1.0 } else { 0.0 }
}

/// A function of one argument.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Unary {
    Neg,
    Abs,
    Signum,
    Sign,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Sinh,
    Cosh,
    Tanh,
    Asinh,
    Acosh,
    Atanh,
    Floor,
    Round,
    Ceil,
    Trunc,
    Fract,
    Exp,
    Sqrt,
    Cbrt,
    Ln,
    Log2,
    Log10,
}

impl Unary {
    /// Every function, in declaration order: `ALL[f as usize] == f`.
    const ALL: [Self; 27] = [
        Self::Neg,
        Self::Abs,
        Self::Signum,
        Self::Sign,
        Self::Sin,
        Self::Cos,
        Self::Tan,
        Self::Asin,
        Self::Acos,
        Self::Atan,
        Self::Sinh,
        Self::Cosh,
        Self::Tanh,
        Self::Asinh,
        Self::Acosh,
        Self::Atanh,
        Self::Floor,
        Self::Round,
        Self::Ceil,
        Self::Trunc,
        Self::Fract,
        Self::Exp,
        Self::Sqrt,
        Self::Cbrt,
        Self::Ln,
        Self::Log2,
        Self::Log10,
    ];

    /// The function whose `f as u32` is `code` (how compiled code names
    /// it).
    pub(crate) fn from_code(code: u32) -> Option<Self> {
        Self::ALL.get(code as usize).copied()
    }

    /// Its value at `x`.
    #[inline]
    pub(crate) fn apply(self, x: f64) -> f64 {
        match self {
            Self::Neg => -x,
            Self::Abs => x.abs(),
            Self::Signum => x.signum(),
            Self::Sign => {
                if x == 0.0 {
                    0.0
                } else {
                    x.signum()
                }
            }
            Self::Sin => x.sin(),
            Self::Cos => x.cos(),
            Self::Tan => x.tan(),
            Self::Asin => x.asin(),
            Self::Acos => x.acos(),
            Self::Atan => x.atan(),
            Self::Sinh => x.sinh(),
            Self::Cosh => x.cosh(),
            Self::Tanh => x.tanh(),
            Self::Asinh => x.asinh(),
            Self::Acosh => x.acosh(),
            Self::Atanh => x.atanh(),
            Self::Floor => x.floor(),
            Self::Round => x.round(),
            Self::Ceil => x.ceil(),
            Self::Trunc => x.trunc(),
            Self::Fract => x.fract(),
            Self::Exp => x.exp(),
            Self::Sqrt => x.sqrt(),
            Self::Cbrt => x.cbrt(),
            Self::Ln => x.ln(),
            Self::Log2 => x.log2(),
            Self::Log10 => x.log10(),
        }
    }
}

/// A function of two arguments (an operator or a two-argument call).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Binary {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
    Atan2,
    Min,
    Max,
    Sat,
    Le,
    Ge,
    Eq,
    Ne,
    Lt,
    Gt,
    Then,
    Else,
}

impl Binary {
    /// Every function, in declaration order: `ALL[f as usize] == f`.
    const ALL: [Self; 17] = [
        Self::Add,
        Self::Sub,
        Self::Mul,
        Self::Div,
        Self::Pow,
        Self::Atan2,
        Self::Min,
        Self::Max,
        Self::Sat,
        Self::Le,
        Self::Ge,
        Self::Eq,
        Self::Ne,
        Self::Lt,
        Self::Gt,
        Self::Then,
        Self::Else,
    ];

    /// The function whose `f as u32` is `code` (how compiled code names
    /// it).
    pub(crate) fn from_code(code: u32) -> Option<Self> {
        Self::ALL.get(code as usize).copied()
    }

    /// Its value at `(a, b)`.
    #[inline]
    pub(crate) fn apply(self, a: f64, b: f64) -> f64 {
        match self {
            Self::Add => a + b,
            Self::Sub => a - b,
            Self::Mul => a * b,
            Self::Div => a / b,
            Self::Pow => a.powf(b),
            Self::Atan2 => a.atan2(b),
            // Spelled out, not f64::min and max, whose choice between
            // equal operands (0 and -0) is left to the compiler: compiled
            // code does the same one comparison. A
            // NaN first operand passes on, as arithmetic passes NaN on.
            Self::Min => {
                if b < a {
                    b
                } else {
                    a
                }
            }
            Self::Max => {
                if a < b {
                    b
                } else {
                    a
                }
            }
            // f64::clamp panics on a NaN bound: a NaN limit gives NaN,
            // which fails its record with the state named.
            Self::Sat => {
                if b.is_nan() {
                    f64::NAN
                } else {
                    a.clamp(-b.abs(), b.abs())
                }
            }
            Self::Le => truth(a <= b),
            Self::Ge => truth(a >= b),
            // Exact, as the user wrote it: a tolerance would be a choice
            // the equation does not state.
            #[expect(clippy::float_cmp, reason = "an equation's == is exact equality")]
            Self::Eq => truth(a == b),
            #[expect(clippy::float_cmp, reason = "an equation's != is exact inequality")]
            Self::Ne => truth(a != b),
            Self::Lt => truth(a < b),
            Self::Gt => truth(a > b),
            Self::Then => {
                if a != 0.0 && !a.is_nan() {
                    b
                } else {
                    no_branch()
                }
            }
            Self::Else => {
                if lacks_branch(a) {
                    b
                } else {
                    a
                }
            }
        }
    }
}

/// An equation's value as a tree of the table's slots, numbers and
/// functions: what exmex's evaluation builds from [`Traced::Slot`]
/// variables. Numbers combined with numbers are folded as they meet, by
/// the same [`Unary::apply`] and [`Binary::apply`] a record uses.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Traced {
    Number(f64),
    Slot(usize),
    Unary(Unary, Box<Traced>),
    Binary(Binary, Box<Traced>, Box<Traced>),
}

impl Default for Traced {
    fn default() -> Self {
        Self::Number(0.0)
    }
}

impl FromStr for Traced {
    type Err = std::num::ParseFloatError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        s.parse().map(Self::Number)
    }
}

/// Numbers as an equation writes them: digits with at most one decimal
/// point, and an exponent (`2.0e5`, `1E-3`) where digits follow the `e`.
#[derive(Clone, Debug)]
pub(crate) struct DecimalMatcher;

impl MatchLiteral for DecimalMatcher {
    fn is_literal(text: &str) -> Option<&str> {
        let bytes = text.as_bytes();
        let digits_from = |start: usize| {
            start
                + bytes[start..]
                    .iter()
                    .take_while(|b| b.is_ascii_digit())
                    .count()
        };
        let whole = digits_from(0);
        let mut end = whole;
        if bytes.get(end) == Some(&b'.') {
            end = digits_from(end + 1);
        }
        if end == 0 || (end == 1 && whole == 0) {
            return None;
        }
        if let Some(b'e' | b'E') = bytes.get(end) {
            let sign = usize::from(matches!(bytes.get(end + 1), Some(b'+' | b'-')));
            let exponent = digits_from(end + 1 + sign);
            if exponent > end + 1 + sign {
                end = exponent;
            }
        }
        Some(&text[..end])
    }
}

impl Traced {
    fn unary(f: Unary, x: Self) -> Self {
        match x {
            Self::Number(v) => Self::Number(f.apply(v)),
            x => Self::Unary(f, Box::new(x)),
        }
    }

    fn binary(f: Binary, a: Self, b: Self) -> Self {
        match (a, b) {
            (Self::Number(a), Self::Number(b)) => Self::Number(f.apply(a, b)),
            (a, b) => Self::Binary(f, Box::new(a), Box::new(b)),
        }
    }
}

/// exmex's operator for `f` written `repr`, with exmex's priority.
fn binary(
    repr: &'static str,
    f: fn(Traced, Traced) -> Traced,
    prio: i64,
) -> Operator<'static, Traced> {
    Operator::make_bin(
        repr,
        BinOp {
            apply: f,
            prio,
            is_commutative: false,
        },
    )
}

/// The operator factory of equations: exmex's float operators with their
/// priorities (`FloatOpsFactory`), then ours, each building its node.
#[derive(Debug, Clone)]
pub(crate) struct EquationOps;

impl MakeOperators<Traced> for EquationOps {
    fn make<'a>() -> Vec<Operator<'a, Traced>> {
        use std::f64::consts::{E, PI, TAU};
        let n = Traced::Number;
        macro_rules! b {
            ($f:ident) => {
                |a: Traced, b: Traced| Traced::binary(Binary::$f, a, b)
            };
        }
        macro_rules! u {
            ($repr:literal, $f:ident) => {
                Operator::make_unary($repr, |x: Traced| Traced::unary(Unary::$f, x))
            };
        }
        vec![
            binary("^", b!(Pow), 4),
            Operator::make_bin(
                "*",
                BinOp {
                    apply: b!(Mul),
                    prio: 2,
                    is_commutative: true,
                },
            ),
            binary("/", b!(Div), 3),
            Operator::make_bin_unary(
                "+",
                BinOp {
                    apply: b!(Add),
                    prio: 0,
                    is_commutative: true,
                },
                |x| x,
            ),
            Operator::make_bin_unary(
                "-",
                BinOp {
                    apply: b!(Sub),
                    prio: 1,
                    is_commutative: false,
                },
                |x| Traced::unary(Unary::Neg, x),
            ),
            binary("atan2", b!(Atan2), 0),
            binary("min", b!(Min), 0),
            binary("max", b!(Max), 0),
            u!("abs", Abs),
            u!("signum", Signum),
            u!("sin", Sin),
            u!("cos", Cos),
            u!("tan", Tan),
            u!("asin", Asin),
            u!("acos", Acos),
            u!("atan", Atan),
            u!("sinh", Sinh),
            u!("cosh", Cosh),
            u!("tanh", Tanh),
            u!("asinh", Asinh),
            u!("acosh", Acosh),
            u!("atanh", Atanh),
            u!("floor", Floor),
            u!("round", Round),
            u!("ceil", Ceil),
            u!("trunc", Trunc),
            u!("fract", Fract),
            u!("exp", Exp),
            u!("sqrt", Sqrt),
            u!("cbrt", Cbrt),
            u!("ln", Ln),
            u!("log2", Log2),
            u!("log10", Log10),
            u!("log", Ln),
            Operator::make_constant("PI", n(PI)),
            Operator::make_constant("π", n(PI)),
            Operator::make_constant("E", n(E)),
            Operator::make_constant("e", n(E)),
            Operator::make_constant("TAU", n(TAU)),
            Operator::make_constant("τ", n(TAU)),
            u!("sign", Sign),
            binary("sat", b!(Sat), 0),
            // Longer representations first: `<=` is not `<` then `=`.
            binary("<=", b!(Le), COMPARISON),
            binary(">=", b!(Ge), COMPARISON),
            binary("==", b!(Eq), COMPARISON),
            binary("!=", b!(Ne), COMPARISON),
            binary("<", b!(Lt), COMPARISON),
            binary(">", b!(Gt), COMPARISON),
            // `if` only reads well: the condition is what `then` tests.
            Operator::make_unary("if", |x| x),
            binary("then", b!(Then), THEN),
            binary("else", b!(Else), ELSE),
        ]
    }
}
