//! The functions an equation may call: exmex's defaults for floats
//! (arithmetic, powers, sqrt, exp, logarithms, trigonometric and
//! hyperbolic functions, abs, min, max, atan2) and what an engineer's
//! model needs beside them: `sign`, a saturation `sat(x, limit)`,
//! comparisons (1 where true, else 0) and a piecewise
//! `if CONDITION then VALUE else OTHER`.

use exmex::{BinOp, FloatOpsFactory, MakeOperators, Operator};

/// What `then` gives where its condition is false: a NaN whose bits no
/// arithmetic produces, which `else` replaces by its right side. An
/// equation never sees it: a `then` without an `else` is refused at load.
const NO_BRANCH: u64 = 0x7ff8_0000_0b1a_7c4e;

fn no_branch() -> f64 {
    f64::from_bits(NO_BRANCH)
}

fn is_no_branch(x: f64) -> bool {
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

fn comparison(repr: &'static str, apply: fn(f64, f64) -> f64) -> Operator<'static, f64> {
    Operator::make_bin(
        repr,
        BinOp {
            apply,
            prio: COMPARISON,
            is_commutative: false,
        },
    )
}

/// The operator factory of equations.
#[derive(Debug, Clone)]
pub struct EquationOps;

impl MakeOperators<f64> for EquationOps {
    fn make<'a>() -> Vec<Operator<'a, f64>> {
        let mut ops = FloatOpsFactory::<f64>::make();
        ops.extend([
            Operator::make_unary("sign", |x: f64| if x == 0.0 { 0.0 } else { x.signum() }),
            Operator::make_bin(
                "sat",
                BinOp {
                    apply: |x: f64, limit: f64| x.clamp(-limit.abs(), limit.abs()),
                    prio: 0,
                    is_commutative: false,
                },
            ),
            // Longer representations first: `<=` is not `<` then `=`.
            comparison("<=", |a, b| truth(a <= b)),
            comparison(">=", |a, b| truth(a >= b)),
            // Exact, as the user wrote it: a tolerance would be a choice
            // the equation does not state.
            #[expect(clippy::float_cmp, reason = "an equation's == is exact equality")]
            comparison("==", |a, b| truth(a == b)),
            #[expect(clippy::float_cmp, reason = "an equation's != is exact inequality")]
            comparison("!=", |a, b| truth(a != b)),
            comparison("<", |a, b| truth(a < b)),
            comparison(">", |a, b| truth(a > b)),
            // `if` only reads well: the condition is what `then` tests.
            Operator::make_unary("if", |x| x),
            Operator::make_bin(
                "then",
                BinOp {
                    apply: |condition: f64, value| {
                        if condition != 0.0 && !condition.is_nan() {
                            value
                        } else {
                            no_branch()
                        }
                    },
                    prio: THEN,
                    is_commutative: false,
                },
            ),
            Operator::make_bin(
                "else",
                BinOp {
                    apply: |chosen: f64, other| if is_no_branch(chosen) { other } else { chosen },
                    prio: ELSE,
                    is_commutative: false,
                },
            ),
        ]);
        ops
    }
}

/// Whether a value is a `then` whose condition failed with no `else`.
pub(crate) fn lacks_branch(x: f64) -> bool {
    is_no_branch(x)
}
