//! The designs against direct computations of what they draw.

use super::*;
use crate::rng::experiment_rng;
use rustfft::FftPlannerScalar;

pub(super) fn filled(design: &Design, sample_time: f64, n: usize, experiment: u64) -> Vec<f64> {
    let mut u = vec![0.0; n];
    design
        .fill(sample_time, &mut experiment_rng(5, experiment), &mut u)
        .unwrap();
    u
}

/// The power of `u` at grid line `k`, by a direct DFT (the second
/// algorithm beside the FFT that made it).
pub(super) fn line_power(u: &[f64], k: usize) -> f64 {
    let n = u.len() as f64;
    let (mut re, mut im) = (0.0, 0.0);
    for (t, v) in u.iter().enumerate() {
        let angle = 2.0 * PI * (k * t % u.len()) as f64 / n;
        re += v * angle.cos();
        im -= v * angle.sin();
    }
    (re * re + im * im) / (n * n)
}

#[test]
fn a_multisine_has_its_lines_in_its_band_and_its_level() {
    let (n, dt) = (512, 0.01);
    let odd = Design::Multisine {
        band: (Drawn::fixed(2.0), Drawn::fixed(20.0)),
        grid: Grid::Odd,
        phases: Phases::Random,
        level: Level::Rms(Drawn::fixed(0.7)),
        spectrum: None,
    };
    let u = filled(&odd, dt, n, 0);
    let rms = (u.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    assert!((rms - 0.7).abs() < 1e-12, "{rms}");
    // Grid spacing 1 / (512 * 0.01) = 0.1953 Hz: lines 11..=102 in band.
    let band = |k: usize| (11..=102).contains(&k);
    let powers: Vec<f64> = (1..n / 2).map(|k| line_power(&u, k)).collect();
    let total: f64 = powers.iter().sum();
    for (i, p) in powers.iter().enumerate() {
        let k = i + 1;
        if band(k) && k % 2 == 1 {
            // Equal lines: each a 1/46 share of the power.
            assert!((p / total - 1.0 / 46.0).abs() < 1e-9, "line {k}: {p}");
        } else {
            assert!(*p < 1e-20 * total, "line {k} outside: {p}");
        }
    }
    // Another experiment, other phases; the same one, the same bits.
    assert_ne!(u, filled(&odd, dt, n, 1));
    assert_eq!(u, filled(&odd, dt, n, 0));
}

#[test]
fn schroeder_phases_lower_the_crest_factor_and_a_peak_level_holds() {
    let (n, dt) = (1024, 1.0);
    let crest = |phases| {
        let d = Design::Multisine {
            band: (Drawn::fixed(0.0), Drawn::fixed(0.2)),
            grid: Grid::Full,
            phases,
            level: Level::Peak(Drawn::fixed(1.0)),
            spectrum: None,
        };
        let u = filled(&d, dt, n, 3);
        let peak = u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!((peak - 1.0).abs() < 1e-12);
        peak / (u.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt()
    };
    let (schroeder, random) = (crest(Phases::Schroeder), crest(Phases::Random));
    assert!(
        schroeder < 2.0 && schroeder < random,
        "{schroeder} vs {random}"
    );
}

#[test]
fn prbs_registers_are_maximal() {
    for order in 2..=MAX_PRBS_ORDER {
        let period = (1usize << order) - 1;
        let d = Design::Prbs {
            order,
            amplitude: Drawn::fixed(1.0),
            hold: 1,
        };
        let u = filled(&d, 1.0, 2 * period, u64::from(order));
        // Periodic with 2^n - 1 bits, and no shorter period that
        // divides it; one more +1 than -1 per period.
        assert_eq!(u[..period], u[period..], "order {order}");
        let ones = u[..period].iter().filter(|v| **v > 0.0).count();
        assert_eq!(2 * ones, period + 1, "order {order}");
        for p in (1..period).filter(|p| period.is_multiple_of(*p)) {
            assert_ne!(u[..period], u[p..p + period], "order {order}: period {p}");
        }
    }
}

#[test]
fn binary_steps_and_sweeps_keep_their_settings() {
    let binary = Design::RandomBinary {
        amplitude: Drawn::between(0.5, 2.0).unwrap(),
        hold: 4,
    };
    let u = filled(&binary, 1.0, 400, 0);
    let a = u[0].abs();
    assert!((0.5..=2.0).contains(&a));
    assert!(u.iter().all(|v| v.abs().to_bits() == a.to_bits()));
    assert!(
        u.chunks(4)
            .all(|c| c.iter().all(|v| v.to_bits() == c[0].to_bits()))
    );
    let steps = Design::Steps {
        level: (1.0, 3.5),
        hold: (2.0, 5.0),
    };
    let s = filled(&steps, 0.5, 1000, 2);
    let mut runs: Vec<usize> = vec![1];
    for w in s.windows(2) {
        if w[0].to_bits() == w[1].to_bits() {
            *runs.last_mut().unwrap() += 1;
        } else {
            runs.push(1);
        }
    }
    // Holds of 4 to 10 samples (the last may be cut by the record).
    assert!(
        runs[..runs.len() - 1].iter().all(|r| (4..=10).contains(r)),
        "{runs:?}"
    );
    assert!(s.iter().all(|v| (1.0..=3.5).contains(v)));
    // A sweep from 0 to 5 Hz over 10 s crosses zero about 2 * 25 times
    // (its mean frequency 2.5 Hz).
    let sweep = Design::Sweep {
        from: Drawn::fixed(0.0),
        to: Drawn::fixed(5.0),
        amplitude: Drawn::fixed(1.0),
    };
    let w = filled(&sweep, 0.001, 10_000, 0);
    let crossings = w.windows(2).filter(|p| p[0] < 0.0 && p[1] >= 0.0).count();
    assert!((24..=26).contains(&crossings), "{crossings}");
}

/// Filtered noise has its level and its band: the sample variance of
/// a long record is the drawn RMS squared, and the power outside the
/// band is what the filters' closed-form response lets through.
#[test]
fn filtered_noise_keeps_its_level_and_its_band() {
    let (n, dt) = (1 << 15, 0.01);
    let design = Design::FilteredNoise {
        band: (Drawn::fixed(5.0), Drawn::fixed(10.0)),
        order: 6,
        rms: Drawn::fixed(2.0),
    };
    let records: Vec<Vec<f64>> = (0..4).map(|i| filled(&design, dt, n, i)).collect();
    let variance = records.iter().flatten().map(|v| v * v).sum::<f64>() / (4 * n) as f64;
    // A 5 Hz band over 4 records of 328 s: about 13,000 independent
    // samples, a relative standard error of 0.0125 on the variance.
    assert!((variance / 4.0 - 1.0).abs() < 0.05, "variance {variance}");
    // The lines of the record's grid well outside [5, 10] Hz hold a
    // small share of the power, as 1 / (1 + ratio^12) says.
    let mut spectrum: Vec<Complex<f64>> =
        records[0].iter().map(|v| Complex::new(*v, 0.0)).collect();
    FftPlannerScalar::new()
        .plan_fft_forward(n)
        .process(&mut spectrum);
    let df = 1.0 / (n as f64 * dt);
    let (mut inside, mut outside) = (0.0, 0.0);
    for (k, line) in spectrum.iter().enumerate().take(n / 2).skip(1) {
        let f = k as f64 * df;
        let p = line.norm_sqr();
        if (5.0..=10.0).contains(&f) {
            inside += p;
        } else if !(3.5..=14.0).contains(&f) {
            outside += p;
        }
    }
    assert!(
        outside < 0.01 * inside,
        "{outside} outside, {inside} inside"
    );
    // The start is already stationary: over 400 experiments the first
    // sample's mean square is the level's (a filter started at rest
    // would begin near 0). Its relative standard error is 0.07.
    let first = (0..400)
        .map(|i| filled(&design, dt, 256, i)[0].powi(2))
        .sum::<f64>()
        / 400.0;
    assert!(
        (first / 4.0 - 1.0).abs() < 0.25,
        "first samples' mean square {first}"
    );
    // An edge below the record's resolution, and an order out of range.
    let coarse = Design::FilteredNoise {
        band: (Drawn::fixed(0.0), Drawn::fixed(0.5)),
        order: 4,
        rms: Drawn::fixed(1.0),
    };
    let mut short = vec![0.0; 100];
    let e = coarse
        .fill(dt, &mut experiment_rng(5, 0), &mut short)
        .unwrap_err()
        .to_string();
    assert!(e.contains("resolution") && e.contains("1 Hz"), "{e}");
    let steep = Design::FilteredNoise {
        band: (Drawn::fixed(0.0), Drawn::fixed(5.0)),
        order: 11,
        rms: Drawn::fixed(1.0),
    };
    assert!(steep.check(dt).unwrap_err().to_string().contains("1 to 10"));
}

#[test]
fn impossible_designs_are_refused_with_what_would_work() {
    let high = Design::Multisine {
        band: (Drawn::fixed(0.0), Drawn::fixed(60.0)),
        grid: Grid::Full,
        phases: Phases::Random,
        level: Level::Rms(Drawn::fixed(1.0)),
        spectrum: None,
    };
    let e = high.check(0.01).unwrap_err().to_string();
    assert!(e.contains("above the Nyquist frequency 50 Hz"), "{e}");
    let narrow = Design::Multisine {
        band: (Drawn::fixed(1.2), Drawn::fixed(1.5)),
        grid: Grid::Full,
        phases: Phases::Random,
        level: Level::Rms(Drawn::fixed(1.0)),
        spectrum: None,
    };
    let mut u = vec![0.0; 100];
    let e = narrow
        .fill(0.01, &mut experiment_rng(0, 0), &mut u)
        .unwrap_err()
        .to_string();
    assert!(e.contains("holds no line of the record's grid"), "{e}");
    assert!(Drawn::between(2.0, 1.0).is_err());
    let held = Design::RandomBinary {
        amplitude: Drawn::fixed(1.0),
        hold: 0,
    };
    assert!(
        held.check(1.0)
            .unwrap_err()
            .to_string()
            .contains("at least 1 sample")
    );
    let order = Design::Prbs {
        order: 40,
        amplitude: Drawn::fixed(1.0),
        hold: 1,
    };
    assert!(order.check(1.0).is_err());
}

/// A band's bottom drawn per experiment: each record's lowest line lies
/// in its range, and records differ in it; a bottom that may reach its
/// top is refused.
#[test]
fn a_band_s_bottom_is_drawn_per_experiment() {
    let (n, dt) = (400, 0.01); // lines every 0.25 Hz
    let design = Design::Multisine {
        band: (Drawn::between(1.0, 3.0).unwrap(), Drawn::fixed(10.0)),
        grid: Grid::Full,
        phases: Phases::Random,
        level: Level::Rms(Drawn::fixed(1.0)),
        spectrum: None,
    };
    let lowest: Vec<f64> = (0..8)
        .map(|e| {
            let u = filled(&design, dt, n, e);
            let total: f64 = (1..n / 2).map(|k| line_power(&u, k)).sum();
            let k = (1..n / 2)
                .find(|&k| line_power(&u, k) > 1e-12 * total)
                .unwrap();
            k as f64 * 0.25
        })
        .collect();
    assert!(lowest.iter().all(|f| (1.0..3.25).contains(f)), "{lowest:?}");
    assert!(
        lowest.iter().any(|f| (*f - lowest[0]).abs() > 0.1),
        "{lowest:?}"
    );
    let reaching = Design::Multisine {
        band: (Drawn::between(1.0, 12.0).unwrap(), Drawn::fixed(10.0)),
        grid: Grid::Full,
        phases: Phases::Random,
        level: Level::Rms(Drawn::fixed(1.0)),
        spectrum: None,
    };
    let e = reaching.check(dt).unwrap_err().to_string();
    assert!(e.contains("below the band's top"), "{e}");
    // A noise's bottom drawn from 0: some draws no record resolves.
    let noise = Design::FilteredNoise {
        band: (Drawn::between(0.0, 1.0).unwrap(), Drawn::fixed(10.0)),
        order: 4,
        rms: Drawn::fixed(1.0),
    };
    let e = noise.check_record(dt, n).unwrap_err().to_string();
    assert!(
        e.contains("noise band bottom") && e.contains("0.25 Hz"),
        "{e}"
    );
    let resolved = Design::FilteredNoise {
        band: (Drawn::between(0.5, 1.0).unwrap(), Drawn::fixed(10.0)),
        order: 4,
        rms: Drawn::fixed(1.0),
    };
    assert!(resolved.check_record(dt, n).is_ok());
}
