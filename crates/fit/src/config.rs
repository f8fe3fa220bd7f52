//! The stage-2 choice as a serializable value, its specification as the
//! command line and model files write it (`linear`, `mlp:10`,
//! `piecewise:4,20`), and the fitted map it gives.

use crate::InvalidSetting;
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::error::{FitError as Error, Result};
use crate::mlp::DEFAULT_RESTARTS;
use crate::{
    FittedLinear, FittedMlp, FittedPiecewise, Mlp, MlpParams, Piecewise, Predictor, Regressor,
    Ridge,
};

/// Whole numbers separated by commas, exactly `count` of them.
fn counts(spec: &str, whole: &str, count: usize, what: &'static str) -> Result<Vec<usize>> {
    let values: Option<Vec<usize>> = spec.split(',').map(|v| v.trim().parse().ok()).collect();
    values.filter(|v| v.len() == count).ok_or_else(|| {
        Error::InvalidSetting(InvalidSetting {
            name: what,
            value: whole.to_string(),
            reason: format!(
                "the part after ':' must be {count} whole number(s) separated by commas"
            ),
        })
    })
}

/// The fitting method of stage 2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum RegressorConfig {
    /// Linear (ridge) least squares.
    Linear(Ridge),
    /// A tanh network, trained by Levenberg-Marquardt or Adam as its
    /// `Trainer` says.
    Mlp(Mlp),
    /// A global network routing each record to a specialist network of its
    /// piece of the first parameter's range.
    Piecewise(Piecewise),
}

impl std::fmt::Display for RegressorConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Linear(r) => write!(f, "linear (ridge lambda {:e})", r.lambda()),
            Self::Mlp(m) => write!(
                f,
                "{}MLP {:?} tanh, {}",
                if m.params().is_ensemble() {
                    "averaged restarts of "
                } else {
                    ""
                },
                m.params().hidden(),
                m.params().trainer_choice()
            ),
            Self::Piecewise(p) => write!(
                f,
                "{} x MLP {:?} by pieces",
                p.pieces(),
                p.global().params().hidden()
            ),
        }
    }
}

impl std::str::FromStr for RegressorConfig {
    type Err = Error;

    /// A stage-2 specification as the command line and model files write
    /// it: `linear`, `mlp:H[,H...]` (hidden sizes), `ensemble:H[,H...]`
    /// (the same network's restarts, independently seeded, averaged; four
    /// of them, or N with `ensemble:H[,H...]xN`) or `piecewise:K,H` (a
    /// global H-unit network routing to K experts by pieces of the first
    /// parameter's range).
    ///
    /// ```
    /// use twostage_fit::RegressorConfig;
    /// assert!(matches!("mlp:10".parse()?, RegressorConfig::Mlp(_)));
    /// let RegressorConfig::Mlp(eight) = "ensemble:64,64x8".parse()? else { unreachable!() };
    /// assert_eq!((eight.params().hidden(), eight.params().n_restarts()), (&[64, 64][..], 8));
    /// assert!("mlp:ten".parse::<RegressorConfig>().is_err());
    /// assert!("ensemble:20x0".parse::<RegressorConfig>().is_err());
    /// # Ok::<(), twostage_fit::FitError>(())
    /// ```
    fn from_str(spec: &str) -> Result<Self> {
        const WHAT: &str = "regressor";
        if spec.trim() == "linear" {
            return Ok(Self::Linear(Ridge::default()));
        }
        if let Some(rest) = spec.trim().strip_prefix("piecewise:") {
            let c = counts(rest, spec, 2, WHAT)?;
            let mlp = MlpParams::new(&[c[1]]).and_then(MlpParams::check)?;
            return Ok(Self::Piecewise(Piecewise::new(mlp.clone(), mlp, c[0])?));
        }
        let trimmed = spec.trim();
        let (hidden, ensemble) = match (
            trimmed.strip_prefix("mlp:"),
            trimmed.strip_prefix("ensemble:"),
        ) {
            (Some(hidden), _) => (hidden, false),
            (None, Some(hidden)) => (hidden, true),
            (None, None) => {
                return Err(Error::InvalidSetting(InvalidSetting {
                    name: WHAT,
                    value: spec.to_string(),
                    reason: "use linear, mlp:H[,H...], ensemble:H[,H...][xN] or piecewise:PIECES,H"
                        .into(),
                }));
            }
        };
        let (hidden, members) = match hidden.split_once('x') {
            Some((hidden, members)) if ensemble => (hidden, Some(members)),
            _ => (hidden, None),
        };
        let n = hidden.split(',').count();
        let sizes = counts(hidden, spec, n, WHAT)?;
        let mut params = MlpParams::new(&sizes)?.ensemble(ensemble);
        if let Some(members) = members {
            let n = members.trim().parse().map_err(|_| {
                Error::InvalidSetting(InvalidSetting {
                    name: WHAT,
                    value: spec.to_string(),
                    reason: format!(
                        "after 'x' comes the number of members, a whole number: not '{members}'"
                    ),
                })
            })?;
            params = params.restarts(n);
        }
        Ok(Self::Mlp(params.check()?))
    }
}

