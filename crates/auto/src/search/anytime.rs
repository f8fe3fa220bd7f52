//! The anytime final fit: where the winner's final
//! fit ended before the deadline, the time left goes to more records, the
//! shipped fit trained further on all of them, a step at a time, each step
//! kept only if it scores better on added records it did not train on.

use std::time::Instant;

use ndarray::{Axis, s};
use twostage_estimator::space::to_learning_space;
use twostage_models::Simulator;
use twostage_sources::StoredChart;
use twostage_train::{Error, Result};

use super::final_fit::{MAX_COMPARED_RECORDS, MIN_COMPARED_RECORDS};
use super::{Search, Winner, compress_all, design, readable_rows};
use crate::Budget;
use crate::outcome::Continuation;

/// A step grows the records at least this many times: a smaller step
/// costs a fit's overhead for little.
const MIN_STEP_GROWTH: f64 = 1.25;
/// A step at most doubles the records, so that each is checked on records
/// it did not train on before the next grows them again.
const MAX_STEP_GROWTH: f64 = 2.0;
/// Share of the time left a step plans to fit in (the simulations and the
/// comparison take the rest); the deadline stops it in any case, no worse
/// than its start.
const STEP_SHARE: f64 = 0.7;
/// Share of the budget that must be left for a step to start: less buys
/// too few epochs on the grown records to pay for their simulation.
const MIN_LEFT_SHARE: f64 = 0.05;

impl<S: Simulator + ?Sized> Search<'_, '_, S> {
    /// How many records to simulate for one more step of the winner's
    /// final fit: none unless the source grows under a time budget, the
    /// last fit ended before the deadline, at least [`MIN_LEFT_SHARE`] of
    /// the budget is left, and the records stay below `cap`. The step adds
    /// as many as its share of the time left fits at `per_added` seconds
    /// a record added ([`crate::cost::slowest_pace`]: a fit trained further spends its
    /// iterations on what the records it goes on from did not show), each
    /// simulated in `per_simulation` seconds.
    pub(crate) fn next_step_records(
        &self,
        winner: &Winner,
        per_added: f64,
        per_simulation: f64,
        cap: usize,
    ) -> usize {
        let Budget::Seconds(budget) = self.plan.budget else {
            return 0;
        };
        if !self.plan.grows || winner.final_fit.stopped() {
            return 0;
        }
        let left = self.plan.seconds_left();
        if left < MIN_LEFT_SHARE * budget {
            return 0;
        }
        let rows = winner.features.nrows();
        let affordable = STEP_SHARE * left / per_added.max(1e-9);
        let growth =
            (1.0 + affordable / rows.max(1) as f64).clamp(MIN_STEP_GROWTH, MAX_STEP_GROWTH);
        let mut target = ((rows as f64 * growth) as usize).min(cap);
        // The simulations must leave most of the time to the fit.
        let simulable = (0.25 * left / per_simulation.max(1e-9)) as usize;
        target = target.min(rows.saturating_add(simulable));
        let added = target.saturating_sub(rows);
        if added < 5 * MIN_COMPARED_RECORDS {
            return 0;
        }
        added
    }

