//! The parameters' conditional density given a record, where the
//! estimator was trained with one: draws from `p(θ | record)` through
//! stage 1's features.

use ndarray::ArrayView2;
use rand::Rng;
use rayon::prelude::*;
use twostage_compress::Compressor;
use twostage_fit::FittedMixture;
use twostage_models::{IoData, Marginal, StreamPurpose, stream_rng};
use twostage_validate::PosteriorCalibration;

use crate::error::{Error, Result};
use crate::estimator::{EstimateWorkspace, Estimator};

impl Estimator {
    /// The parameters' conditional density given a record's features,
    /// where the estimator was trained with one.
    pub fn posterior(&self) -> Option<&FittedMixture> {
        self.posterior.as_ref()
    }

    /// The estimator with `posterior`, a density of its parameters given
    /// its stage 1's features.
    ///
    /// # Errors
    /// A density of other features, or of other parameters or supports
    /// than the estimator's priors give.
    pub fn with_posterior(mut self, posterior: FittedMixture) -> Result<Self> {
        check_against(&posterior, self.compressor.n_features(), &self.marginals).map_err(
            |what| {
                Error::InvalidSetting(crate::InvalidSetting {
                    name: "posterior",
                    value: what,
                    reason: "train the density on this estimator's features and priors".into(),
                })
            },
        )?;
        self.posterior = Some(posterior);
        Ok(self)
    }

    /// The estimator without its posterior: the point estimate, its
    /// intervals and flags as before, no draws (what a control unit that
    /// needs no draws carries: `export --without-posterior`).
    pub fn without_posterior(mut self) -> Self {
        self.posterior = None;
        self
    }

    /// The posterior's spread calibrated on held-out records (parameters
    /// `thetas`, stage 1's `features`, rows of each): the factor that
    /// gives them the least negative log-likelihood
    /// ([`FittedMixture::calibrate_spread`]). Nothing without a posterior.
    ///
    /// # Errors
    /// Rows that do not fit the density.
    pub fn calibrate_posterior(
        &mut self,
        thetas: ndarray::ArrayView2<'_, f64>,
        features: ndarray::ArrayView2<'_, f64>,
    ) -> Result<()> {
        if let Some(posterior) = self.posterior.as_mut() {
            posterior.calibrate_spread(features, thetas)?;
        }
        Ok(())
    }

    /// Draws of the parameters given `record` into `out` (draws x
    /// parameters, row after row: as many draws as it holds rows), from
    /// the random numbers of `rng`, each inside its prior's support.
    ///
    /// ```
    /// use rand::SeedableRng;
    /// use twostage::TwoStage;
    /// use twostage::fit::{MixtureDensity, MlpParams};
    /// use twostage::models::{Benchmark, Simulator, experiment_rng};
    /// let model = Benchmark::builder().n_samples(300).build()?;
    /// let estimator = TwoStage::builder(&model)
    ///     .simulations(1000).validation(0).calibration(0)
    ///     .posterior(MixtureDensity::new(MlpParams::new(&[16])?.check()?, 2)?)
    ///     .train()?;
    /// let mut record = model.spec().new_record();
    /// model.simulate(&[0.3], &mut experiment_rng(4, 0), &mut record)?;
    /// let mut draws = vec![0.0; 500];
    /// estimator.sample_record(&record, &mut rand_chacha::ChaCha8Rng::seed_from_u64(1), &mut draws)?;
    /// let mean = draws.iter().sum::<f64>() / 500.0;
    /// assert!((mean - 0.3).abs() < 0.1, "{mean}");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// An estimator without a density, a record that cannot be compressed,
    /// or `out` not a whole number of draws.
    pub fn sample_record(
        &self,
        record: &IoData,
        rng: &mut impl Rng,
        out: &mut [f64],
    ) -> Result<()> {
        self.sample_into(
            record.inputs(),
            record.outputs(),
            &mut EstimateWorkspace::new(),
            rng,
            out,
        )
    }