impl RegressorConfig {
    /// The specification the command line and model files write for this
    /// method (`linear`, `mlp:20,20`, `ensemble:64,64x8`, `piecewise:4,20`),
    /// when one gives it back exactly (not for a ridge penalty, trainer, or
    /// a single network's restarts other than the defaults, which only the
    /// library sets).
    ///
    /// ```
    /// use twostage_fit::RegressorConfig;
    /// for spec in ["linear", "mlp:20,20", "ensemble:20", "ensemble:64,64x8", "piecewise:4,20"] {
    ///     let r: RegressorConfig = spec.parse()?;
    ///     assert_eq!(r.spec().as_deref(), Some(spec));
    /// }
    /// # Ok::<(), twostage_fit::FitError>(())
    /// ```
    pub fn spec(&self) -> Option<String> {
        let sizes = |hidden: &[usize]| -> String {
            let text: Vec<String> = hidden.iter().map(usize::to_string).collect();
            text.join(",")
        };
        let text = match self {
            Self::Linear(_) => "linear".to_string(),
            Self::Mlp(m) if m.params().is_ensemble() => {
                let members = match m.params().n_restarts() {
                    DEFAULT_RESTARTS => String::new(),
                    n => format!("x{n}"),
                };
                format!("ensemble:{}{members}", sizes(m.params().hidden()))
            }
            Self::Mlp(m) => format!("mlp:{}", sizes(m.params().hidden())),
            Self::Piecewise(p) => format!(
                "piecewise:{},{}",
                p.pieces(),
                sizes(p.global().params().hidden())
            ),
        };
        (text.parse::<Self>().ok().as_ref() == Some(self)).then_some(text)
    }

    /// Fit stage 2 on features `x` and parameters `y`; `seed` seeds the
    /// network's initial weights and held-out split, so that the run's one
    /// seed decides every random choice.
    ///
    /// # Errors
    /// What the chosen method's fit reports.
    pub fn fit(
        &self,
        x: ArrayView2<'_, f64>,
        y: ArrayView2<'_, f64>,
        seed: u64,
    ) -> Result<FittedRegressor> {
        Ok(match self {
            Self::Linear(r) => FittedRegressor::Linear(r.fit(x, y)?),
            Self::Mlp(m) => FittedRegressor::Mlp(m.with_seed(seed).fit(x, y)?),
            Self::Piecewise(p) => FittedRegressor::Piecewise(p.with_seed(seed).fit(x, y)?),
        })
    }

