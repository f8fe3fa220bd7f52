//! Parameters held at known values: an engineer who knows the mass from a
//! datasheet fixes it, and the model left has the other parameters only.
//! The model file is not touched; the estimator trained on the smaller
//! model records what was fixed, and every request through it simulates
//! with those values.

use twostage_kernels::mixture::Support;

use crate::error::{InvalidSetting, Result, SimError};
use crate::simulator::{Block, Capabilities, Conditions, ModelSpec, Simulator};
use crate::{ExperimentRng, IoData, Prior};

/// One parameter held at a value.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FixedValue {
    /// The parameter's name, as the model names it.
    pub name: String,
    /// The value it is held at.
    pub value: f64,
}

/// Parameters held at values, in the order given (`--fix NAME=VALUE`,
/// repeatable; Python's `fix={name: value}`).
///
/// ```
/// use twostage_models::{FixedValues, PacejkaCar, Simulator};
/// let fixed = FixedValues::parse(&["pK2=-1.1"])?;
/// assert_eq!(fixed.to_string(), "pK2 = -1.1");
/// // Checked against the model: a name it does not have is refused,
/// // naming those it has.
/// let car = PacejkaCar::new();
/// assert_eq!(fixed.positions(car.spec())?, vec![1]);
/// let e = FixedValues::parse(&["mass=1500"])?.positions(car.spec()).unwrap_err();
/// assert!(e.to_string().contains("pK1, pK2"), "{e}");
/// assert!(FixedValues::parse(&["pK2"]).is_err());
/// // A value outside the prior's support is refused, naming it.
/// let e = FixedValues::parse(&["pK2=0.31"])?.positions(car.spec()).unwrap_err();
/// assert!(e.to_string().contains("[-1.22, -0.98]"), "{e}");
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FixedValues(Vec<FixedValue>);

impl FixedValues {
    /// Parse `NAME=VALUE` pairs.
    ///
    /// # Errors
    /// A pair without `=`, an empty name, a value that is not a finite
    /// number, or a name given twice ([`SimError::InvalidSetting`] named
    /// `fix`, quoting the pair).
    pub fn parse<T: AsRef<str>>(pairs: &[T]) -> Result<Self> {
        let mut values: Vec<FixedValue> = Vec::with_capacity(pairs.len());
        for pair in pairs {
            let pair = pair.as_ref();
            let refuse = |reason: String| {
                SimError::InvalidSetting(InvalidSetting {
                    name: "fix",
                    value: pair.to_string(),
                    reason,
                })
            };
            let Some((name, value)) = pair.split_once('=') else {
                return Err(refuse(
                    "give NAME=VALUE, a parameter's name and the value it is held at, such as \
                     pK2=0.31"
                        .into(),
                ));
            };
            let name = name.trim();
            if name.is_empty() {
                return Err(refuse("the parameter's name before '=' is empty".into()));
            }
            let value = value
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| refuse(format!("'{}' is not a finite number", value.trim())))?;
            if values.iter().any(|v| v.name == name) {
                return Err(refuse(format!("{name} is fixed twice: give it once")));
            }
            values.push(FixedValue {
                name: name.to_string(),
                value,
            });
        }
        Ok(Self(values))
    }

    /// The pairs, as `(name, value)`.
    ///
    /// # Errors
    /// As [`FixedValues::parse`].
    pub fn from_pairs<'a>(pairs: impl IntoIterator<Item = (&'a str, f64)>) -> Result<Self> {
        let text: Vec<String> = pairs
            .into_iter()
            .map(|(name, value)| format!("{name}={value:?}"))
            .collect();
        Self::parse(&text)
    }

    /// Whether nothing is fixed.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The values held, in the order given.
    pub fn values(&self) -> &[FixedValue] {
        &self.0
    }

    /// The position in the model's theta of each value held, in the order
    /// given.
    ///
    /// # Errors
    /// A name the model does not have (naming those it has), a value
    /// outside its prior's support, or every parameter fixed (nothing
    /// left to estimate).
    pub fn positions(&self, spec: &ModelSpec) -> Result<Vec<usize>> {
        let names = spec.param_names();
        let mut positions = Vec::with_capacity(self.0.len());
        for fixed in &self.0 {
            let refuse = |reason: String| {
                SimError::InvalidSetting(InvalidSetting {
                    name: "fix",
                    value: format!("{}={}", fixed.name, fixed.value),
                    reason,
                })
            };
            let Some(j) = names.iter().position(|n| *n == fixed.name) else {
                return Err(refuse(format!(
                    "the model '{}' has no parameter '{}'; its parameters are {}",
                    spec.name(),
                    fixed.name,
                    names.join(", ")
                )));
            };
            let outside = match spec.prior().marginals()[j].support() {
                Support::Real => None,
                Support::Positive => (fixed.value <= 0.0).then(|| "positive values".to_string()),
                Support::Interval { low, high } => (!(low..=high).contains(&fixed.value))
                    .then(|| format!("values in [{low}, {high}]")),
            };
            if let Some(support) = outside {
                return Err(refuse(format!(
                    "{}'s prior holds {support} only: the model was not written for this value",
                    fixed.name
                )));
            }
            positions.push(j);
        }
        if positions.len() == names.len() {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "fix",
                value: self.to_string(),
                reason: "every parameter is fixed: leave at least one to estimate".into(),
            }));
        }
        Ok(positions)
    }
}

