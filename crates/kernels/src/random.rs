//! Random numbers from a generator's 64-bit words, the same bits on every
//! platform: the key a stream's seed expands to, uniforms and standard
//! normals. A host and a microcontroller that read the same words (one
//! ChaCha8 stream of one key) draw the same numbers, because every
//! function here is integer arithmetic or libm's.
//!
//! ```
//! use twostage_kernels::random::{normal_pair, unit_uniform};
//! // The largest and smallest words give the ends of [0, 1).
//! assert_eq!(unit_uniform(0), 0.0);
//! assert!(unit_uniform(u64::MAX) < 1.0);
//! // A first uniform of 1 - e^(-1/2) gives a radius of 1; a second of 0
//! // puts the pair on the first axis.
//! let word = |u: f64| ((u * (1u64 << 53) as f64) as u64) << 11;
//! let [a, b] = normal_pair(word(1.0 - (-0.5f64).exp()), 0);
//! assert!((a - 1.0).abs() < 1e-12 && b == 0.0);
//! ```

/// SplitMix64 (Steele, Lea and Flood, "Fast splittable pseudorandom
/// number generators", OOPSLA 2014): a bijective mixer that spreads a
/// 64-bit seed over a longer key.
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The 256-bit ChaCha key of `seed` for one purpose (`tag`): four words of
/// SplitMix64 from `seed ^ tag`, little-endian. The project derives its
/// keys itself rather than through `seed_from_u64`, whose expansion is not
/// part of its own compatibility promise.
pub fn stream_key(seed: u64, tag: u64) -> [u8; 32] {
    let mut state = seed ^ tag;
    let mut key = [0u8; 32];
    for chunk in key.chunks_exact_mut(8) {
        chunk.copy_from_slice(&splitmix64(&mut state).to_le_bytes());
    }
    key
}

/// The purpose tag of the streams a posterior draws from ("POSTERIO"):
/// record `i`'s draws of seed `s` read the ChaCha8 stream `i` of
/// `stream_key(s, POSTERIOR_TAG)`.
pub const POSTERIOR_TAG: u64 = 0x504f_5354_4552_494f;

