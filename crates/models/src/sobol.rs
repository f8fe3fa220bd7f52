//! The Sobol low-discrepancy sequence, with the direction numbers of Joe
//! and Kuo ("Constructing Sobol sequences with better two-dimensional
//! projections", SIAM J. Sci. Comput. 30, 2008; table new-joe-kuo-6.21201,
//! rows d = 2..21). Dimension 1 is the van der Corput sequence in base 2.

/// Number of bits of each coordinate.
const BITS: usize = 32;

/// `(s, a, m_1..m_s)` for dimensions 2..=21 of the Joe-Kuo table.
const JOE_KUO: [(u32, u32, &[u32]); 20] = [
    (1, 0, &[1]),
    (2, 1, &[1, 3]),
    (3, 1, &[1, 3, 1]),
    (3, 2, &[1, 1, 1]),
    (4, 1, &[1, 1, 3, 3]),
    (4, 4, &[1, 3, 5, 13]),
    (5, 2, &[1, 1, 5, 5, 17]),
    (5, 4, &[1, 1, 5, 5, 5]),
    (5, 7, &[1, 1, 7, 11, 19]),
    (5, 11, &[1, 1, 5, 1, 1]),
    (5, 13, &[1, 1, 1, 3, 11]),
    (5, 14, &[1, 3, 5, 5, 31]),
    (6, 1, &[1, 3, 3, 9, 7, 49]),
    (6, 13, &[1, 1, 1, 15, 21, 21]),
    (6, 16, &[1, 3, 1, 13, 27, 49]),
    (6, 19, &[1, 1, 1, 15, 7, 5]),
    (6, 22, &[1, 3, 1, 15, 13, 25]),
    (6, 25, &[1, 1, 5, 5, 19, 61]),
    (7, 1, &[1, 3, 7, 11, 23, 15, 103]),
    (7, 4, &[1, 3, 7, 13, 13, 15, 69]),
];

/// The largest dimension supported.
pub const MAX_DIMENSION: usize = JOE_KUO.len() + 1;

/// Direction numbers `v[k]` (k = 0..32) of one dimension, scaled to 32 bits.
fn direction_numbers(dimension: usize) -> [u32; BITS] {
    let mut v = [0u32; BITS];
    if dimension == 0 {
        for (k, vk) in v.iter_mut().enumerate() {
            *vk = 1 << (BITS - 1 - k);
        }
        return v;
    }
    let (s, a, m) = JOE_KUO[dimension - 1];
    let s = s as usize;
    for k in 0..s.min(BITS) {
        v[k] = m[k] << (BITS - 1 - k);
    }
    for k in s..BITS {
        let mut value = v[k - s] ^ (v[k - s] >> s);
        for j in 1..s {
            if (a >> (s - 1 - j)) & 1 == 1 {
                value ^= v[k - j];
            }
        }
        v[k] = value;
    }
    v
}

/// A Sobol point generator in Gray-code order, with random access by index.
#[derive(Debug, Clone)]
pub(crate) struct Sobol {
    directions: Vec<[u32; BITS]>,
}

impl Sobol {
    /// Generator for `dimension` coordinates (1..=MAX_DIMENSION; checked by the caller).
    pub(crate) fn new(dimension: usize) -> Self {
        Self {
            directions: (0..dimension).map(direction_numbers).collect(),
        }
    }

    /// Coordinate `j` of point `index` as a 32-bit integer (point 0 is the origin).
    pub(crate) fn coordinate_bits(&self, index: u32, j: usize) -> u32 {
        let gray = index ^ (index >> 1);
        let v = &self.directions[j];
        (0..BITS)
            .filter(|k| (gray >> k) & 1 == 1)
            .fold(0u32, |acc, k| acc ^ v[k])
    }
}

/// 2^-32, to map 32-bit coordinates into [0, 1).
pub(crate) const UNIT: f64 = 1.0 / 4_294_967_296.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn point(sobol: &Sobol, index: u32) -> Vec<f64> {
        (0..sobol.directions.len())
            .map(|j| f64::from(sobol.coordinate_bits(index, j)) * UNIT)
            .collect()
    }

    #[test]
    fn first_points_match_the_hand_derived_sequence() {
        // Gray-code order, dimensions 1..3: derived by hand from m = (1), (1), (1, 3).
        let sobol = Sobol::new(3);
        let expected = [
            [0.0, 0.0, 0.0],
            [0.5, 0.5, 0.5],
            [0.75, 0.25, 0.25],
            [0.25, 0.75, 0.75],
            [0.375, 0.375, 0.625],
        ];
        for (index, want) in expected.iter().enumerate() {
            let got = point(&sobol, index as u32);
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 1e-15, "point {index}: {got:?} != {want:?}");
            }
        }
    }

    #[test]
    fn every_pair_of_dimensions_is_a_digital_net() {
        // The first 2^k points of each coordinate fall one in each interval
        // of width 2^-k. Dimensions 1 and 2 together form a (0, k, 2)-net: one
        // point in each box of size 2^-a x 2^-b with a + b = k. Wrong
        // direction numbers for dimension 2 break the second property.
        let sobol = Sobol::new(MAX_DIMENSION);
        let k = 10u32;
        let n = 1u32 << k;
        for j in 0..MAX_DIMENSION {
            let mut seen = vec![false; n as usize];
            for index in 0..n {
                let cell = (sobol.coordinate_bits(index, j) >> (32 - k)) as usize;
                assert!(!seen[cell], "dimension {j}: two points in cell {cell}");
                seen[cell] = true;
            }
        }
        for a in 0..=k {
            let b = k - a;
            let mut seen = vec![false; n as usize];
            for index in 0..n {
                let x = if a == 0 {
                    0
                } else {
                    sobol.coordinate_bits(index, 0) >> (32 - a)
                };
                let y = if b == 0 {
                    0
                } else {
                    sobol.coordinate_bits(index, 1) >> (32 - b)
                };
                let cell = ((x << b) | y) as usize;
                assert!(!seen[cell], "a = {a}, b = {b}: two points in one box");
                seen[cell] = true;
            }
        }
    }
}
