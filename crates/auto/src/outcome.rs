//! What an automatic design reports: every candidate's score and status,
//! what round 3 measured, how the winner's final fit went.

use twostage_estimator::Estimator;

/// One candidate structure and how it scored.
#[derive(Debug, Clone, PartialEq)]
pub struct CandidateReport {
    /// Stage 1.
    pub compressor: String,
    /// Stage 2.
    pub regressor: String,
    /// Both stages as the command line writes them (`log+pca:8 mlp:20`),
    /// or as they read where a stage has no such form.
    pub design: String,
    /// Search round: 1 compares compressors with one network, 2 compares
    /// networks on the best compressors, 3 averages the winner's restarts.
    pub round: usize,
    /// RMSE per parameter on the held-out chart rows (empty when not run).
    pub rmse: Vec<f64>,
    /// Mean over parameters of RMSE / prior standard deviation (lower is
    /// better; 1 means nothing learned).
    pub score: f64,
    /// Seconds spent compressing and fitting it.
    pub seconds: f64,
    /// Chart rows its network was fitted on: all the fitting rows, or a
    /// screening share of them in round 1, or what round 2
    /// or 3 could afford.
    pub fit_rows: usize,
    /// Whether it was scored, and why not if it was not.
    pub status: Status,
    /// How its network was trained (trainer, stop reason, restarts).
    pub trained_by: Option<String>,
}

/// Whether a candidate was scored, and why not if it was not.
#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    /// Fitted, and scored on the held-out rows.
    Scored,
    /// Not started: about `seconds` would have overrun the time budget.
    Skipped {
        /// Its estimated cost.
        seconds: f64,
    },
    /// Its stage 1 does not apply to these records (an autoregression of
    /// a noise-free decay is rank deficient, say): why.
    NotApplicable(String),
    /// Its fit went wrong: why.
    Failed(String),
}

impl Status {
    /// Whether the candidate has a score.
    ///
    /// ```
    /// assert!(twostage::auto::Status::Scored.is_scored());
    /// assert!(!twostage::auto::Status::Failed("diverged".into()).is_scored());
    /// ```
    pub fn is_scored(&self) -> bool {
        matches!(self, Self::Scored)
    }
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Scored => write!(f, "scored"),
            Self::Skipped { seconds } => write!(
                f,
                "skipped: about {seconds:.0} s would overrun the time budget"
            ),
            Self::NotApplicable(why) => write!(f, "does not apply to these records: {why}"),
            Self::Failed(why) => write!(f, "failed: {why}"),
        }
    }
}

/// The result of [`crate::AutoDesign::run`].
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
    /// The simulations among them that failed (left out of every fit).
    pub failures: usize,
    /// Seconds of the search (without calibration and validation).
    pub search_seconds: f64,
    /// How the shipped network was fitted: as scored, anew, trained
    /// further, or both and the better shipped; on how many rows.
    pub final_fit: FinalFit,
    /// The round-2 winner's score at the run's seed and, where the budget
    /// allowed, at two other seeds: how much the seed alone moves it.
    pub seed_scores: Vec<f64>,
    /// The round-2 winner fitted on half its rows (how many, and its
    /// score), where the budget allowed: a learning curve's last step,
    /// which says whether more records would pay.
    pub half_rows: Option<(usize, f64)>,
    /// Simulations added after the search for the winner's final fit and
    /// its anytime steps (counted in `simulations`), where more records
    /// pay and the time left afforded them.
    pub added_simulations: usize,
    /// How the round-2 winner's fit time grew with its rows (the exponent,
    /// from its half-rows and seed trials timed alone), where measured: the
    /// final fit's rows follow from it.
    pub rows_exponent: Option<f64>,
    /// The anytime final fit's steps after the final fit, in order (empty
    /// where it ended at the deadline, or no time was left).
    pub steps: Vec<Continuation>,
    /// Where the search picked a candidate over a better-scoring one that
    /// the seed alone could have ranked either way, for its lower cost.
    pub cheaper_tie: Option<CheaperTie>,
    /// Where the search picked a single network over its restarts
    /// averaged, which it would otherwise have picked, because in the
    /// same time the single network trains further on more records.
    pub equal_time: Option<EqualTime>,
}

/// Round 3's averaged network passed over for the network it averages, at
/// equal final-fit time: both indices in [`AutoOutcome::candidates`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EqualTime {
    /// The single network, picked.
    pub single: usize,
    /// Its restarts averaged, the search's pick before this comparison.
    pub averaged: usize,
    /// The single network's score projected onto the records its final
    /// fit takes in the average's time.
    pub projected: f64,
    /// How many times the rows that is.
    pub records_factor: f64,
}

/// A tie the search broke for the cheaper candidate: both indices in
/// [`AutoOutcome::candidates`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CheaperTie {
    /// The candidate the search picked.
    pub picked: usize,
    /// The best-scoring candidate, passed over.
    pub best_score: usize,
}

