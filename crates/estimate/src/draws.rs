//! Draws from a trained estimator's posterior for each record a request
//! estimates (`samples`): how many, refused where they cannot be made,
//! and each record's draws with their mean and sd.

use twostage_estimator::{EstimateWorkspace, Estimator};
use twostage_models::{IoData, StreamPurpose, stream_rng};

use crate::{GivenValues, Purpose, RegionValues, RequestError, RequestProblem};

/// One record's draws from the estimator's posterior, row after row.
#[derive(Debug, Clone, PartialEq)]
pub struct PosteriorDraws {
    draws: Vec<f64>,
    dim: usize,
    /// The draws' correlation matrix, row-major `dim x dim`.
    correlation: Vec<f64>,
    /// The smallest level of the posterior's region of highest density
    /// that holds the values tested, where values were given.
    region_level: Option<f64>,
}

impl PosteriorDraws {
    /// The draws (draws x parameters, row after row).
    pub fn draws(&self) -> &[f64] {
        &self.draws
    }

    /// How many draws.
    pub fn len(&self) -> usize {
        self.draws.len() / self.dim.max(1)
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.draws.is_empty()
    }

    /// The draws' mean, per parameter.
    ///
    /// ```
    /// let draws = twostage::PosteriorDraws::of(vec![1.0, 10.0, 3.0, 30.0], 2);
    /// assert_eq!(draws.mean(), [2.0, 20.0]);
    /// assert_eq!(draws.sd(), [1.0, 10.0]);
    /// ```
    pub fn mean(&self) -> Vec<f64> {
        let n = self.len().max(1) as f64;
        (0..self.dim)
            .map(|j| self.column(j).sum::<f64>() / n)
            .collect()
    }

    /// The draws' standard deviation (of the draws themselves, divided by
    /// their count), per parameter.
    pub fn sd(&self) -> Vec<f64> {
        let n = self.len().max(1) as f64;
        self.mean()
            .iter()
            .enumerate()
            .map(|(j, m)| (self.column(j).map(|v| (v - m).powi(2)).sum::<f64>() / n).sqrt())
            .collect()
    }

    /// The draws' correlation matrix (row-major, parameters x
    /// parameters; NaN off the diagonal where a parameter does not vary).
    ///
    /// ```
    /// // (1, 2), (2, 4), (3, 5): a covariance of 1 over variances 2/3 and
    /// // 14/9, a correlation of 1 / sqrt(28/27).
    /// let draws = twostage::PosteriorDraws::of(vec![1.0, 2.0, 2.0, 4.0, 3.0, 5.0], 2);
    /// let r = draws.correlation();
    /// assert_eq!(r[0], 1.0);
    /// assert!((r[1] - (27f64 / 28.0).sqrt()).abs() < 1e-12);
    /// assert_eq!(r[1], r[2]);
    /// ```
    pub fn correlation(&self) -> &[f64] {
        &self.correlation
    }

    /// Where values were tested against the posterior
    /// ([`crate::EstimateRequest::region_at`]): the smallest level of its
    /// region of highest density that holds them, the share of the draws
    /// the posterior finds more probable
    /// ([`twostage_fit::FittedMixture::region_level`]). The values lie in
    /// the joint 90% region where it is at most 0.9.
    pub fn region_level(&self) -> Option<f64> {
        self.region_level
    }

    /// Draws of `dim` parameters, row after row.
    pub fn of(draws: Vec<f64>, dim: usize) -> Self {
        let mut made = Self {
            draws,
            dim,
            correlation: Vec::new(),
            region_level: None,
        };
        made.correlation = made.correlation_matrix();
        made
    }

    fn correlation_matrix(&self) -> Vec<f64> {
        let (q, n) = (self.dim, self.len().max(1) as f64);
        let mean = self.mean();
        let covariance = |a: usize, b: usize| {
            self.draws
                .chunks_exact(q.max(1))
                .map(|d| (d[a] - mean[a]) * (d[b] - mean[b]))
                .sum::<f64>()
                / n
        };
        let sd: Vec<f64> = (0..q).map(|j| covariance(j, j).sqrt()).collect();
        let mut r = vec![0.0; q * q];
        for a in 0..q {
            for b in 0..q {
                r[a * q + b] = if a == b {
                    1.0
                } else {
                    covariance(a, b) / (sd[a] * sd[b])
                };
            }
        }
        r
    }

