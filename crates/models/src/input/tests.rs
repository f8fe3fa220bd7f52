use super::*;
use crate::rng::experiment_rng;
use between_samples::interpolate;

#[test]
fn interpolation_holds_the_ends_for_any_index() {
    let samples = [1.0, 3.0, 7.0];
    assert_eq!(interpolate(&samples, 0.5).to_bits(), 2.0f64.to_bits());
    assert_eq!(interpolate(&samples, 1.25).to_bits(), 4.0f64.to_bits());
    for past in [2.0, 2.5, 1e300, f64::INFINITY] {
        assert_eq!(
            interpolate(&samples, past).to_bits(),
            7.0f64.to_bits(),
            "{past}"
        );
    }
    assert_eq!(
        interpolate(&samples, f64::NEG_INFINITY).to_bits(),
        1.0f64.to_bits()
    );
    assert!(interpolate(&samples, f64::NAN).is_nan());
    assert!(interpolate(&[4.0], f64::NAN).is_nan());
    assert_eq!(interpolate(&[4.0], 0.3).to_bits(), 4.0f64.to_bits());
    assert_eq!(interpolate(&[], 0.3).to_bits(), 0.0f64.to_bits());
}

/// A slalom's 0.6 Hz sine sampled at 50 Hz, read between its samples:
/// the cubic reading within 1e-6 of the sine itself (the bound of the
/// cubic through four nodes, (h w)^4 9 / 384, is 7.5e-7), the linear one
/// 7e-4 off ((h w)^2 / 8); every sample read as itself. (Its phase keeps
/// two samples from straddling a peak at equal values, which are read
/// as a hold.)
#[test]
fn a_smooth_signal_is_read_by_its_cubic_and_a_held_one_straight() {
    let (h, w) = (0.02, std::f64::consts::TAU * 0.6);
    let sine = |t: f64| (w * t + 0.3).sin();
    let samples: Vec<f64> = (0..200).map(|k| sine(k as f64 * h)).collect();
    let (mut cubic, mut linear) = (0.0f64, 0.0f64);
    for step in 0..199 * 40 {
        let t = step as f64 * h / 40.0;
        cubic = cubic.max((InputSignal::sampled_value_at(t, h, &samples) - sine(t)).abs());
        if (1.0..198.0).contains(&(t / h)) {
            linear = linear.max((InputSignal::linear_value_at(t, h, &samples) - sine(t)).abs());
        }
    }
    let bound = (h * w).powi(4) * 9.0 / 384.0;
    // The first and last intervals are read straight.
    let ends = (h * w).powi(2) / 8.0;
    assert!(cubic <= ends * 1.01, "{cubic}");
    let mut inner = 0.0f64;
    for step in 40..197 * 40 {
        let t = step as f64 * h / 40.0;
        inner = inner.max((InputSignal::sampled_value_at(t, h, &samples) - sine(t)).abs());
    }
    assert!(
        inner <= bound * 1.01 && inner < 1e-6,
        "{inner} against {bound}"
    );
    assert!(
        linear > 0.9 * ends && linear > 500.0 * inner,
        "{linear} {inner}"
    );
    for (k, s) in samples.iter().enumerate() {
        assert_eq!(
            InputSignal::sampled_value_at(k as f64, 1.0, &samples).to_bits(),
            s.to_bits()
        );
    }
    // A held signal stays flat where it holds and straight across its
    // steps, never past them.
    let held = [0.0, 0.0, 1.0, 1.0, 1.0, -2.0, -2.0, 0.5, 3.0, 3.0];
    for step in 0..90 {
        let x = step as f64 / 10.0;
        let k = x.floor() as usize;
        let read = InputSignal::sampled_value_at(x, 1.0, &held);
        let (a, b) = (held[k], held[k + 1]);
        assert!(read >= a.min(b) && read <= a.max(b), "{x}: {read}");
        if a.to_bits() == b.to_bits() {
            assert_eq!(read.to_bits(), a.to_bits());
        }
    }
}

#[test]
fn chicane_is_zero_outside_its_window_and_matches_the_formula() {
    let c = InputSignal::chicane(0.2).unwrap();
    assert_eq!(c.value_at(0.5, 0.02, &[]).to_bits(), 0);
    assert_eq!(c.value_at(9.5, 0.02, &[]).to_bits(), 0);
    // t = 4: sin(3 pi / 2) sin(3 pi / 8)^2 = -(0.9238795...)^2
    let want = -0.2 * 0.923_879_532_511_286_7_f64.powi(2);
    assert!((c.value_at(4.0, 0.02, &[]) - want).abs() < 1e-15);
    let mut u = vec![0.0; 500];
    c.fill(0.02, &mut experiment_rng(0, 0), &mut u).unwrap();
    assert!((u[200] - want).abs() < 1e-15);
}

#[test]
fn white_noise_has_the_requested_variance() {
    let w = InputSignal::white_gaussian(2.0).unwrap();
    let mut u = vec![0.0; 100_000];
    w.fill(1.0, &mut experiment_rng(3, 1), &mut u).unwrap();
    let mean = u.iter().sum::<f64>() / u.len() as f64;
    let var = u.iter().map(|v| v * v).sum::<f64>() / u.len() as f64;
    // Standard errors: 0.0063 for the mean, 0.018 for the variance.
    assert!(mean.abs() < 0.03, "{mean}");
    assert!((var - 4.0).abs() < 0.08, "{var}");
}