    /// One more step of `simulations` (`more` holds those that did not
    /// fail): the `more` records appended to the winner's, its
    /// shipped fit trained further on all but the last fifth of them (at
    /// most [`MAX_COMPARED_RECORDS`]) under the deadline, and kept where it
    /// scores better on those than the fit before.
    pub(crate) fn step(
        &self,
        winner: &mut Winner,
        more: &StoredChart,
        simulations: usize,
    ) -> Result<Continuation> {
        let deadline = self.plan.deadline.ok_or_else(|| Error::Search {
            what: "the anytime final fit needs a time budget".into(),
        })?;
        let features = compress_all(
            &winner.compressor,
            &more.records,
            self.plan.base.max_failure_fraction,
        )?;
        let (features, thetas) = readable_rows(features.view(), more.thetas.view());
        let added = features.nrows();
        winner.left_out += more.records.len() - added;
        let grown = |what: &str, e: ndarray::ShapeError| Error::Search {
            what: format!("the records added to the final fit do not match its {what}: {e}"),
        };
        winner
            .features
            .append(Axis(0), features.view())
            .map_err(|e| grown("features", e))?;
        winner
            .thetas
            .append(Axis(0), thetas.view())
            .map_err(|e| grown("parameters", e))?;
        let total = winner.features.nrows();
        let compared = (added / 5).clamp(MIN_COMPARED_RECORDS.min(added), MAX_COMPARED_RECORDS);
        let train_rows = total - compared;
        let marginals = self.plan.base.simulator().spec().prior().marginals();
        let rows = s![..train_rows, ..];
        let (x, z) = (
            winner.features.slice(rows),
            to_learning_space(winner.thetas.slice(rows), marginals),
        );
        self.plan.base.progress().status(&format!(
            "final fit: {} trained further on {train_rows} records; {}",
            design(&winner.compressor, &winner.regressor_config),
            self.plan.budget_words()
        ));
        let continued = winner.regressor_config.fit_from(
            Some(&winner.regressor),
            (x, z.view()),
            self.plan.base.seed(),
            Some(deadline),
        )?;
        let held = s![train_rows.., ..];
        let (x_held, t_held) = (winner.features.slice(held), winner.thetas.slice(held));
        let before = self.plan.score(&winner.regressor, x_held, t_held)?.1;
        let after = self.plan.score(&continued, x_held, t_held)?.1;
        let step = Continuation {
            simulations,
            rows: train_rows,
            compared,
            before,
            after,
            stopped: continued.stopped_at_deadline() || Instant::now() >= deadline,
        };
        if step.kept() {
            winner.regressor = continued;
        }
        Ok(step)
    }
}

#[cfg(test)]
mod tests {
    // A panic is how a test fails.
    #![allow(clippy::unwrap_used)]

    use std::time::{Duration, Instant};

    use ndarray::{Array2, s};
    use twostage_compress::{Arx, CompressorConfig};
    use twostage_estimator::space::{rows_to_estimates, to_learning_space};
    use twostage_fit::{MlpParams, Predictor, RegressorConfig};
    use twostage_models::{Benchmark, Simulator};
    use twostage_sources::ForModel;
    use twostage_train::TwoStage;

    use super::super::{Scope, Search, Winner, compress_all};
    use super::STEP_SHARE;
    use crate::{Budget, FinalFit};

    const CHART: usize = 1500;

    /// RMSE per parameter over the prior's sd, averaged: the search's
    /// score, computed here apart from it.
    fn score_by_hand(
        model: &Benchmark,
        fitted: &twostage_fit::FittedRegressor,
        x: ndarray::ArrayView2<'_, f64>,
        thetas: ndarray::ArrayView2<'_, f64>,
    ) -> f64 {
        let prior = model.spec().prior();
        let mut estimates = fitted.predict(x).unwrap();
        rows_to_estimates(
            &mut estimates,
            prior.marginals(),
            prior.lower(),
            prior.upper(),
        );
        let q = thetas.ncols();
        (0..q)
            .map(|j| {
                let mse = (&thetas.column(j) - &estimates.column(j))
                    .mapv(|d| d * d)
                    .mean()
                    .unwrap();
                mse.sqrt() / ((prior.upper()[j] - prior.lower()[j]) / 12f64.sqrt())
            })
            .sum::<f64>()
            / q as f64
    }

    fn predictions(w: &Winner, x: ndarray::ArrayView2<'_, f64>) -> Array2<f64> {
        w.regressor.predict(x).unwrap()
    }

