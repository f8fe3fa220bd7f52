//! `[equations]`: a model written as equations in its model file, read
//! into the equations crate's text and compiled
//! against the file's parameters and signals at load.

use toml::Spanned;
use twostage_equations::{
    Equation, EquationError, EquationModel, EquationsText, InputPath, Integrator, Measure, State,
    Time,
};
use twostage_models::ModelSpec;

use super::ModelSource;
use super::locator::Locator;
use super::raw::{RawEquations, RawInput, RawNoise, RawSource};
use crate::{Error, Result};

impl Locator<'_> {
    /// The equations source, where the file has `[equations]` and no
    /// `[source]`.
    pub(super) fn equations(
        &self,
        equations: &Spanned<RawEquations>,
        source: Option<&Spanned<RawSource>>,
        noise: Option<&Spanned<RawNoise>>,
        input: Option<&Spanned<RawInput>>,
    ) -> Result<ModelSource> {
        if let Some(source) = source {
            return Err(self.error(
                Some(source.span()),
                "source",
                "the file writes its model as [equations]: leave out [source] (or the \
                 equations, to simulate with the source)"
                    .into(),
            ));
        }
        if let Some(noise) = noise {
            let raw = noise.get_ref();
            if raw.model.is_some() || raw.inputs.is_some() {
                return Err(self.error(
                    Some(noise.span()),
                    "noise",
                    "`model` and `inputs` are for built-in models and FMUs; equations take \
                     their own noise as a state's `noise` and an output's `lognormal` under \
                     [equations], additive output noise as output_sd here"
                        .into(),
                ));
            }
        }
        let raw = equations.get_ref();
        let time = match raw.time.as_ref().map(|t| t.get_ref().as_str()) {
            None | Some("continuous") => {
                let substeps = match &raw.substeps {
                    None => DEFAULT_SUBSTEPS,
                    Some(s) => usize::try_from(*s.get_ref())
                        .ok()
                        .filter(|n| (1..=MAX_SUBSTEPS).contains(n))
                        .ok_or_else(|| {
                            self.error(
                                Some(s.span()),
                                "equations.substeps",
                                format!(
                                    "must be a whole number from 1 to {MAX_SUBSTEPS}, not {} \
                                     (for dynamics faster than that, sample faster: a \
                                     shorter sample_time)",
                                    s.get_ref()
                                ),
                            )
                        })?,
                };
                Time::Continuous { substeps }
            }
            Some("discrete") => {
                if let Some(s) = &raw.substeps {
                    return Err(self.error(
                        Some(s.span()),
                        "equations.substeps",
                        "a discrete-time model steps once per sample: substeps are for \
                         time = \"continuous\""
                            .into(),
                    ));
                }
                Time::Discrete
            }
            Some(other) => {
                return Err(self.error(
                    raw.time.as_ref().map(Spanned::span),
                    "equations.time",
                    format!(
                        "`{other}`: give \"continuous\" (derivatives) or \"discrete\" (next values)"
                    ),
                ));
            }
        };
        let measure = match raw.measure.as_ref().map(|m| m.get_ref().as_str()) {
            None | Some("start") => Measure::Start,
            Some("end") => Measure::End,
            Some(other) => {
                return Err(self.error(
                    raw.measure.as_ref().map(Spanned::span),
                    "equations.measure",
                    format!(
                        "`{other}`: give \"start\" (sample k at t = k T) or \"end\" (at (k + 1) T)"
                    ),
                ));
            }
        };
        let choice = |given: &Option<Spanned<String>>, key: &str, options: &[&str]| match given {
            None => Ok(0),
            Some(g) => options
                .iter()
                .position(|o| o == g.get_ref())
                .ok_or_else(|| {
                    self.error(
                        Some(g.span()),
                        key,
                        format!("`{}`: give one of {}", g.get_ref(), options.join(", ")),
                    )
                }),
        };
        let integrator = match choice(&raw.integrator, "equations.integrator", &["rk4", "euler"])? {
            0 => Integrator::Rk4,
            _ => Integrator::Euler,
        };
        let inputs = match choice(
            &raw.inputs,
            "equations.inputs",
            &["cubic", "linear", "hold"],
        )? {
            0 => InputPath::Cubic,
            1 => InputPath::Linear,
            _ => InputPath::Hold,
        };
        if let (Time::Discrete, Some(key)) = (time, raw.integrator.as_ref().or(raw.inputs.as_ref()))
        {
            return Err(self.error(
                Some(key.span()),
                "equations",
                "`integrator` and `inputs` say how a continuous-time model moves between \
                 samples: a discrete-time one steps once per sample on the sample's inputs"
                    .into(),
            ));
        }
        let (update_key, other_key) = match time {
            Time::Continuous { .. } => ("derivative", "next"),
            Time::Discrete => ("next", "derivative"),
        };
        let mut states = Vec::with_capacity(raw.states.len());
        for spanned in &raw.states {
            let s = spanned.get_ref();
            let line = self.line(spanned.span().start);
            let key = format!("equations.states.{}", s.name.get_ref());
            let (update, wrong) = match time {
                Time::Continuous { .. } => (&s.derivative, &s.next),
                Time::Discrete => (&s.next, &s.derivative),
            };
            if let Some(wrong) = wrong {
                return Err(self.error(
                    Some(wrong.span()),
                    &key,
                    format!(
                        "`{other_key}` is for the other time base: this model's states take \
                         `{update_key}` (time = \"{}\")",
                        if update_key == "next" {
                            "discrete"
                        } else {
                            "continuous"
                        }
                    ),
                ));
            }
            let update = update.as_ref().ok_or_else(|| {
                self.error(
                    Some(spanned.span()),
                    &key,
                    format!("the state has no `{update_key}`: give one"),
                )
            })?;
            states.push(State {
                name: s.name.get_ref().clone(),
                initial: s.initial.get_ref().text(),
                update: update.get_ref().text(),
                noise_sd: s.noise.as_ref().map_or(0.0, |n| *n.get_ref()),
                line: Some(line),
            });
        }
        let equations_of = |table: &std::collections::BTreeMap<String, Spanned<_>>| {
            let mut list: Vec<Equation> = table
                .iter()
                .map(
                    |(name, text): (&String, &Spanned<super::raw::ExpressionText>)| Equation {
                        name: name.clone(),
                        text: text.get_ref().text(),
                        line: Some(self.line(text.span().start)),
                    },
                )
                .collect();
            // As written, for messages and listings.
            list.sort_by_key(|e| e.line);
            list
        };
        let text = EquationsText {
            time,
            measure,
            integrator,
            inputs,
            states,
            definitions: equations_of(&raw.define),
            outputs: equations_of(&raw.outputs),
            lognormal_sd: Vec::new(),
        };
        let lognormal = raw
            .lognormal
            .iter()
            .map(|(name, sd)| (name.clone(), *sd.get_ref(), self.line(sd.span().start)))
            .collect();
        let input = input
            .filter(|i| i.get_ref().file.is_none())
            .map(|i| self.input(i))
            .transpose()?;
        Ok(ModelSource::Equations {
            text,
            lognormal,
            line: self.line(equations.span().start),
            input,
        })
    }
}

