//! The candidates a careful human would try: stage-1 structures shaped
//! for the records, the output transforms the records call for, the
//! networks, and how each is named and weighed.

use twostage_compress::{
    Arx, Compressor, CompressorConfig, Narx, OutputPca, RawRecord, SignalTransform, Transformed,
};
use twostage_compress::{DEFAULT_SUBSTEPS, Linearized};
use twostage_fit::{Mlp, MlpParams, Piecewise, RegressorConfig};
use twostage_models::{IoData, ModelSpec};
use twostage_sources::ForModel;

use twostage_train::Result;

/// Both stages as the command line writes them, for reports and progress.
pub(super) fn design(compressor: &CompressorConfig, regressor: &RegressorConfig) -> String {
    format!(
        "{} {}",
        compressor.spec().unwrap_or_else(|| compressor.to_string()),
        regressor.spec().unwrap_or_else(|| regressor.to_string())
    )
}

/// A network's layer sizes on n features and q outputs.
fn layer_sizes(mlp: &Mlp, n: usize, q: usize) -> Vec<usize> {
    let mut sizes = vec![n];
    sizes.extend_from_slice(mlp.params().hidden());
    sizes.push(q);
    sizes
}

/// What one Levenberg-Marquardt iteration of a candidate's fit costs a
/// training row on n features and q outputs: a fit's time grows with its
/// power [`PRODUCTS_EXPONENT`](crate::cost::PRODUCTS_EXPONENT) or so
/// (round 2). A network of one hidden layer shared by several outputs
/// costs far less than its weights say: its products come from its
/// structure.
pub(super) fn fit_cost(regressor: &RegressorConfig, n: usize, q: usize) -> f64 {
    match regressor {
        RegressorConfig::Mlp(mlp) => twostage_fit::products_per_sample(&layer_sizes(mlp, n, q)),
        // The global network on every row, then experts that together see
        // the rows about 1.5 times: counted as a network of 2.5 times the
        // weights, whose products are the square of that.
        RegressorConfig::Piecewise(p) => {
            2.5 * 2.5 * fit_cost(&RegressorConfig::Mlp(p.global().clone()), n, q)
        }
        _ => {
            let weights = (n * q + q) as f64;
            weights * weights / 2.0
        }
    }
}

/// Weights and biases of a network candidate on n features and q outputs.
pub(super) fn network_size(regressor: &RegressorConfig, n: usize, q: usize) -> f64 {
    match regressor {
        RegressorConfig::Mlp(mlp) => twostage_fit::n_parameters(&layer_sizes(mlp, n, q)) as f64,
        // The global network on every row, then experts that together see
        // the rows about 1.5 times (their margins overlap).
        RegressorConfig::Piecewise(p) => {
            2.5 * network_size(&RegressorConfig::Mlp(p.global().clone()), n, q)
        }
        _ => (n * q + q) as f64,
    }
}

pub(super) fn pieces(count: usize, hidden: &[usize]) -> Result<RegressorConfig> {
    let mlp = MlpParams::new(hidden)?.check()?;
    Ok(RegressorConfig::Piecewise(Piecewise::new(
        mlp.clone(),
        mlp,
        count,
    )?))
}

pub(super) fn network(hidden: &[usize]) -> Result<RegressorConfig> {
    Ok(RegressorConfig::Mlp(MlpParams::new(hidden)?.check()?))
}

