//! The figures people read: estimates against the true values, one panel
//! per parameter, with the bisector dashed and the least-squares line solid,
//! as in the paper's Figures 3 to 8, 11 and 12. SVG via plotters, with no
//! system fonts needed (text is left to the viewer).
//!
//! ```
//! use twostage_plot::{Panel, estimates_vs_truth};
//! let truth = [0.1, 0.5, -0.3, 0.8];
//! let estimate = [0.12, 0.45, -0.28, 0.83];
//! let panel = Panel { caption: "TS", name: "theta", truth: &truth, estimate: &estimate, range: (-0.9, 0.9) };
//! let svg = estimates_vs_truth("Figure 8: TS", &[panel])?;
//! assert!(svg.starts_with("<svg") && svg.contains("Figure 8"));
//! # Ok::<(), twostage_plot::PlotError>(())
//! ```
#![deny(missing_docs)]

use plotters::prelude::*;
use thiserror::Error;

/// Why a figure could not be drawn.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum PlotError {
    /// The data do not make a figure.
    #[error("cannot plot: {0}")]
    Data(String),
    /// The drawing backend failed.
    #[error("drawing failed: {0}")]
    Drawing(String),
}

/// One parameter's points: estimate against truth on a given range.
#[derive(Debug, Clone, Copy)]
pub struct Panel<'a> {
    /// The panel's caption, e.g. the method (empty for none).
    pub caption: &'a str,
    /// The parameter's name, for the axis labels.
    pub name: &'a str,
    /// True values.
    pub truth: &'a [f64],
    /// Estimates, one per true value (non-finite ones are skipped).
    pub estimate: &'a [f64],
    /// Axis range, usually the prior box.
    pub range: (f64, f64),
}

/// The least-squares line `estimate = a + b truth` over the finite pairs.
pub fn least_squares_line(truth: &[f64], estimate: &[f64]) -> Option<(f64, f64)> {
    let pairs: Vec<(f64, f64)> = truth
        .iter()
        .zip(estimate)
        .filter(|(t, e)| t.is_finite() && e.is_finite())
        .map(|(t, e)| (*t, *e))
        .collect();
    let n = pairs.len() as f64;
    if pairs.len() < 2 {
        return None;
    }
    let (mt, me) = (
        pairs.iter().map(|p| p.0).sum::<f64>() / n,
        pairs.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let stt: f64 = pairs.iter().map(|p| (p.0 - mt).powi(2)).sum();
    let ste: f64 = pairs.iter().map(|p| (p.0 - mt) * (p.1 - me)).sum();
    if stt <= 0.0 {
        return None;
    }
    let b = ste / stt;
    Some((me - b * mt, b))
}

fn drawing<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError::Drawing(e.to_string())
}