impl std::fmt::Display for FixedValues {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let parts: Vec<String> = self
            .0
            .iter()
            .map(|v| format!("{} = {}", v.name, v.value))
            .collect();
        f.write_str(&parts.join(", "))
    }
}

/// A model with some parameters held at values: its spec names the others
/// (their priors, in the model's order) and every experiment runs the
/// model at the whole vector, the held values put back in their places.
///
/// ```
/// use twostage_models::{experiment_rng, FixedValues, PacejkaCar, Simulator, WithFixed};
/// let car = PacejkaCar::new();
/// let fixed = WithFixed::new(&car, &FixedValues::parse(&["pK2=-1.1"])?)?;
/// assert_eq!(fixed.spec().param_names(), ["pK1".to_string()]);
/// let (mut a, mut b) = (car.spec().new_record(), car.spec().new_record());
/// let pk1 = (car.prior().lower()[0] + car.prior().upper()[0]) / 2.0;
/// fixed.simulate(&[pk1], &mut experiment_rng(1, 0), &mut a)?;
/// car.simulate(&[pk1, -1.1], &mut experiment_rng(1, 0), &mut b)?;
/// assert_eq!(a, b);
/// # Ok::<(), twostage_models::SimError>(())
/// ```
pub struct WithFixed<S> {
    inner: S,
    spec: ModelSpec,
    /// The whole theta with the held values in place; the free ones are
    /// written at `free`.
    template: Vec<f64>,
    free: Vec<usize>,
}

impl<S: Simulator> WithFixed<S> {
    /// `inner` with `fixed` held.
    ///
    /// # Errors
    /// As [`FixedValues::positions`].
    pub fn new(inner: S, fixed: &FixedValues) -> Result<Self> {
        let full = inner.spec();
        let held = fixed.positions(full)?;
        let mut template = full.prior().lower().to_vec();
        for (&j, v) in held.iter().zip(fixed.values()) {
            template[j] = v.value;
        }
        let free: Vec<usize> = (0..full.n_params()).filter(|j| !held.contains(j)).collect();
        let prior = Prior::new(free.iter().map(|&j| full.prior().marginals()[j]).collect())?
            .with_sampling(full.prior().sampling());
        let spec = full.with_parameters(&free, prior);
        Ok(Self {
            inner,
            spec,
            template,
            free,
        })
    }

    /// The model's whole theta for the free parameters `theta`.
    pub fn whole(&self, theta: &[f64]) -> Vec<f64> {
        let mut whole = self.template.clone();
        for (&j, &v) in self.free.iter().zip(theta) {
            whole[j] = v;
        }
        whole
    }