    /// [`Estimator::sample_record`] of the record `inputs` (N x n_u),
    /// `outputs` (N x n_y), with a workspace kept across records.
    ///
    /// # Errors
    /// As [`Estimator::sample_record`].
    pub fn sample_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut EstimateWorkspace,
        rng: &mut impl Rng,
        out: &mut [f64],
    ) -> Result<()> {
        let posterior = self.posterior.as_ref().ok_or(Error::NoPosterior)?;
        let features = self.features_of(inputs, outputs, work)?;
        posterior.sample(features, rng, out)?;
        Ok(())
    }

    /// [`Estimator::sample_into`], the same draws, and the smallest level
    /// of the posterior's region of highest density that holds the values
    /// `at`: the share of the draws it finds more probable
    /// ([`FittedMixture::region_level`]; at most 0.9 where `at` lies in
    /// the joint 90% region). Stage 1 runs once for both.
    ///
    /// # Errors
    /// As [`Estimator::sample_into`], and values of the wrong length or
    /// outside a parameter's support.
    pub fn sample_testing(
        &self,
        (inputs, outputs): (ArrayView2<'_, f64>, ArrayView2<'_, f64>),
        work: &mut EstimateWorkspace,
        rng: &mut impl Rng,
        out: &mut [f64],
        at: &[f64],
    ) -> Result<f64> {
        let posterior = self.posterior.as_ref().ok_or(Error::NoPosterior)?;
        let features = self.features_of(inputs, outputs, work)?;
        posterior.sample(features, rng, out)?;
        Ok(posterior.region_level(features, out, at)?)
    }

    /// Where a record's known parameters `truth` fall among its
    /// posterior's draws (as many as `out` holds, drawn into it by
    /// [`Estimator::sample_testing`]): per parameter the share of draws
    /// below its value, the ends split (`(below + 1/2) / (L + 1)`, uniform
    /// over records where the posterior is calibrated: simulation-based
    /// calibration's rank), and the smallest region level that holds the
    /// whole vector.
    ///
    /// # Errors
    /// As [`Estimator::sample_testing`].
    pub fn truth_ranks(
        &self,
        record: (ArrayView2<'_, f64>, ArrayView2<'_, f64>),
        work: &mut EstimateWorkspace,
        rng: &mut impl Rng,
        out: &mut [f64],
        truth: &[f64],
    ) -> Result<(Vec<f64>, f64)> {
        let level = self.sample_testing(record, work, rng, out, truth)?;
        Ok((ranks_among(out, truth), level))
    }

    /// The posterior's calibration on records of known parameters given by
    /// their stage-1 `features` and `truth` (rows of each): record i's
    /// truth ranked among `draws` draws from the stream of (`seed`, i),
    /// in parallel ([`PosteriorCalibration`]). `None` without a posterior.
    ///
    /// # Errors
    /// Rows that do not fit the posterior.
    pub fn posterior_calibration(
        &self,
        truth: ArrayView2<'_, f64>,
        features: ArrayView2<'_, f64>,
        draws: usize,
        seed: u64,
    ) -> Result<Option<PosteriorCalibration>> {
        let Some(posterior) = self.posterior.as_ref() else {
            return Ok(None);
        };
        let q = truth.ncols();
        let ranked: Vec<(Vec<f64>, f64)> = (0..truth.nrows())
            .into_par_iter()
            .map(|i| -> Result<(Vec<f64>, f64)> {
                let (x, theta) = (features.row(i).to_vec(), truth.row(i).to_vec());
                let mut out = vec![0.0; draws * q];
                let mut rng = stream_rng(seed, i as u64, StreamPurpose::Posterior);
                posterior.sample(&x, &mut rng, &mut out)?;
                let level = posterior.region_level(&x, &out, &theta)?;
                Ok((ranks_among(&out, &theta), level))
            })
            .collect::<Result<_>>()?;
        let (ranks, levels): (Vec<Vec<f64>>, Vec<f64>) = ranked.into_iter().unzip();
        Ok(Some(PosteriorCalibration::from_ranks(
            &ranks, &levels, draws,
        )?))
    }
}

/// Per parameter, the share of `draws` (rows of `truth`'s width) below
/// `truth`, the ends split: `(below + 1/2) / (L + 1)`.
fn ranks_among(draws: &[f64], truth: &[f64]) -> Vec<f64> {
    let q = truth.len();
    let count = draws.len() / q.max(1);
    (0..q)
        .map(|j| {
            let below = draws.chunks_exact(q).filter(|d| d[j] < truth[j]).count();
            (below as f64 + 0.5) / (count + 1) as f64
        })
        .collect()
}

/// Whether `posterior` reads `n_features` features and draws parameters
/// of the priors `marginals` on their supports; what disagrees, else.
pub(crate) fn check_against(
    posterior: &FittedMixture,
    n_features: usize,
    marginals: &[Marginal],
) -> std::result::Result<(), String> {
    if posterior.n_features() != n_features {
        return Err(format!(
            "a density of {} features, stage 1 gives {n_features}",
            posterior.n_features()
        ));
    }
    let supports: Vec<_> = marginals.iter().map(Marginal::support).collect();
    if posterior.supports() != supports.as_slice() {
        return Err(format!(
            "a density on {:?}, the priors' supports are {supports:?}",
            posterior.supports()
        ));
    }
    Ok(())
}
