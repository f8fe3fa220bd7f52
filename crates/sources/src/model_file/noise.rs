//! A model file's `[noise]` for the outputs: white of `output_sd`, AR(1)
//! with `output_ar`, or shaped like a measured residual
//! (`output_residual`); each mistake named by key and line.

use toml::Spanned;

use super::locator::Locator;
use super::raw::{OneOrMany, RawNoise};
use crate::error::Result;

impl Locator<'_> {
    /// `[noise] output_ar`: each output's noise as AR(1) of this
    /// coefficient (its sd still `output_sd`), one for all or one per
    /// output, each in (-1, 1); none: white.
    pub(super) fn output_correlation(
        &self,
        noise: Option<&Spanned<RawNoise>>,
        outputs: usize,
        output_sd: &[f64],
    ) -> Result<Vec<f64>> {
        let Some(ar) = noise.and_then(|n| n.get_ref().output_ar.as_ref()) else {
            return Ok(vec![0.0; outputs]);
        };
        let values = match ar.get_ref() {
            OneOrMany::One(v) => vec![*v; outputs],
            OneOrMany::Many(v) => v.clone(),
        };
        if values.len() != outputs || values.iter().any(|v| !(v.is_finite() && v.abs() < 1.0)) {
            return Err(self.error(
                Some(ar.span()),
                "noise.output_ar",
                format!(
                    "{values:?}: give one AR(1) coefficient in (-1, 1) for all outputs, or a \
                     list of {outputs} (one per output)"
                ),
            ));
        }
        if output_sd.iter().all(|sd| *sd == 0.0) {
            return Err(self.error(
                Some(ar.span()),
                "noise.output_ar",
                "colours the output noise of `output_sd`, which is not given: add output_sd".into(),
            ));
        }
        Ok(values)
    }

    /// `[noise] output_residual = "residual.csv"`: output noise shaped
    /// like a measured residual (columns named as the outputs), instead of
    /// `output_sd`.
    pub(super) fn output_residual(
        &self,
        noise: Option<&Spanned<RawNoise>>,
        output_sd: &[f64],
    ) -> Result<Option<(std::path::PathBuf, usize)>> {
        let Some(file) = noise.and_then(|n| n.get_ref().output_residual.as_ref()) else {
            return Ok(None);
        };
        let colliding = noise.and_then(|n| {
            let raw = n.get_ref();
            raw.output_ar.as_ref().map(|a| a.span()).or(raw
                .output_sd
                .as_ref()
                .filter(|_| output_sd.iter().any(|sd| *sd > 0.0))
                .map(|s| s.span()))
        });
        if let Some(span) = colliding {
            return Err(self.error(
                Some(span),
                "noise.output_residual",
                "shapes the output noise from a measured residual: leave out output_sd and \
                 output_ar, or the residual"
                    .into(),
            ));
        }
        Ok(Some((
            std::path::PathBuf::from(file.get_ref()),
            self.line(file.span().start),
        )))
    }

    pub(super) fn output_noise(
        &self,
        noise: Option<&Spanned<RawNoise>>,
        outputs: usize,
    ) -> Result<Vec<f64>> {
        let Some(sd) = noise.and_then(|n| n.get_ref().output_sd.as_ref()) else {
            return Ok(vec![0.0; outputs]);
        };
        let values = match sd.get_ref() {
            OneOrMany::One(v) => vec![*v; outputs],
            OneOrMany::Many(v) => v.clone(),
        };
        if values.len() != outputs || values.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(self.error(
                Some(sd.span()),
                "noise.output_sd",
                format!(
                    "{values:?}: give one standard deviation >= 0 for all outputs, or a list of \
                     {outputs} (one per output)"
                ),
            ));
        }
        Ok(values)
    }
}

/// What a model file's noise note says: the source's own noise, then the
/// noise the file adds to the outputs (shaped like a residual, or white
/// Gaussian with its sd and AR(1) coefficient per output).
pub(super) fn added_noise_note(
    own: String,
    outputs: &[&str],
    (output_sd, output_ar): (&[f64], &[f64]),
    residual: Option<&std::path::Path>,
) -> String {
    let mut note = own;
    if let Some(path) = residual {
        note = format!(
            "{note}{}added to the outputs: noise shaped like the residual in {} (an AR model of \
             it)",
            if note.is_empty() { "" } else { "; " },
            path.display()
        );
    }
    if output_sd.iter().any(|sd| *sd > 0.0) {
        let added: Vec<String> = outputs
            .iter()
            .zip(output_sd.iter().zip(output_ar))
            .map(|(y, (sd, a))| {
                if *a == 0.0 {
                    format!("{y} sd {sd}")
                } else {
                    format!("{y} sd {sd} AR(1) {a}")
                }
            })
            .collect();
        note = format!(
            "{note}{}white Gaussian added to the outputs: {}",
            if note.is_empty() { "" } else { "; " },
            added.join(", ")
        );
    }
    note
}
