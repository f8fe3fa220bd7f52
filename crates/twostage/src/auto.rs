//! Automatic design: search stage-1 structures and network sizes by
//! validation error on simulated data, so that no human picks the ARX
//! order or the network (the paper leaves both to "a few trial-and-error
//! attempts").
//!
//! The chart is simulated once and its records kept; every candidate
//! compressor compresses them, every candidate network fits the same rows,
//! and all are scored on the same held-out rows. The winner is refitted on
//! the whole chart, then calibrated and validated on fresh simulations like
//! any trained estimator (so the final report is not biased by the
//! selection).

use std::time::{Duration, Instant};
use twostage_kernels::vector::clip_to_box;

use ndarray::{Array2, Axis};
use rayon::prelude::*;
use twostage_compress::{Arx, Compressor, Narx, OutputPca, Workspace};
use twostage_fit::{MlpParams, Piecewise};
use twostage_models::{IoData, Simulator};

use crate::builder::{TrainedOn, TwoStage};
use crate::chart::{StoredChart, simulate_records};
use crate::config::{CompressorConfig, FittedRegressor, RegressorConfig};
use crate::error::{Error, Result};
use crate::estimator::Estimator;
use crate::progress::Stage;

/// How much the search may spend.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Budget {
    /// Wall-clock seconds for the whole search (chart, fits, refit;
    /// calibration and validation come on top). The chart size follows
    /// from a timed pilot, and candidates that would not finish in time are
    /// skipped, so the outcome depends on the machine.
    Seconds(f64),
    /// A chart of exactly this many simulations, and every candidate
    /// evaluated: the same seed gives the same estimator on any machine.
    Simulations(usize),
}

/// One candidate structure and how it scored.
#[derive(Debug, Clone, PartialEq)]
pub struct CandidateReport {
    /// Stage 1.
    pub compressor: String,
    /// Stage 2.
    pub regressor: String,
    /// Search round: 1 compares compressors with one network, 2 compares
    /// networks on the best compressors.
    pub round: usize,
    /// RMSE per parameter on the held-out chart rows (empty when not run).
    pub rmse: Vec<f64>,
    /// Mean over parameters of RMSE / prior standard deviation (lower is
    /// better; 1 means nothing learned).
    pub score: f64,
    /// Seconds spent compressing and fitting it.
    pub seconds: f64,
    /// Why it has no score, if it has none (skipped for time, or failed).
    pub note: Option<String>,
}

/// The result of [`AutoDesign::run`].
#[derive(Debug)]
pub struct AutoOutcome {
    /// The best candidate, refitted on the whole chart, calibrated and
    /// validated.
    pub estimator: Estimator,
    /// Every candidate, in the order tried.
    pub candidates: Vec<CandidateReport>,
    /// Index of the winner in `candidates`.
    pub best: usize,
    /// Simulations in the chart.
    pub simulations: usize,
    /// Seconds of the search (without calibration and validation).
    pub search_seconds: f64,
    /// Whether the winner was refitted on the whole chart (a time budget
    /// may leave only its fit on the first 80% of rows).
    pub refitted: bool,
}

impl std::fmt::Display for AutoOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "automatic design on m = {} simulations ({:.1} s), held-out RMSE per candidate:",
            self.simulations, self.search_seconds
        )?;
        if !self.refitted {
            writeln!(
                f,
                "(the time budget left no room to refit the winner on the whole chart: \
                 it ships as fitted on the first 80%)"
            )?;
        }
        for (i, c) in self.candidates.iter().enumerate() {
            let mark = if i == self.best { "*" } else { " " };
            let rmse: Vec<String> = c.rmse.iter().map(|r| format!("{r:.4e}")).collect();
            match &c.note {
                Some(note) => {
                    writeln!(f, " {mark} {:<28} {:<14} {note}", c.compressor, c.regressor)?
                }
                None => writeln!(
                    f,
                    " {mark} {:<28} {:<14} score {:.4}  RMSE [{}]  {:.1} s",
                    c.compressor,
                    c.regressor,
                    c.score,
                    rmse.join(", "),
                    c.seconds
                )?,
            }
        }
        Ok(())
    }
}