/// A sequence's cuts are the order statistics of uniform draws: with
/// three parts the first cut's mean is a third of the record, the
/// second's two thirds (each within four standard errors over 2000
/// experiments), and every sample belongs to its stretch's part.
#[test]
fn a_sequence_cuts_the_record_at_uniform_times() {
    let level = |v: f64| InputSignal::steps((v, v), (1.0, 1.0)).unwrap();
    let three = InputSignal::sequence(vec![level(1.0), level(2.0), level(3.0)]).unwrap();
    let n = 300;
    let mut u = vec![0.0; n];
    let (mut first, mut second) = (0.0, 0.0);
    for e in 0..2000 {
        three.fill(0.1, &mut experiment_rng(6, e), &mut u).unwrap();
        assert!(u.windows(2).all(|w| w[0] <= w[1]), "{u:?}");
        assert!(u.iter().all(|v| [1.0, 2.0, 3.0].contains(v)));
        first += u.iter().filter(|v| v.to_bits() == 1f64.to_bits()).count() as f64 / 2000.0;
        second += u.iter().filter(|v| **v < 3.0).count() as f64 / 2000.0;
    }
    // sd of the minimum of two uniforms on [0, 300]: 300 / sqrt(18).
    let error = 4.0 * 300.0 / 18f64.sqrt() / 2000f64.sqrt();
    assert!((first - 100.0).abs() < error, "{first}");
    assert!((second - 200.0).abs() < error, "{second}");
    // Each part at its own times: a ramp of k after a hold shows k at k.
    let ramp = InputSignal::fixed((0..n).map(|k| k as f64).collect()).unwrap();
    let held_then_ramp = InputSignal::sequence(vec![level(-1.0), ramp]).unwrap();
    held_then_ramp
        .fill(0.1, &mut experiment_rng(6, 3), &mut u)
        .unwrap();
    let cut = u.iter().position(|v| *v >= 0.0).unwrap_or(n);
    assert!(cut > 0 && cut < n, "{cut}");
    assert!(u[..cut].iter().all(|v| v.to_bits() == (-1f64).to_bits()));
    assert!(
        u[cut..]
            .iter()
            .enumerate()
            .all(|(i, v)| v.to_bits() == ((cut + i) as f64).to_bits())
    );
    // A band noise on a short stretch keeps its band: it is drawn as a
    // whole record.
    let noise =
        InputSignal::filtered_noise(0.0, Drawn::fixed(0.5), 4, Drawn::fixed(1.0), 0.0).unwrap();
    let rest = level(0.0);
    let mixed = InputSignal::sequence(vec![noise.clone(), rest.clone(), noise]).unwrap();
    mixed.check_sampling(0.1, n).unwrap();
    for e in 0..50 {
        mixed.fill(0.1, &mut experiment_rng(6, e), &mut u).unwrap();
    }
}

#[test]
fn mixtures_and_sequences_refuse_what_no_family_could_be() {
    let rest = InputSignal::steps((0.0, 0.0), (1.0, 1.0)).unwrap();
    let e = |r: Result<InputSignal>| r.unwrap_err().to_string();
    assert!(e(InputSignal::one_of(vec![], vec![])).contains("no parts"));
    assert!(e(InputSignal::one_of(vec![rest.clone()], vec![1.0, 2.0])).contains("1 part"));
    let zero = e(InputSignal::one_of(
        vec![rest.clone(), rest.clone()],
        vec![1.0, 0.0],
    ));
    assert!(zero.contains("0 for part 2"), "{zero}");
    assert!(e(InputSignal::sequence(vec![rest.clone()])).contains("two or more"));
    let mut deep = rest.clone();
    for _ in 0..MAX_INPUT_NESTING - 1 {
        deep = InputSignal::sequence(vec![deep, rest.clone()]).unwrap();
    }
    assert_eq!(deep.depth(), MAX_INPUT_NESTING);
    let too_deep = e(InputSignal::one_of(vec![deep], vec![1.0]));
    assert!(too_deep.contains("nested 5 deep"), "{too_deep}");
    // A mixture of one deterministic part is that part; a sequence
    // never is (its cuts are drawn).
    let chicane = InputSignal::chicane(0.1).unwrap();
    assert!(
        InputSignal::one_of(vec![chicane.clone()], vec![2.0])
            .unwrap()
            .is_deterministic()
    );
    assert!(
        !InputSignal::sequence(vec![chicane.clone(), chicane])
            .unwrap()
            .is_deterministic()
    );
}

#[test]
fn fixed_signals_are_checked_and_interpolated() {
    assert!(InputSignal::fixed(vec![]).is_err());
    assert!(InputSignal::fixed(vec![1.0, f64::NAN]).is_err());
    assert!(InputSignal::white_gaussian(0.0).is_err());
    let f = InputSignal::fixed(vec![0.0, 2.0, 4.0]).unwrap();
    let mut u = vec![0.0; 4];
    assert!(f.fill(0.1, &mut experiment_rng(0, 0), &mut u).is_err());
    let s = [0.0, 2.0, 4.0];
    assert!((f.value_at(0.15, 0.1, &s) - 3.0).abs() < 1e-12);
    assert!((f.value_at(5.0, 0.1, &s) - 4.0).abs() < 1e-12);
    assert!((f.value_at(-1.0, 0.1, &s) - 0.0).abs() < 1e-12);
}
