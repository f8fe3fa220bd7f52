//! Where a training request's records come from: simulated as the run
//! goes, a chart folder (or arrays in memory), or shard files.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use twostage_models::Simulator;

use crate::{ChartArrays, ChartFiles, Result};

/// A chart folder (CSV or NumPy files), and how the estimator file names
/// it when not by its folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChartDir {
    /// The folder.
    pub dir: PathBuf,
    /// The name the estimator's record gives it (default: the folder).
    #[serde(default)]
    pub label: Option<String>,
}

impl ChartDir {
    /// The folder `dir`, named by itself.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            label: None,
        }
    }

    /// The chart in the folder, for `model`, named by the label where
    /// there is one.
    ///
    /// # Errors
    /// What [`ChartFiles::open`] reports.
    pub fn open(&self, model: &dyn Simulator) -> Result<ChartFiles> {
        let chart = ChartFiles::open(&self.dir, model.spec())?;
        Ok(match &self.label {
            Some(label) => chart.labelled(label.clone()),
            None => chart,
        })
    }
}

/// A chart given to a request in memory or by its folder (the Python
/// package's `chart` argument: arrays or a folder).
#[derive(Debug, Clone, PartialEq)]
pub enum ChartGiven {
    /// A chart folder.
    Folder(ChartDir),
    /// Arrays, and how the estimator file names them.
    Arrays {
        /// The chart's arrays.
        arrays: Arc<ChartArrays>,
        /// The name the estimator's record gives them.
        label: String,
    },
}

impl ChartGiven {
    /// The chart, for `model`.
    ///
    /// # Errors
    /// What [`ChartFiles::open`] or [`ChartFiles::from_arrays`] reports.
    pub fn open(&self, model: &dyn Simulator) -> Result<ChartFiles> {
        match self {
            Self::Folder(dir) => dir.open(model),
            Self::Arrays { arrays, label } => Ok(ChartFiles::from_arrays(
                arrays.clone(),
                model.spec(),
                label.clone(),
            )?),
        }
    }
}

/// Where a request's records come from.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RecordsRequest {
    /// Simulated by the model as the run goes.
    #[default]
    Simulated,
    /// A chart simulated elsewhere; calibration and validation on charts
    /// of their own when given, else on records held out of it.
    Chart {
        /// The training chart.
        training: ChartDir,
        /// A chart of its own for the intervals.
        #[serde(default)]
        calibration: Option<ChartDir>,
        /// A chart of its own for the validation report.
        #[serde(default)]
        validation: Option<ChartDir>,
    },
    /// Shard files of `twostage simulate --shard`, named by a pattern such
    /// as `DIR/shard-*`.
    Shards {
        /// The pattern.
        pattern: String,
    },
    /// Charts given in memory or by folder ([`Self::Chart`] with arrays
    /// allowed; a request file cannot hold arrays, so it never has one).
    #[serde(skip)]
    Given {
        /// The training chart.
        training: ChartGiven,
        /// A chart of its own for the intervals.
        calibration: Option<ChartGiven>,
        /// A chart of its own for the validation report.
        validation: Option<ChartGiven>,
    },
}

impl RecordsRequest {
    /// The records a `--chart` argument names: shard files when it is a
    /// pattern (`*`, `?`, `[`) or a `.tsshard` file, else a chart folder.
    ///
    /// ```
    /// use twostage_sources::RecordsRequest;
    /// assert!(matches!(RecordsRequest::chart("runs/shard-*"), RecordsRequest::Shards { .. }));
    /// assert!(matches!(RecordsRequest::chart("runs/sir"), RecordsRequest::Chart { .. }));
    /// ```
    pub fn chart(argument: impl AsRef<Path>) -> Self {
        let text = argument.as_ref().to_string_lossy();
        if text.contains(['*', '?', '[']) || text.ends_with(".tsshard") {
            Self::Shards {
                pattern: text.into_owned(),
            }
        } else {
            Self::Chart {
                training: ChartDir::new(argument.as_ref()),
                calibration: None,
                validation: None,
            }
        }
    }
}
