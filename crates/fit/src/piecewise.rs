//! Piecewise networks: a global network routes each record to a specialist
//! trained only on its part of the parameter range.

use crate::InvalidSetting;
use ndarray::{ArrayView2, Axis};
use serde::{Deserialize, Serialize};

use crate::error::{FitError, Result};
use crate::mlp::{FittedMlp, Mlp};
use crate::{Predictor, Regressor};

/// A global network, then one expert per piece of the first parameter's
/// range.
///
/// When the map from features to parameters oscillates (the benchmark's
/// sin(50 theta^2)), one small network cannot follow it everywhere; a
/// coarse global estimate is accurate enough to say which piece of the
/// range a record belongs to, and a specialist trained only on that piece
/// (widened by a margin on both sides, so records near a boundary that the
/// global estimate puts in the wrong piece are still inside its expert's
/// training range) does better there.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `pieces` | none | 2..=16 |
/// | `margin` | 0.25 | 0..=1, fraction of a piece's width added on each side |
///
/// ```
/// use ndarray::Array2;
/// use twostage_fit::{MlpParams, Piecewise, Predictor, Regressor};
///
/// // Features that wind around the parameter: x = (t + 0.3 sin 8t, cos 3t).
/// let t = Array2::from_shape_fn((1200, 1), |(i, _)| i as f64 / 600.0 - 1.0);
/// let x = Array2::from_shape_fn((1200, 2), |(i, j)| {
///     let t = t[[i, 0]];
///     if j == 0 { t + 0.3 * (8.0 * t).sin() } else { (3.0 * t).cos() }
/// });
/// let net = MlpParams::new(&[3])?.seed(2).check()?;
/// let piecewise = Piecewise::new(net.clone(), net.clone(), 4)?.fit(x.view(), t.view())?;
/// let single = net.fit(x.view(), t.view())?;
/// let error = |p: &dyn Predictor| -> f64 {
///     let e = p.predict(x.view()).unwrap() - &t;
///     e.mapv(|v| v * v).mean().unwrap().sqrt()
/// };
/// // Four 3-unit experts follow the winding where one 3-unit network cannot.
/// assert!(error(&piecewise) < 0.2 * error(&single));
/// # Ok::<(), twostage_fit::FitError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Piecewise {
    global: Mlp,
    expert: Mlp,
    pieces: usize,
    margin: f64,
}

