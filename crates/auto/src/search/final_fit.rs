//! The winner's final fit: on the chart, or on more records simulated for
//! it where the learning curve says they pay, trained
//! further from its scored fit and anew where the time affords, the better
//! on added records no fit saw.

use std::time::{Duration, Instant};

use ndarray::{Array2, Axis};
use twostage_compress::CompressorConfig;
use twostage_fit::{FittedRegressor, MlpParams, RegressorConfig};
use twostage_models::Simulator;
use twostage_sources::StoredChart;

use super::{Search, compress_all, design, readable_rows};
use crate::Budget;
use crate::candidates::network_size;
use crate::cost::{
    ANEW_SHARE, CHART_FINISH_SHARE, COST_MARGIN, ROWS_EXPONENT, fit_seconds, held_out_seconds,
    rows_for_final_fit,
};
use crate::outcome::{FinalFit, FinalFits, RivalNetwork};
use twostage_compress::Compressor;
use twostage_estimator::space::to_learning_space;
use twostage_train::{Error, Result};

impl<S: Simulator + ?Sized> Search<'_, '_, S> {
    /// The records the winner's final fit takes: more than the chart's
    /// where the source can simulate them, the half-rows trial says more
    /// records pay or had no time to run (`more_records`,
    /// [`crate::outcome::more_records_to_try`]), and the time left affords
    /// simulating them (`per_simulation` wall seconds each) and fitting on
    /// all, at most four times the chart (a learning curve says little
    /// beyond that) and `cap`; else the chart's (trained further from the
    /// scored fit, which the deadline may stop at any time without making
    /// it worse, so no row need be left out for time).
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
            (per_simulation, self.further_estimate(best, scored), scored),
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
        let compressing = Instant::now();
        let features = compress_all(&compressor, records, self.plan.base.max_failure_fraction)?;
        let per_record = compressing.elapsed().as_secs_f64() / records.len().max(1) as f64;
        let (features, kept_thetas) = readable_rows(features.view(), thetas.view());
        let left_out = thetas.nrows() - kept_thetas.nrows();
        let refit_rows = final_rows.min(kept_thetas.nrows());
        let mut winner = Winner {
            compressor,
            features,
            thetas: kept_thetas,
            left_out,
            regressor_config,
            regressor: held_out_fit,
            final_fit: FinalFit::AsScored { rows: scored_rows },
            candidate: best,
        };
        if refit_rows <= scored_rows {
            return Ok(winner);
        }
        let marginals = self.plan.base.simulator().spec().prior().marginals();
        let seed = self.plan.base.seed();
        let Some(deadline) = self.plan.deadline else {
            let rows = ndarray::s![..refit_rows, ..];
            let z = to_learning_space(winner.thetas.slice(rows), marginals);
            winner.regressor =
                winner
                    .regressor_config
                    .fit(winner.features.slice(rows), z.view(), seed)?;
            winner.final_fit = FinalFit::Anew { rows: refit_rows };
            return Ok(winner);
        };
        let added = more.map_or(0, |m| m.records.len());
        let deadline = self.final_deadline(deadline, per_record);
        self.fit_by_deadline(best, &mut winner, (refit_rows, added), deadline)?;
        Ok(winner)
    }

    /// The deadline of the winner's final fit: the search's `deadline`,
    /// or, on records read from files (they cannot grow, and their
    /// held-out records cost only their compression), the budget's end
    /// less what compressing those at the winner's measured pace
    /// (`per_record` seconds) and finishing take, where that is later.
    /// The search's own deadline keeps 5% of the budget for them,
    /// unmeasured, which on a chart whose held-out records compress in
    /// moments is time the sized ensemble could have grown in.
    fn final_deadline(&self, deadline: Instant, per_record: f64) -> Instant {
        let (Some(end), Budget::Seconds(t)) = (self.plan.budget_end, self.plan.budget) else {
            return deadline;
        };
        if self.plan.grows {
            return deadline;
        }
        let finish = held_out_seconds(per_record, self.plan.base.held_out) + CHART_FINISH_SHARE * t;
        end.checked_sub(Duration::from_secs_f64(finish))
            .map_or(deadline, |d| d.max(deadline))
    }

    /// The winner's final fit on `refit_rows` under a time budget, of which
    /// `added` were simulated for it.
    fn fit_by_deadline(
        &self,
        best: usize,
        winner: &mut Winner,
        (refit_rows, added): (usize, usize),
        deadline: Instant,
    ) -> Result<()> {
        let marginals = self.plan.base.simulator().spec().prior().marginals();
        let seed = self.plan.base.seed();
        let scored_rows = winner.final_fit.rows();
        // Under a time budget the winner is trained further from the fit it
        // was scored with: cheaper than anew, and a fit that can stop at
        // the deadline (the costs are estimates) and still be no worse than
        // its start. Where records were added, a rival fit competes: both
        // leave out the last fifth of the added records (seen by no fit; at
        // most 2000: the fits are compared on the same records, so their
        // difference is measured well before their scores are) and the
        // better on them ships.
        let compared = (added / 5)
            .min(MAX_COMPARED_RECORDS)
            .min(refit_rows.saturating_sub(scored_rows));
        let rival = self.rival(best, refit_rows, compared);
        let rival = rival.as_ref();
        let train_rows = if rival.is_some() {
            refit_rows - compared
        } else {
            refit_rows
        };
        let rows = ndarray::s![..train_rows, ..];
        let (x, z) = (
            winner.features.slice(rows),
            to_learning_space(winner.thetas.slice(rows), marginals),
        );
        let further_design = design(&winner.compressor, &winner.regressor_config);
        self.plan.base.progress().status(&format!(
            "final fit: {further_design} trained further on {train_rows} records; {}",
            self.plan.budget_words()
        ));
        // A rival trained further shares the time left: the winner's fit
        // stops at its share ([`winner_share`]: both fits go about as far);
        // beside a fit anew at the deadline; beside a network sized for
        // the records, fitted anew and grown while time is left, at an
        // eighth (each wave of members it gains pays more than the
        // winner's further epochs).
        let now = Instant::now();
        let left = deadline.saturating_duration_since(now);
        let winner_stop = match rival {
            Some(r) if matches!(r.of, RivalNetwork::SizedForRows { .. }) => now + left / 8,
            Some(Rival {
                of: RivalNetwork::Candidate(i),
                anew: false,
                ..
            }) => {
                let share = winner_share(
                    self.further_estimate(best, train_rows),
                    self.further_estimate(*i, train_rows),
                );
                now + left.mul_f64(share)
            }
            _ => deadline,
        };
        let continued = winner.regressor_config.fit_from(
            Some(&winner.regressor),
            (x, z.view()),
            seed,
            Some(winner_stop),
        )?;
        // The rival starts only while time is left: the fit trained
        // further may have used it all.
        let Some(rival) = rival.filter(|_| Instant::now() < deadline) else {
            winner.final_fit = FinalFit::TrainedFurther {
                rows: train_rows,
                stopped: continued.stopped_at_deadline(),
            };
            winner.regressor = continued;
            return Ok(());
        };
        let rival_network = rival.network.clone();
        let start = match (rival.of, rival.anew) {
            (RivalNetwork::Candidate(i), false) => {
                self.candidates[i].fitted.as_ref().map(|(_, fitted)| fitted)
            }
            _ => None,
        };
        self.plan.base.progress().status(&format!(
            "final fit: {} {} on {train_rows} records; {}",
            design(&winner.compressor, &rival_network),
            if rival.anew {
                "anew"
            } else {
                "trained further"
            },
            self.plan.budget_words()
        ));
        let started = Instant::now();
        let rival_fit = rival_network.fit_from(start, (x, z.view()), seed, Some(deadline))?;
        let (rival_network, rival_fit, rival_of) = match rival.of {
            RivalNetwork::SizedForRows { width, .. } => {
                let (network, fit) = self.more_members(
                    rival_network,
                    rival_fit,
                    (x, z.view()),
                    started.elapsed(),
                    deadline,
                )?;
                let members = network_members(&network);
                (network, fit, RivalNetwork::SizedForRows { width, members })
            }
            of => (rival_network, rival_fit, of),
        };
        let rows = ndarray::s![train_rows..refit_rows, ..];
        let (x_held, t_held) = (winner.features.slice(rows), winner.thetas.slice(rows));
        let score = |fitted: &FittedRegressor| -> Result<f64> {
            Ok(self.plan.score(fitted, x_held, t_held)?.1)
        };
        let fits = FinalFits {
            compared,
            further: score(&continued)?,
            rival: score(&rival_fit)?,
            rival_of,
            rival_anew: rival.anew,
        };
        let chosen = if fits.rival < fits.further {
            winner.regressor_config = rival_network;
            if let RivalNetwork::Candidate(i) = rival.of {
                winner.candidate = i;
            }
            rival_fit
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

    /// The ensemble sized for the records (`network`, fitted as `fitted` in
    /// `first`) with members added, a wave of one a thread, while the time
    /// left affords a wave ([`WAVE_MARGIN`] times the longest measured) and
    /// up to [`MAX_MEMBERS`]: a chart cannot grow, and more members average
    /// away more of each network's own error. A wave the
    /// deadline cuts short is left out whole, so the members are restarts
    /// 0 to N - 1 and `ensemble:..xN` trains them again.
    fn more_members(
        &self,
        network: RegressorConfig,
        fitted: FittedRegressor,
        (x, z): (ndarray::ArrayView2<'_, f64>, ndarray::ArrayView2<'_, f64>),
        first: Duration,
        deadline: Instant,
    ) -> Result<(RegressorConfig, FittedRegressor)> {
        let (RegressorConfig::Mlp(mlp), FittedRegressor::Mlp(fit)) = (&network, &fitted) else {
            return Ok((network, fitted));
        };
        if fitted.stopped_at_deadline() || !mlp.params().is_ensemble() {
            return Ok((network, fitted));
        }
        let wave = rayon::current_num_threads().max(1);
        // The first fit ran its members a wave at a time too.
        let rounds = fit.n_members().div_ceil(wave).max(1);
        let mut wave_time = first / rounds as u32;
        let grower = mlp.with_seed(self.plan.base.seed()).stopped_by(deadline);
        let mut fit = fit.clone();
        while fit.n_members() + wave <= MAX_MEMBERS
            && Instant::now() + wave_time.mul_f64(WAVE_MARGIN) < deadline
        {
            self.plan.base.progress().status(&format!(
                "final fit: {} more members beside {}; {}",
                wave,
                fit.n_members(),
                self.plan.budget_words()
            ));
            let began = Instant::now();
            let grown = grower.fit_more(&fit, x, z, wave)?;
            wave_time = wave_time.max(began.elapsed());
            if grown.n_members() < fit.n_members() + wave {
                break;
            }
            fit = grown;
        }
        let members = fit.n_members();
        let network = MlpParams::clone(mlp.params())
            .restarts(members)
            .check()
            .map(RegressorConfig::Mlp)?;
        Ok((network, FittedRegressor::Mlp(fit)))
    }

    /// Whether a network sized for the records will compete in the final
    /// fit of candidate `i`'s stage 1 on the chart: a chart that cannot
    /// grow, with records for one ([`network_for_rows`], the compared
    /// records left out). The rounds ask before every network is scored,
    /// so this does not ask, as [`Self::sized_for_rows`] does, whether a
    /// scored network is larger still (pieces of `[20]` on many features can
    /// be larger than [32, 32]); where one is, the sized network does not
    /// compete and the winner and its other rival have the larger share.
    pub(super) fn sized_network_competes(&self, i: usize) -> bool {
        let Some((compressor, _)) = self.candidates[i].fitted.as_ref() else {
            return false;
        };
        let rows = self
            .plan
            .chart
            .thetas
            .nrows()
            .saturating_sub(MAX_COMPARED_RECORDS);
        !self.plan.grows
            && self.plan.deadline.is_some()
            && network_for_rows(
                rows,
                compressor.n_features(),
                self.plan.chart.thetas.ncols(),
            )
            .is_some()
    }

    /// The fit that competes with the winner trained further on
    /// `refit_rows`, where `compared` added records can judge them: on a
    /// chart's many records, a network sized for them
    /// ([`Self::sized_for_rows`]) fitted anew; else a larger network ([`Self::larger_network`]) fitted anew
    /// where the time left affords it, or trained further from its own
    /// scored fit (as cheap as the winner's); without one, the winner's
    /// network anew where affordable.
    fn rival(&self, best: usize, refit_rows: usize, compared: usize) -> Option<Rival> {
        if compared < MIN_COMPARED_RECORDS {
            return None;
        }
        let train_rows = refit_rows - compared;
        if let Some((network, width)) = self.sized_for_rows(best, train_rows) {
            return Some(Rival {
                of: RivalNetwork::SizedForRows {
                    width,
                    members: network_members(&network),
                },
                network,
                anew: true,
            });
        }
        let affordable =
            |i: usize| self.fit_estimate(i, train_rows) < ANEW_SHARE * self.plan.seconds_left();
        let (i, anew) = match self.larger_network(best, refit_rows) {
            Some(i) => (i, affordable(i)),
            None => (best, true),
        };
        (i != best || affordable(best)).then(|| Rival {
            network: self.candidates[i].network.clone(),
            of: RivalNetwork::Candidate(i),
            anew,
        })
    }

    /// The network sized for `rows` training records on the winner's
    /// stage 1 ([`network_for_rows`]), where the records cannot grow (a
    /// chart) and it is larger than every network the search scored
    /// there: the search's networks are sized for the rows it scores on,
    /// and a chart of many records carries more than they can learn.
    fn sized_for_rows(&self, best: usize, rows: usize) -> Option<(RegressorConfig, usize)> {
        // Where the source simulates, more records (the anytime steps)
        // are the better use of the time: a wide rival's fit takes the
        // time of a larger candidate's and of the steps. A chart cannot
        // grow.
        if self.plan.grows {
            return None;
        }
        let (compressor, _) = self.candidates[best].fitted.as_ref()?;
        let (n, q) = (compressor.n_features(), self.plan.chart.thetas.ncols());
        let (network, width) = network_for_rows(rows, n, q)?;
        let size = network_size(&network, n, q);
        let largest = self
            .candidates
            .iter()
            .filter(|c| c.report.status.is_scored())
            .filter(|c| {
                c.fitted
                    .as_ref()
                    .is_some_and(|(other, _)| other == compressor)
            })
            .map(|c| network_size(&c.network, n, q))
            .fold(0.0, f64::max);
        (size > largest).then_some((network, width))
    }

    /// Where the final fit's `rows` are at least [`GROWN_ROWS`] times those
    /// the winner was scored on: a candidate with a larger network on the
    /// winner's stage 1, scored on the same rows. More records carry more
    /// than a small network can learn; among the larger networks
    /// that the seed alone could have ranked either way (within
    /// [`Self::tie`] of the best of them), the cheapest to fit anew: on
    /// the final records it trains longest in the time there is. The
    /// comparison on added records decides whether it ships.
    fn larger_network(&self, best: usize, rows: usize) -> Option<usize> {
        let winner = &self.candidates[best];
        let scored = winner.report.fit_rows;
        if rows < GROWN_ROWS * scored {
            return None;
        }
        let (compressor, _) = winner.fitted.as_ref()?;
        let (n, q) = (compressor.n_features(), self.plan.chart.thetas.ncols());
        let size = network_size(&winner.network, n, q);
        let larger: Vec<usize> = (0..self.candidates.len())
            .filter(|&i| {
                let c = &self.candidates[i];
                c.report.status.is_scored()
                    && c.report.fit_rows == scored
                    && c.fitted
                        .as_ref()
                        .is_some_and(|(other, _)| other == compressor)
                    && network_size(&c.network, n, q) > size
            })
            .collect();
        let score = |i: usize| self.candidates[i].report.score;
        let top = larger.iter().map(|&i| score(i)).min_by(f64::total_cmp)?;
        larger
            .into_iter()
            .filter(|&i| score(i) <= top * (1.0 + self.tie()))
            .min_by(|&a, &b| {
                self.fit_estimate(a, rows)
                    .total_cmp(&self.fit_estimate(b, rows))
            })
    }

    /// The seconds a fit anew of candidate `i` (the winner, or its rival)
    /// on `rows` rows takes on the whole machine, from its time alone where
    /// round 3 measured it, else from its round's shared time.
    pub(super) fn fit_estimate(&self, i: usize, rows: usize) -> f64 {
        let report = &self.candidates[i].report;
        let scored = report.fit_rows;
        let growth = (rows as f64 / scored.max(1) as f64).powf(self.cost_exponent());
        match self.candidates[i].solo_seconds {
            Some(seconds) => COST_MARGIN * seconds * growth,
            None => fit_seconds(report.seconds, scored, rows),
        }
    }

    /// The seconds candidate `i`'s scored fit takes to train further on
    /// `rows` rows: a fit anew's ([`Self::fit_estimate`]) for the networks
    /// that go on, the kept restart of a best-of-restarts network
    /// ([`trained_further_share`]).
    pub(super) fn further_estimate(&self, i: usize, rows: usize) -> f64 {
        self.fit_estimate(i, rows) * trained_further_share(&self.candidates[i].network)
    }

    /// How a fit's time grows with its rows: as round 3 measured it, or
    /// [`ROWS_EXPONENT`].
    pub(super) fn cost_exponent(&self) -> f64 {
        self.rows_exponent.unwrap_or(ROWS_EXPONENT)
    }
}

/// The network sized for `rows` training records of `n` features and `q`
/// parameters, where they are at least [`SIZED_MIN_ROWS`]: two hidden
/// layers of the widest of [`SIZED_WIDTHS`] with at least
/// [`ROWS_PER_WEIGHT`] records a weight, its restarts averaged. Trained
/// by Adam (beyond Levenberg-Marquardt's size), as a careful human trains
/// a network on a large chart.
pub(crate) fn network_for_rows(
    rows: usize,
    n: usize,
    q: usize,
) -> Option<(RegressorConfig, usize)> {
    if rows < SIZED_MIN_ROWS {
        return None;
    }
    let width = SIZED_WIDTHS
        .iter()
        .copied()
        .filter(|&w| twostage_fit::n_parameters(&[n, w, w, q]) * ROWS_PER_WEIGHT <= rows)
        .max()?;
    // Its restarts averaged rather than the best kept: the same training,
    // and a wide network's restarts err in different directions, which
    // their average cancels and the best alone keeps.
    let averaged = MlpParams::new(&[width, width])
        .and_then(|p| p.ensemble(true).check())
        .ok()?;
    Some((RegressorConfig::Mlp(averaged), width))
}

/// The share of a fit anew's work that training its fit further takes:
/// a best-of-restarts network goes on from its kept restart alone (its
/// restarts ran side by side on the machine's threads; the one left runs
/// its products on them all), an ensemble from every member. A piecewise
/// regressor's networks are restarted as its global network is.
fn trained_further_share(network: &RegressorConfig) -> f64 {
    let mlp = match network {
        RegressorConfig::Mlp(m) => m,
        RegressorConfig::Piecewise(p) => p.global(),
        _ => return 1.0,
    };
    if mlp.params().is_ensemble() {
        1.0
    } else {
        1.0 / mlp.params().n_restarts().max(1) as f64
    }
}

/// The share of the time left the winner's fit trained further takes
/// beside a larger network trained further, from their estimated
/// `winner` and `rival` seconds: in proportion to its cost, so that both
/// fits go about as far, between [`MIN_WINNER_SHARE`] and a half. A fit
/// trained further keeps its best held-out weights, so a short one is
/// never worse than its start.
fn winner_share(winner: f64, rival: f64) -> f64 {
    let share = winner / (winner + rival);
    if share.is_finite() {
        share.clamp(MIN_WINNER_SHARE, 0.5)
    } else {
        0.5
    }
}

/// The least share of the time left the winner's fit trained further
/// takes beside a larger network's: cost estimates can be wrong.
const MIN_WINNER_SHARE: f64 = 0.1;

/// The members of an ensemble configuration (1 for any other).
pub(super) fn network_members(network: &RegressorConfig) -> usize {
    match network {
        RegressorConfig::Mlp(m) if m.params().is_ensemble() => m.params().n_restarts(),
        _ => 1,
    }
}

/// Members of the network sized for the records at most: each is a
/// network the estimate runs (sixteen [64, 64] networks on 40 features have 112,704
/// weights and biases an estimate reads).
const MAX_MEMBERS: usize = 16;
/// How many times a wave's measured time must be left for another wave of
/// members to start.
const WAVE_MARGIN: f64 = 1.1;

/// Training records below which the final fit keeps the search's
/// networks.
const SIZED_MIN_ROWS: usize = 20_000;
/// The widths a network sized for the records may take.
const SIZED_WIDTHS: [usize; 3] = [32, 64, 128];
/// Training records a weight of a network sized for them, at least (the
/// hand design of docs/accuracy.md's predator-prey task: 7,044 weights on
/// 93,000 records, 13 a weight).
const ROWS_PER_WEIGHT: usize = 12;

/// The final fit's rival: its network, whose it is, and whether it is
/// fitted anew (else trained further from its candidate's scored fit).
struct Rival {
    network: RegressorConfig,
    of: RivalNetwork,
    anew: bool,
}

/// How many times the rows a winner was scored on its final fit must have
/// for a fit anew to take a larger network.
const GROWN_ROWS: usize = 4;
/// Records a fit anew and a fit trained further are compared on, at least.
pub(super) const MIN_COMPARED_RECORDS: usize = 200;
/// Records a fit anew and a fit trained further are compared on, at most.
pub(super) const MAX_COMPARED_RECORDS: usize = 2000;

/// What the search ships: the winning structure, fitted.
pub(crate) struct Winner {
    pub(crate) compressor: CompressorConfig,
    /// The whole chart's features under the winning compressor, with the
    /// records added for the final fit.
    pub(crate) features: Array2<f64>,
    /// The parameters of the same records, row for row.
    pub(crate) thetas: Array2<f64>,
    /// Records its stage 1 could not compress, left out of both.
    pub(crate) left_out: usize,
    pub(crate) regressor_config: RegressorConfig,
    pub(crate) regressor: FittedRegressor,
    /// How `regressor` was fitted.
    pub(crate) final_fit: FinalFit,
    /// The candidate whose structure ships: the winner, or the larger
    /// network that beat it (a network sized for the records is no
    /// candidate: when it ships, the winner's stage 1 stays marked).
    pub(crate) candidate: usize,
}

#[cfg(test)]
mod tests;
