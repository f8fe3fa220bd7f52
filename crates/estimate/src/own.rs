//! A record's own parameters (`per_record = true` in a model file: an
//! initial state, a sensor offset) fitted to its first samples with the
//! plant's held, so that a plant estimated on one record predicts another
//! that starts elsewhere (MATLAB's `findstates`).

use twostage_fit::TerminationReason;
use twostage_models::{FixedValues, IoData, Simulator, WithFixed};
use twostage_refine::{InvalidSetting, OutputError, RefineError, Refinement, SearchStarts};

/// What [`fit_own_parameters`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnFit {
    /// The whole parameter vector: the plant's as given, the record's own
    /// at their best fit to its first samples.
    pub theta: Vec<f64>,
    /// Why the best descent stopped.
    pub stop: TerminationReason,
    /// The distinct optima the search ended in.
    pub optima: usize,
}

/// The record's own parameters of `simulator`'s model (those its spec
/// marks per record) fitted by output error to the first `samples`
/// samples of `record`, every other parameter held at its value in
/// `theta`: a best-fit search from `theta`'s own values and `search`'s
/// starts over their prior.
///
/// ```
/// use twostage::refine::SearchStarts;
/// use twostage::{fit_own_parameters, sources::ModelFile};
/// let file = ModelFile::parse(r#"
///     [model]
///     name = "lag"
///     [[parameter]]
///     name = "a"
///     prior = { dist = "uniform", low = 0.5, high = 0.95 }
///     [[parameter]]
///     name = "x0"
///     prior = { dist = "uniform", low = -5.0, high = 5.0 }
///     per_record = true
///     [signals]
///     inputs = ["u"]
///     outputs = ["y"]
///     samples = 60
///     [input]
///     signal = "multisine"
///     band = [0.0, 0.2]
///     rms = [0.5, 1.0]
///     [equations]
///     time = "discrete"
///     states = [{ name = "x", initial = "x0", next = "a * x + u" }]
///     outputs = { y = "x" }
/// "#, "lag.toml")?;
/// let model = file.simulator()?;
/// // A record of a = 0.8 starting at x0 = 3, its input a ramp.
/// let u: Vec<f64> = (0..60).map(|t| (t % 7) as f64 / 7.0).collect();
/// let mut x = 3.0;
/// let y: Vec<f64> = u.iter().map(|u| { let y = x; x = 0.8 * x + u; y }).collect();
/// let record = twostage::models::IoData::siso(&u, &y)?;
/// let own = fit_own_parameters(model.as_ref(), &record, &[0.8, 0.0], 10, SearchStarts { from_prior: 2, seed: 0 })?;
/// assert_eq!(own.theta[0], 0.8);
/// assert!((own.theta[1] - 3.0).abs() < 1e-6);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// A model without own parameters, a count of samples outside `1..=`
/// the record's, held values outside their prior's support, or a model
/// that cannot run noise-free on the record's input.
pub fn fit_own_parameters<S: Simulator>(
    simulator: S,
    record: &IoData,
    theta: &[f64],
    samples: usize,
    search: SearchStarts,
) -> Result<OwnFit, RefineError> {
    let spec = simulator.spec();
    let refuse = |name: &'static str, value: String, reason: String| {
        RefineError::InvalidSetting(InvalidSetting {
            name,
            value,
            reason,
        })
    };
    if theta.len() != spec.n_params() {
        return Err(RefineError::Length {
            what: "the parameter vector",
            found: theta.len(),
            expected: spec.n_params(),
        });
    }
    let own = spec.per_record();
    if !own.contains(&true) {
        return Err(refuse(
            "own parameters",
            spec.name().to_string(),
            format!(
                "none of {}'s parameters ({}) belongs to a record: mark an initial state or a \
                 sensor offset with per_record = true in its [[parameter]]",
                spec.name(),
                spec.param_names().join(", ")
            ),
        ));
    }
    if samples == 0 || samples > record.n_samples() {
        return Err(refuse(
            "samples",
            samples.to_string(),
            format!(
                "the record's own parameters are fitted to its first 1 to {} samples",
                record.n_samples()
            ),
        ));
    }
    let held = FixedValues::from_pairs(
        spec.param_names()
            .iter()
            .zip(theta)
            .zip(own)
            .filter(|(_, own)| !**own)
            .map(|((name, v), _)| (name.as_str(), *v)),
    )
    .map_err(|source| RefineError::Simulation {
        what: "holding the plant's parameters",
        source,
    })?;
    let start: Vec<f64> = theta
        .iter()
        .zip(own)
        .filter(|(_, own)| **own)
        .map(|(v, _)| *v)
        .collect();
    let plant = WithFixed::new(simulator, &held).map_err(|source| RefineError::Simulation {
        what: "holding the plant's parameters",
        source,
    })?;
    let fit = Refinement::new(OutputError::new(plant)?);
    let first = record.window(0, samples);
    let mut starts = search.starts(fit.model().simulator().spec().prior(), &start, None)?;
    // A start outside the prior (a row's value of another record's
    // model, say) is left to the prior's starts.
    starts.retain(|s| fit.model().simulator().spec().prior().contains(s));
    let best = fit
        .best_fits(vec![(&first, starts)])
        .pop()
        .unwrap_or_else(|| unreachable!("one search, one result"))?;
    Ok(OwnFit {
        theta: fit.model().simulator().whole(&best.best.theta),
        stop: best.best.stop,
        optima: best.optima.len(),
    })
}
