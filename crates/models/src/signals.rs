//! Signal names as files write them: a model's own, or the generic `u`,
//! `y` (`u1`, `u2`, ..., `y1`, ...) that `twostage simulate` writes for any
//! model, and where each named column of a record's file goes.

/// Where a column of a record's file goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum SignalColumn {
    /// Input signal `j`.
    Input(usize),
    /// Output signal `j`.
    Output(usize),
}

/// The generic names of `n` signals: `prefix` alone for one, `prefix1`,
/// `prefix2`, ... for more.
///
/// ```
/// use twostage_models::generic_signal_names;
/// assert_eq!(generic_signal_names("u", 1), ["u"]);
/// assert_eq!(generic_signal_names("y", 2), ["y1", "y2"]);
/// assert!(generic_signal_names("u", 0).is_empty());
/// ```
pub fn generic_signal_names(prefix: &str, n: usize) -> Vec<String> {
    if n == 1 {
        vec![prefix.to_string()]
    } else {
        (1..=n).map(|j| format!("{prefix}{j}")).collect()
    }
}

/// Where each of `header`'s columns goes, when they name every input and
/// output exactly once, either all by the model's names (`inputs`,
/// `outputs`) or all by the generic ones; `None` otherwise.
///
/// ```
/// use twostage_models::{SignalColumn, signal_columns};
/// let (inputs, outputs) = (["steer".to_string()], ["ay".to_string()]);
/// let by_name = signal_columns(&["ay", "steer"], &inputs, &outputs);
/// assert_eq!(by_name, Some(vec![SignalColumn::Output(0), SignalColumn::Input(0)]));
/// let generic = signal_columns(&["u", "y"], &inputs, &outputs);
/// assert_eq!(generic, Some(vec![SignalColumn::Input(0), SignalColumn::Output(0)]));
/// // Mixed, missing or doubled names are not a record's columns.
/// assert_eq!(signal_columns(&["u", "ay"], &inputs, &outputs), None);
/// assert_eq!(signal_columns(&["ay"], &inputs, &outputs), None);
/// assert_eq!(signal_columns(&["ay", "ay"], &inputs, &outputs), None);
/// ```
pub fn signal_columns(
    header: &[&str],
    inputs: &[String],
    outputs: &[String],
) -> Option<Vec<SignalColumn>> {
    let (n_u, n_y) = (inputs.len(), outputs.len());
    if header.len() != n_u + n_y {
        return None;
    }
    let generic = (
        generic_signal_names("u", n_u),
        generic_signal_names("y", n_y),
    );
    [(inputs, outputs), (&generic.0[..], &generic.1[..])]
        .into_iter()
        .find_map(|(inputs, outputs)| {
            let columns: Vec<SignalColumn> = header
                .iter()
                .map(|name| {
                    inputs
                        .iter()
                        .position(|s| s == name)
                        .map(SignalColumn::Input)
                        .or_else(|| {
                            outputs
                                .iter()
                                .position(|s| s == name)
                                .map(SignalColumn::Output)
                        })
                })
                .collect::<Option<_>>()?;
            let mut distinct = columns.clone();
            distinct.sort_unstable();
            distinct.dedup();
            (distinct.len() == header.len()).then_some(columns)
        })
}