/// Whether a score of `half` on half the rows against `own` on all of them
/// says more records would pay: the learning curve still falls. Time a
/// search would leave unused then goes to more records, trained further
/// from the winner's fit, which cannot make it worse on held-out rows.
pub(crate) fn more_records_pay(half: f64, own: f64) -> bool {
    half > own
}

/// Whether the winner's final fit should take more records than the
/// chart: where round 3 measured the learning curve (`half_rows` against
/// the winner's `own` score), as it says; where the time left no room for
/// that trial, yes: the final fit then compares its fits on
/// records no fit saw, and the anytime steps after it measure for
/// themselves.
pub(crate) fn more_records_to_try(half_rows: Option<(usize, f64)>, own: Option<f64>) -> bool {
    match (half_rows, own) {
        (Some((_, half)), Some(own)) => more_records_pay(half, own),
        _ => true,
    }
}

impl std::fmt::Display for AutoOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "automatic design on m = {} simulations ({:.1} s), held-out RMSE per candidate:",
            self.simulations, self.search_seconds
        )?;
        self.fmt_shortened_fit(f)?;
        self.fmt_round_three(f)?;
        self.fmt_final_fit(f)?;
        if let Some(e) = self.equal_time
            && let (Some(p), Some(b)) = (
                self.candidates.get(e.single),
                self.candidates.get(e.averaged),
            )
        {
            writeln!(
                f,
                "the search picked {} (score {:.4}) over its restarts averaged, {} ({:.4}): \
                 trained further, the single network takes {:.1} times the records in the \
                 average's time, where its learning curve projects {:.4}",
                p.design, p.score, b.design, b.score, e.records_factor, e.projected
            )?;
        } else if let Some(CheaperTie { picked, best_score }) = self.cheaper_tie
            && let (Some(p), Some(b)) =
                (self.candidates.get(picked), self.candidates.get(best_score))
        {
            writeln!(
                f,
                "the search picked {} (score {:.4}) over {} ({:.4}): the seed alone could rank \
                 them either way, none beats it on every parameter, and it is the cheaper to fit \
                 (its time goes to records)",
                p.design, p.score, b.design, b.score
            )?;
        }
        for (i, c) in self.candidates.iter().enumerate() {
            let mark = if i == self.best { "*" } else { " " };
            let rmse: Vec<String> = c.rmse.iter().map(|r| format!("{r:.4e}")).collect();
            match &c.status {
                Status::Scored => writeln!(
                    f,
                    " {mark} {:<28} score {:.4}  RMSE [{}]  {:.1} s on {} rows{}",
                    c.design,
                    c.score,
                    rmse.join(", "),
                    c.seconds,
                    c.fit_rows,
                    c.trained_by
                        .as_ref()
                        .map_or_else(String::new, |t| format!("; {t}"))
                )?,
                status => writeln!(f, " {mark} {:<28} {status}", c.design)?,
            }
        }
        Ok(())
    }
}

impl AutoOutcome {
    /// A final fit the deadline stopped, or one on fewer records than the
    /// chart's.
    fn fmt_shortened_fit(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let fitted_rows = self.final_fit.rows();
        if self.final_fit.stopped() {
            let anew_shipped = matches!(
                self.final_fit,
                FinalFit::Compared { fits, .. } if fits.rival < fits.further
            );
            writeln!(
                f,
                "(the winner's final fit on {fitted_rows} records was stopped at the time budget's \
                 end: it ships {})",
                if anew_shipped {
                    "the fit anew as far as it got, better on the added records than the one \
                     trained further"
                } else {
                    "trained as far as it got from the fit it was scored with"
                }
            )
        } else if !matches!(self.final_fit, FinalFit::Compared { .. })
            // The steps train the shipped fit further on every record
            // they add; their lines say how far.
            && self.steps.is_empty()
            && fitted_rows < self.simulations - self.failures
        {
            writeln!(
                f,
                "(the time budget left no room to refit the winner on the whole chart: it ships \
                 fitted on {} of its {} records)",
                fitted_rows, self.simulations
            )
        } else {
            Ok(())
        }
    }

