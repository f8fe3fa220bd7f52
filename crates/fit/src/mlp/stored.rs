//! What a stored network is checked for while it is decoded: every
//! shape its forward pass relies on, so that a decoded network (or
//! density) predicts or errs but never indexes out of range.

use serde::Deserialize;

use crate::error::{FitError, Result};
use crate::standardize::Standardizer;

use super::network::{FittedMlp, MAX_WIDTH, RestartReport, parameter_count};

/// What a file stores; decoding checks every shape the forward pass relies
/// on, so a decoded network predicts or errs but never indexes out of range.
#[derive(Deserialize)]
pub(super) struct FittedMlpFields {
    features: Standardizer,
    targets: Standardizer,
    sizes: Vec<usize>,
    members: Vec<Vec<f64>>,
    reports: Vec<RestartReport>,
    best: usize,
}

impl TryFrom<FittedMlpFields> for FittedMlp {
    type Error = FitError;
    fn try_from(f: FittedMlpFields) -> Result<Self> {
        let shape = |what: String| Err(FitError::ShapeMismatch(format!("stored network: {what}")));
        stored_layers(&f.sizes, f.features.dim(), f.targets.dim())?;
        let count = parameter_count(&f.sizes);
        if f.members.is_empty() || f.members.iter().any(|m| m.len() != count) {
            return shape(format!(
                "{} member networks, each must have {count} weights",
                f.members.len()
            ));
        }
        stored_best(f.best, f.reports.len())?;
        Ok(Self {
            features: f.features,
            targets: f.targets,
            sizes: f.sizes,
            members: f.members,
            reports: f.reports,
            best: f.best,
        })
    }
}

/// Checks a stored network's layer `sizes` against its `inputs` and
/// `outputs`: what the forward pass relies on.
///
/// # Errors
/// The first size out of range, said as a stored network's.
pub(super) fn stored_layers(sizes: &[usize], inputs: usize, outputs: usize) -> Result<()> {
    let shape = |what: String| Err(FitError::ShapeMismatch(format!("stored network: {what}")));
    if sizes.len() < 3 || sizes.len() > 6 {
        return shape(format!("{} layers, expected 3 to 6", sizes.len()));
    }
    if let Some(w) = sizes.iter().find(|&&w| w == 0 || w > MAX_WIDTH) {
        return shape(format!("a layer of width {w}, expected 1..={MAX_WIDTH}"));
    }
    if sizes[0] != inputs || sizes[sizes.len() - 1] != outputs {
        return shape(format!(
            "layers {sizes:?} for {inputs} features and {outputs} targets"
        ));
    }
    Ok(())
}

/// Checks that the kept restart `best` is one of `reports` restarts.
///
/// # Errors
/// It is not, said as a stored network's.
pub(super) fn stored_best(best: usize, reports: usize) -> Result<()> {
    if best >= reports {
        return Err(FitError::ShapeMismatch(format!(
            "stored network: best restart {best} of {reports} reports"
        )));
    }
    Ok(())
}