/// RK4 steps per sample where the file does not say.
pub const DEFAULT_SUBSTEPS: usize = 10;

/// The most integrator steps a sample: a record's work grows with them, and
/// a step of a hundred-thousandth of the sample time is finer than RK4
/// needs in f64 (a typo of a few zeros would otherwise run for days).
pub const MAX_SUBSTEPS: usize = 100_000;

/// `text` compiled for `spec`, the file's `lognormal` (output name, sd,
/// line) placed in the outputs' order; an error names the file, the line
/// of the equation and its position.
pub(super) fn compile(
    origin: &str,
    (text, lognormal, table_line): (&EquationsText, &[(String, f64, usize)], usize),
    spec: &ModelSpec,
) -> Result<EquationModel> {
    let mut text = text.clone();
    text.lognormal_sd = vec![0.0; spec.output_names().len()];
    for (name, sd, line) in lognormal {
        let j = spec
            .output_names()
            .iter()
            .position(|o| o == name)
            .ok_or_else(|| Error::ModelFile {
                file: origin.to_string(),
                line: Some(*line),
                key: format!("equations.lognormal.{name}"),
                message: format!(
                    "not an output of the model (its outputs: {})",
                    spec.output_names().join(", ")
                ),
            })?;
        text.lognormal_sd[j] = *sd;
    }
    EquationModel::compile(&text, spec).map_err(|e| located(origin, &text, table_line, e))
}

/// `error` with the line of its equation in the file.
fn located(origin: &str, text: &EquationsText, table_line: usize, error: EquationError) -> Error {
    let name = error.equation.split('.').next().unwrap_or_default();
    let line = text
        .states
        .iter()
        .find(|s| s.name == name)
        .and_then(|s| s.line)
        .or_else(|| {
            text.definitions
                .iter()
                .chain(&text.outputs)
                .find(|e| e.name == name)
                .and_then(|e| e.line)
        })
        .unwrap_or(table_line);
    let EquationError {
        equation,
        position,
        message,
    } = error;
    Error::ModelFile {
        file: origin.to_string(),
        line: Some(line),
        key: format!("equations.{equation}"),
        message: match position {
            Some(p) => format!("at character {} of the equation: {message}", p + 1),
            None => message,
        },
    }
}

/// What `models` says of an equations model's own noise.
pub(super) fn noise_note(text: &EquationsText, lognormal: &[(String, f64, usize)]) -> String {
    let mut parts: Vec<String> = text
        .states
        .iter()
        .filter(|s| s.noise_sd > 0.0)
        .map(|s| format!("process noise on {} (sd {})", s.name, s.noise_sd))
        .collect();
    parts.extend(
        lognormal
            .iter()
            .filter(|(_, sd, _)| *sd > 0.0)
            .map(|(name, sd, _)| format!("{name} times exp(N(0, {sd}^2))")),
    );
    if parts.is_empty() {
        "none of the equations' own".into()
    } else {
        parts.join(", ")
    }
}