    /// What round 3 measured: the seed's effect, the learning curve's last
    /// step, the fit time's growth.
    fn fmt_round_three(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let [own, others @ ..] = self.seed_scores.as_slice()
            && !others.is_empty()
        {
            let (low, high) = others
                .iter()
                .fold((*own, *own), |(l, h), s| (l.min(*s), h.max(*s)));
            let listed: Vec<String> = others.iter().map(|s| format!("{s:.4}")).collect();
            writeln!(
                f,
                "the round-2 winner scores {own:.4} at the run's seed and {} at two others: \
                 the seed moves it by {:.1}%",
                listed.join(" and "),
                100.0 * (high - low) / own.max(f64::MIN_POSITIVE)
            )?;
        }
        if let (Some((rows, half)), Some(own)) = (self.half_rows, self.seed_scores.first()) {
            writeln!(
                f,
                "on half its records ({rows}) the round-2 winner scores {half:.4} against \
                 {own:.4}: more records would {}",
                // Beyond what the seed alone moves a score by.
                if half > 1.03 * own {
                    "pay"
                } else if more_records_pay(half, *own) {
                    "pay a little"
                } else if self.steps.is_empty() {
                    "not pay"
                } else {
                    "not pay, by this trial alone (the steps below tried them, each kept only \
                     where it paid)"
                }
            )?;
        }
        if self.half_rows.is_none() && (self.added_simulations > 0 || !self.steps.is_empty()) {
            writeln!(
                f,
                "no time was left to score the winner on half its records: more records were \
                 tried, each fit kept only where it scored better on records it did not train on"
            )?;
        }
        if let Some(exponent) = self.rows_exponent {
            writeln!(
                f,
                "its fit time grows as rows^{exponent:.2} (half its rows and all of them, timed alone)"
            )?;
        }
        Ok(())
    }

    /// The records added for the final fit, and its two fits compared.
    fn fmt_final_fit(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.added_simulations == 0
            && let FinalFit::TrainedFurther {
                rows,
                stopped: false,
            } = self.final_fit
        {
            writeln!(
                f,
                "the winner's final fit: trained further from its scored fit on {rows} records"
            )?;
        }
        let stepped: usize = self.steps.iter().map(|s| s.simulations).sum();
        if self.added_simulations > stepped {
            let rows = self.final_fit.rows();
            let of_all = of_the_chart(&self.final_fit, self.simulations, self.failures);
            writeln!(
                f,
                "so the winner's final fit took {} more simulations: fitted on {rows} \
                 records{of_all}",
                self.added_simulations - stepped,
            )?;
        }
        if let FinalFit::Compared {
            fits:
                FinalFits {
                    compared,
                    further,
                    rival,
                    rival_of,
                    rival_anew,
                },
            ..
        } = self.final_fit
        {
            let rival_design = match rival_of {
                RivalNetwork::Candidate(i) => self
                    .candidates
                    .get(i)
                    .map_or_else(String::new, |c| format!(" as {}", c.design)),
                RivalNetwork::SizedForRows { width, members } => {
                    format!(
                        " as MLP [{width}, {width}] (its {members} restarts averaged), sized for \
                         the records"
                    )
                }
            };
            writeln!(
                f,
                "on the last {compared} added records, seen by no fit, the winner trained further \
                 scores {further:.4} and {}{rival_design} {rival:.4}: the {} ships",
                if rival_anew {
                    "fitted anew"
                } else {
                    "trained further"
                },
                match (rival < further, rival_anew) {
                    (true, _) if matches!(rival_of, RivalNetwork::SizedForRows { .. }) => {
                        "network sized for the records"
                    }
                    (true, true) => "fit anew",
                    (true, false) => "larger network",
                    (false, _) => "fit trained further",
                }
            )?;
        }
        for step in &self.steps {
            writeln!(
                f,
                "with time left, {} more simulations: trained further on {} records, it scores \
                 {:.4} against {:.4} before on the last {} added{}: {}",
                step.simulations,
                step.rows,
                step.after,
                step.before,
                step.compared,
                if step.stopped {
                    " (stopped at the deadline)"
                } else {
                    ""
                },
                if step.kept() {
                    "kept"
                } else {
                    "the fit before ships"
                }
            )?;
        }
        Ok(())
    }
}

/// How the winner's shipped network was fitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FinalFit {
    /// The fit the winner was scored with ships: a final fit would have
    /// had no more rows (the search scored it on the whole chart, or the
    /// time budget left no room for more).
    AsScored {
        /// The rows it was fitted on.
        rows: usize,
    },
    /// Fitted anew on more rows (no time budget to stop it).
    Anew {
        /// The rows it was fitted on.
        rows: usize,
    },
    /// Trained further from the fit it was scored with, on more rows.
    TrainedFurther {
        /// The rows it was trained on.
        rows: usize,
        /// Whether the time budget's end stopped it: it ships trained as
        /// far as it got, no worse than its start on its held-out rows.
        stopped: bool,
    },
    /// Trained further and a rival fit on the same rows, the better on
    /// added records seen by neither shipped.
    Compared {
        /// The rows both were trained on.
        rows: usize,
        /// Their scores.
        fits: FinalFits,
        /// Whether the time budget's end stopped the one that ships.
        stopped: bool,
    },
}

