//! The file as TOML gives it: unknown keys are refused with their line.

use std::collections::BTreeMap;
use std::ops::Range;

use serde::Deserialize;
use toml::Spanned;

// ---- The file as TOML gives it (unknown keys are refused with their line).

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFile {
    pub(super) model: RawModel,
    pub(super) source: Option<Spanned<RawSource>>,
    #[serde(default)]
    pub(super) parameter: Vec<Spanned<RawParameter>>,
    pub(super) signals: Option<Spanned<RawSignals>>,
    pub(super) input: Option<Spanned<RawInput>>,
    pub(super) noise: Option<Spanned<RawNoise>>,
    pub(super) equations: Option<Spanned<RawEquations>>,
    #[serde(default)]
    pub(super) preset: Vec<Spanned<RawPreset>>,
}

/// `[equations]`: the model written as equations.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawEquations {
    pub(super) time: Option<Spanned<String>>,
    pub(super) substeps: Option<Spanned<i64>>,
    pub(super) measure: Option<Spanned<String>>,
    pub(super) integrator: Option<Spanned<String>>,
    pub(super) inputs: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) states: Vec<Spanned<RawState>>,
    #[serde(default)]
    pub(super) define: BTreeMap<String, Spanned<ExpressionText>>,
    #[serde(default)]
    pub(super) outputs: BTreeMap<String, Spanned<ExpressionText>>,
    #[serde(default)]
    pub(super) lognormal: BTreeMap<String, Spanned<f64>>,
}

/// One state of `[equations]`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawState {
    pub(super) name: Spanned<String>,
    pub(super) initial: Spanned<ExpressionText>,
    pub(super) derivative: Option<Spanned<ExpressionText>>,
    pub(super) next: Option<Spanned<ExpressionText>>,
    pub(super) noise: Option<Spanned<f64>>,
}

/// A right side: an expression, or a plain number.
#[derive(Deserialize)]
#[serde(untagged)]
pub(super) enum ExpressionText {
    Text(String),
    Number(f64),
}

