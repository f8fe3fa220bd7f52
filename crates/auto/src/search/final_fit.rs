//! The winner's final fit: on the chart, or on more records simulated for
//! it where the learning curve says they pay (decision 034), trained
//! further from its scored fit and anew where the time affords, the better
//! on added records no fit saw.

use std::time::Instant;

use ndarray::{Array2, Axis};
use twostage_compress::CompressorConfig;
use twostage_fit::{FittedRegressor, RegressorConfig};
use twostage_models::Simulator;
use twostage_sources::StoredChart;

use super::{Search, compress_all, design};
use crate::cost::{ANEW_SHARE, COST_MARGIN, ROWS_EXPONENT, fit_seconds, rows_for_final_fit};
use crate::outcome::{FinalFit, FinalFits};
use twostage_estimator::space::to_learning_space;
use twostage_estimator::{Error, Result};

impl<S: Simulator + ?Sized> Search<'_, '_, S> {
    /// The records the winner's final fit takes: more than the chart's
    /// where the source can simulate them, the half-rows trial says more
    /// records pay (`more_records`), and the time left affords simulating
    /// them (`per_simulation` wall seconds each) and fitting on all, at
    /// most four times the chart (a learning curve says little beyond
    /// that) and `cap`; else the chart's (trained further from the scored
    /// fit, which the deadline may stop at any time without making it
    /// worse, so no row need be left out for time).
    pub(crate) fn final_rows(
        &self,
        best: usize,
        more_records: bool,
        per_simulation: f64,
        cap: usize,
    ) -> usize {
        let chart_rows = self.plan.chart.thetas.nrows();
        if !(self.plan.deadline.is_some() && self.plan.grows && more_records) {
            return chart_rows;
        }
        let scored = self.candidates[best].report.fit_rows;
        rows_for_final_fit(
            self.plan.seconds_left(),
            (per_simulation, self.fit_estimate(best, scored), scored),
            self.cost_exponent(),
            chart_rows,
            cap.min(4 * chart_rows),
        )
    }

    /// The winner, refitted on the first `final_rows` of the chart and the
    /// `more` records simulated for it ([`Self::final_rows`]), or with the
    /// fit it was scored with when that is not more rows. Under a time
    /// budget the refit is trained further from that fit, stopped at the
    /// deadline if need be, and fitted anew too where the time affords.
    pub(crate) fn winner(
        &self,
        best: usize,
        more: Option<&StoredChart>,
        final_rows: usize,
    ) -> Result<Winner> {
        let (compressor, held_out_fit) =
            self.candidates[best]
                .fitted
                .clone()
                .ok_or_else(|| Error::Search {
                    what: "the best candidate has no fit to ship".into(),
                })?;
        let regressor_config = self.candidates[best].network.clone();
        let scored_rows = self.candidates[best].report.fit_rows;
        let grown;
        let (records, thetas) = match more {
            Some(more) => {
                let mut thetas = self.plan.chart.thetas.clone();
                thetas
                    .append(Axis(0), more.thetas.view())
                    .map_err(|e| Error::Search {
                        what: format!(
                            "the records added for the final fit do not match the chart: {e}"
                        ),
                    })?;
                grown = [self.plan.chart.records.as_slice(), more.records.as_slice()].concat();
                (grown.as_slice(), thetas)
            }
            None => (
                self.plan.chart.records.as_slice(),
                self.plan.chart.thetas.clone(),
            ),
        };
        let refit_rows = final_rows.min(thetas.nrows());
        let features = compress_all(&compressor, records)?;
        let mut winner = Winner {
            compressor,
            features,
            regressor_config,
            regressor: held_out_fit,
            final_fit: FinalFit::AsScored { rows: scored_rows },
        };
        if refit_rows <= scored_rows {
            return Ok(winner);
        }
        let marginals = self.plan.base.simulator().spec().prior().marginals();
        let seed = self.plan.base.seed();
        let Some(deadline) = self.plan.deadline else {
            let rows = ndarray::s![..refit_rows, ..];
            let z = to_learning_space(thetas.slice(rows), marginals);
            winner.regressor =
                winner
                    .regressor_config
                    .fit(winner.features.slice(rows), z.view(), seed)?;
            winner.final_fit = FinalFit::Anew { rows: refit_rows };
            return Ok(winner);
        };
        let added = more.map_or(0, |m| m.records.len());
        self.fit_by_deadline(best, &mut winner, &thetas, (refit_rows, added), deadline)?;
        Ok(winner)
    }