    /// [`Self::fit`] from `start`, a fit of this configuration, trained
    /// further on `x` and `y` (typically more rows; [`crate::Mlp::fit_from`],
    /// [`crate::Piecewise::fit_from`]), or anew without one; the networks'
    /// training stopped at `stop_by` if given and not ended by then
    /// ([`crate::Mlp::stopped_by`]). Trained further, the fit is never worse
    /// than `start` on its held-out rows however early it stops; anew, a
    /// fit stopped early may be poor (an ensemble member or an expert of
    /// one step), and its caller judges it. A linear map is fitted in one
    /// solve and ignores both. `seed` seeds the held-out split as in
    /// [`Self::fit`].
    ///
    /// ```
    /// use std::time::Instant;
    /// use ndarray::Array2;
    /// use twostage_fit::{FittedRegressor, RegressorConfig};
    ///
    /// let x = Array2::from_shape_fn((600, 1), |(i, _)| i as f64 / 300.0 - 1.0);
    /// let y = x.mapv(|v| (3.0 * v).sin());
    /// let net: RegressorConfig = "mlp:8".parse()?;
    /// let few = ndarray::s![..150, ..];
    /// let start = net.fit(x.slice(few), y.slice(few), 1)?;
    /// // Stopped at once: anew, every restart takes one step; trained
    /// // further, each network keeps its best held-out weights.
    /// let steps = |f: &FittedRegressor| match f {
    ///     FittedRegressor::Mlp(m) => m.reports().iter().map(|r| r.iterations).max(),
    ///     _ => None,
    /// };
    /// let anew = net.fit_from(None, (x.view(), y.view()), 1, Some(Instant::now()))?;
    /// assert_eq!(steps(&anew), Some(1));
    /// let further = net.fit_from(Some(&start), (x.view(), y.view()), 1, Some(Instant::now()))?;
    /// assert_eq!(steps(&further), Some(1));
    /// let other: RegressorConfig = "piecewise:2,8".parse()?;
    /// assert!(other.fit_from(Some(&start), (x.view(), y.view()), 1, None).is_err());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// A `start` of another configuration, or what the fit reports.
    pub fn fit_from(
        &self,
        start: Option<&FittedRegressor>,
        (x, y): (ArrayView2<'_, f64>, ArrayView2<'_, f64>),
        seed: u64,
        stop_by: Option<std::time::Instant>,
    ) -> Result<FittedRegressor> {
        let stopped = |m: &crate::Mlp| match stop_by {
            Some(t) => m.with_seed(seed).stopped_by(t),
            None => m.with_seed(seed),
        };
        let pieces = |p: &crate::Piecewise| match stop_by {
            Some(t) => p.with_seed(seed).stopped_by(t),
            None => p.with_seed(seed),
        };
        Ok(match (self, start) {
            (Self::Linear(r), _) => FittedRegressor::Linear(r.fit(x, y)?),
            (Self::Mlp(m), None) => FittedRegressor::Mlp(stopped(m).fit(x, y)?),
            (Self::Mlp(m), Some(FittedRegressor::Mlp(s))) => {
                FittedRegressor::Mlp(stopped(m).fit_from(s, x, y)?)
            }
            (Self::Piecewise(p), None) => FittedRegressor::Piecewise(pieces(p).fit(x, y)?),
            (Self::Piecewise(p), Some(FittedRegressor::Piecewise(s))) => {
                FittedRegressor::Piecewise(pieces(p).fit_from(s, x, y)?)
            }
            _ => {
                return Err(crate::FitError::InvalidSetting(InvalidSetting {
                    name: "start",
                    value: format!("{self}"),
                    reason: "the start was fitted by another kind of regressor".into(),
                }));
            }
        })
    }
}

/// A fitted stage-2 map h.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum FittedRegressor {
    /// A linear map.
    Linear(FittedLinear),
    /// A network.
    Mlp(FittedMlp),
    /// Networks by pieces.
    Piecewise(FittedPiecewise),
}

impl FittedRegressor {
    /// How the networks were trained (trainer, stop reason, restarts), in
    /// words; `None` for a linear map. Networks by pieces say it of their
    /// global network.
    pub fn training_summary(&self) -> Option<String> {
        match self {
            Self::Linear(_) => None,
            Self::Mlp(m) => Some(m.training_summary()),
            Self::Piecewise(p) => {
                Some(format!("global network: {}", p.global().training_summary()))
            }
        }
    }

    /// Whether the fit's time ran out (`stop_by` of
    /// [`RegressorConfig::fit_from`]) before some network ended its
    /// training on its own: it ships trained as far as it got.
    pub fn stopped_at_deadline(&self) -> bool {
        let stopped = |m: &FittedMlp| m.reports().iter().any(|r| r.reason.is_deadline());
        match self {
            Self::Linear(_) => false,
            Self::Mlp(m) => stopped(m),
            Self::Piecewise(p) => stopped(p.global()) || p.experts().iter().any(stopped),
        }
    }
}

impl Predictor for FittedRegressor {
    fn n_inputs(&self) -> usize {
        match self {
            Self::Linear(m) => m.n_inputs(),
            Self::Mlp(m) => m.n_inputs(),
            Self::Piecewise(m) => m.n_inputs(),
        }
    }

    fn n_outputs(&self) -> usize {
        match self {
            Self::Linear(m) => m.n_outputs(),
            Self::Mlp(m) => m.n_outputs(),
            Self::Piecewise(m) => m.n_outputs(),
        }
    }

    fn predict_into(&self, x: &[f64], out: &mut [f64]) -> Result<()> {
        match self {
            Self::Linear(m) => m.predict_into(x, out),
            Self::Mlp(m) => m.predict_into(x, out),
            Self::Piecewise(m) => m.predict_into(x, out),
        }
    }
}