/// Stage-1 candidates that fit the records' shape: ARX orders (AR on the
/// outputs for a model without input), a quadratic NARX for one input and
/// one output, output PCAs, and the raw record when it has at most
/// [`RAW_CANDIDATE_VALUES`] values. A least-squares structure is left out
/// when its coefficients would be more than a quarter of the samples.
/// Unfitted compressors (NARX scales, PCA directions) are fitted on the
/// chart's fitting rows before use.
///
/// With `transforms`, every structure is tried a second time on the
/// transformed outputs: the held-out risk, not a rule, decides whether
/// logarithms pay. With `inputs_vary` false (an input that never varies
/// within a record: no regression can fit its lags), the ARX orders
/// regress on the outputs alone and the NARX is left out.
pub(super) fn candidate_compressors(
    n_outputs: usize,
    n_inputs: usize,
    n_samples: usize,
    transforms: Option<Vec<SignalTransform>>,
    inputs_vary: bool,
) -> Vec<CompressorConfig> {
    let fits = |coefficients: usize| 4 * coefficients <= n_samples;
    let mut list: Vec<CompressorConfig> = Vec::new();
    for order in [2, 3, 4, 5, 6, 8] {
        let input_lags = if n_inputs == 0 || !inputs_vary {
            0
        } else {
            order
        };
        if let Ok(arx) =
            Arx::new(order, input_lags).and_then(|a| a.with_signals(n_inputs, n_outputs))
            && fits(order * n_outputs + input_lags * n_inputs)
        {
            list.push(arx.into());
        }
    }
    if (n_inputs, n_outputs) == (1, 1)
        && inputs_vary
        && let Ok(narx) = Narx::new(2, 2, 2)
        && fits(narx.n_features())
    {
        list.push(narx.into());
    }
    for k in [8, 12, 16] {
        if let Ok(pca) = OutputPca::new(k)
            && k < n_samples * n_outputs
        {
            list.push(pca.into());
        }
    }
    let values = n_samples * (n_inputs + n_outputs);
    if values <= RAW_CANDIDATE_VALUES
        && let Ok(raw) = RawRecord::new(n_samples, n_inputs, n_outputs)
    {
        list.push(CompressorConfig::Raw(raw));
    }
    if let Some(transforms) = transforms {
        let transformed: Vec<CompressorConfig> = list
            .iter()
            .filter_map(|c| Transformed::new(transforms.clone(), c.clone()).ok())
            .map(CompressorConfig::Transformed)
            .collect();
        list.extend(transformed);
    }
    list
}

/// The stage 1s the model's own equations make possible, shaped for it:
/// the car linearized at its prior's centre where twostage holds the
/// car's equations (decision 085), none otherwise. Round 1 scores it
/// beside the regressions: what it costs (a run of the car a record) is
/// in its time.
pub(super) fn model_candidates(spec: &ModelSpec) -> Vec<CompressorConfig> {
    if spec.car_equations().is_none() {
        return Vec::new();
    }
    Linearized::new(DEFAULT_SUBSTEPS)
        .map(CompressorConfig::Linearized)
        .ok()
        .and_then(|c| c.for_model(spec).ok())
        .into_iter()
        .collect()
}

/// The transform a careful human would try on each output, judged from
/// the training records: the logarithm where an output is always
/// positive, `ln(1 + y)` where it is never negative but reaches zero (a
/// count), none where it goes negative; `None` when no output would be
/// transformed. Only the outputs that span more than a decade are
/// transformed: on a narrow range the logarithm is nearly linear and
/// changes nothing a network cannot absorb.
pub(super) fn output_transforms(records: &[IoData]) -> Option<Vec<SignalTransform>> {
    let n_outputs = records.first()?.n_outputs();
    let transforms: Vec<SignalTransform> = (0..n_outputs)
        .map(|j| {
            let (mut low, mut high, mut low_positive) = (f64::INFINITY, 0.0f64, f64::INFINITY);
            for record in records {
                for &v in record.output(j) {
                    low = low.min(v);
                    high = high.max(v);
                    if v > 0.0 {
                        low_positive = low_positive.min(v);
                    }
                }
            }
            let spans_decades = high > 10.0 * low_positive;
            match () {
                _ if !spans_decades || !low.is_finite() => SignalTransform::Identity,
                _ if low > 0.0 => SignalTransform::Log,
                _ if low == 0.0 => SignalTransform::Log1p,
                _ => SignalTransform::Identity,
            }
        })
        .collect();
    transforms
        .iter()
        .any(|t| *t != SignalTransform::Identity)
        .then_some(transforms)
}

/// The inputs that never vary within any of `records` (zero or constant
/// over every experiment), by index: an ARX or NARX cannot fit their
/// lags, so its candidates leave them out before the search.
pub(super) fn constant_inputs(records: &[IoData]) -> Vec<usize> {
    let Some(first) = records.first() else {
        return Vec::new();
    };
    (0..first.n_inputs())
        .filter(|&j| {
            records.iter().all(|record| {
                let (low, high) = record
                    .input(j)
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                        (l.min(*v), h.max(*v))
                    });
                high - low <= 0.0
            })
        })
        .collect()
}

/// How many times the smallest input RMS among the records the largest
/// must be for the records to be a family of operating levels: white
/// noise of a few hundred samples varies by a few per cent, a family of
/// drawn levels or of manoeuvres by several times.
const FAMILY_LEVEL_RATIO: f64 = 2.0;

