//! What an input signal's shape is like, in a few numbers, and how far a
//! record's shape lies from a family's: the judgement that tells a step,
//! a slalom or random steering from a family of sine bursts whose level,
//! size and mean frequency ([`crate::input_summary`]) they share.
//!
//! The shape is the signal's autocorrelation at [`SHAPE_LAGS`], spread
//! from a few samples to a few hundred: how much of the signal is still
//! there after a lag. A held steer keeps all of it, a burst between rests
//! loses it once the lag passes the burst, a slalom gets it back every
//! period, broadband noise loses it within a few samples. The estimate
//! is the biased one (sums over the overlap divided by the whole
//! record's sum of squares, Box and Jenkins, "Time Series Analysis",
//! Section 2.1.5), so a lag as long as the record gives 0 and the numbers
//! are defined for any length.
//!
//! A family is a set of reference shapes; a record's distance from it is
//! the root mean square of its [`NEIGHBOURS`] nearest reference shapes'
//! Euclidean distances (a k-nearest-neighbour density estimate:
//! Loftsgaarden and Quesenberry, 1965), in the family's standardized
//! coordinates.

/// The lags, in samples, of a shape's autocorrelations: about 2.5 times
/// apart, from 2 samples to 200.
pub const SHAPE_LAGS: [usize; 7] = [2, 5, 12, 25, 50, 100, 200];

/// How many numbers describe one signal's shape.
pub const SHAPE_LEN: usize = SHAPE_LAGS.len();

/// How many nearest reference shapes a distance averages over: few enough
/// that a sample of a few hundred shapes resolves a family's edges
/// (docs/decisions/078-an-input-is-judged-by-its-shape.md).
pub const NEIGHBOURS: usize = 5;

/// The autocorrelations of `x` at [`SHAPE_LAGS`]: `sum_t (x_t - m)
/// (x_(t+L) - m) / sum_t (x_t - m)^2` over the overlap `t < N - L`, with
/// `m` the mean. A lag of at least the record's length gives 0; a
/// constant signal, which keeps all of itself, gives the overlap's share
/// `(N - L) / N` (the limit of a signal that varies ever more slowly).
///
/// ```
/// use twostage_kernels::input_shape::{SHAPE_LEN, autocorrelations};
/// let mut rho = [0.0; SHAPE_LEN];
/// // A sinusoid of period 10 samples: at lag 5 half a period, so about -1.
/// let x: Vec<f64> = (0..1000).map(|k| (0.2 * std::f64::consts::PI * k as f64).sin()).collect();
/// autocorrelations(&x, &mut rho);
/// assert!((rho[1] + 0.995).abs() < 1e-3);
/// // A held level keeps all of itself, but for the overlap.
/// autocorrelations(&[3.0; 400], &mut rho);
/// assert_eq!(rho[6], 0.5);
/// ```
pub fn autocorrelations(x: &[f64], out: &mut [f64; SHAPE_LEN]) {
    let n = x.len();
    if n == 0 {
        *out = [0.0; SHAPE_LEN];
        return;
    }
    let mut sum = 0.0;
    for v in x {
        sum += v;
    }
    let mean = sum / n as f64;
    let mut squares = 0.0;
    for v in x {
        squares += (v - mean) * (v - mean);
    }
    for (rho, &lag) in out.iter_mut().zip(&SHAPE_LAGS) {
        *rho = if lag >= n {
            0.0
        } else if squares > 0.0 {
            let mut products = 0.0;
            for (a, b) in x[..n - lag].iter().zip(&x[lag..]) {
                products += (a - mean) * (b - mean);
            }
            products / squares
        } else {
            (n - lag) as f64 / n as f64
        };
    }
}

