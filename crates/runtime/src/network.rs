//! A trained network read in place: an ensemble of tanh networks with
//! their standardizations, as the host's `FittedMlp` evaluates it.

use twostage_kernels::Values;
use twostage_kernels::layer::{Activation, dense_layer};
use twostage_kernels::vector::{standardize, unstandardize_in_place};

use crate::bytes::{Cursor, LeF64s, u32_at};
use crate::error::Error;
use crate::format::{MAX_MEMBERS, MAX_SIZES, MAX_WIDTH};

/// One network of the blob.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Network<'a> {
    sizes: &'a [u8],
    n_sizes: usize,
    members: usize,
    per_member: usize,
    feature_mean: LeF64s<'a>,
    feature_scale: LeF64s<'a>,
    target_mean: LeF64s<'a>,
    target_scale: LeF64s<'a>,
    params: LeF64s<'a>,
}

impl<'a> Network<'a> {
    /// Reads and checks a network that maps `inputs` numbers to `outputs`.
    pub(crate) fn read(
        cursor: &mut Cursor<'a>,
        inputs: usize,
        outputs: usize,
    ) -> Result<Self, Error> {
        let at = cursor.at;
        let n_sizes = cursor.count("network layer count", MAX_SIZES)?;
        let members = cursor.count("network ensemble size", MAX_MEMBERS)?;
        if n_sizes < 2 || members == 0 {
            return Err(Error::Invalid {
                field: "network shape",
                at,
            });
        }
        let sizes_at = cursor.at;
        let sizes = cursor.u32s(n_sizes)?;
        let mut per_member = 0usize;
        for l in 0..n_sizes {
            let w = size_of(sizes, l);
            if w == 0 || w > MAX_WIDTH {
                return Err(Error::Invalid {
                    field: "network layer width",
                    at: sizes_at + 4 * l,
                });
            }
            if l > 0 {
                // Bounded by MAX_SIZES * MAX_WIDTH^2: no overflow.
                per_member += w * (size_of(sizes, l - 1) + 1);
            }
        }
        if size_of(sizes, 0) != inputs || size_of(sizes, n_sizes - 1) != outputs {
            return Err(Error::Invalid {
                field: "network input or output width",
                at: sizes_at,
            });
        }
        let feature_mean = cursor.finite("feature mean", inputs)?;
        let feature_scale = positive(cursor, "feature scale", inputs)?;
        let target_mean = cursor.finite("target mean", outputs)?;
        let target_scale = positive(cursor, "target scale", outputs)?;
        let params = cursor.finite("network weight", members * per_member)?;
        Ok(Self {
            sizes,
            n_sizes,
            members,
            per_member,
            feature_mean,
            feature_scale,
            target_mean,
            target_scale,
            params,
        })
    }

    /// The widest layer.
    pub(crate) fn max_width(&self) -> usize {
        (0..self.n_sizes)
            .map(|l| size_of(self.sizes, l))
            .max()
            .unwrap_or(0)
    }

    /// `out = h(x)`: standardize, average the members, unstandardize, in
    /// the host's order. `scratch` holds `inputs + 2 * max_width` numbers.
    pub(crate) fn predict(
        &self,
        x: &[f64],
        scratch: &mut [f64],
        out: &mut [f64],
    ) -> Result<(), Error> {
        let n0 = size_of(self.sizes, 0);
        let width = self.max_width();
        let short = Error::WorkspaceTooSmall {
            needed: n0 + 2 * width,
            given: scratch.len(),
        };
        let (input, rest) = scratch.split_at_mut_checked(n0).ok_or(short)?;
        let (mut a, rest) = rest.split_at_mut_checked(width).ok_or(short)?;
        let mut b = rest.get_mut(..width).ok_or(short)?;
        standardize(x, &self.feature_mean, &self.feature_scale, input);
        out.fill(0.0);
        let layers = self.n_sizes - 1;
        for member in 0..self.members {
            a.get_mut(..n0).ok_or(short)?.copy_from_slice(input);
            let mut p = member * self.per_member;
            for l in 0..layers {
                let (n_in, n_out) = (size_of(self.sizes, l), size_of(self.sizes, l + 1));
                let weights = self.params.sub(p, n_out * n_in);
                let bias = self.params.sub(p + n_out * n_in, n_out);
                let activation = if l + 1 < layers {
                    Activation::Tanh
                } else {
                    Activation::Identity
                };
                let layer_in = a.get(..n_in).ok_or(short)?;
                dense_layer(
                    &weights,
                    &bias,
                    layer_in,
                    activation,
                    b.get_mut(..n_out).ok_or(short)?,
                );
                core::mem::swap(&mut a, &mut b);
                p += n_out * (n_in + 1);
            }
            for (o, v) in out.iter_mut().zip(a.iter()) {
                *o += v;
            }
        }
        let members = self.members as f64;
        for o in out.iter_mut() {
            *o /= members;
        }
        unstandardize_in_place(out, &self.target_mean, &self.target_scale);
        Ok(())
    }
}

/// Layer size `l` (checked when the network was read).
fn size_of(sizes: &[u8], l: usize) -> usize {
    u32_at(sizes, 4 * l).map_or(0, |v| v as usize)
}

fn positive<'a>(
    cursor: &mut Cursor<'a>,
    field: &'static str,
    count: usize,
) -> Result<LeF64s<'a>, Error> {
    let at = cursor.at;
    let v = cursor.finite(field, count)?;
    if (0..v.len()).any(|i| v.at(i) <= 0.0) {
        return Err(Error::Invalid { field, at });
    }
    Ok(v)
}
