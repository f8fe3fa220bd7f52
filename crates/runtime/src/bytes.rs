//! Numbers read in place from the blob's little-endian bytes.

use twostage_kernels::Values;

use crate::error::Error;

/// A run of little-endian `f64` inside the blob, read where it lies (any
/// alignment): the [`Values`] the kernels compute with.
#[derive(Debug, Clone, Copy, Default)]
pub struct LeF64s<'a> {
    pub(crate) bytes: &'a [u8],
}

impl<'a> LeF64s<'a> {
    /// The numbers `start..start + count`, or none when out of range.
    pub(crate) fn sub(&self, start: usize, count: usize) -> LeF64s<'a> {
        let range = start
            .checked_mul(8)
            .zip(count.checked_mul(8))
            .and_then(|(a, n)| Some(a..a.checked_add(n)?));
        LeF64s {
            bytes: range.and_then(|r| self.bytes.get(r)).unwrap_or(&[]),
        }
    }

    /// Whether every number is finite.
    pub(crate) fn all_finite(&self) -> bool {
        (0..self.len()).all(|i| self.at(i).is_finite())
    }
}

#[inline]
fn le_f64(chunk: &[u8]) -> f64 {
    chunk
        .try_into()
        .map_or(f64::NAN, |b: [u8; 8]| f64::from_le_bytes(b))
}

impl Values for LeF64s<'_> {
    #[inline]
    fn len(&self) -> usize {
        self.bytes.len() / 8
    }
    #[inline]
    fn at(&self, i: usize) -> f64 {
        i.checked_mul(8)
            .and_then(|a| self.bytes.get(a..a.checked_add(8)?))
            .map_or(f64::NAN, le_f64)
    }
    #[inline]
    fn dot_from(&self, offset: usize, x: &[f64]) -> f64 {
        let run = offset
            .checked_mul(8)
            .zip(x.len().checked_mul(8))
            .and_then(|(a, n)| self.bytes.get(a..a.checked_add(n)?));
        match run {
            Some(run) => run.chunks_exact(8).zip(x).map(|(w, v)| le_f64(w) * v).sum(),
            None => f64::NAN,
        }
    }
}

/// A little-endian `u32` at byte `at`, or `None` past the end.
pub(crate) fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    let chunk: [u8; 4] = bytes.get(at..at.checked_add(4)?)?.try_into().ok()?;
    Some(u32::from_le_bytes(chunk))
}

/// Reads the blob's sections in order, checking every bound.
pub(crate) struct Cursor<'a> {
    bytes: &'a [u8],
    pub(crate) at: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(bytes: &'a [u8], at: usize) -> Self {
        Self { bytes, at }
    }

    pub(crate) fn u32(&mut self) -> Result<u32, Error> {
        let run = self.take(1, 4)?;
        Ok(u32_at(run, 0).unwrap_or(0))
    }

    /// A count no larger than `max`.
    pub(crate) fn count(&mut self, field: &'static str, max: usize) -> Result<usize, Error> {
        let at = self.at;
        let v = self.u32()? as usize;
        if v > max {
            return Err(Error::Invalid { field, at });
        }
        Ok(v)
    }

    /// The next `count` items of `size` bytes.
    fn take(&mut self, count: usize, size: usize) -> Result<&'a [u8], Error> {
        let start = self.at;
        let run = count
            .checked_mul(size)
            .and_then(|n| self.bytes.get(start..start.checked_add(n)?))
            .ok_or(Error::Truncated { at: start })?;
        self.at += run.len();
        Ok(run)
    }

    /// Step to byte `end` (at or after the cursor) without reading.
    pub(crate) fn skip_to(&mut self, end: usize) -> Result<(), Error> {
        self.take(end.saturating_sub(self.at), 1)?;
        Ok(())
    }

    /// `count` u32s as bytes, then padding to the next multiple of 8.
    pub(crate) fn u32s(&mut self, count: usize) -> Result<&'a [u8], Error> {
        let run = self.take(count, 4)?;
        self.align()?;
        Ok(run)
    }

    fn align(&mut self) -> Result<(), Error> {
        let padded = self.at.div_ceil(8).saturating_mul(8);
        if padded > self.bytes.len() {
            return Err(Error::Truncated { at: self.at });
        }
        self.at = padded;
        Ok(())
    }

    pub(crate) fn f64s(&mut self, count: usize) -> Result<LeF64s<'a>, Error> {
        Ok(LeF64s {
            bytes: self.take(count, 8)?,
        })
    }

    /// `count` finite numbers.
    pub(crate) fn finite(
        &mut self,
        field: &'static str,
        count: usize,
    ) -> Result<LeF64s<'a>, Error> {
        let at = self.at;
        let v = self.f64s(count)?;
        if !v.all_finite() {
            return Err(Error::Invalid { field, at });
        }
        Ok(v)
    }

    pub(crate) fn f64(&mut self, field: &'static str) -> Result<f64, Error> {
        Ok(self.finite(field, 1)?.at(0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_read_in_place_give_the_slice_s_numbers_and_sums() {
        let values: [f64; 6] = [0.1, -2.5, 3.0e-7, 1.0e12, -0.0, 7.25];
        // One byte of offset: an unaligned run, as a blob in flash may be.
        let mut bytes = [0u8; 49];
        for (chunk, v) in bytes[1..].chunks_exact_mut(8).zip(values) {
            chunk.copy_from_slice(&v.to_le_bytes());
        }
        let run = LeF64s { bytes: &bytes[1..] };
        assert_eq!(run.len(), 6);
        assert!((0..6).all(|i| run.at(i).to_bits() == values[i].to_bits()));
        assert!(run.at(6).is_nan() && run.at(usize::MAX).is_nan());
        let x = [1.5, -0.25, 4.0];
        for offset in 0..=3 {
            let from_bytes = run.dot_from(offset, &x);
            assert_eq!(
                from_bytes.to_bits(),
                values[..].dot_from(offset, &x).to_bits()
            );
            let by_hand: f64 = (0..3).map(|c| values[offset + c] * x[c]).sum();
            assert_eq!(from_bytes.to_bits(), by_hand.to_bits());
        }
        assert!(run.dot_from(4, &x).is_nan() && values[..].dot_from(4, &x).is_nan());
        assert!(run.dot_from(usize::MAX, &x).is_nan());
        assert_eq!(run.sub(2, 3).at(0).to_bits(), values[2].to_bits());
        assert_eq!(run.sub(5, 2).len(), 0);
    }
}