/// Draw the panels side by side and return the SVG text.
///
/// # Errors
/// [`PlotError::Data`] for no panels, mismatched lengths or an empty range;
/// [`PlotError::Drawing`] if the backend fails.
pub fn estimates_vs_truth(title: &str, panels: &[Panel<'_>]) -> Result<String, PlotError> {
    if panels.is_empty() {
        return Err(PlotError::Data("no panels".into()));
    }
    for p in panels {
        if p.truth.len() != p.estimate.len() {
            return Err(PlotError::Data(format!(
                "{}: {} true values but {} estimates",
                p.name,
                p.truth.len(),
                p.estimate.len()
            )));
        }
        let (lo, hi) = p.range;
        if lo.is_nan() || hi.is_nan() || lo >= hi {
            return Err(PlotError::Data(format!(
                "{}: empty range {:?}",
                p.name, p.range
            )));
        }
    }
    let mut svg = String::new();
    {
        let width = 420 * panels.len() as u32;
        let root = SVGBackend::with_string(&mut svg, (width, 440)).into_drawing_area();
        root.fill(&WHITE).map_err(drawing)?;
        let root = root.titled(title, ("sans-serif", 20)).map_err(drawing)?;
        let areas = root.split_evenly((1, panels.len()));
        for (area, p) in areas.iter().zip(panels) {
            let (lo, hi) = p.range;
            let mut chart = ChartBuilder::on(area)
                .caption(p.caption, ("sans-serif", 15))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(55)
                .build_cartesian_2d(lo..hi, lo..hi)
                .map_err(drawing)?;
            chart
                .configure_mesh()
                .x_desc(format!("true {}", p.name))
                .y_desc(format!("estimated {}", p.name))
                .disable_mesh()
                .draw()
                .map_err(drawing)?;
            let points = p
                .truth
                .iter()
                .zip(p.estimate)
                .filter(|(t, e)| t.is_finite() && e.is_finite())
                .map(|(t, e)| Circle::new((*t, e.clamp(lo, hi)), 2, BLUE.mix(0.6).filled()));
            chart.draw_series(points).map_err(drawing)?;
            chart
                .draw_series(DashedLineSeries::new(
                    vec![(lo, lo), (hi, hi)],
                    6,
                    4,
                    BLACK.into(),
                ))
                .map_err(drawing)?;
            if let Some((a, b)) = least_squares_line(p.truth, p.estimate) {
                let line = [(lo, a + b * lo), (hi, a + b * hi)];
                chart
                    .draw_series(LineSeries::new(line, RED.stroke_width(2)))
                    .map_err(drawing)?;
            }
        }
        root.present().map_err(drawing)?;
    }
    Ok(svg)
}

/// One curve of a learning-curve figure: RMSE against the number of
/// training simulations.
#[derive(Debug, Clone, Copy)]
pub struct Curve<'a> {
    /// The parameter's name.
    pub name: &'a str,
    /// Training simulations m, increasing.
    pub simulations: &'a [usize],
    /// RMSE at each m (non-finite values are skipped).
    pub rmse: &'a [f64],
    /// A floor to draw dashed, e.g. the Bayes-optimal RMSE, if known.
    pub limit: Option<f64>,
}