impl FinalFit {
    /// The rows the shipped network was fitted on.
    pub fn rows(&self) -> usize {
        match *self {
            Self::AsScored { rows }
            | Self::Anew { rows }
            | Self::TrainedFurther { rows, .. }
            | Self::Compared { rows, .. } => rows,
        }
    }

    /// Whether the time budget's end stopped the shipped fit.
    pub fn stopped(&self) -> bool {
        match *self {
            Self::AsScored { .. } | Self::Anew { .. } => false,
            Self::TrainedFurther { stopped, .. } | Self::Compared { stopped, .. } => stopped,
        }
    }
}

/// One step of the anytime final fit: where the final fit ended before
/// the deadline, more records are simulated and the shipped fit trained
/// further on them, kept only where it then scores better on added
/// records it did not train on.
///
/// ```
/// let step = twostage::auto::Continuation {
///     simulations: 4000, rows: 14000, compared: 800, before: 0.042, after: 0.040, stopped: false,
/// };
/// assert!(step.kept());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Continuation {
    /// Simulations of this step (any that failed included).
    pub simulations: usize,
    /// Records the fit was trained further on: all but the compared ones.
    pub rows: usize,
    /// The last added records, left out of its training, on which it was
    /// compared with the fit before the step.
    pub compared: usize,
    /// The fit before the step, scored on the compared records.
    pub before: f64,
    /// The fit trained further, scored on them.
    pub after: f64,
    /// Whether the deadline stopped it.
    pub stopped: bool,
}

impl Continuation {
    /// Whether the step's fit ships in place of the one before it.
    pub fn kept(&self) -> bool {
        self.after < self.before
    }
}

/// The network of the final fit's rival.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RivalNetwork {
    /// A candidate's (by index): a larger one, or the winner's own.
    Candidate(usize),
    /// Two hidden layers of `width` units, as wide as the final fit's
    /// records afford, on the winner's stage 1, trained by Adam, its
    /// restarts averaged, as many as the time left afforded.
    SizedForRows {
        /// The units of each hidden layer.
        width: usize,
        /// The networks averaged.
        members: usize,
    },
}

/// The winner's two final fits under a time budget, where both ran: the
/// winner trained further from its scored fit, and a rival (its network
/// anew, a larger candidate's network, or on many records a network sized
/// for them), scored on added records.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FinalFits {
    /// The added records (seen by neither fit) they were scored on.
    pub compared: usize,
    /// The held-out score of the winner trained further from its fit.
    pub further: f64,
    /// The held-out score of the rival fit.
    pub rival: f64,
    /// Whose network the rival is: a network sized for many records, a
    /// larger candidate's where the records grew well past the winner's,
    /// or the winner's own.
    pub rival_of: RivalNetwork,
    /// Whether the rival was fitted anew (else trained further from its
    /// candidate's scored fit).
    pub rival_anew: bool,
}

/// Where the final fit's rows fall short of the chart's kept records,
/// how many of the chart's `simulations` it fitted and why (the file's m
/// counts them all); else nothing.
fn of_the_chart(final_fit: &FinalFit, simulations: usize, failures: usize) -> String {
    let (rows, kept) = (final_fit.rows(), simulations - failures);
    if rows >= kept {
        return String::new();
    }
    let why = match final_fit {
        FinalFit::Compared { .. } => "held out to compare the fits",
        _ => "not reached by the fit",
    };
    format!(
        " of the {simulations} training records (inspect's m; the other {} {why})",
        kept - rows
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fitted_rows_short_of_the_chart_are_said_beside_its_m() {
        let anew = FinalFit::Anew { rows: 5466 };
        assert_eq!(of_the_chart(&anew, 5466, 0), "");
        assert_eq!(
            of_the_chart(&anew, 6295, 9),
            " of the 6295 training records (inspect's m; the other 820 not reached by the fit)"
        );
        let compared = FinalFit::Compared {
            rows: 5466,
            fits: FinalFits {
                compared: 829,
                further: 0.02,
                rival: 0.021,
                rival_of: RivalNetwork::Candidate(0),
                rival_anew: true,
            },
            stopped: false,
        };
        assert!(of_the_chart(&compared, 6295, 0).ends_with("829 held out to compare the fits)"));
    }

    #[test]
    fn more_records_are_tried_unless_the_learning_curve_was_measured_flat() {
        // Measured: as the half-rows trial says.
        assert!(more_records_to_try(Some((1000, 0.040)), Some(0.038)));
        assert!(!more_records_to_try(Some((1000, 0.038)), Some(0.038)));
        assert!(!more_records_to_try(Some((1000, 0.037)), Some(0.038)));
        // Not measured (round 3 had no time, or its trial was cut): tried,
        // the anytime steps judge them.
        assert!(more_records_to_try(None, Some(0.038)));
        assert!(more_records_to_try(None, None));
        assert!(more_records_to_try(Some((1000, 0.037)), None));
    }
}
