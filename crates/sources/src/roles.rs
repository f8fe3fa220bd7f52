//! The roles of a training run's records, designed in one place whatever
//! their source: which records train, which calibrate the intervals and
//! which validate, and, for simulated records, which parameters they are
//! drawn at.

use serde::{Deserialize, Serialize};
use twostage_models::{Design, Prior, Sampling, StreamPurpose, random_permutation, stream_rng};

use crate::error::Result;

/// Offsets that give the calibration and validation charts their own
/// streams, disjoint from the training chart of the same seed.
const CALIBRATION_SEED: u64 = 0x4341_4c49_4252_4154; // "CALIBRAT"
const VALIDATION_SEED: u64 = 0x5641_4c49_4441_5445; // "VALIDATE"

/// The three charts of a training run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ChartRole {
    /// The training chart, from the prior's own sampling.
    Training,
    /// The calibration chart of the intervals: i.i.d. uniform draws.
    Calibration,
    /// The validation chart of the report: i.i.d. uniform draws.
    Validation,
}

impl ChartRole {
    /// All three, in file order.
    pub const ALL: [ChartRole; 3] = [Self::Training, Self::Calibration, Self::Validation];

    /// A word for messages.
    pub fn label(self) -> &'static str {
        match self {
            Self::Training => "training",
            Self::Calibration => "calibration",
            Self::Validation => "validation",
        }
    }

    pub(crate) fn slot(self) -> usize {
        match self {
            Self::Training => 0,
            Self::Calibration => 1,
            Self::Validation => 2,
        }
    }

    /// The design of this chart of a run with `seed`: the training chart
    /// from `prior` as it samples, the calibration and validation charts
    /// i.i.d. uniform (Theorem 1 and the conformal guarantee assume
    /// independent draws) with streams of their own. One place, so that
    /// `train` and the shards draw the same experiments.
    ///
    /// # Errors
    /// An empty design or a malformed prior.
    pub fn design(self, prior: &Prior, count: usize, seed: u64) -> Result<Design> {
        let iid = || prior.clone().with_sampling(Sampling::Uniform);
        Ok(match self {
            Self::Training => prior.design(count, seed)?,
            Self::Calibration => iid().design(count, seed ^ CALIBRATION_SEED)?,
            Self::Validation => iid().design(count, seed ^ VALIDATION_SEED)?,
        })
    }
}

/// How many records each chart of a run holds, one count per
/// [`ChartRole`].
///
/// ```
/// use twostage_sources::{ChartRole, RoleCounts};
/// let counts = RoleCounts::new(800, 4000, 100);
/// assert_eq!(counts[ChartRole::Calibration], 4000);
/// assert_eq!(counts.total(), 4900);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct RoleCounts {
    /// Training records (simulations asked for, or the chart's left after
    /// the held-out ones).
    pub training: usize,
    /// Records that calibrate the intervals.
    pub calibration: usize,
    /// Records that validate the estimator.
    pub validation: usize,
}

impl RoleCounts {
    /// The counts of the training, calibration and validation charts.
    pub fn new(training: usize, calibration: usize, validation: usize) -> Self {
        Self {
            training,
            calibration,
            validation,
        }
    }

    /// All records of the run.
    pub fn total(&self) -> usize {
        self.training + self.calibration + self.validation
    }
}

impl std::ops::Index<ChartRole> for RoleCounts {
    type Output = usize;
    fn index(&self, role: ChartRole) -> &usize {
        match role {
            ChartRole::Training => &self.training,
            ChartRole::Calibration => &self.calibration,
            ChartRole::Validation => &self.validation,
        }
    }
}

/// Roles for the `m` records of one chart read from files: `validation`
/// and `calibration` of them held out by a seeded permutation (the first
/// ranks validate, the next calibrate), the rest train. Indexed by the
/// chart's row, so the order of its files never changes the roles.
pub(crate) fn held_out_roles(
    m: usize,
    validation: usize,
    calibration: usize,
    seed: u64,
) -> Vec<ChartRole> {
    let order = random_permutation(m, &mut stream_rng(seed, 0, StreamPurpose::Design));
    let mut roles = vec![ChartRole::Training; m];
    for (rank, &row) in order.iter().enumerate() {
        if rank < validation {
            roles[row as usize] = ChartRole::Validation;
        } else if rank < validation + calibration {
            roles[row as usize] = ChartRole::Calibration;
        }
    }
    roles
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn held_out_roles_count_and_depend_on_the_seed() {
        let roles = held_out_roles(100, 20, 30, 7);
        let count = |r: ChartRole| roles.iter().filter(|x| **x == r).count();
        assert_eq!(count(ChartRole::Validation), 20);
        assert_eq!(count(ChartRole::Calibration), 30);
        assert_eq!(count(ChartRole::Training), 50);
        assert_eq!(roles, held_out_roles(100, 20, 30, 7));
        assert_ne!(roles, held_out_roles(100, 20, 30, 8));
    }
}
