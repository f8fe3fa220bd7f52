//! Input signals: what excites the system during an experiment.

use crate::InvalidSetting;
use std::sync::Arc;

use rand::{Rng, RngExt};
use rand_distr::{Distribution, StandardNormal};

use crate::error::{Result, SimError};
use crate::input_design::{Design, Drawn, Grid, Level, Phases};
use between_samples::chicane;

/// The input applied in every experiment of a model.
///
/// Three kinds exist: white Gaussian noise drawn anew for each experiment
/// (the benchmark's `u ~ N(0, 1)`), the chicane steering manoeuvre of the
/// Pacejka example (spec/pacejka-car.md), and a fixed signal given by the
/// user, the same in every experiment (Section 4.1 of the paper: train on
/// inputs like the ones real experiments will use).
///
/// ```
/// use twostage_models::InputSignal;
/// let steer = InputSignal::chicane(0.2)?;
/// // delta(2) = 0.2 sin(pi/2) sin(pi/8)^2
/// assert!((steer.value_at(2.0, 0.02, &[]) - 0.0292893218813).abs() < 1e-12);
/// let fixed = InputSignal::fixed(vec![0.0, 1.0, 2.0])?;
/// // Between samples a continuous-time model sees the straight line through them.
/// assert!((fixed.value_at(0.5, 1.0, &[0.0, 1.0, 2.0]) - 0.5).abs() < 1e-15);
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct InputSignal {
    kind: Kind,
}

#[derive(Debug, Clone, PartialEq)]
enum Kind {
    WhiteGaussian {
        std_dev: f64,
    },
    Chicane {
        amplitude: f64,
    },
    Fixed(Arc<[f64]>),
    /// A design drawn per experiment, about `offset` (drawn after the
    /// design's own settings, where it is a range).
    Designed {
        design: Box<Design>,
        offset: Drawn,
    },
    /// The sum of signals, each drawn in turn from the experiment's stream.
    Sum(Vec<InputSignal>),
    /// One of the signals per experiment, drawn by its weight.
    OneOf {
        parts: Vec<InputSignal>,
        weights: Vec<f64>,
    },
    /// The signals one after another, the record cut at drawn times.
    Sequence(Vec<InputSignal>),
}

/// How deep signals may nest in mixtures, sequences and sums: a design
/// deeper than that is a file's mistake, not a family.
pub const MAX_INPUT_NESTING: usize = 4;

impl InputSignal {
    /// White Gaussian noise of standard deviation `std_dev`, a new
    /// realization in every experiment.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] unless `std_dev` is finite and positive.
    pub fn white_gaussian(std_dev: f64) -> Result<Self> {
        if !(std_dev.is_finite() && std_dev > 0.0) {
            return Err(invalid(
                "input standard deviation",
                std_dev,
                "must be finite and > 0",
            ));
        }
        Ok(Self {
            kind: Kind::WhiteGaussian { std_dev },
        })
    }

    /// The chicane steering angle of spec/pacejka-car.md, in radians:
    /// `A sin(2 pi (t - 1) / 4) sin(pi (t - 1) / 8)^2` for `1 <= t <= 9`, else 0.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] unless `amplitude` is finite.
    pub fn chicane(amplitude: f64) -> Result<Self> {
        if !amplitude.is_finite() {
            return Err(invalid("chicane amplitude", amplitude, "must be finite"));
        }
        Ok(Self {
            kind: Kind::Chicane { amplitude },
        })
    }

    /// A fixed sampled signal, the same in every experiment. It must hold at
    /// least as many samples as the model's record length.
    ///
    /// # Errors
    /// [`SimError::InvalidData`] if it is empty or holds a non-finite value.
    pub fn fixed(samples: Vec<f64>) -> Result<Self> {
        if samples.is_empty() {
            return Err(SimError::InvalidData(
                "the fixed input signal is empty".into(),
            ));
        }
        if let Some(k) = samples.iter().position(|v| !v.is_finite()) {
            return Err(SimError::InvalidData(format!(
                "the fixed input signal has a non-finite value at sample {k}"
            )));
        }
        Ok(Self {
            kind: Kind::Fixed(samples.into()),
        })
    }