impl ExpressionText {
    pub(super) fn text(&self) -> String {
        match self {
            Self::Text(t) => t.clone(),
            // Exact: Rust's shortest representation reads back the same.
            Self::Number(x) => format!("{x:?}"),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawModel {
    pub(super) name: Spanned<String>,
    pub(super) description: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSource {
    pub(super) builtin: Option<Spanned<String>>,
    pub(super) command: Option<Spanned<Vec<String>>>,
    pub(super) fmu: Option<Spanned<String>>,
    pub(super) timeout_seconds: Option<Spanned<f64>>,
    pub(super) batch: Option<Spanned<i64>>,
    pub(super) protocol: Option<Spanned<i64>>,
    pub(super) interface: Option<Spanned<String>>,
    pub(super) step_divisor: Option<Spanned<i64>>,
    pub(super) start_time: Option<Spanned<f64>>,
    pub(super) start: Option<Spanned<BTreeMap<String, f64>>>,
}

impl RawSource {
    /// The first key given that only an FMU source takes.
    pub(super) fn fmu_key(&self) -> Option<(&'static str, Range<usize>)> {
        [
            (
                "source.interface",
                self.interface.as_ref().map(Spanned::span),
            ),
            (
                "source.step_divisor",
                self.step_divisor.as_ref().map(Spanned::span),
            ),
            (
                "source.start_time",
                self.start_time.as_ref().map(Spanned::span),
            ),
            ("source.start", self.start.as_ref().map(Spanned::span)),
        ]
        .into_iter()
        .find_map(|(key, span)| span.map(|s| (key, s)))
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawParameter {
    pub(super) name: Spanned<String>,
    pub(super) prior: Option<Spanned<RawPrior>>,
    /// The parameter belongs to one record (an initial state, a sensor
    /// offset), not to the plant.
    #[serde(default)]
    pub(super) per_record: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawPrior {
    pub(super) dist: Spanned<String>,
    pub(super) low: Option<f64>,
    pub(super) high: Option<f64>,
    pub(super) mu: Option<f64>,
    pub(super) sigma: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSignals {
    pub(super) inputs: Option<Spanned<Vec<String>>>,
    pub(super) outputs: Option<Spanned<Vec<String>>>,
    pub(super) samples: Option<Spanned<i64>>,
    pub(super) sample_time: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawInput {
    pub(super) signal: Spanned<String>,
    pub(super) sd: Option<f64>,
    /// One value, or `[low, high]` drawn per experiment.
    pub(super) amplitude: Option<OneOrMany>,
    pub(super) values: Option<Vec<f64>>,
    /// A design's band in Hz: its bottom and its top, each one value or
    /// `[low, high]`.
    pub(super) band: Option<(OneOrMany, OneOrMany)>,
    /// A multisine's lines: "full" or "odd".
    pub(super) grid: Option<String>,
    /// A multisine's phases: "random" or "schroeder".
    pub(super) phases: Option<String>,
    pub(super) rms: Option<OneOrMany>,
    pub(super) peak: Option<OneOrMany>,
    /// A multisine's or a band noise's relative line amplitudes,
    /// `[[Hz, level], ...]`.
    pub(super) spectrum: Option<Spanned<Vec<[f64; 2]>>>,
    /// The same, shaped like a measured record's column.
    pub(super) like: Option<Spanned<RawLike>>,
    /// A constant added to a design.
    pub(super) offset: Option<OneOrMany>,
    /// Samples each value of a binary sequence is held.
    pub(super) hold: Option<usize>,
    /// A PRBS register's bits.
    pub(super) order: Option<u32>,
    /// Random steps' levels and holds (seconds), each `[low, high]`.
    pub(super) levels: Option<[f64; 2]>,
    pub(super) hold_seconds: Option<[f64; 2]>,
    /// Ramps' move times in seconds: one number or `[low, high]`.
    pub(super) ramp_seconds: Option<OneOrMany>,
    /// Bursts per record: one number, or `[low, high]` drawn per record.
    pub(super) count: Option<OneOrMany>,
    /// Each burst's length in seconds and its sine's cycles.
    pub(super) seconds: Option<OneOrMany>,
    pub(super) cycles: Option<OneOrMany>,
    /// A burst's window: "hann", "none" or "mixed".
    pub(super) taper: Option<String>,
    /// Seconds a burst holds one of its crests: one number or `[low, high]`.
    pub(super) dwell: Option<OneOrMany>,
    /// A sum's, a mixture's or a sequence's parts, each an input table of
    /// its own.
    pub(super) parts: Option<Vec<Spanned<RawInput>>>,
    /// A mixture's chance of each part (relative), one per part.
    pub(super) weights: Option<Vec<f64>>,
    pub(super) file: Option<Spanned<String>>,
    /// The file's columns to read, in the order of the model's inputs.
    pub(super) columns: Option<Spanned<Vec<String>>>,
    /// The file's data rows to read, first and last (from 1), inclusive.
    pub(super) rows: Option<Spanned<[usize; 2]>>,
}

/// A measured record whose input's spectrum a design takes the shape of.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLike {
    pub(super) file: Spanned<String>,
    pub(super) column: Spanned<String>,
    /// Data rows to read, first and last from 1, inclusive.
    pub(super) rows: Option<Spanned<[usize; 2]>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawNoise {
    pub(super) model: Option<bool>,
    pub(super) output_sd: Option<Spanned<OneOrMany>>,
    pub(super) output_ar: Option<Spanned<OneOrMany>>,
    pub(super) output_residual: Option<Spanned<String>>,
    pub(super) inputs: Option<Spanned<Vec<RawNoiseInput>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawNoiseInput {
    pub(super) name: String,
    pub(super) sd: f64,
}

#[derive(Deserialize)]
#[serde(untagged)]
pub(super) enum OneOrMany {
    One(f64),
    Many(Vec<f64>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawPreset {
    pub(super) name: Spanned<String>,
    pub(super) compress: Spanned<String>,
    pub(super) fit: Spanned<String>,
    pub(super) sims: Option<Spanned<i64>>,
}
