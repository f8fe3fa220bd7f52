//! The network's activation, the same bits on every platform.
//!
//! A platform's `tanh` is a library call the compiler cannot vectorize and
//! whose last bits differ between C libraries (glibc on a host, libm on a
//! microcontroller). This one is branch-free arithmetic on `f64` (no fused
//! multiply-add, no table), so a loop of it vectorizes and every target
//! rounds it alike: training, the estimator and the embedded runtime compute
//! one function.
//!
//! It reads `tanh |x| = -m / (2 + m)` with `m = expm1(-2 |x|)`, which keeps
//! full relative precision near zero where `1 - exp(-2 |x|)` would cancel;
//! `expm1` reduces its argument by multiples of ln 2 (Cody and Waite's
//! split constant) and sums a degree-13 Taylor polynomial on the remainder
//! (`|r| <= ln(2) / 2`, where the first omitted term is below 2^-60 of the
//! sum).

/// ln 2 split in two: the first with its low 21 bits zero, so `k * LN2_HI`
/// is exact for the `k` used here (fdlibm's constants, by their bits).
const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
const LOG2_E: f64 = core::f64::consts::LOG2_E;
/// 1.5 * 2^52: adding it rounds to an integer held in the low mantissa bits.
const ROUND_TO_INTEGER: f64 = 6_755_399_441_055_744.0;
/// Beyond this `tanh` is 1 to the last bit (1 - tanh(20) is about 8e-18).
const SATURATED: f64 = 20.0;
const SIGN: u64 = 1 << 63;

/// `1 / n!` for n = 13 down to 2: the Taylor coefficients of `expm1(r) - r`
/// over `r^2`, highest first, for Horner's rule.
const INVERSE_FACTORIALS: [f64; 12] = [
    1.0 / 6_227_020_800.0,
    1.0 / 479_001_600.0,
    1.0 / 39_916_800.0,
    1.0 / 3_628_800.0,
    1.0 / 362_880.0,
    1.0 / 40_320.0,
    1.0 / 5_040.0,
    1.0 / 720.0,
    1.0 / 120.0,
    1.0 / 24.0,
    1.0 / 6.0,
    0.5,
];

/// The hyperbolic tangent, within 3 units in the last place of a correctly
/// rounded one, odd to the bit, `tanh(±inf) = ±1`, NaN for NaN.
///
/// ```
/// use twostage_kernels::tanh;
/// assert_eq!(tanh(0.0), 0.0);
/// assert_eq!(tanh(-0.5), -tanh(0.5));
/// assert!((tanh(0.5) - 0.462_117_157_260_009_8).abs() < 1e-16);
/// assert_eq!(tanh(f64::INFINITY), 1.0);
/// assert!(tanh(f64::NAN).is_nan());
/// ```
#[inline]
pub fn tanh(x: f64) -> f64 {
    let magnitude = f64::from_bits(x.to_bits() & !SIGN);
    // NaN compares false and would saturate; it is returned at the end.
    let a = if magnitude < SATURATED {
        magnitude
    } else {
        SATURATED
    };
    let y = -2.0 * a;
    let shifted = y * LOG2_E + ROUND_TO_INTEGER;
    let k = shifted - ROUND_TO_INTEGER;
    let r = (y - k * LN2_HI) - k * LN2_LO;
    let polynomial = INVERSE_FACTORIALS
        .iter()
        .fold(0.0, |sum, &coefficient| sum * r + coefficient);
    let expm1_r = r + r * r * polynomial;
    // 2^k from the integer in the low bits (k lies in -58..=0): its
    // exponent field is k + 1023, and the shift drops everything above.
    let scale = f64::from_bits(shifted.to_bits().wrapping_add(1023) << 52);
    let expm1_y = scale * expm1_r + (scale - 1.0);
    let t = -expm1_y / (2.0 + expm1_y);
    let odd = f64::from_bits((t.to_bits() & !SIGN) | (x.to_bits() & SIGN));
    if x.is_nan() { x } else { odd }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    /// Units in the last place between two finite numbers of one sign.
    fn ulps(a: f64, b: f64) -> u64 {
        a.to_bits().abs_diff(b.to_bits())
    }

    #[test]
    fn within_three_ulps_of_the_platforms_on_every_scale() {
        let mut worst = 0;
        for scale in [1e-300, 1e-8, 1e-3, 0.1, 0.35, 1.0, 3.0, 10.0, 19.0, 25.0] {
            for i in 0..=200_000 {
                let x = (f64::from(i) / 100_000.0 - 1.0) * scale;
                let (own, platform) = (tanh(x), x.tanh());
                assert_eq!(own.is_sign_negative(), platform.is_sign_negative(), "{x}");
                worst = worst.max(ulps(own, platform));
            }
        }
        // The platform's is itself within about one ulp of the truth.
        assert!(worst <= 3, "{worst} ulps");
    }

    #[test]
    fn odd_monotone_and_bounded() {
        let mut previous = -1.0;
        for i in -400_000..=400_000 {
            let x = f64::from(i) * 1e-4;
            let t = tanh(x);
            assert_eq!(tanh(-x).to_bits(), (-t).to_bits(), "{x}");
            assert!(t >= previous && t.abs() <= 1.0, "{x}: {t} after {previous}");
            previous = t;
        }
    }

    #[test]
    fn the_limits_and_special_values() {
        assert_eq!(tanh(0.0).to_bits(), 0.0f64.to_bits());
        assert_eq!(tanh(-0.0).to_bits(), (-0.0f64).to_bits());
        // Below 2^-27 tanh x rounds to x itself.
        for x in [1e-310, 5e-324, 1e-20, 3e-9] {
            assert_eq!(tanh(x).to_bits(), x.to_bits());
        }
        assert_eq!(tanh(20.0).to_bits(), 1f64.to_bits());
        assert_eq!(tanh(-1e300).to_bits(), (-1f64).to_bits());
        assert_eq!(tanh(f64::NEG_INFINITY).to_bits(), (-1f64).to_bits());
        assert!(tanh(f64::NAN).is_nan());
        // A closed form: tanh(ln 3) = (9 - 1) / (9 + 1) = 0.8.
        assert!(ulps(tanh(3f64.ln()), 0.8) <= 2);
    }
}