/// How far the records' input shapes must spread for their inputs to
/// differ in kind: the standard deviation across records of one of an
/// input's autocorrelations (the input shape's numbers), at its most spread lag. White
/// noise of N samples spreads as 1/sqrt(N) at every lag (0.1 at 100
/// samples); a family of holds, bursts and noise spreads over most of
/// [-1, 1].
const SHAPE_SPREAD: f64 = 0.2;

/// Whether the `records`' inputs differ in level from one experiment to
/// another (an input family): one input's RMS varies by more than
/// [`FAMILY_LEVEL_RATIO`] over the records.
fn inputs_differ_in_level(records: &[IoData]) -> bool {
    let Some(first) = records.first() else {
        return false;
    };
    // The input family's own RMS range (the sample time does not enter
    // the RMS).
    let mut family = twostage_models::InputFamily::new(first.n_inputs(), 1.0);
    records.iter().for_each(|record| family.include(record));
    (0..first.n_inputs()).any(|j| {
        family
            .ranges(j)
            .is_some_and(|[_, [low, high], ..]| *high > FAMILY_LEVEL_RATIO * *low)
    })
}

/// Whether the `records`' inputs differ in shape: one of their
/// autocorrelations spreads over the records by more than
/// [`SHAPE_SPREAD`] (steps, bursts and noise mixed, not realizations of
/// one noise).
fn inputs_differ_in_shape(records: &[IoData]) -> bool {
    let shapes: Vec<Vec<f64>> = records
        .iter()
        .map(twostage_models::record_shape_numbers)
        .collect();
    let Some(width) = shapes.first().map(Vec::len) else {
        return false;
    };
    let n = shapes.len() as f64;
    (0..width).any(|k| {
        let mean = shapes.iter().map(|s| s[k]).sum::<f64>() / n;
        let variance = shapes.iter().map(|s| (s[k] - mean).powi(2)).sum::<f64>() / n;
        variance.sqrt() > SHAPE_SPREAD
    })
}

/// The winner's stage 1 with each signal's mean, RMS, peak and mean
/// frequency appended, where the `records`' inputs differ in level from
/// one experiment to another (an input family): the coefficients of a
/// nonlinear system then depend on how hard each record drove it, which
/// they do not say. The held-out risk decides whether it pays.
pub(super) fn with_summary(
    compressor: &CompressorConfig,
    records: &[IoData],
) -> Option<CompressorConfig> {
    let first = records.first()?;
    // A learned summary comes last: nothing is appended after it.
    if matches!(
        compressor,
        CompressorConfig::Summarized(_) | CompressorConfig::Learned(_)
    ) || !inputs_differ_in_level(records)
    {
        return None;
    }
    twostage_compress::WithSummary::new(compressor.clone(), first.n_inputs(), first.n_outputs())
        .ok()
        .map(CompressorConfig::Summarized)
}

/// The winner's stage 1 (with the summary, where [`with_summary`] adds
/// it) and after it a summary network of the default shape trained on
/// the records, where the `records`' inputs differ in level or
/// in shape: what one stage 1 reads of a step differs from what it reads
/// of a burst, and a network can learn to tell them apart.
/// The held-out risk decides whether it pays for its training.
pub(super) fn with_learned(
    compressor: &CompressorConfig,
    records: &[IoData],
) -> Option<CompressorConfig> {
    let first = records.first()?;
    if first.n_inputs() == 0
        || matches!(compressor, CompressorConfig::Learned(_))
        || !(inputs_differ_in_level(records) || inputs_differ_in_shape(records))
    {
        return None;
    }
    let inner = with_summary(compressor, records).unwrap_or_else(|| compressor.clone());
    twostage_compress::WithLearned::new(Some(inner), twostage_compress::LearnedShape::default())
        .ok()
        .map(CompressorConfig::Learned)
}

/// The winner's stage 1 with each output's first sample and mean
/// appended, where its features discard the record's level (ARX and NARX
/// coefficients, also of transformed outputs): what a careful human adds
/// when an initial state or an offset is to be estimated. The held-out
/// risk decides whether it pays.
pub(super) fn with_level(
    compressor: &CompressorConfig,
    n_outputs: usize,
) -> Option<CompressorConfig> {
    let stage1 = match compressor {
        CompressorConfig::Transformed(t) => t.inner(),
        other => other,
    };
    if !matches!(stage1, CompressorConfig::Arx(_) | CompressorConfig::Narx(_)) {
        return None;
    }
    twostage_compress::WithLevel::new(compressor.clone(), n_outputs)
        .ok()
        .map(CompressorConfig::Leveled)
}