impl Piecewise {
    /// `pieces` experts like `expert`, routed by `global`.
    ///
    /// # Errors
    /// [`FitError::InvalidSetting`] for pieces outside 2..=16.
    pub fn new(global: Mlp, expert: Mlp, pieces: usize) -> Result<Self> {
        if !(2..=16).contains(&pieces) {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "pieces",
                value: pieces.to_string(),
                reason: "must lie in 2..=16".into(),
            }));
        }
        Ok(Self {
            global,
            expert,
            pieces,
            margin: 0.25,
        })
    }

    /// The margin added on each side of a piece, as a fraction of its width.
    ///
    /// # Errors
    /// [`FitError::InvalidSetting`] outside [0, 1].
    pub fn margin(mut self, margin: f64) -> Result<Self> {
        if !(0.0..=1.0).contains(&margin) {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "margin",
                value: margin.to_string(),
                reason: "must lie in [0, 1]".into(),
            }));
        }
        self.margin = margin;
        Ok(self)
    }

    /// Number of pieces.
    pub fn pieces(&self) -> usize {
        self.pieces
    }

    /// The global network.
    pub fn global(&self) -> &Mlp {
        &self.global
    }

    /// The same regressor with every network reseeded from `seed`.
    pub fn with_seed(&self, seed: u64) -> Self {
        Self {
            global: self.global.with_seed(seed),
            expert: self.expert.with_seed(seed),
            ..self.clone()
        }
    }

    /// Train `start` further on `x` and `y` ([`Mlp::fit_from`] for the
    /// global network and each expert, on the rows of its piece as `start`
    /// cut them): never worse than `start` on each network's held-out rows,
    /// however early [`Self::stopped_by`] stops it.
    ///
    /// # Errors
    /// A `start` of another shape, or a piece without rows to train on.
    pub fn fit_from(
        &self,
        start: &FittedPiecewise,
        x: ArrayView2<'_, f64>,
        y: ArrayView2<'_, f64>,
    ) -> Result<FittedPiecewise> {
        if start.experts.len() != self.pieces {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "start",
                value: format!("{} pieces", start.experts.len()),
                reason: format!("this regressor has {} pieces", self.pieces),
            }));
        }
        let global = self.global.fit_from(&start.global, x, y)?;
        let margin = self.margin * start.width;
        let first = y.column(0);
        let mut experts = Vec::with_capacity(self.pieces);
        for (piece, expert_start) in start.experts.iter().enumerate() {
            let from = start.start + piece as f64 * start.width - margin;
            let to = start.start + (piece + 1) as f64 * start.width + margin;
            let rows = piece_rows(first, from, to);
            let expert = self.expert_of(piece);
            experts.push(expert.fit_from(
                expert_start,
                x.select(Axis(0), &rows).view(),
                y.select(Axis(0), &rows).view(),
            )?);
        }
        Ok(FittedPiecewise {
            global,
            experts,
            start: start.start,
            width: start.width,
        })
    }

    /// The expert of `piece`, seeded apart from the others.
    fn expert_of(&self, piece: usize) -> Mlp {
        self.expert.with_seed(
            self.expert
                .params()
                .seed_value()
                .wrapping_add(piece as u64 + 1),
        )
    }

    /// The same regressor with every network's training stopped at
    /// `stop_by` ([`Mlp::stopped_by`]).
    pub fn stopped_by(&self, stop_by: std::time::Instant) -> Self {
        Self {
            global: self.global.stopped_by(stop_by),
            expert: self.expert.stopped_by(stop_by),
            ..self.clone()
        }
    }
}

/// A fitted [`Piecewise`] regressor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "FittedPiecewiseFields")]
pub struct FittedPiecewise {
    global: FittedMlp,
    experts: Vec<FittedMlp>,
    /// Lower end of the first piece and the pieces' width, in units of the
    /// first parameter.
    start: f64,
    width: f64,
}

#[derive(Deserialize)]
struct FittedPiecewiseFields {
    global: FittedMlp,
    experts: Vec<FittedMlp>,
    start: f64,
    width: f64,
}

impl TryFrom<FittedPiecewiseFields> for FittedPiecewise {
    type Error = FitError;
    fn try_from(f: FittedPiecewiseFields) -> Result<Self> {
        let (n, q) = (f.global.n_inputs(), f.global.n_outputs());
        if f.experts.is_empty()
            || f.experts.len() > 16
            || f.experts
                .iter()
                .any(|e| e.n_inputs() != n || e.n_outputs() != q)
            || !(f.start.is_finite() && f.width.is_finite() && f.width > 0.0)
        {
            return Err(FitError::ShapeMismatch(format!(
                "stored piecewise networks: {} experts for a global network of {n} inputs and \
                 {q} outputs, pieces from {} of width {}",
                f.experts.len(),
                f.start,
                f.width
            )));
        }
        Ok(Self {
            global: f.global,
            experts: f.experts,
            start: f.start,
            width: f.width,
        })
    }
}

impl FittedPiecewise {
    /// The global network.
    pub fn global(&self) -> &FittedMlp {
        &self.global
    }
    /// The experts, piece by piece.
    pub fn experts(&self) -> &[FittedMlp] {
        &self.experts
    }
    /// Where piece 0 starts and how wide each piece is, on the first
    /// output of the global network: piece `floor((out0 - start) / width)`,
    /// clamped to the pieces.
    pub fn pieces_start_width(&self) -> (f64, f64) {
        (self.start, self.width)
    }
}