    fn check(&self, theta: &[f64]) -> Result<()> {
        if theta.len() == self.free.len() {
            Ok(())
        } else {
            Err(SimError::WrongParameterCount {
                expected: self.free.len(),
                got: theta.len(),
                names: self.spec.param_names().join(", "),
            })
        }
    }
}

impl<S: Simulator> Simulator for WithFixed<S> {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<()> {
        self.check(theta)?;
        self.inner
            .simulate_one(&self.whole(theta), rng, conditions, out)
    }

    fn capabilities(&self) -> Capabilities {
        self.inner.capabilities()
    }

    fn shared_input(&self) -> Option<IoData> {
        self.inner.shared_input()
    }

    fn batch_size(&self) -> usize {
        self.inner.batch_size()
    }

    fn simulate_block(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        block: Block<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        if let Some(e) = thetas.iter().find_map(|t| self.check(t).err()) {
            return thetas.iter().map(|_| Err(e.clone())).collect();
        }
        let wholes: Vec<Vec<f64>> = thetas.iter().map(|t| self.whole(t)).collect();
        let views: Vec<&[f64]> = wholes.iter().map(Vec::as_slice).collect();
        self.inner.simulate_block(&views, rngs, block, outs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Benchmark, PacejkaCar, experiment_rng};

    fn refused(pairs: &[&str], spec: &ModelSpec) -> String {
        match FixedValues::parse(pairs).and_then(|f| f.positions(spec)) {
            Err(e) => e.to_string(),
            Ok(p) => panic!("{pairs:?} accepted at {p:?}"),
        }
    }

    #[test]
    fn every_malformed_or_impossible_fix_is_refused_by_its_pair() {
        let car = PacejkaCar::new();
        let spec = car.spec();
        assert!(refused(&["pK2:-1.1"], spec).contains("give NAME=VALUE"));
        assert!(refused(&["=-1.1"], spec).contains("name before '=' is empty"));
        assert!(refused(&["pK2=abc"], spec).contains("'abc' is not a finite number"));
        assert!(refused(&["pK2=inf"], spec).contains("'inf' is not a finite number"));
        assert!(refused(&["pK2=-1.1", "pK2=-1.0"], spec).contains("fixed twice"));
        let all = refused(&["pK1=-30", "pK2=-1.1"], spec);
        assert!(all.contains("every parameter is fixed"), "{all}");
        // The benchmark's one parameter cannot be fixed either.
        assert!(refused(&["theta=0.1"], Benchmark::new().spec()).contains("every parameter"));
    }

    /// A block goes to the model as whole vectors, each experiment's
    /// held values in place: the records of the model run one by one.
    #[test]
    fn a_block_is_the_model_s_experiments_at_the_whole_vectors() {
        let car = PacejkaCar::new();
        let fixed = WithFixed::new(&car, &FixedValues::parse(&["pK2=-1.05"]).unwrap()).unwrap();
        let (lo, hi) = (car.prior().lower()[0], car.prior().upper()[0]);
        let free = [[lo + 0.2 * (hi - lo)], [lo + 0.7 * (hi - lo)]];
        let views: Vec<&[f64]> = free.iter().map(|t| t.as_slice()).collect();
        let mut rngs = [experiment_rng(3, 0), experiment_rng(3, 1)];
        let mut outs = [car.spec().new_record(), car.spec().new_record()];
        let results = fixed.simulate_batch(&views, &mut rngs, &mut outs);
        assert!(results.iter().all(Result::is_ok), "{results:?}");
        for (k, theta) in free.iter().enumerate() {
            let mut expected = car.spec().new_record();
            car.simulate(
                &[theta[0], -1.05],
                &mut experiment_rng(3, k as u64),
                &mut expected,
            )
            .unwrap();
            assert_eq!(outs[k], expected, "experiment {k}");
        }
        // A vector of the whole model's length is refused, not truncated.
        let whole: [&[f64]; 1] = [&[-30.0, -1.05]];
        let results = fixed.simulate_batch(&whole, &mut rngs[..1], &mut outs[..1]);
        assert!(matches!(
            results[0],
            Err(SimError::WrongParameterCount {
                expected: 1,
                got: 2,
                ..
            })
        ));
    }
}