    /// The winner's final fit on `refit_rows` under a time budget, of which
    /// `added` were simulated for it.
    fn fit_by_deadline(
        &self,
        best: usize,
        winner: &mut Winner,
        thetas: &Array2<f64>,
        (refit_rows, added): (usize, usize),
        deadline: Instant,
    ) -> Result<()> {
        let marginals = self.plan.base.simulator().spec().prior().marginals();
        let seed = self.plan.base.seed();
        let scored_rows = winner.final_fit.rows();
        // Under a time budget the winner is trained further from the fit it
        // was scored with: cheaper than anew, and a fit that can stop at
        // the deadline (the costs are estimates) and still be no worse than
        // its start. Where records were added and the time left affords a
        // fit anew too, both leave out the last fifth of the added records
        // (seen by no fit; at most 2000: the fits are compared on the same
        // records, so their difference is measured well before their
        // scores are) and the better on them ships.
        let compared = (added / 5)
            .min(MAX_COMPARED_RECORDS)
            .min(refit_rows.saturating_sub(scored_rows));
        let anew_affordable = compared >= MIN_COMPARED_RECORDS
            && self.fit_estimate(best, refit_rows - compared)
                < ANEW_SHARE * self.plan.seconds_left();
        let train_rows = if anew_affordable {
            refit_rows - compared
        } else {
            refit_rows
        };
        let rows = ndarray::s![..train_rows, ..];
        let (x, z) = (
            winner.features.slice(rows),
            to_learning_space(thetas.slice(rows), marginals),
        );
        let design = design(&winner.compressor, &winner.regressor_config);
        self.plan.base.progress().status(&format!(
            "final fit: {design} trained further on {train_rows} records; {}",
            self.plan.budget_words()
        ));
        let continued = winner.regressor_config.fit_from(
            Some(&winner.regressor),
            (x, z.view()),
            seed,
            Some(deadline),
        )?;
        // A fit anew starts only while time is left: the one trained
        // further may have used it all.
        if !(anew_affordable && Instant::now() < deadline) {
            winner.final_fit = FinalFit::TrainedFurther {
                rows: train_rows,
                stopped: continued.stopped_at_deadline(),
            };
            winner.regressor = continued;
            return Ok(());
        }
        self.plan.base.progress().status(&format!(
            "final fit: {design} anew on {train_rows} records; {}",
            self.plan.budget_words()
        ));
        let anew = winner
            .regressor_config
            .fit_from(None, (x, z.view()), seed, Some(deadline))?;
        let rows = ndarray::s![train_rows..refit_rows, ..];
        let (x_held, t_held) = (winner.features.slice(rows), thetas.slice(rows));
        let score = |fitted: &FittedRegressor| -> Result<f64> {
            Ok(self.plan.score(fitted, x_held, t_held)?.1)
        };
        let fits = FinalFits {
            compared,
            further: score(&continued)?,
            anew: score(&anew)?,
        };
        let chosen = if fits.anew < fits.further {
            anew
        } else {
            continued
        };
        winner.final_fit = FinalFit::Compared {
            rows: train_rows,
            fits,
            stopped: chosen.stopped_at_deadline(),
        };
        winner.regressor = chosen;
        Ok(())
    }

    /// The seconds a fit anew of candidate `best` on `rows` rows takes on
    /// the whole machine, from its time alone where round 3 measured it.
    fn fit_estimate(&self, best: usize, rows: usize) -> f64 {
        let winner = &self.candidates[best].report;
        let scored = winner.fit_rows;
        let growth = (rows as f64 / scored.max(1) as f64).powf(self.cost_exponent());
        match self.candidates[best].solo_seconds {
            Some(seconds) => COST_MARGIN * seconds * growth,
            None => fit_seconds(winner.seconds, scored, rows),
        }
    }

    /// How a fit's time grows with its rows: as round 3 measured it, or
    /// [`ROWS_EXPONENT`].
    fn cost_exponent(&self) -> f64 {
        self.rows_exponent.unwrap_or(ROWS_EXPONENT)
    }
}

/// Records a fit anew and a fit trained further are compared on, at least.
const MIN_COMPARED_RECORDS: usize = 200;
/// Records a fit anew and a fit trained further are compared on, at most.
const MAX_COMPARED_RECORDS: usize = 2000;

/// What the search ships: the winning structure, fitted.
pub(crate) struct Winner {
    pub(crate) compressor: CompressorConfig,
    /// The whole chart's features under the winning compressor.
    pub(crate) features: Array2<f64>,
    pub(crate) regressor_config: RegressorConfig,
    pub(crate) regressor: FittedRegressor,
    /// How `regressor` was fitted.
    pub(crate) final_fit: FinalFit,
}