/// Builder of an automatic design for one simulator; see [`TwoStage::auto`].
#[derive(Debug)]
pub struct AutoDesign<'a, S: ?Sized> {
    base: TwoStage<'a, S>,
    budget: Budget,
    compressors: Option<Vec<CompressorConfig>>,
    networks: Option<(RegressorConfig, Vec<RegressorConfig>)>,
}

/// Streams of the timing pilot, apart from the training chart's.
const PILOT_SEED: u64 = 0x0050_494c_4f54; // "PILOT"
/// Largest chart a time budget chooses: beyond it the network fits, not
/// the simulations, dominate the cost.
const MAX_AUTO_SIMULATIONS: usize = 8000;
/// Share of the chart held out to score candidates.
const HELD_OUT: f64 = 0.2;
/// Memory allowed for the stored records.
const MAX_CHART_BYTES: usize = 2 << 30;

impl<'a, S: Simulator + ?Sized> TwoStage<'a, S> {
    /// An automatic design for `simulator`: the settings of the builder
    /// (seed, calibration, validation, progress...) apply, the compressor,
    /// regressor and m are searched.
    ///
    /// ```
    /// use twostage::{Budget, RegressorConfig, TwoStage};
    /// use twostage::compress::Arx;
    /// use twostage::fit::MlpParams;
    /// use twostage::models::Benchmark;
    ///
    /// let model = Benchmark::builder().n_samples(300).build()?;
    /// let net = |h: usize| -> Result<RegressorConfig, twostage::Error> {
    ///     Ok(RegressorConfig::Mlp(MlpParams::new(&[h])?.restarts(2).check()?))
    /// };
    /// let outcome = TwoStage::auto(&model)
    ///     .budget(Budget::Simulations(400))
    ///     // A small search for the example; the defaults search more.
    ///     .compressors(vec![Arx::new(2, 2)?.into(), Arx::new(4, 4)?.into()])
    ///     .networks(net(6)?, vec![net(3)?])
    ///     .settings(|b| b.calibration(100).validation(100))
    ///     .run()?;
    /// assert_eq!(outcome.candidates.len(), 4);
    /// let best = &outcome.candidates[outcome.best];
    /// assert!(outcome.candidates.iter().all(|c| c.note.is_some() || c.score >= best.score));
    /// println!("{outcome}");
    /// # Ok::<(), twostage::Error>(())
    /// ```
    pub fn auto(simulator: &'a S) -> AutoDesign<'a, S> {
        AutoDesign {
            base: TwoStage::builder(simulator),
            budget: Budget::Seconds(120.0),
            compressors: None,
            networks: None,
        }
    }
}

impl<'a, S: Simulator + ?Sized> AutoDesign<'a, S> {
    /// The search budget (default: 120 seconds).
    pub fn budget(mut self, budget: Budget) -> Self {
        self.budget = budget;
        self
    }

    /// Replace the round-1 compressors (default: ARX(n, n) for n = 2, 3, 4,
    /// 5, 6, 8, NARX(2, 2, 2), output PCA with 8, 12, 16 components).
    pub fn compressors(mut self, compressors: Vec<CompressorConfig>) -> Self {
        self.compressors = Some(compressors);
        self
    }

    /// Replace the networks: `first` for round 1, `others` for round 2
    /// (default: MLP `[20]`; then `[10]`, `[40]`, `[20, 20]`, and 4 pieces of `[20]`).
    pub fn networks(mut self, first: RegressorConfig, others: Vec<RegressorConfig>) -> Self {
        self.networks = Some((first, others));
        self
    }

