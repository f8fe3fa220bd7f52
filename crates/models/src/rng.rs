//! Per-experiment random streams.
//!
//! Experiment `i` of a chart with seed `s` draws everything random (its
//! parameter vector, its input and its noise) from ChaCha8 streams that
//! depend only on `(s, i)`. Charts are therefore bitwise identical whatever
//! the thread count, the order in which experiments run, or how they are
//! split into shards (docs/decisions/004-random-streams.md).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The random generator handed to [`Simulator::simulate`](crate::Simulator::simulate).
pub type ExperimentRng = ChaCha8Rng;

/// What a stream is used for. Each purpose gets its own ChaCha key, so the
/// draws of one purpose never shift the draws of another.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum StreamPurpose {
    /// Input signal and noise of one simulation.
    Simulation,
    /// The parameter vector of one experiment.
    Parameter,
    /// Design-wide randomness (Latin hypercube permutations, Sobol shifts).
    Design,
    /// The posterior's draws given one record.
    Posterior,
}

impl StreamPurpose {
    fn tag(self) -> u64 {
        match self {
            Self::Simulation => 0x5349_4d55_4c41_5445, // "SIMULATE"
            Self::Parameter => 0x5041_5241_4d45_5445,  // "PARAMETE"
            Self::Design => 0x4445_5349_474e_0000,     // "DESIGN"
            Self::Posterior => twostage_kernels::random::POSTERIOR_TAG,
        }
    }
}

/// The stream of experiment `index` of the chart seeded with `seed`, for
/// one `purpose`.
///
/// ```
/// use twostage_models::{stream_rng, StreamPurpose};
/// use rand::Rng;
/// let a = stream_rng(7, 3, StreamPurpose::Simulation).next_u64();
/// let b = stream_rng(7, 3, StreamPurpose::Simulation).next_u64();
/// let c = stream_rng(7, 4, StreamPurpose::Simulation).next_u64();
/// assert_eq!(a, b);
/// assert_ne!(a, c);
/// ```
pub fn stream_rng(seed: u64, index: u64, purpose: StreamPurpose) -> ExperimentRng {
    // The key's expansion is the kernels' (SplitMix64), so that a
    // microcontroller's posterior draws read the host's stream.
    let mut rng = ChaCha8Rng::from_seed(twostage_kernels::random::stream_key(seed, purpose.tag()));
    rng.set_stream(index);
    rng
}

/// The simulation stream (input and noise) of experiment `index` of seed `seed`.
///
/// ```
/// use twostage_models::experiment_rng;
/// let rng = experiment_rng(42, 0);
/// assert_eq!(rng.get_stream(), 0);
/// ```
pub fn experiment_rng(seed: u64, index: u64) -> ExperimentRng {
    stream_rng(seed, index, StreamPurpose::Simulation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn purposes_and_seeds_give_distinct_streams() {
        let first = |seed, index, purpose| stream_rng(seed, index, purpose).next_u64();
        let base = first(1, 0, StreamPurpose::Simulation);
        assert_ne!(base, first(1, 0, StreamPurpose::Parameter));
        assert_ne!(base, first(1, 0, StreamPurpose::Design));
        assert_ne!(base, first(2, 0, StreamPurpose::Simulation));
        assert_ne!(base, first(1, 1, StreamPurpose::Simulation));
    }
}