impl Regressor for Piecewise {
    type Model = FittedPiecewise;

    fn fit(&self, x: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>) -> Result<FittedPiecewise> {
        let global = self.global.fit(x, y)?;
        let first = y.column(0);
        let (lo, hi) = first
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        let width = (hi - lo) / self.pieces as f64;
        if !(width.is_finite() && width > 0.0) {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "pieces",
                value: self.pieces.to_string(),
                reason: "the first target does not vary: there is nothing to split".into(),
            }));
        }
        let margin = self.margin * width;
        let mut experts = Vec::with_capacity(self.pieces);
        for piece in 0..self.pieces {
            let from = lo + piece as f64 * width - margin;
            let to = lo + (piece + 1) as f64 * width + margin;
            let rows = piece_rows(first, from, to);
            let expert = self.expert_of(piece);
            experts.push(expert.fit(
                x.select(Axis(0), &rows).view(),
                y.select(Axis(0), &rows).view(),
            )?);
        }
        Ok(FittedPiecewise {
            global,
            experts,
            start: lo,
            width,
        })
    }
}

/// The rows whose first target lies in `from..=to`: one piece's.
fn piece_rows(first: ndarray::ArrayView1<'_, f64>, from: f64, to: f64) -> Vec<usize> {
    first
        .iter()
        .enumerate()
        .filter(|(_, v)| (from..=to).contains(*v))
        .map(|(i, _)| i)
        .collect()
}

impl Predictor for FittedPiecewise {
    fn n_inputs(&self) -> usize {
        self.global.n_inputs()
    }

    fn n_outputs(&self) -> usize {
        self.global.n_outputs()
    }