    /// A multisine: equal lines on the record's frequency grid `k / (N T)`
    /// from `low` Hz to `high` Hz (its top may be drawn per experiment),
    /// every line or the odd ones, random or Schroeder phases, scaled to
    /// `level` about `offset`.
    ///
    /// ```
    /// use twostage_models::{Drawn, Grid, InputSignal, Level, Phases, experiment_rng};
    /// let u = InputSignal::multisine(0.0, Drawn::fixed(5.0), Grid::Odd, Phases::Random,
    ///     Level::Rms(Drawn::fixed(0.5)), 2.0)?;
    /// let mut x = vec![0.0; 1000];
    /// u.fill(0.01, &mut experiment_rng(1, 0), &mut x)?;
    /// let mean = x.iter().sum::<f64>() / 1000.0;
    /// let rms = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 1000.0).sqrt();
    /// assert!((mean - 2.0).abs() < 1e-12 && (rms - 0.5).abs() < 1e-12);
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for a band whose bottom is not below
    /// its top, or a non-finite offset.
    pub fn multisine(
        low: impl Into<Drawn>,
        high: Drawn,
        grid: Grid,
        phases: Phases,
        level: Level,
        offset: f64,
    ) -> Result<Self> {
        Self::designed(
            Design::Multisine {
                band: (low.into(), high),
                grid,
                phases,
                level,
                spectrum: None,
            },
            offset,
        )
    }

    /// A random binary signal: `offset +- amplitude`, a fair coin per
    /// value, each held `hold` samples.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for a hold of 0 samples.
    pub fn random_binary(amplitude: Drawn, hold: usize, offset: f64) -> Result<Self> {
        Self::designed(Design::RandomBinary { amplitude, hold }, offset)
    }

    /// A pseudo-random binary sequence of a maximal shift register of
    /// `order` bits (period `2^order - 1` bits, each held `hold` samples),
    /// `offset +- amplitude`, from a register state drawn per experiment.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for an order outside 2 to
    /// [`crate::MAX_PRBS_ORDER`] or a hold of 0.
    pub fn prbs(order: u32, amplitude: Drawn, hold: usize, offset: f64) -> Result<Self> {
        Self::designed(
            Design::Prbs {
                order,
                amplitude,
                hold,
            },
            offset,
        )
    }

    /// A linear swept sine from `from` Hz at the first sample to `to` Hz
    /// at the record's end, of `amplitude`, about `offset`.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for a negative start.
    pub fn sweep(from: impl Into<Drawn>, to: Drawn, amplitude: Drawn, offset: f64) -> Result<Self> {
        Self::designed(
            Design::Sweep {
                from: from.into(),
                to,
                amplitude,
            },
            offset,
        )
    }

    /// Band-limited Gaussian noise: white Gaussian noise through
    /// Butterworth filters of `order` (a high-pass at `low` Hz unless it
    /// is 0, a low-pass at the band's top unless it is the Nyquist
    /// frequency; the top may be drawn per experiment), scaled so that its
    /// stationary standard deviation is `rms` (drawn per experiment where
    /// a range), about `offset`. Each record is a stretch of the
    /// stationary process: the filters run through their start-up first.
    ///
    /// ```
    /// use twostage_models::{Drawn, InputSignal, experiment_rng};
    /// let u = InputSignal::filtered_noise(0.0, Drawn::fixed(2.0), 4, Drawn::fixed(0.5), 0.0)?;
    /// let mut x = vec![0.0; 100_000];
    /// u.fill(0.01, &mut experiment_rng(1, 0), &mut x)?;
    /// let rms = (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
    /// assert!((rms - 0.5).abs() < 0.05);
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for a band whose bottom is not below
    /// its top, an order outside 1 to [`crate::MAX_FILTER_ORDER`], or a
    /// non-finite offset.
    pub fn filtered_noise(
        low: impl Into<Drawn>,
        high: Drawn,
        order: u32,
        rms: Drawn,
        offset: f64,
    ) -> Result<Self> {
        Self::designed(
            Design::FilteredNoise {
                band: (low.into(), high),
                order,
                rms,
            },
            offset,
        )
    }

    /// Random steps: levels uniform in `[level.0, level.1]`, each held a
    /// time uniform in `[hold.0, hold.1]` seconds (rounded to samples).
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for an empty level range or hold range.
    pub fn steps(level: (f64, f64), hold: (f64, f64)) -> Result<Self> {
        Self::designed(Design::Steps { level, hold }, 0.0)
    }