    /// Change the shared settings (seed, calibration, validation, alpha,
    /// delta, progress) through the ordinary builder.
    pub fn settings(mut self, f: impl FnOnce(TwoStage<'a, S>) -> TwoStage<'a, S>) -> Self {
        self.base = f(self.base);
        self
    }

    /// Run the search, keep the best candidate, calibrate and validate it.
    ///
    /// # Errors
    /// An invalid budget, too many failed simulations, or no candidate
    /// that could be fitted.
    pub fn run(self) -> Result<AutoOutcome> {
        let start = Instant::now();
        let base = &self.base;
        let spec = base.simulator.spec();
        let record_bytes =
            spec.n_samples() * (spec.input_names().len() + spec.output_names().len()) * 8;
        let memory_cap = (MAX_CHART_BYTES / record_bytes.max(1)).max(100);
        let (m, deadline) = match self.budget {
            Budget::Simulations(m) => (m, None),
            Budget::Seconds(t) => {
                if !(t.is_finite() && t > 0.0) {
                    return Err(Error::InvalidSetting {
                        name: "budget seconds",
                        value: t.to_string(),
                        reason: "must be finite and > 0".into(),
                    });
                }
                let per_simulation = base.pilot_seconds_per_simulation()?;
                // A fifth of the budget for the chart, the rest for fits.
                let m = (0.2 * t / per_simulation) as usize;
                (
                    m.clamp(500, MAX_AUTO_SIMULATIONS).min(memory_cap),
                    Some(start + Duration::from_secs_f64(t)),
                )
            }
        };
        if m < 50 || m > memory_cap {
            return Err(Error::InvalidSetting {
                name: "budget simulations",
                value: m.to_string(),
                reason: format!("must lie in 50..={memory_cap} (the records are kept in memory)"),
            });
        }
        let chart = base.stored_chart(m)?;
        let q = spec.n_params();
        let prior_sd: Vec<f64> = spec
            .prior()
            .lower()
            .iter()
            .zip(spec.prior().upper())
            .map(|(lo, hi)| (hi - lo) / 12f64.sqrt())
            .collect();
        let rows = chart.thetas.nrows();
        let fit_rows = ((1.0 - HELD_OUT) * rows as f64).round() as usize;
        let mut candidates: Vec<CandidateReport> = Vec::new();
        let mut fitted: Vec<Option<(CompressorConfig, FittedRegressor)>> = Vec::new();
        let mut networks_of: Vec<RegressorConfig> = Vec::new();

        // Round 1: every compressor with one medium network. Nothing is
        // known about costs yet: each starts unless the deadline has passed.
        let (medium, networks) = match self.networks.clone() {
            Some(pair) => pair,
            None => (
                network(&[20])?,
                vec![
                    network(&[10])?,
                    network(&[40])?,
                    network(&[20, 20])?,
                    pieces(4, &[20])?,
                ],
            ),
        };
        let compressors = self.compressors.clone().unwrap_or_else(|| {
            candidate_compressors(spec.output_names().len(), spec.input_names().len())
        });
        base.progress.begin(Stage::Fitting, 0);
        let round1: Vec<_> = compressors
            .par_iter()
            .map(|c| {
                let limit = deadline.map(|d| (d, 0.0));
                evaluate(base, &chart, c, &medium, fit_rows, &prior_sd, limit, 1)
            })
            .collect();
        for (report, outcome) in round1 {
            candidates.push(report);
            fitted.push(outcome);
            networks_of.push(medium.clone());
        }
        // Round 2: other networks on the two best compressors, each started
        // only if its cost (the round-1 time scaled by the network's size)
        // leaves time to refit the best candidate found so far.
        let mut ranked: Vec<usize> = (0..candidates.len())
            .filter(|&i| candidates[i].note.is_none())
            .collect();
        ranked.sort_by(|&a, &b| candidates[a].score.total_cmp(&candidates[b].score));
        let reserve = ranked
            .first()
            .map_or(0.0, |&i| 1.25 * candidates[i].seconds);
        let pairs: Vec<(CompressorConfig, RegressorConfig, f64)> = ranked
            .iter()
            .take(2)
            .filter_map(|&i| {
                let (c, _) = fitted[i].as_ref()?;
                let n = c.n_features();
                let base_size = network_size(&medium, n, q);
                let seconds = candidates[i].seconds;
                Some(networks.iter().map(move |net| {
                    let scale = network_size(net, n, q) / base_size;
                    (c.clone(), net.clone(), seconds * scale)
                }))
            })
            .flatten()
            .collect();
        let round2: Vec<_> = pairs
            .par_iter()
            .map(|(c, net, cost)| {
                let limit = deadline.map(|d| (d, cost + reserve));
                evaluate(base, &chart, c, net, fit_rows, &prior_sd, limit, 2)
            })
            .collect();
        for (report, outcome) in round2 {
            candidates.push(report);
            fitted.push(outcome);
        }
        networks_of.extend(pairs.iter().map(|(_, n, _)| n.clone()));
        let best = (0..candidates.len())
            .filter(|&i| candidates[i].note.is_none())
            .min_by(|&a, &b| candidates[a].score.total_cmp(&candidates[b].score))
            .ok_or_else(|| Error::InvalidSetting {
                name: "budget",
                value: format!("{:?}", self.budget),
                reason: format!(
                    "no candidate could be fitted within it (first: {})",
                    candidates
                        .first()
                        .and_then(|c| c.note.clone())
                        .unwrap_or_default()
                ),
            })?;
        let (compressor, held_out_fit) =
            fitted[best].clone().ok_or_else(|| Error::InvalidSetting {
                name: "budget",
                value: format!("{:?}", self.budget),
                reason: "the best candidate lost its fit".into(),
            })?;
        let features = compress_all(&compressor, &chart.records)?;
        let regressor_config = networks_of[best].clone();
        // The winner on the whole chart, if there is time for it; else the
        // fit on the first 80% of rows that won is shipped as it is.
        let refit_cost = 1.25 * candidates[best].seconds;
        let refitted =
            deadline.is_none_or(|d| Instant::now() + Duration::from_secs_f64(refit_cost) <= d);
        let regressor: FittedRegressor = if refitted {
            regressor_config.fit(features.view(), chart.thetas.view(), base.seed)?
        } else {
            held_out_fit
        };
        base.progress.end(Stage::Fitting);
        let search_seconds = start.elapsed().as_secs_f64();
        let estimator = base.finish(
            compressor,
            regressor,
            TrainedOn {
                features: features.view(),
                simulations: m,
                failures: m - rows,
                sampling: format!("{:?}", spec.prior().sampling()),
                regressor: regressor_config,
            },
        )?;
        Ok(AutoOutcome {
            estimator,
            candidates,
            best,
            simulations: m,
            search_seconds,
            refitted,
        })
    }
}

impl<S: Simulator + ?Sized> TwoStage<'_, S> {
    /// Parallel throughput of the simulator, from a small timed pilot.
    fn pilot_seconds_per_simulation(&self) -> Result<f64> {
        let pilot = 64;
        let design = self
            .simulator
            .prior()
            .design(pilot, self.seed ^ PILOT_SEED)?;
        let start = Instant::now();
        simulate_records(self.simulator, &design, pilot, 0.0, None)?;
        Ok((start.elapsed().as_secs_f64() / pilot as f64).max(1e-9))
    }