    fn predict_into(&self, x: &[f64], out: &mut [f64]) -> Result<()> {
        self.global.predict_into(x, out)?;
        let position = (out[0] - self.start) / self.width;
        // NaN and out-of-range positions go to the nearest piece.
        let piece = if position.is_nan() {
            0
        } else {
            (position.max(0.0) as usize).min(self.experts.len() - 1)
        };
        self.experts[piece].predict_into(x, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MlpParams;
    use ndarray::Array2;

    #[test]
    fn each_record_gets_the_expert_of_its_global_estimate() {
        let t = Array2::from_shape_fn((600, 1), |(i, _)| i as f64 / 300.0 - 1.0);
        let x = t.mapv(|v| v + 0.2 * (5.0 * v).sin());
        let net = MlpParams::new(&[4]).unwrap().seed(1).check().unwrap();
        let fitted = Piecewise::new(net.clone(), net, 3)
            .unwrap()
            .fit(x.view(), t.view())
            .unwrap();
        // Three pieces over the training targets' range [-1, 599/300 - 1].
        let width = (599.0 / 300.0) / 3.0;
        assert!((fitted.start + 1.0).abs() < 1e-12 && (fitted.width - width).abs() < 1e-12);
        for probe in [-1.5, -0.9, -0.2, 0.4, 0.99, 2.0] {
            let mut global = [0.0];
            fitted.global.predict_into(&[probe], &mut global).unwrap();
            let piece = ((global[0] + 1.0) / width).floor().clamp(0.0, 2.0) as usize;
            let (mut expected, mut got) = ([0.0], [0.0]);
            fitted.experts[piece]
                .predict_into(&[probe], &mut expected)
                .unwrap();
            fitted.predict_into(&[probe], &mut got).unwrap();
            assert_eq!(got[0].to_bits(), expected[0].to_bits(), "x = {probe}");
        }
        let small = MlpParams::new(&[2]).unwrap().check().unwrap();
        assert!(Piecewise::new(small.clone(), small, 1).is_err());
    }

    /// Trained further on more rows, the pieces get better; stopped at
    /// once, they stay as good as they were (each keeps its best held-out
    /// weights, the start's among them), never a network of one step.
    #[test]
    fn trained_further_never_gets_worse() {
        let t = Array2::from_shape_fn((1200, 1), |(i, _)| ((i * 7919) % 1200) as f64 / 600.0 - 1.0);
        let x = t.mapv(|v| v + 0.3 * (4.0 * v).sin());
        let net = MlpParams::new(&[6]).unwrap().seed(2).check().unwrap();
        let piecewise = Piecewise::new(net.clone(), net, 3).unwrap();
        let few = ndarray::s![..150, ..];
        let start = piecewise.fit(x.slice(few), t.slice(few)).unwrap();
        let mse = |f: &FittedPiecewise| {
            let p = crate::Predictor::predict(f, x.view()).unwrap();
            (&p - &t).mapv(|e| e * e).mean().unwrap()
        };
        let further = piecewise.fit_from(&start, x.view(), t.view()).unwrap();
        assert!(
            mse(&further) < mse(&start),
            "{} {}",
            mse(&further),
            mse(&start)
        );
        let stopped = piecewise
            .stopped_by(std::time::Instant::now())
            .fit_from(&start, x.view(), t.view())
            .unwrap();
        assert!(
            mse(&stopped) < 1.1 * mse(&start),
            "{} {}",
            mse(&stopped),
            mse(&start)
        );
        let (a, b) = (start.pieces_start_width(), stopped.pieces_start_width());
        assert_eq!(
            (a.0.to_bits(), a.1.to_bits()),
            (b.0.to_bits(), b.1.to_bits())
        );
        let other = Piecewise::new(
            MlpParams::new(&[6]).unwrap().check().unwrap(),
            MlpParams::new(&[6]).unwrap().check().unwrap(),
            4,
        )
        .unwrap();
        assert!(other.fit_from(&start, x.view(), t.view()).is_err());
    }

    /// A stop time reaches the global network and every expert, by either
    /// trainer: past it, each restart takes one step (one epoch for Adam)
    /// and says the deadline stopped it; a whole fit says nothing of it.
    #[test]
    fn a_stop_time_stops_every_network() {
        let t = Array2::from_shape_fn((300, 1), |(i, _)| i as f64 / 150.0 - 1.0);
        let x = t.mapv(|v| v + 0.2 * (5.0 * v).sin());
        for trainer in [crate::Trainer::LevenbergMarquardt, crate::Trainer::ADAM] {
            let net = MlpParams::new(&[4])
                .unwrap()
                .trainer(trainer)
                .check()
                .unwrap();
            let piecewise = Piecewise::new(net.clone(), net, 3).unwrap();
            let steps = |f: &FittedPiecewise| -> Vec<usize> {
                std::iter::once(&f.global)
                    .chain(&f.experts)
                    .flat_map(|n| n.reports().iter().map(|r| r.iterations))
                    .collect()
            };
            let stopped = piecewise
                .stopped_by(std::time::Instant::now())
                .fit(x.view(), t.view())
                .unwrap();
            assert!(steps(&stopped).iter().all(|&s| s == 1), "{trainer:?}");
            let reasons = |f: &FittedPiecewise| -> Vec<crate::TerminationReason> {
                std::iter::once(&f.global)
                    .chain(&f.experts)
                    .flat_map(|n| n.reports().iter().map(|r| r.reason))
                    .collect()
            };
            assert!(
                reasons(&stopped).iter().all(|r| r.is_deadline()),
                "{trainer:?}: {:?}",
                reasons(&stopped)
            );
            assert!(crate::FittedRegressor::Piecewise(stopped).stopped_at_deadline());
            let whole = piecewise.fit(x.view(), t.view()).unwrap();
            assert!(steps(&whole).iter().all(|&s| s > 1), "{trainer:?}");
            assert!(!crate::FittedRegressor::Piecewise(whole).stopped_at_deadline());
        }
    }
}
