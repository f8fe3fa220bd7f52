//! Which shard of how many, from an argument or a batch system's
//! environment (Slurm, Kubernetes).

use crate::InvalidSetting;
use std::ops::Range;

use crate::error::{Error, Result};

/// Which shard of how many.
///
/// ```
/// use twostage_sources::ShardIndex;
/// let shard: ShardIndex = "2/4".parse()?;
/// // Records [2 m / 4, 3 m / 4): the four shards cover 0..10 exactly.
/// assert_eq!(shard.range(10), 5..7);
/// # Ok::<(), twostage_sources::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShardIndex {
    /// Which one, from 0.
    pub index: usize,
    /// How many.
    pub count: usize,
}

impl std::str::FromStr for ShardIndex {
    type Err = Error;
    fn from_str(text: &str) -> Result<Self> {
        let bad = || {
            Error::InvalidSetting(InvalidSetting {
                name: "shard",
                value: text.to_string(),
                reason: "give I/N with 0 <= I < N (shard I of N, from 0), or auto (Slurm's \
                     SLURM_ARRAY_TASK_ID and SLURM_ARRAY_TASK_COUNT) or auto/N (the index from \
                     SLURM_ARRAY_TASK_ID or Kubernetes' JOB_COMPLETION_INDEX)"
                    .into(),
            })
        };
        let (i, n) = text.split_once('/').ok_or_else(bad)?;
        let (index, count) = (
            i.trim().parse::<usize>().map_err(|_| bad())?,
            n.trim().parse::<usize>().map_err(|_| bad())?,
        );
        if index >= count {
            return Err(bad());
        }
        Ok(Self { index, count })
    }
}

impl ShardIndex {
    /// Parse `I/N`, or read the index (and count) from a batch system's
    /// environment: `auto` takes Slurm's `SLURM_ARRAY_TASK_ID` and
    /// `SLURM_ARRAY_TASK_COUNT` (an array `0-(N-1)`); `auto/N` takes the
    /// index from `SLURM_ARRAY_TASK_ID` or Kubernetes' indexed-job
    /// `JOB_COMPLETION_INDEX`, so that an array re-submitted for some
    /// shards only (`sbatch --array=2,5`) still knows N.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming what is missing or malformed.
    pub fn resolve(text: &str, env: impl Fn(&str) -> Option<String>) -> Result<Self> {
        let Some(rest) = text.strip_prefix("auto") else {
            return text.parse();
        };
        let number = |name: &str| -> Result<Option<usize>> {
            env(name)
                .map(|v| {
                    v.trim().parse::<usize>().map_err(|_| {
                        Error::InvalidSetting(InvalidSetting {
                            name: "shard",
                            value: format!("{name}={v}"),
                            reason: "is not a whole number".into(),
                        })
                    })
                })
                .transpose()
        };
        let slurm = number("SLURM_ARRAY_TASK_ID")?;
        let (index, count) = match rest.strip_prefix('/') {
            None if rest.is_empty() => (slurm, number("SLURM_ARRAY_TASK_COUNT")?),
            Some(n) => (
                slurm.or(number("JOB_COMPLETION_INDEX")?),
                Some(n.trim().parse::<usize>().map_err(|_| {
                    Error::InvalidSetting(InvalidSetting {
                        name: "shard",
                        value: text.into(),
                        reason: "auto/N takes the number of shards N".into(),
                    })
                })?),
            ),
            None => return text.parse(),
        };
        match (index, count) {
            (Some(index), Some(count)) => format!("{index}/{count}").parse(),
            _ => Err(Error::InvalidSetting(InvalidSetting {
                name: "shard",
                value: text.into(),
                reason: "no array task in the environment (SLURM_ARRAY_TASK_ID and \
                         SLURM_ARRAY_TASK_COUNT, or JOB_COMPLETION_INDEX with auto/N): run it \
                         as an array job, or give I/N"
                    .into(),
            })),
        }
    }

    /// The records of a chart of `m` that this shard simulates.
    pub fn range(&self, m: usize) -> Range<usize> {
        // In u128: an index and a chart of a few billion each overflow usize.
        let at = |i: usize| {
            let bound = i as u128 * m as u128 / self.count.max(1) as u128;
            usize::try_from(bound).unwrap_or(m)
        };
        at(self.index)..at(self.index + 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_ranges_cover_every_record_once() {
        for m in [0usize, 1, 7, 100, 1001] {
            for n in 1..=9 {
                let mut next = 0;
                for index in 0..n {
                    let r = ShardIndex { index, count: n }.range(m);
                    assert_eq!(r.start, next, "m {m}, n {n}");
                    next = r.end;
                }
                assert_eq!(next, m);
            }
        }
        // Counts whose products overflow 64 bits: the exact bounds.
        let huge = ShardIndex {
            index: (1 << 40) - 1,
            count: 1 << 40,
        };
        assert_eq!(huge.range(1 << 40), (1 << 40) - 1..1 << 40);
        let last = ShardIndex {
            index: usize::MAX - 1,
            count: usize::MAX,
        };
        assert_eq!(last.range(1_000_000), 999_999..1_000_000);
    }

    #[test]
    fn shard_indices_come_from_slurm_or_kubernetes() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                vars.iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| v.to_string())
            }
        };
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        // An array re-submitted for shard 5 alone: Slurm counts 1 task.
        let again = env(&[
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_COUNT", "1"),
        ]);
        assert!(ShardIndex::resolve("auto", again).is_err(), "5 of 1");
        assert_eq!(
            ShardIndex::resolve("auto/8", again).unwrap(),
            ShardIndex { index: 5, count: 8 }
        );
        assert_eq!(
            ShardIndex::resolve("auto", slurm).unwrap(),
            ShardIndex { index: 2, count: 4 }
        );
        let k8s = env(&[("JOB_COMPLETION_INDEX", "3")]);
        assert_eq!(
            ShardIndex::resolve("auto/8", k8s).unwrap(),
            ShardIndex { index: 3, count: 8 }
        );
        assert!(ShardIndex::resolve("auto", k8s).is_err(), "no count");
        assert!(ShardIndex::resolve("auto/2", k8s).is_err(), "index 3 of 2");
        assert!(ShardIndex::resolve("auto", env(&[])).is_err());
        assert_eq!(
            ShardIndex::resolve("1/3", env(&[])).unwrap(),
            ShardIndex { index: 1, count: 3 }
        );
        for bad in ["3/3", "1", "a/2", "-1/2", "1/0"] {
            assert!(bad.parse::<ShardIndex>().is_err(), "{bad}");
        }
    }
}