    /// Simulate m experiments of the training design and keep the records
    /// (failed experiments are dropped, within the failure allowance).
    pub(crate) fn stored_chart(&self, m: usize) -> Result<StoredChart> {
        let design = self.simulator.prior().design(m, self.seed)?;
        simulate_records(
            self.simulator,
            &design,
            m,
            self.max_failure_fraction,
            Some((Stage::Training, self.progress)),
        )
    }
}

/// Weights and biases of a network candidate on n features and q outputs:
/// the cost of a Levenberg-Marquardt fit grows with it.
fn network_size(regressor: &RegressorConfig, n: usize, q: usize) -> f64 {
    match regressor {
        RegressorConfig::Mlp(mlp) => {
            let mut sizes = vec![n];
            sizes.extend_from_slice(mlp.params().hidden());
            sizes.push(q);
            twostage_fit::n_parameters(&sizes) as f64
        }
        // The global network on every row, then experts that together see
        // the rows about 1.5 times (their margins overlap).
        RegressorConfig::Piecewise(p) => {
            2.5 * network_size(&RegressorConfig::Mlp(p.global().clone()), n, q)
        }
        _ => (n * q + q) as f64,
    }
}

fn pieces(count: usize, hidden: &[usize]) -> Result<RegressorConfig> {
    let mlp = MlpParams::new(hidden)?.check()?;
    Ok(RegressorConfig::Piecewise(Piecewise::new(
        mlp.clone(),
        mlp,
        count,
    )?))
}

fn network(hidden: &[usize]) -> Result<RegressorConfig> {
    Ok(RegressorConfig::Mlp(MlpParams::new(hidden)?.check()?))
}

/// Stage-1 candidates: ARX orders, a quadratic NARX, and output PCAs.
/// Unfitted compressors (NARX scales, PCA directions) are fitted on the
/// chart's fitting rows before use.
fn candidate_compressors(n_outputs: usize, n_inputs: usize) -> Vec<CompressorConfig> {
    let mut list: Vec<CompressorConfig> = Vec::new();
    for order in [2, 3, 4, 5, 6, 8] {
        if let Ok(arx) = Arx::new(order, order).and_then(|a| a.with_signals(n_inputs, n_outputs)) {
            list.push(arx.into());
        }
    }
    if let Ok(narx) = Narx::new(2, 2, 2) {
        list.push(narx.into());
    }
    for k in [8, 12, 16] {
        if let Ok(pca) = OutputPca::new(k) {
            list.push(pca.into());
        }
    }
    list
}

/// Features of every record, in parallel (row i is record i).
fn compress_all(compressor: &CompressorConfig, records: &[IoData]) -> Result<Array2<f64>> {
    let n = compressor.n_features();
    let mut features = vec![0.0; records.len() * n];
    features
        .par_chunks_mut(n.max(1))
        .zip(records.par_iter())
        .map_init(Workspace::new, |work, (alpha, record)| {
            compressor.compress_into(record.inputs(), record.outputs(), work, alpha)
        })
        .collect::<twostage_compress::Result<Vec<()>>>()?;
    Ok(Array2::from_shape_vec((records.len(), n), features)
        .unwrap_or_else(|_| unreachable!("n features per record")))
}

/// Compress, fit on the first `fit_rows` rows, score on the rest.
#[allow(clippy::too_many_arguments)]
fn evaluate<S: Simulator + ?Sized>(
    base: &TwoStage<'_, S>,
    chart: &StoredChart,
    compressor: &CompressorConfig,
    regressor: &RegressorConfig,
    fit_rows: usize,
    prior_sd: &[f64],
    deadline: Option<(Instant, f64)>,
    round: usize,
) -> (CandidateReport, Option<(CompressorConfig, FittedRegressor)>) {
    let mut report = CandidateReport {
        compressor: compressor.to_string(),
        regressor: regressor.to_string(),
        round,
        rmse: Vec::new(),
        score: f64::INFINITY,
        seconds: 0.0,
        note: None,
    };
    // (deadline, estimated seconds): skip what would not finish in time.
    if let Some((deadline, cost)) = deadline
        && Instant::now() + Duration::from_secs_f64(cost) > deadline
    {
        report.note = Some(format!(
            "skipped: about {cost:.0} s would overrun the time budget"
        ));
        return (report, None);
    }
    let start = Instant::now();
    let outcome = (|| -> Result<(Vec<f64>, CompressorConfig, FittedRegressor)> {
        let compressor = compressor.prepared(&chart.records[..fit_rows])?;
        let features = compress_all(&compressor, &chart.records)?;
        let (x_fit, x_held) = features.view().split_at(Axis(0), fit_rows);
        let (t_fit, t_held) = chart.thetas.view().split_at(Axis(0), fit_rows);
        let fitted = regressor.fit(x_fit, t_fit, base.seed)?;
        // Standard layout, so that every row is a slice.
        let mut estimates = twostage_fit::Predictor::predict(&fitted, x_held)?
            .as_standard_layout()
            .into_owned();
        let prior = base.simulator.spec().prior();
        for mut row in estimates.rows_mut() {
            if let Some(theta) = row.as_slice_mut() {
                clip_to_box(theta, prior.lower(), prior.upper());
            }
        }
        let rmse = (0..t_held.ncols())
            .map(|j| {
                let sq: f64 = t_held
                    .column(j)
                    .iter()
                    .zip(estimates.column(j))
                    .map(|(t, e)| (t - e).powi(2))
                    .sum();
                (sq / t_held.nrows().max(1) as f64).sqrt()
            })
            .collect();
        Ok((rmse, compressor, fitted))
    })();
    report.seconds = start.elapsed().as_secs_f64();
    match outcome {
        Ok((rmse, compressor, fitted)) => {
            report.score = rmse.iter().zip(prior_sd).map(|(r, sd)| r / sd).sum::<f64>()
                / rmse.len().max(1) as f64;
            report.rmse = rmse;
            (report, Some((compressor, fitted)))
        }
        Err(e) => {
            report.note = Some(format!("failed: {e}"));
            (report, None)
        }
    }
}