/// A uniform number in `[0, 1)` from the top 53 bits of `word`: every
/// value a multiple of 2⁻⁵³, as `rand`'s standard `f64` makes it.
pub fn unit_uniform(word: u64) -> f64 {
    (word >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Two independent standard normal numbers from two words, by the
/// Box-Muller transform (Box and Muller, "A note on the generation of
/// random normal deviates", Ann. Math. Statist. 29, 1958): the radius
/// `sqrt(-2 ln u)` of `u = 1 - unit_uniform(first)` (in `(0, 1]`, so the
/// logarithm is finite) and the angle `2π unit_uniform(second)`. It needs
/// no rejection, so a fixed number of words makes each draw, and libm's
/// `log`, `sqrt`, `sin` and `cos` give the same bits everywhere.
pub fn normal_pair(first: u64, second: u64) -> [f64; 2] {
    let radius = libm::sqrt(-2.0 * libm::log(1.0 - unit_uniform(first)));
    let angle = 2.0 * core::f64::consts::PI * unit_uniform(second);
    [radius * libm::cos(angle), radius * libm::sin(angle)]
}

/// Fill `out` with standard normal numbers from `words`: pair after pair
/// ([`normal_pair`]), the last pair's second number dropped for an odd
/// count, so that `out.len()` normals take `2 ⌈len / 2⌉` words.
pub fn standard_normals(words: &mut impl FnMut() -> u64, out: &mut [f64]) {
    for pair in out.chunks_mut(2) {
        let normals = normal_pair(words(), words());
        for (o, n) in pair.iter_mut().zip(normals) {
            *o = n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic stream of words (SplitMix64 from 1): any sequence
    /// of well-mixed words serves these tests.
    fn words() -> impl FnMut() -> u64 {
        let mut state = 1u64;
        move || splitmix64(&mut state)
    }

    /// The standard normal's distribution function by its series: an
    /// independent computation of what the draws should follow.
    fn normal_cdf(x: f64) -> f64 {
        0.5 * (1.0 + libm::erf(x / core::f64::consts::SQRT_2))
    }

    #[test]
    fn splitmix_gives_its_published_first_outputs() {
        // The reference implementation's outputs from the state 0
        // (Vigna's splitmix64.c).
        let mut state = 0u64;
        assert_eq!(splitmix64(&mut state), 0xe220_a839_7b1d_cdaf);
        assert_eq!(splitmix64(&mut state), 0x6e78_9e6a_a1b9_65f4);
    }

    #[test]
    fn uniforms_are_53_bit_multiples_in_the_unit_interval() {
        let bits = |word| unit_uniform(word).to_bits();
        let step = 1.0 / (1u64 << 53) as f64;
        assert_eq!(bits(1 << 11), step.to_bits());
        assert_eq!(bits((1 << 11) - 1), 0f64.to_bits());
        assert_eq!(bits(1 << 63), 0.5f64.to_bits());
        assert_eq!(bits(u64::MAX), (1.0 - step).to_bits());
    }

    #[test]
    fn the_pair_is_the_transform_written_out() {
        // u = 1 - 0.25 gives a radius sqrt(-2 ln 0.75); the angle of a
        // quarter turn puts it on the second axis.
        let [a, b] = normal_pair(1 << 62, 1 << 62);
        let radius = (-2.0 * 0.75f64.ln()).sqrt();
        assert!(a.abs() < 1e-15 * radius, "{a}");
        assert!((b - radius).abs() < 1e-15, "{b} {radius}");
        // The smallest word gives u = 1 and a radius of 0, never a NaN.
        assert_eq!(normal_pair(0, 12345).map(|v| v.abs().to_bits()), [0; 2]);
        // The largest gives the largest radius, finite.
        let [a, _] = normal_pair(u64::MAX, 0);
        assert!(a.is_finite() && a > 8.0, "{a}");
    }

    #[test]
    fn normals_follow_the_standard_normal() {
        let n = 200_000;
        let mut draws = std::vec![0.0; n];
        standard_normals(&mut words(), &mut draws);
        let mean = draws.iter().sum::<f64>() / n as f64;
        let var = draws.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n as f64;
        // Standard errors 1/sqrt(n) = 0.0022 and sqrt(2/n) = 0.0032.
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var - 1.0).abs() < 0.015, "{var}");
        // Kolmogorov-Smirnov against the closed form: 1.95 / sqrt(n) is
        // its 0.1% critical value.
        draws.sort_by(f64::total_cmp);
        let distance = draws
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let f = normal_cdf(x);
                (f - i as f64 / n as f64).max((i + 1) as f64 / n as f64 - f)
            })
            .fold(0.0, f64::max);
        assert!(distance < 1.95 / (n as f64).sqrt(), "{distance}");
        // The pair's two numbers are uncorrelated.
        let mut pairs = std::vec![0.0; n];
        standard_normals(&mut words(), &mut pairs);
        let cross = pairs.chunks_exact(2).map(|p| p[0] * p[1]).sum::<f64>() / (n / 2) as f64;
        assert!(cross.abs() < 0.015, "{cross}");
    }

    #[test]
    fn an_odd_count_takes_whole_pairs_of_words() {
        let mut counted = 0;
        let mut inner = words();
        let mut counting = || {
            counted += 1;
            inner()
        };
        let mut three = [0.0; 3];
        standard_normals(&mut counting, &mut three);
        assert_eq!(counted, 4);
        // The odd count's numbers are the even count's first ones.
        let mut four = [0.0; 4];
        standard_normals(&mut words(), &mut four);
        assert_eq!(three.map(f64::to_bits)[..], four.map(f64::to_bits)[..3]);
    }

    #[test]
    fn the_key_spreads_seed_and_tag() {
        let key = stream_key(7, POSTERIOR_TAG);
        let mut state = 7 ^ POSTERIOR_TAG;
        assert_eq!(key[..8], splitmix64(&mut state).to_le_bytes());
        assert_ne!(stream_key(7, POSTERIOR_TAG), stream_key(8, POSTERIOR_TAG));
        assert_ne!(stream_key(7, POSTERIOR_TAG), stream_key(7, 0));
    }
}