/// The root mean square of the Euclidean distances from `point` to its
/// `nearest.len()` nearest rows of `reference` (row-major, `point.len()`
/// columns), leaving out row `skip` where given (a reference row's own
/// distance from the others). `nearest` is scratch for the squared
/// distances kept; where fewer rows than its length are left, the mean
/// is over those there are, and over none it is infinite.
///
/// ```
/// use twostage_kernels::input_shape::nearest_distance;
/// let reference = [0.0, 0.0, 3.0, 4.0, 0.0, 1.0];
/// let mut nearest = [0.0; 2];
/// // From the origin: 0 and 1 away; the root mean square is sqrt(1 / 2).
/// let d = nearest_distance(&reference, &[0.0, 0.0], None, &mut nearest);
/// assert!((d - 0.5f64.sqrt()).abs() < 1e-15);
/// // The first row left out: 1 and 5 away.
/// let d = nearest_distance(&reference, &[0.0, 0.0], Some(0), &mut nearest);
/// assert!((d - 13f64.sqrt()).abs() < 1e-15);
/// ```
pub fn nearest_distance(
    reference: &[f64],
    point: &[f64],
    skip: Option<usize>,
    nearest: &mut [f64],
) -> f64 {
    let dim = point.len();
    let k = nearest.len();
    if dim == 0 || k == 0 {
        return 0.0;
    }
    let mut kept = 0;
    for (row, values) in reference.chunks_exact(dim).enumerate() {
        if skip == Some(row) {
            continue;
        }
        let mut squared = 0.0;
        for (a, b) in values.iter().zip(point) {
            squared += (a - b) * (a - b);
        }
        // Insertion into the sorted `nearest[..kept]`, the largest
        // dropped once k are kept.
        if kept < k {
            kept += 1;
        } else if squared >= nearest[k - 1] {
            continue;
        }
        let mut i = kept - 1;
        while i > 0 && nearest[i - 1] > squared {
            nearest[i] = nearest[i - 1];
            i -= 1;
        }
        nearest[i] = squared;
    }
    if kept == 0 {
        return f64::INFINITY;
    }
    let mut sum = 0.0;
    for v in &nearest[..kept] {
        sum += v;
    }
    crate::sqrt(sum / kept as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The autocorrelations against a direct computation of the
    /// definition with a second summation (pairs formed by index).
    #[test]
    fn autocorrelations_match_the_definition() {
        let x: [f64; 300] = core::array::from_fn(|k| {
            let t = k as f64;
            (0.05 * t).sin() + 0.3 * (0.9 * t).cos() + if k > 150 { 0.4 } else { 0.0 }
        });
        let mut rho = [0.0; SHAPE_LEN];
        autocorrelations(&x, &mut rho);
        let mean = x.iter().sum::<f64>() / 300.0;
        let c = |lag: usize| -> f64 {
            (lag..300)
                .map(|t| (x[t] - mean) * (x[t - lag] - mean))
                .sum::<f64>()
        };
        for (j, &lag) in SHAPE_LAGS.iter().enumerate() {
            let expected = if lag >= 300 { 0.0 } else { c(lag) / c(0) };
            assert!((rho[j] - expected).abs() < 1e-12, "lag {lag}: {}", rho[j]);
        }
        // Lag 200 of 300 samples: a third of the record overlaps.
        assert!(rho[6].abs() < 0.5);
    }

    #[test]
    fn a_short_record_has_no_long_lags() {
        let mut rho = [9.0; SHAPE_LEN];
        let x = [1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0];
        autocorrelations(&x, &mut rho);
        // Lag 2 of an alternating signal: 8 of 10 products are +1.
        assert!((rho[0] - 0.8).abs() < 1e-15);
        assert!((rho[1] + 0.5).abs() < 1e-15);
        assert!(rho[2..].iter().all(|v| *v == 0.0));
        autocorrelations(&[], &mut rho);
        assert!(rho.iter().all(|v| *v == 0.0));
    }

    /// Against sorting every distance: the same neighbours, any order.
    #[test]
    fn the_nearest_distance_is_that_of_the_sorted_distances() {
        let reference: [f64; 60] = core::array::from_fn(|i| ((i * 37 % 23) as f64 - 11.0) / 3.0);
        let point = [0.3, -0.7, 1.1];
        for k in [1usize, 3, 10, 20, 25] {
            let mut nearest = [0.0; 25];
            let found = nearest_distance(&reference, &point, Some(4), &mut nearest[..k]);
            let mut all = [0.0; 19];
            let mut n = 0;
            for (row, values) in reference.chunks_exact(3).enumerate() {
                if row != 4 {
                    all[n] = values
                        .iter()
                        .zip(&point)
                        .map(|(a, b)| (a - b) * (a - b))
                        .sum();
                    n += 1;
                }
            }
            all.sort_by(f64::total_cmp);
            let kept = k.min(19);
            let expected = (all[..kept].iter().sum::<f64>() / kept as f64).sqrt();
            assert!(
                (found - expected).abs() < 1e-12,
                "k {k}: {found} {expected}"
            );
        }
        assert!(nearest_distance(&[], &point, None, &mut [0.0; 3]).is_infinite());
    }
}