    /// Random manoeuvres: `count` bursts per experiment (drawn from the
    /// whole numbers between its ends), each a sine of a whole number of
    /// half `cycles` over `seconds`, of `amplitude` with a random sign,
    /// under a Hann `taper` or none, holding one of its crests (drawn)
    /// `dwell` seconds (`Drawn::fixed(0.0)`: none), at a random time that
    /// keeps it wholly in the record; zero (`offset`) between them.
    ///
    /// ```
    /// use twostage_models::{Drawn, InputSignal, Taper, experiment_rng};
    /// let one = InputSignal::bursts(
    ///     (1, 1), Drawn::fixed(2.0), Drawn::fixed(0.5), Drawn::fixed(1.0), Taper::None,
    ///     Drawn::fixed(0.0), 0.0,
    /// )?;
    /// let mut u = vec![0.0; 1000];
    /// one.fill(0.01, &mut experiment_rng(1, 0), &mut u)?;
    /// // Half a sine of 2 s: 200 samples of one sign, rest elsewhere.
    /// let nonzero = u.iter().filter(|v| **v != 0.0).count();
    /// assert!((199..=200).contains(&nonzero));
    /// assert!(u.iter().all(|v| v.abs() <= 1.0));
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for a count range outside 1 to
    /// [`crate::MAX_BURSTS`], a length that is not positive, a cycles
    /// range without a whole number of half cycles, a dwell below zero,
    /// or a non-finite offset.
    pub fn bursts(
        count: (usize, usize),
        seconds: Drawn,
        cycles: Drawn,
        amplitude: Drawn,
        taper: crate::Taper,
        dwell: Drawn,
        offset: f64,
    ) -> Result<Self> {
        Self::designed(
            Design::Bursts(crate::input_design::Bursts {
                count,
                seconds,
                cycles,
                amplitude,
                taper,
                dwell,
            }),
            offset,
        )
    }