/// Draw RMSE against m on log-log axes, one panel per parameter, and
/// return the SVG text.
///
/// ```
/// use twostage_plot::{Curve, learning_curve};
/// let m = [250, 500, 1000, 2000];
/// let rmse = [0.08, 0.05, 0.035, 0.03];
/// let curve = Curve { name: "theta", simulations: &m, rmse: &rmse, limit: Some(0.017) };
/// let svg = learning_curve("Learning curve", &[curve])?;
/// assert!(svg.starts_with("<svg") && svg.contains("Learning curve"));
/// # Ok::<(), twostage_plot::PlotError>(())
/// ```
///
/// # Errors
/// [`PlotError::Data`] for no curves, mismatched lengths, or no positive
/// finite RMSE; [`PlotError::Drawing`] if the backend fails.
pub fn learning_curve(title: &str, curves: &[Curve<'_>]) -> Result<String, PlotError> {
    if curves.is_empty() {
        return Err(PlotError::Data("no curves".into()));
    }
    for c in curves {
        if c.simulations.len() != c.rmse.len() || c.simulations.is_empty() {
            return Err(PlotError::Data(format!(
                "{}: {} sizes but {} RMSE values",
                c.name,
                c.simulations.len(),
                c.rmse.len()
            )));
        }
        if !c.rmse.iter().any(|r| r.is_finite() && *r > 0.0) {
            return Err(PlotError::Data(format!(
                "{}: no positive finite RMSE",
                c.name
            )));
        }
    }
    let mut svg = String::new();
    {
        let width = 420 * curves.len() as u32;
        let root = SVGBackend::with_string(&mut svg, (width, 400)).into_drawing_area();
        root.fill(&WHITE).map_err(drawing)?;
        let root = root.titled(title, ("sans-serif", 20)).map_err(drawing)?;
        let areas = root.split_evenly((1, curves.len()));
        for (area, c) in areas.iter().zip(curves) {
            let points: Vec<(f64, f64)> = c
                .simulations
                .iter()
                .zip(c.rmse)
                .filter(|(m, r)| **m > 0 && r.is_finite() && **r > 0.0)
                .map(|(m, r)| (*m as f64, *r))
                .collect();
            let (x_lo, x_hi) = points
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
            let (mut y_lo, mut y_hi) = points
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.1), b.max(p.1)));
            if let Some(l) = c.limit.filter(|l| l.is_finite() && *l > 0.0) {
                y_lo = y_lo.min(l);
                y_hi = y_hi.max(l);
            }
            let mut chart = ChartBuilder::on(area)
                .caption(c.name, ("sans-serif", 15))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(
                    (x_lo / 1.2..x_hi * 1.2).log_scale(),
                    (y_lo / 1.3..y_hi * 1.3).log_scale(),
                )
                .map_err(drawing)?;
            chart
                .configure_mesh()
                .x_desc("training simulations m")
                .y_desc(format!("validation RMSE of {}", c.name))
                .draw()
                .map_err(drawing)?;
            chart
                .draw_series(LineSeries::new(points.clone(), BLUE.stroke_width(2)))
                .map_err(drawing)?;
            chart
                .draw_series(points.iter().map(|p| Circle::new(*p, 3, BLUE.filled())))
                .map_err(drawing)?;
            if let Some(l) = c.limit.filter(|l| l.is_finite() && *l > 0.0) {
                chart
                    .draw_series(DashedLineSeries::new(
                        vec![(x_lo / 1.2, l), (x_hi * 1.2, l)],
                        6,
                        4,
                        BLACK.into(),
                    ))
                    .map_err(drawing)?;
            }
        }
        root.present().map_err(drawing)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_least_squares_line_of_an_exact_line() {
        let t = [0.0, 1.0, 2.0, 3.0];
        let e = [1.0, 3.0, 5.0, 7.0];
        let (a, b) = least_squares_line(&t, &e).unwrap_or((0.0, 0.0));
        assert!((a - 1.0).abs() < 1e-12 && (b - 2.0).abs() < 1e-12);
        assert!(least_squares_line(&[1.0], &[1.0]).is_none());
        assert!(least_squares_line(&[1.0, 1.0], &[0.0, 2.0]).is_none());
    }

    #[test]
    fn a_figure_has_one_panel_per_parameter_and_refuses_bad_data() {
        let (t, e) = ([1.0, 2.0, 3.0], [1.1, 1.9, f64::NAN]);
        let panel = Panel {
            caption: "PF",
            name: "pK1",
            truth: &t,
            estimate: &e,
            range: (0.0, 4.0),
        };
        let svg = estimates_vs_truth(
            "two",
            &[
                panel,
                Panel {
                    name: "pK2",
                    ..panel
                },
            ],
        )
        .unwrap_or_default();
        assert!(
            svg.contains("true pK1") && svg.contains("true pK2"),
            "{svg}"
        );
        // Two finite points per panel, as circles.
        assert_eq!(svg.matches("<circle").count(), 4);
        assert!(estimates_vs_truth("none", &[]).is_err());
        let short = Panel {
            caption: "PF",
            name: "x",
            truth: &t,
            estimate: &e[..2],
            range: (0.0, 1.0),
        };
        assert!(estimates_vs_truth("bad", &[short]).is_err());
        let empty = Panel {
            caption: "PF",
            name: "x",
            truth: &t,
            estimate: &e,
            range: (1.0, 1.0),
        };
        assert!(estimates_vs_truth("bad", &[empty]).is_err());
    }

    #[test]
    fn a_learning_curve_draws_one_marker_per_finite_point_and_refuses_bad_data() {
        let m = [250, 500, 1000, 2000];
        let rmse = [0.08, f64::NAN, 0.035, 0.03];
        let curve = Curve {
            name: "theta",
            simulations: &m,
            rmse: &rmse,
            limit: None,
        };
        let svg = learning_curve("curve", &[curve]).unwrap_or_default();
        assert_eq!(svg.matches("<circle").count(), 3, "the NaN is skipped");
        let short = Curve {
            name: "theta",
            simulations: &m[..2],
            rmse: &rmse,
            limit: None,
        };
        assert!(learning_curve("curve", &[short]).is_err());
        let zero = Curve {
            name: "theta",
            simulations: &m,
            rmse: &[0.0; 4],
            limit: None,
        };
        assert!(learning_curve("curve", &[zero]).is_err());
        assert!(learning_curve("curve", &[]).is_err());
    }
}

