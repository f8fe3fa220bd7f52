//! One equation's right side, parsed and compiled once by exmex, with
//! its names resolved to slots of the model's value table.

use exmex::{Express, FlatEx};

use crate::ops::EquationOps;
use crate::{EquationError, Names};

/// A compiled right side: exmex's flat expression and, for each of its
/// variables (in exmex's order), the slot of the value table it reads.
#[derive(Debug, Clone)]
pub(crate) struct Expression {
    flat: FlatEx<f64, EquationOps>,
    slots: Vec<usize>,
    /// Where the expression is one name alone (`y = x2`): its slot, read
    /// without evaluating.
    alias: Option<usize>,
}

impl Expression {
    /// Parse `text`, the right side of the equation called `key`, and
    /// resolve its names among `names` (those `allowed` for this kind of
    /// equation; a known name that is not allowed says why).
    pub(crate) fn compile(
        key: &str,
        text: &str,
        names: &Names,
        allowed: impl Fn(usize) -> Result<(), String>,
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
        if let Some(at) = negated_power(text) {
            return Err(error(
                Some(at),
                "a minus sign before a power: exmex reads -x^2 as (-x)^2, not -(x^2) as \
                 mathematics does; write -(x^2) or (-x)^2, whichever is meant"
                    .into(),
            ));
        }
        let flat = FlatEx::<f64, EquationOps>::parse(text)
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
        let alias =
            (slots.len() == 1 && flat.unparse().trim() == flat.var_names()[0]).then(|| slots[0]);
        Ok(Self { flat, slots, alias })
    }

    /// The slots this expression reads.
    pub(crate) fn reads(&self) -> &[usize] {
        &self.slots
    }

    /// Its value with the table `values`; `scratch` holds the gathered
    /// variables (kept by the caller so that nothing is allocated).
    pub(crate) fn eval(&self, values: &[f64], scratch: &mut Vec<f64>) -> f64 {
        if let Some(slot) = self.alias {
            return values[slot];
        }
        scratch.clear();
        scratch.extend(self.slots.iter().map(|&s| values[s]));
        // The variables are exactly the expression's, in its order: exmex
        // only fails on a count that differs, which `compile` rules out.
        self.flat.eval(scratch).unwrap_or(f64::NAN)
    }
}

/// Where `text` puts a unary minus before an operand raised to a power
/// (`-x^2`, `2 * -f(x)^3`, `-(a + b)^2`), which exmex evaluates as
/// `(-x)^2`: unary operators bind tighter than binary ones there
/// (exmex's documentation). A unary minus is one at the start, or after
/// an opening parenthesis, a comma or another operator.
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