    /// The sum of `parts` (a multisine on a step sequence, say), each
    /// drawn in turn from the experiment's stream.
    ///
    /// ```
    /// use twostage_models::{Drawn, InputSignal, experiment_rng};
    /// let steps = InputSignal::steps((1.0, 3.0), (10.0, 20.0))?;
    /// let dither = InputSignal::random_binary(Drawn::fixed(0.1), 1, 0.0)?;
    /// let sum = InputSignal::sum(vec![steps.clone(), dither.clone()])?;
    /// let (mut a, mut b, mut both) = (vec![0.0; 100], vec![0.0; 100], vec![0.0; 100]);
    /// let mut rng = experiment_rng(2, 0);
    /// steps.fill(1.0, &mut rng, &mut a)?;
    /// dither.fill(1.0, &mut rng, &mut b)?;
    /// sum.fill(1.0, &mut experiment_rng(2, 0), &mut both)?;
    /// assert!(both.iter().zip(a.iter().zip(&b)).all(|(s, (x, y))| (s - (x + y)).abs() < 1e-15));
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for fewer than two parts, a part that
    /// is itself a sum, or parts nested deeper than [`MAX_INPUT_NESTING`].
    pub fn sum(parts: Vec<InputSignal>) -> Result<Self> {
        if parts.len() < 2 {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "input sum",
                value: format!("{} part(s)", parts.len()),
                reason: "a sum takes two or more signals".into(),
            }));
        }
        if parts.iter().any(|p| matches!(p.kind, Kind::Sum(_))) {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "input sum",
                value: "a sum among its parts".into(),
                reason: "give the inner sum's parts to the outer sum instead".into(),
            }));
        }
        Self::nested(Kind::Sum(parts))
    }

    /// Ramps and holds from rest: the record rests a hold time, then moves
    /// to a level uniform in `[level.0, level.1]` over a ramp time, holds
    /// it, and so on; each hold uniform in `hold`, each ramp in `ramp`
    /// seconds (a ramp of zero is a step), about `offset`.
    ///
    /// ```
    /// use twostage_models::{Drawn, InputSignal, experiment_rng};
    /// let steer = InputSignal::ramps(Drawn::between(0.1, 0.2)?, Drawn::fixed(1.0),
    ///     Drawn::fixed(0.0), 0.0)?;
    /// let mut u = vec![0.0; 300];
    /// steer.fill(0.01, &mut experiment_rng(1, 0), &mut u)?;
    /// // A second's rest, then a step to a level held a second.
    /// assert!(u[..100].iter().all(|v| *v == 0.0));
    /// assert!((0.1..=0.2).contains(&u[100]) && u[100..200].iter().all(|v| *v == u[100]));
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for a hold that is not positive, a
    /// ramp below zero or a non-finite offset.
    pub fn ramps(level: Drawn, hold: Drawn, ramp: Drawn, offset: f64) -> Result<Self> {
        Self::designed(
            Design::Ramps(crate::input_design::Ramps { level, hold, ramp }),
            offset,
        )
    }

    /// One of `parts` per experiment, part `i` with probability
    /// `weights[i]` over their sum: a family of several kinds of
    /// operation (manoeuvres, holds, noise) in one chart.
    ///
    /// ```
    /// use twostage_models::{Drawn, InputSignal, experiment_rng};
    /// let low = InputSignal::steps((0.0, 0.0), (1.0, 1.0))?;
    /// let high = InputSignal::steps((1.0, 1.0), (1.0, 1.0))?;
    /// let either = InputSignal::one_of(vec![low, high], vec![1.0, 3.0])?;
    /// let mut u = vec![0.0; 10];
    /// let highs = (0..4000)
    ///     .filter(|&e| {
    ///         either.fill(1.0, &mut experiment_rng(3, e), &mut u).unwrap();
    ///         u[0] == 1.0
    ///     })
    ///     .count();
    /// // Three in four, within four standard errors (27).
    /// assert!((highs as i64 - 3000).abs() < 110, "{highs}");
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for no parts, another number of
    /// weights than parts, a weight that is not finite and positive, or
    /// parts nested deeper than [`MAX_INPUT_NESTING`].
    pub fn one_of(parts: Vec<InputSignal>, weights: Vec<f64>) -> Result<Self> {
        if parts.is_empty() {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "input mix",
                value: "no parts".into(),
                reason: "give one or more signals to draw from".into(),
            }));
        }
        if weights.len() != parts.len() {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "input mix weights",
                value: format!("{} weight(s) for {} part(s)", weights.len(), parts.len()),
                reason: "give one weight per part, or none for equal chances".into(),
            }));
        }
        if let Some((i, w)) = weights
            .iter()
            .enumerate()
            .find(|(_, w)| !(w.is_finite() && **w > 0.0))
        {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "input mix weights",
                value: format!("{w} for part {}", i + 1),
                reason: "each weight is finite and above zero: drop a part never drawn".into(),
            }));
        }
        Self::nested(Kind::OneOf { parts, weights })
    }

    /// `parts` one after another: the record is cut at `parts.len() - 1`
    /// times uniform over it (sorted), drawn per experiment, and each part,
    /// drawn as a whole record, shows its own samples from its cut to the
    /// next (a hold, then bursts where they fall, say): a part's band or
    /// level is its design's whatever the cut, and a part that rests first
    /// does not fill the later stretches with rest.
    ///
    /// ```
    /// use twostage_models::{Drawn, InputSignal, experiment_rng};
    /// let rest = InputSignal::steps((0.0, 0.0), (1.0, 1.0))?;
    /// let held = InputSignal::steps((2.0, 2.0), (1.0, 1.0))?;
    /// let both = InputSignal::sequence(vec![rest, held])?;
    /// let mut u = vec![0.0; 100];
    /// both.fill(1.0, &mut experiment_rng(8, 0), &mut u)?;
    /// let cut = u.iter().position(|v| *v == 2.0).unwrap_or(100);
    /// assert!(u[..cut].iter().all(|v| *v == 0.0) && u[cut..].iter().all(|v| *v == 2.0));
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for fewer than two parts or parts
    /// nested deeper than [`MAX_INPUT_NESTING`].
    pub fn sequence(parts: Vec<InputSignal>) -> Result<Self> {
        if parts.len() < 2 {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "input sequence",
                value: format!("{} part(s)", parts.len()),
                reason: "a sequence takes two or more signals".into(),
            }));
        }
        Self::nested(Kind::Sequence(parts))
    }

    fn nested(kind: Kind) -> Result<Self> {
        let signal = Self { kind };
        if signal.depth() > MAX_INPUT_NESTING {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "input parts",
                value: format!("nested {} deep", signal.depth()),
                reason: format!(
                    "mixtures, sequences and sums nest at most {MAX_INPUT_NESTING} deep: \
                     give the inner parts to the outer signal"
                ),
            }));
        }
        Ok(signal)
    }

    /// How many signals deep it nests (a design alone: 1).
    fn depth(&self) -> usize {
        1 + self
            .parts()
            .iter()
            .map(InputSignal::depth)
            .max()
            .unwrap_or(0)
    }

    /// The signals it is made of (none for a design alone).
    fn parts(&self) -> &[InputSignal] {
        match &self.kind {
            Kind::Sum(parts) | Kind::OneOf { parts, .. } | Kind::Sequence(parts) => parts,
            _ => &[],
        }
    }

    fn designed(design: Design, offset: f64) -> Result<Self> {
        if !offset.is_finite() {
            return Err(invalid("input offset", offset, "must be finite"));
        }
        let offset = Drawn::fixed(offset);
        // The settings that need no sample time are checked now; the band
        // against the Nyquist frequency with [`InputSignal::check_sampling`].
        design.check(0.0)?;
        Ok(Self {
            kind: Kind::Designed {
                design: Box::new(design),
                offset,
            },
        })
    }

    /// Refuses a design whose frequencies lie above the Nyquist frequency
    /// of `sample_time`, or whose band a record of `n_samples` cannot
    /// resolve, naming it and what would work: before any experiment is
    /// drawn.
    ///
    /// ```
    /// use twostage_models::{Drawn, InputSignal};
    /// let noise = InputSignal::filtered_noise(0.05, Drawn::fixed(1.0), 4, Drawn::fixed(0.1), 0.0)?;
    /// // 500 samples every 0.02 s resolve 0.1 Hz, not 0.05.
    /// let e = noise.check_sampling(0.02, 500).unwrap_err().to_string();
    /// assert!(e.contains("below the record's resolution"), "{e}");
    /// assert!(noise.check_sampling(0.02, 1000).is_ok());
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] as said.
    pub fn check_sampling(&self, sample_time: f64, n_samples: usize) -> Result<()> {
        match &self.kind {
            Kind::Designed { design, .. } => {
                design.check(sample_time)?;
                design.check_record(sample_time, n_samples)
            }
            Kind::Sum(_) | Kind::OneOf { .. } | Kind::Sequence(_) => self
                .parts()
                .iter()
                .try_for_each(|p| p.check_sampling(sample_time, n_samples)),
            _ => Ok(()),
        }
    }

    /// Whether it is a fixed sampled signal (the same samples in every
    /// experiment, whatever the sample time).
    pub fn is_fixed(&self) -> bool {
        matches!(self.kind, Kind::Fixed(_))
    }

    /// The record of `spec`'s shape whose every input is this signal,
    /// when the signal is the same in every experiment (`None` for white
    /// noise, or a fixed signal too short for the record).
    pub fn shared_record(&self, spec: &crate::ModelSpec) -> Option<crate::IoData> {
        if !self.is_deterministic() {
            return None;
        }
        let mut record = spec.new_record();
        // A deterministic signal draws nothing: any stream serves.
        let mut rng = crate::experiment_rng(0, 0);
        for j in 0..record.n_inputs() {
            self.fill(spec.sample_time(), &mut rng, record.input_mut(j))
                .ok()?;
        }
        (record.n_inputs() > 0).then_some(record)
    }

    /// Whether every experiment sees the same input.
    pub fn is_deterministic(&self) -> bool {
        match &self.kind {
            Kind::WhiteGaussian { .. } => false,
            Kind::Designed { design, offset } => design.is_deterministic() && offset.is_fixed(),
            Kind::Sum(parts) => parts.iter().all(InputSignal::is_deterministic),
            // A sequence's cuts are drawn; a mixture of one part is that part.
            Kind::OneOf { parts, .. } => parts.len() == 1 && parts[0].is_deterministic(),
            Kind::Sequence(_) => false,
            Kind::Chicane { .. } | Kind::Fixed(_) => true,
        }
    }

    /// A one-line description for people.
    pub fn describe(&self) -> String {
        match &self.kind {
            Kind::WhiteGaussian { std_dev } => format!(
                "white Gaussian noise N(0, {}), drawn anew per experiment",
                std_dev * std_dev
            ),
            Kind::Chicane { amplitude } => format!(
                "chicane steer {amplitude} sin(2 pi (t-1)/4) sin(pi (t-1)/8)^2 rad for 1 <= t <= 9 s, 0 otherwise"
            ),
            Kind::Fixed(samples) => {
                format!("a fixed user-given signal of {} samples", samples.len())
            }
            Kind::Designed { design, offset } if *offset != Drawn::fixed(0.0) => {
                format!("{}, about {}", design.describe(), offset.describe(""))
            }
            Kind::Designed { design, .. } => design.describe(),
            Kind::Sum(parts) => {
                let each: Vec<String> = parts.iter().map(InputSignal::describe).collect();
                format!("the sum of: {}", each.join("; "))
            }
            Kind::OneOf { parts, weights } => {
                let total: f64 = weights.iter().sum();
                let each: Vec<String> = parts
                    .iter()
                    .zip(weights)
                    .map(|(p, w)| format!("{:.3} of them {}", w / total, p.describe()))
                    .collect();
                format!("one per experiment: {}", each.join("; "))
            }
            Kind::Sequence(parts) => {
                let each: Vec<String> = parts.iter().map(InputSignal::describe).collect();
                format!(
                    "in turn, the record cut at times drawn per experiment: {}",
                    each.join("; then ")
                )
            }
        }
    }

    /// Write the sampled input `u_k = u(k * sample_time)`, `k = 0..u.len()`.
    ///
    /// # Errors
    /// [`SimError::InvalidData`] if a fixed signal is shorter than `u`.
    pub fn fill<R: Rng + ?Sized>(
        &self,
        sample_time: f64,
        rng: &mut R,
        u: &mut [f64],
    ) -> Result<()> {
        match &self.kind {
            Kind::WhiteGaussian { std_dev } => {
                for v in u.iter_mut() {
                    let z: f64 = StandardNormal.sample(rng);
                    *v = std_dev * z;
                }
            }
            Kind::Chicane { amplitude } => {
                for (k, v) in u.iter_mut().enumerate() {
                    *v = chicane(*amplitude, k as f64 * sample_time);
                }
            }
            Kind::Fixed(samples) => {
                if samples.len() < u.len() {
                    return Err(SimError::InvalidData(format!(
                        "the fixed input signal has {} samples but the record needs {}: \
                         give a longer signal or shorten the record",
                        samples.len(),
                        u.len()
                    )));
                }
                u.copy_from_slice(&samples[..u.len()]);
            }
            Kind::Designed { design, offset } => {
                design.fill(sample_time, rng, u)?;
                // A fixed offset draws nothing: the design's streams stay.
                let offset = offset.draw(rng);
                for v in u.iter_mut() {
                    *v += offset;
                }
            }
            Kind::Sum(parts) => {
                u.fill(0.0);
                let mut part = vec![0.0; u.len()];
                for p in parts {
                    p.fill(sample_time, rng, &mut part)?;
                    for (v, x) in u.iter_mut().zip(&part) {
                        *v += x;
                    }
                }
            }
            Kind::OneOf { parts, weights } => {
                let total: f64 = weights.iter().sum();
                let mut left = total * rng.random::<f64>();
                // The last part takes what rounding leaves.
                let chosen = weights
                    .iter()
                    .position(|w| {
                        left -= w;
                        left < 0.0
                    })
                    .unwrap_or(parts.len() - 1);
                parts[chosen].fill(sample_time, rng, u)?;
            }
            Kind::Sequence(parts) => {
                let n = u.len();
                let mut cuts: Vec<usize> =
                    (1..parts.len()).map(|_| rng.random_range(0..=n)).collect();
                cuts.sort_unstable();
                // Each part is drawn as a whole record, so that a band or a
                // burst is as the part's own design says whatever the cut.
                let mut whole = vec![0.0; n];
                let mut start = 0;
                for (part, end) in parts.iter().zip(cuts.into_iter().chain([n])) {
                    part.fill(sample_time, rng, &mut whole)?;
                    u[start..end].copy_from_slice(&whole[start..end]);
                    start = end;
                }
            }
        }
        Ok(())
    }
}

fn invalid(name: &'static str, value: f64, reason: &str) -> SimError {
    SimError::InvalidSetting(InvalidSetting {
        name,
        value: value.to_string(),
        reason: reason.into(),
    })
}

mod between_samples;
mod reshaped;
#[cfg(test)]
mod tests;