/// The longest record (in values) whose raw samples the search tries as
/// features.
const RAW_CANDIDATE_VALUES: usize = 256;

#[cfg(test)]
mod tests {
    use super::*;

    fn names(list: &[CompressorConfig]) -> Vec<String> {
        list.iter().map(ToString::to_string).collect()
    }

    /// The built-in models' search is what it was; a short record without
    /// input gets autoregressions and its raw samples, nothing that cannot
    /// run on it.
    #[test]
    fn the_candidates_fit_the_records_shape() {
        let siso = candidate_compressors(1, 1, 1000, None, true);
        assert_eq!(siso.len(), 6 + 1 + 3);
        assert!(siso.iter().all(|c| !matches!(c, CompressorConfig::Raw(_))));
        let short = candidate_compressors(1, 0, 10, None, true);
        let shown = names(&short);
        assert!(
            short.iter().all(|c| c.n_features() * 4 <= 10
                || matches!(c, CompressorConfig::Raw(_) | CompressorConfig::Pca(_))),
            "{shown:?}"
        );
        assert!(
            matches!(short.last(), Some(CompressorConfig::Raw(r)) if r.n_samples() == 10),
            "{shown:?}"
        );
        assert!(!shown.iter().any(|s| s.contains("NARX")), "{shown:?}");
        // Two outputs, no input, a long record: ARs, PCAs, no raw.
        let mimo = candidate_compressors(2, 0, 400, None, true);
        assert!(
            mimo.iter()
                .any(|c| matches!(c, CompressorConfig::Arx(a) if a.nb() == 0))
        );
        assert!(
            mimo.iter()
                .all(|c| !matches!(c, CompressorConfig::Raw(_) | CompressorConfig::Narx(_)))
        );
    }

    /// The car, whose equations twostage holds, offers its linearization
    /// shaped at its prior's centre; the benchmark offers nothing more.
    #[test]
    fn the_car_offers_its_linearization_and_the_benchmark_nothing() {
        use twostage_models::{Benchmark, PacejkaCar, Simulator};
        let car = PacejkaCar::new();
        let offered = model_candidates(car.spec());
        let [CompressorConfig::Linearized(l)] = offered.as_slice() else {
            panic!("{offered:?}")
        };
        let lin = l.car().unwrap();
        let prior = car.spec().prior();
        assert_eq!(lin.lower.to_vec(), prior.lower().to_vec());
        assert_eq!(lin.upper.to_vec(), prior.upper().to_vec());
        assert_eq!(l.substeps(), DEFAULT_SUBSTEPS);
        assert!(model_candidates(Benchmark::new().spec()).is_empty());
    }

    /// A family of input levels earns the summary rival; one level with
    /// the small spread of noise, or a stage 1 already summarized, not.
    #[test]
    fn the_summary_rival_is_for_inputs_of_different_levels() {
        let record = |level: f64| {
            let mut r = IoData::zeros(200, 1, 1);
            for (t, v) in r.input_mut(0).iter_mut().enumerate() {
                *v = level * if t % 2 == 0 { 1.0 } else { -1.0 };
            }
            r
        };
        let arx: CompressorConfig = "arx:2,2".parse().unwrap();
        let arx = arx.for_shape(1, 1, 200).unwrap();
        let one_level: Vec<IoData> = [1.0, 1.1, 0.95].map(record).into();
        assert!(with_summary(&arx, &one_level).is_none());
        let family: Vec<IoData> = [1.0, 0.4, 0.9].map(record).into();
        let summarized = with_summary(&arx, &family).unwrap();
        assert_eq!(summarized.n_features(), 4 + 8);
        assert!(with_summary(&summarized, &family).is_none());
        assert!(with_summary(&arx, &[]).is_none());
    }

