//! Round 3's learned rival: the best stage 1 scored so far with a summary
//! network after it, where the records' inputs differ in kind.

use std::time::Instant;

use twostage_models::Simulator;

use super::Search;
use crate::candidates::with_learned;

impl<S: Simulator + ?Sized> Search<'_, '_, S> {
    /// Round 3's last rival, where the records' inputs differ in kind:
    /// the best of the winner and its rivals just scored (candidates from
    /// `first_rival` on, with the winner's network), with a summary network
    /// after its stage 1, trained on the same `rows`. Its epochs take a
    /// share of the time the others left ([`LEARNED_SHARE`]).
    pub(super) fn learned_rival(
        &mut self,
        best: usize,
        first_rival: usize,
        rows: usize,
        limit: Option<(Instant, f64)>,
    ) {
        let network = self.candidates[best].network.clone();
        let base = std::iter::once(best)
            .chain(first_rival..self.candidates.len())
            .filter(|&i| {
                self.candidates[i].network == network
                    && self.candidates[i].report.status.is_scored()
            })
            .min_by(|&a, &b| {
                self.candidates[a]
                    .report
                    .score
                    .total_cmp(&self.candidates[b].report.score)
            })
            .and_then(|i| self.candidates[i].fitted.as_ref().map(|(c, _)| c.clone()));
        let Some(learned) = base.and_then(|c| with_learned(&c, &self.plan.chart.records[..rows]))
        else {
            return;
        };
        self.plan.tell(3, 0, 1, &learned, &network);
        let (report, outcome) = self.plan.evaluate(&learned, &network, rows, limit, 3, 0);
        self.record_timed_alone(report, outcome, network);
    }
}