    fn column(&self, j: usize) -> impl Iterator<Item = f64> + '_ {
        self.draws.iter().skip(j).step_by(self.dim.max(1)).copied()
    }
}

/// Why `samples` draws per record cannot be made: none asked, a way of
/// estimating without a posterior (`estimator` `None`, or one trained
/// without), a refinement or joint fit (`refined`: their estimates are
/// not the posterior's), or more than memory holds. Every door asks here,
/// so each refuses in the same words.
///
/// ```
/// let refused = twostage::draws_refused(0, None, false).unwrap();
/// assert!(refused.to_string().contains("at least 1"));
/// ```
pub fn draws_refused(
    samples: usize,
    estimator: Option<&Estimator>,
    refined: bool,
) -> Option<RequestProblem> {
    let why = if samples == 0 {
        "0 draws asked: ask at least 1".to_string()
    } else if let Some(estimator) = estimator {
        if estimator.holds_at_estimate_time() {
            "draws with parameters held at estimate time are not built (the posterior is of \
             every parameter): train with --fix and --posterior K (Python: fix=, posterior=K)"
                .to_string()
        } else if estimator.posterior().is_none() {
            "this estimator has no posterior: train it with `--posterior K` (Python: \
             posterior=K), K Gaussian components"
                .to_string()
        } else if refined {
            "the draws are the two-stage posterior's, not a refined or joint estimate's: \
             leave out the refinement and the joint fit, or the draws"
                .to_string()
        } else {
            let each = 8 * estimator.param_names().len() as u64;
            return twostage_sources::refuse_beyond_memory("samples", samples, each, "draws")
                .err()
                .map(|e| RequestProblem::Samples(e.to_string()));
        }
    } else {
        "only a trained estimator with a posterior draws (an estimator file trained with \
         `--posterior K`); the classic methods, the output-error fit and given values do not"
            .to_string()
    };
    Some(RequestProblem::Samples(why))
}

/// `samples` draws given `record`, the `index`th piece of its request,
/// from the stream of (`seed`, `index`): the same draws for the same
/// record and seed whatever the threads; and where values `at` are given,
/// the level of the posterior's region that holds them.
pub(crate) fn draw(
    estimator: &Estimator,
    record: &IoData,
    samples: usize,
    (seed, index): (u64, usize),
    at: Option<&[f64]>,
) -> twostage_estimator::Result<PosteriorDraws> {
    let dim = estimator.param_names().len();
    let mut draws = vec![0.0; samples * dim];
    let mut rng = stream_rng(seed, index as u64, StreamPurpose::Posterior);
    let mut work = EstimateWorkspace::new();
    let region_level = match at {
        Some(at) => Some(estimator.sample_testing(
            (record.inputs(), record.outputs()),
            &mut work,
            &mut rng,
            &mut draws,
            at,
        )?),
        None => {
            let (inputs, outputs) = (record.inputs(), record.outputs());
            estimator.sample_into(inputs, outputs, &mut work, &mut rng, &mut draws)?;
            None
        }
    };
    Ok(PosteriorDraws {
        region_level,
        ..PosteriorDraws::of(draws, dim)
    })
}

/// The values of `values` for parameters `names` (a file read with them),
/// and the file's rows without values, said.
pub(crate) fn region_values(
    values: RegionValues,
    names: &[String],
) -> Result<(GivenValues, Vec<String>), RequestError> {
    let refused = |why: String| RequestError {
        purpose: Purpose::Region,
        error: RequestProblem::Values(why),
    };
    let (values, skipped) = match values {
        RegionValues::Given(values) => (values, Vec::new()),
        RegionValues::File(path) => {
            let read = twostage_sources::parameter_values::read(&path, names).map_err(refused)?;
            let values = GivenValues::new(read.rows, &path.display().to_string())
                .map_err(|e| refused(e.to_string()))?;
            (values, read.skipped)
        }
    };
    if let Some(width) = values.widths().find(|&w| w != names.len()) {
        return Err(refused(format!(
            "{width} values given, the estimator has {} parameters ({})",
            names.len(),
            names.join(", ")
        )));
    }
    Ok((values, skipped))
}
