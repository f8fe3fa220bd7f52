//! A stream's finish that draws: the estimate, then the posterior's
//! draws given the same features. Apart from both the stream and the
//! posterior, so that neither module reaches into the other.

use crate::error::Error;
use crate::stream::{Assessment, Layout, Parts, STATUS_WORDS, Stream};

impl Stream<'_, '_, '_> {
    /// [`Stream::finish`], then draws of the parameters from the
    /// posterior the blob carries, given the same features, into `draws`
    /// (draws x parameters, row after row: as many draws as it holds
    /// rows; each inside its prior's support). The random numbers are the
    /// ChaCha8 stream `record` of `seed`'s posterior key, the host's for
    /// record number `record` of `estimate --samples N --seed seed` (and
    /// of Python's `Estimator.sample`): the same draws wherever the
    /// features agree, with no allocation. A record out of distribution
    /// still gets its draws; the assessment flags it as `finish` does.
    ///
    /// # Errors
    /// [`Error::NoPosterior`] for a blob without one,
    /// [`Error::NotBuiltIn`] for a build without the feature `posterior`,
    /// [`Error::DrawCount`] for `draws` not a whole number of draws, and
    /// those of [`Stream::finish`].
    pub fn finish_with_draws(
        &mut self,
        theta: &mut [f64],
        half_widths: &mut [f64],
        draws: &mut [f64],
        seed: u64,
        record: u64,
    ) -> Result<Assessment, Error> {
        let e = self.estimator;
        let posterior = e.posterior().ok_or(if e.has_posterior() {
            Error::NotBuiltIn {
                feature: "posterior",
            }
        } else {
            Error::NoPosterior
        })?;
        if !draws.len().is_multiple_of(e.n_parameters()) {
            return Err(Error::DrawCount {
                parameters: e.n_parameters(),
            });
        }
        let assessment = self.finish(theta, half_widths)?;
        // The posterior's words close the workspace: cut them off first,
        // so that the parts every finish splits are split as they are.
        let layout = Layout::of(e, self.window);
        let own_at = layout.total - STATUS_WORDS - layout.posterior;
        let (work, own) = self.work.split_at_mut(own_at.min(self.work.len()));
        let own = own.get_mut(..layout.posterior).unwrap_or_default();
        let Parts {
            features, scratch, ..
        } = layout.split(work);
        posterior.draw(features, (seed, record), (own, scratch), draws)?;
        Ok(assessment)
    }
}
