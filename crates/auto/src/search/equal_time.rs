//! Round 3's average of the winner's restarts against the single network
//! it averages, at equal final-fit time where the records grow.

use twostage_models::Simulator;

use super::{Search, final_fit};
use crate::EqualTime;

impl<S: Simulator + ?Sized> Search<'_, '_, S> {
    /// Where `chosen` is round 3's averaged network and the records grow
    /// under a deadline, its comparison with the network it averages at
    /// equal final-fit time: the final fit trains its pick further on
    /// more records, every member of an average but only the kept restart
    /// of the single network, so in the average's time the single network
    /// takes `members^(1 / exponent)` times the records (its cost growing
    /// as rows^exponent). Its score there is projected along its learning
    /// curve's last step (half its rows to all of them) as a power of the
    /// rows; where that beats the average's score, the single network
    /// ships. None where no such comparison applies or the average wins
    /// it.
    pub(crate) fn equal_time(&self, chosen: usize) -> Option<EqualTime> {
        let (single, averaged) = self.averaged_twin?;
        if chosen != averaged || !self.plan.grows || self.plan.deadline.is_none() {
            return None;
        }
        let (_, half) = self.half_rows?;
        let own = self.report(single).score;
        let members = final_fit::network_members(&self.candidates[averaged].network) as f64;
        let records_factor = members.powf(1.0 / self.cost_exponent());
        let projected = projected_score((half, own), records_factor);
        (projected < self.report(averaged).score).then_some(EqualTime {
            single,
            averaged,
            projected,
            records_factor,
        })
    }
}

/// A score of `own` on some rows and `half` on half of them, projected
/// onto `factor` times the rows as a power of the rows through the two
/// (a learning curve that stopped falling stays where it is).
pub(crate) fn projected_score((half, own): (f64, f64), factor: f64) -> f64 {
    let per_doubling = (own / half).min(1.0);
    if !(per_doubling.is_finite() && factor >= 1.0) {
        return own;
    }
    own * per_doubling.powf(factor.log2())
}