/// One output signal of a record beside the model's simulation of it.
#[derive(Debug, Clone, Copy)]
pub struct Trace<'a> {
    /// The signal's name.
    pub name: &'a str,
    /// The measured samples.
    pub measured: &'a [f64],
    /// The simulated samples (same length).
    pub simulated: &'a [f64],
}

/// Draw each output's record (black) and simulation (blue) against time,
/// one panel per output, and return the SVG text.
///
/// ```
/// use twostage_plot::{Trace, record_vs_simulation};
/// let trace = Trace { name: "level", measured: &[1.0, 2.0, 2.5], simulated: &[1.0, 1.8, 2.6] };
/// let svg = record_vs_simulation("record 7", 2.0, &[trace])?;
/// assert!(svg.starts_with("<svg") && svg.contains("record 7") && svg.contains("level"));
/// # Ok::<(), twostage_plot::PlotError>(())
/// ```
///
/// # Errors
/// [`PlotError::Data`] for no traces, mismatched or empty signals, or
/// no finite sample; [`PlotError::Drawing`] if the backend fails.
pub fn record_vs_simulation(
    title: &str,
    sample_time: f64,
    traces: &[Trace<'_>],
) -> Result<String, PlotError> {
    if traces.is_empty() {
        return Err(PlotError::Data("no outputs to draw".into()));
    }
    for t in traces {
        if t.measured.len() != t.simulated.len() || t.measured.is_empty() {
            return Err(PlotError::Data(format!(
                "{}: {} measured and {} simulated samples",
                t.name,
                t.measured.len(),
                t.simulated.len()
            )));
        }
    }
    let mut svg = String::new();
    {
        let height = 260 * traces.len() as u32;
        let root = SVGBackend::with_string(&mut svg, (720, height)).into_drawing_area();
        root.fill(&WHITE).map_err(drawing)?;
        let root = root.titled(title, ("sans-serif", 20)).map_err(drawing)?;
        let areas = root.split_evenly((traces.len(), 1));
        for (area, t) in areas.iter().zip(traces) {
            let finite = t
                .measured
                .iter()
                .chain(t.simulated)
                .filter(|v| v.is_finite());
            let (lo, hi) = finite.fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(*v), b.max(*v)));
            if lo > hi {
                return Err(PlotError::Data(format!("{}: no finite sample", t.name)));
            }
            let pad = if hi > lo { 0.05 * (hi - lo) } else { 1.0 };
            let end = sample_time * (t.measured.len() - 1).max(1) as f64;
            let mut chart = ChartBuilder::on(area)
                .caption(t.name, ("sans-serif", 15))
                .margin(12)
                .x_label_area_size(35)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..end, lo - pad..hi + pad)
                .map_err(drawing)?;
            chart
                .configure_mesh()
                .x_desc("time")
                .draw()
                .map_err(drawing)?;
            let line = |values: &[f64]| -> Vec<(f64, f64)> {
                values
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| v.is_finite())
                    .map(|(k, v)| (sample_time * k as f64, *v))
                    .collect()
            };
            chart
                .draw_series(LineSeries::new(line(t.measured), BLACK.stroke_width(1)))
                .map_err(drawing)?
                .label("record")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK));
            chart
                .draw_series(LineSeries::new(line(t.simulated), BLUE.stroke_width(2)))
                .map_err(drawing)?
                .label("model at the estimate, noise-free")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLUE));
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(drawing)?;
        }
        root.present().map_err(drawing)?;
    }
    Ok(svg)
}