    /// Inputs of one level and one kind (realizations of one noise) earn
    /// no network; inputs of mixed kinds at one level (slow and fast
    /// oscillations) or of different levels do, after the summary where the
    /// levels differ; a stage 1 that learns already, or records without
    /// an input, not.
    #[test]
    fn the_learned_rival_is_for_inputs_that_differ_in_kind() {
        let n = 400;
        // A linear congruential sequence: white enough at these lags.
        let mut state: u64 = 5;
        let mut noise = || {
            let mut r = IoData::zeros(n, 1, 1);
            for v in r.input_mut(0) {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                *v = (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
            }
            r
        };
        // A slow sine, or a fast square wave of about its RMS.
        let shaped = |square: bool, level: f64| {
            let mut r = IoData::zeros(n, 1, 1);
            for (t, v) in r.input_mut(0).iter_mut().enumerate() {
                *v = level
                    * match square {
                        true if t % 4 < 2 => 0.8,
                        true => -0.8,
                        false => (t as f64 * 0.05).sin(),
                    };
            }
            r
        };
        let arx: CompressorConfig = "arx:2,2".parse().unwrap();
        let arx = arx.for_shape(1, 1, n).unwrap();
        let white: Vec<IoData> = (0..40).map(|_| noise()).collect();
        assert!(with_learned(&arx, &white).is_none());
        let kinds: Vec<IoData> = (0..40).map(|k| shaped(k % 2 == 0, 1.0)).collect();
        let learned = with_learned(&arx, &kinds).unwrap();
        assert_eq!(
            learned.spec().as_deref(),
            Some("arx:2,2+learned:8,8,8"),
            "one level: no summary before the network"
        );
        let levels: Vec<IoData> = (0..40)
            .map(|k| shaped(false, if k % 2 == 0 { 1.0 } else { 0.3 }))
            .collect();
        let both = with_learned(&arx, &levels).unwrap();
        assert_eq!(
            both.spec().as_deref(),
            Some("arx:2,2+summary+learned:8,8,8")
        );
        assert!(with_learned(&learned, &kinds).is_none());
        assert!(
            with_summary(&both, &levels).is_none(),
            "nothing after the network"
        );
        let silent: Vec<IoData> = (0..4).map(|_| IoData::zeros(n, 0, 1)).collect();
        assert!(with_learned(&arx, &silent).is_none());
        assert!(with_learned(&arx, &[]).is_none());
    }

    /// An input that never varies within a record is found whatever its
    /// value, and the candidates then regress on the outputs alone: no
    /// ARX lag of it, no NARX.
    #[test]
    fn a_constant_input_leaves_its_regressions_out() {
        let record = |k: usize| {
            let mut r = IoData::zeros(50, 3, 1);
            for (t, v) in r.input_mut(0).iter_mut().enumerate() {
                *v = ((t * (k + 3)) % 7) as f64;
            }
            r.input_mut(2).fill(k as f64 + 0.5);
            r
        };
        let records: Vec<IoData> = (0..4).map(record).collect();
        assert_eq!(constant_inputs(&records), [1, 2]);
        assert!(constant_inputs(&records[..0]).is_empty());
        let held = candidate_compressors(1, 1, 1000, None, false);
        assert!(held.iter().all(|c| match c {
            CompressorConfig::Arx(a) => a.nb() == 0,
            CompressorConfig::Narx(_) => false,
            _ => true,
        }));
        assert!(held.iter().any(|c| matches!(c, CompressorConfig::Arx(_))));
    }

    /// With one target every cost estimate is the weights' power 1.2 it
    /// always was; with several, a network of one hidden layer is
    /// estimated at what its structured products cost, far below a
    /// network of two layers of as many weights a unit.
    #[test]
    fn fit_costs_follow_the_products_a_fit_takes() {
        let net = |hidden: &[usize]| {
            RegressorConfig::Mlp(MlpParams::new(hidden).unwrap().check().unwrap())
        };
        let (small, wide, deep) = (net(&[20]), net(&[40]), net(&[20, 20]));
        let pieces = pieces(4, &[20]).unwrap();
        let ratio = |a: &RegressorConfig, b: &RegressorConfig, q: usize| {
            (fit_cost(a, 4, q) / fit_cost(b, 4, q)).powf(crate::cost::PRODUCTS_EXPONENT)
        };
        let weights = |a: &RegressorConfig, b: &RegressorConfig| {
            (network_size(a, 4, 1) / network_size(b, 4, 1)).powf(1.2)
        };
        for (a, b) in [(&wide, &small), (&deep, &small), (&pieces, &small)] {
            let (new, old) = (ratio(a, b, 1), weights(a, b));
            assert!((new - old).abs() <= 1e-12 * old, "{new} against {old}");
        }
        // Seven targets: [20, 20] by its Jacobian's 7 x 667 weights a row,
        // [20] by the structure's 100 + 21 columns.
        let seven = ratio(&deep, &small, 7);
        assert!(seven > 20.0, "{seven}");
        assert!(ratio(&wide, &small, 7) < 3.0);
    }
}