    #[test]
    fn a_step_trains_further_on_the_added_records_and_keeps_only_a_better_fit() {
        let model = Benchmark::builder().n_samples(200).build().unwrap();
        let run = TwoStage::builder(&model)
            .simulations(CHART)
            .seed(7)
            .prepare()
            .unwrap();
        let (chart, _) = run.records().stored_training().unwrap();
        let scope = Scope::of(&run);
        let far = Instant::now() + Duration::from_secs(1_000_000);
        let search = Search::new(
            &scope,
            &chart,
            (Budget::Seconds(1e6), Instant::now(), Some(far)),
            Some(4000),
            true,
        );
        let compressor = CompressorConfig::from(Arx::new(2, 2).unwrap())
            .for_model(model.spec())
            .unwrap();
        let network = RegressorConfig::Mlp(MlpParams::new(&[4]).unwrap().check().unwrap());
        let features = compress_all(&compressor, &chart.records, 0.0).unwrap();
        let marginals = model.spec().prior().marginals();
        let z = to_learning_space(chart.thetas.view(), marginals);
        let fitted = network.fit(features.view(), z.view(), 7).unwrap();
        let mut winner = Winner {
            compressor,
            features,
            thetas: chart.thetas.clone(),
            left_out: 0,
            regressor_config: network,
            regressor: fitted,
            final_fit: FinalFit::TrainedFurther {
                rows: CHART,
                stopped: false,
            },
            candidate: 0,
        };
        let rows = chart.records.len();
        // Far from the deadline a step doubles the records, within the cap.
        assert_eq!(
            search.next_step_records(&winner, 1.0, 1e-6, usize::MAX),
            rows
        );
        assert_eq!(
            search.next_step_records(&winner, 1.0, 1e-6, rows + 1200),
            1200
        );
        // A step adds what its share of the time left fits at the pace a
        // record added: 0.8 of the records here, within a second's drift.
        let left = search.plan.seconds_left();
        let pace = STEP_SHARE * left / (0.8 * rows as f64);
        let added = search.next_step_records(&winner, pace, 1e-6, usize::MAX);
        assert!(
            (rows * 8 / 10 - 1..=rows * 8 / 10).contains(&added),
            "{added}"
        );
        // At ten times that pace a step would add a quarter (the least a
        // step grows), too few to compare on here: none.
        assert_eq!(
            search.next_step_records(&winner, 10.0 * pace, 1e-6, usize::MAX),
            0
        );
        // Too few to compare a step on, or a fit the deadline stopped: none.
        assert_eq!(search.next_step_records(&winner, 1.0, 1e-6, rows + 999), 0);
        winner.final_fit = FinalFit::TrainedFurther {
            rows: CHART,
            stopped: true,
        };
        assert_eq!(search.next_step_records(&winner, 1.0, 1e-6, usize::MAX), 0);

        let (more, failed) = run
            .records()
            .more_training(CHART, CHART + 2000)
            .unwrap()
            .unwrap();
        assert_eq!(failed, 0);
        let before = predictions(&winner, winner.features.view());
        let step = search.step(&mut winner, &more, 2000).unwrap();
        assert_eq!(winner.features.nrows(), rows + 2000);
        assert_eq!(winner.thetas.nrows(), rows + 2000);
        assert_eq!(
            (step.simulations, step.compared, step.rows),
            (2000, 400, rows + 1600)
        );
        // The added records are the run's own, row for row.
        assert_eq!(winner.thetas.slice(s![rows.., ..]), more.thetas);
        let held = s![rows + 1600.., ..];
        let (x_held, t_held) = (winner.features.slice(held), winner.thetas.slice(held));
        // The fit before the step, scored apart on the compared records.
        let start = network_fit_again(&model, &chart);
        let by_hand = score_by_hand(&model, &start, x_held, t_held);
        assert!(
            (step.before - by_hand).abs() < 1e-12,
            "{} {}",
            step.before,
            by_hand
        );
        let now = predictions(&winner, winner.features.slice(s![..rows, ..]));
        if step.kept() {
            let by_hand = score_by_hand(&model, &winner.regressor, x_held, t_held);
            assert!((step.after - by_hand).abs() < 1e-12);
            assert_ne!(now, before);
        } else {
            assert_eq!(now, before);
        }
        assert!(!step.stopped);
    }

    /// The test's start fit again (the same seed gives the same bits).
    fn network_fit_again(
        model: &Benchmark,
        chart: &twostage_sources::StoredChart,
    ) -> twostage_fit::FittedRegressor {
        let compressor = CompressorConfig::from(Arx::new(2, 2).unwrap())
            .for_model(model.spec())
            .unwrap();
        let network = RegressorConfig::Mlp(MlpParams::new(&[4]).unwrap().check().unwrap());
        let features = compress_all(&compressor, &chart.records, 0.0).unwrap();
        let z = to_learning_space(chart.thetas.view(), model.spec().prior().marginals());
        network.fit(features.view(), z.view(), 7).unwrap()
    }
}
