//! The posterior's density network read in place, and draws of the
//! parameters from it: the host's `FittedMixture::sample` on the same
//! features and the same random words, with the kernels' arithmetic.

use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::{Rng, SeedableRng};
use twostage_kernels::Values;
use twostage_kernels::mixture::{MixtureShape, Support};
use twostage_kernels::random::{POSTERIOR_TAG, stream_key};
use twostage_kernels::vector::unstandardize_in_place;

use crate::bytes::{Cursor, LeF64s, u32_at};
use crate::error::Error;
use crate::format::{
    MAX_COMPONENTS, MAX_PARAMETERS, SUPPORT_INTERVAL, SUPPORT_POSITIVE, SUPPORT_REAL,
};
use crate::network::Network;

/// A conditional density of the parameters given the features: a
/// mixture of Gaussians over the parameters mapped to the real line.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Posterior<'a> {
    pub(crate) shape: MixtureShape,
    supports: &'a [u8],
    bounds: LeF64s<'a>,
    unbounded_mean: LeF64s<'a>,
    unbounded_scale: LeF64s<'a>,
    spread: f64,
    log_spread: f64,
    pub(crate) network: Network<'a>,
}

impl<'a> Posterior<'a> {
    /// Steps over the section by its length, unread: what a build
    /// without the feature `posterior` does, at the fewest bytes of code
    /// (the checksum has vouched for the section).
    pub(crate) fn skip(cursor: &mut Cursor<'a>) -> Result<(), Error> {
        let at = cursor.at;
        let _counts = (cursor.u32()?, cursor.u32()?);
        let length = cursor.u32()? as usize;
        cursor.skip_to(at.saturating_add(length))
    }

    /// Reads and checks a density of `q` parameters given `features`
    /// numbers.
    pub(crate) fn read(cursor: &mut Cursor<'a>, features: usize, q: usize) -> Result<Self, Error> {
        let shape_at = cursor.at;
        let components = cursor.count("posterior component count", MAX_COMPONENTS)?;
        let dim = cursor.count("posterior parameter count", MAX_PARAMETERS)?;
        let length = cursor.u32()? as usize;
        cursor.u32s(0)?;
        let shape = MixtureShape { components, dim };
        if components == 0 || dim != q {
            return Err(Error::Invalid {
                field: "posterior shape",
                at: shape_at,
            });
        }
        let end = shape_at.checked_add(length);
        let Some(end) = end.filter(|end| *end >= cursor.at) else {
            return Err(Error::Invalid {
                field: "posterior section length",
                at: shape_at + 8,
            });
        };
        let supports_at = cursor.at;
        let supports = cursor.u32s(q)?;
        let bounds_at = cursor.at;
        let bounds = cursor.f64s(2 * q)?;
        for j in 0..q {
            let code = u32_at(supports, 4 * j);
            let (low, high) = (bounds.at(2 * j), bounds.at(2 * j + 1));
            let bounds_ok = match code {
                Some(SUPPORT_REAL | SUPPORT_POSITIVE) => low == 0.0 && high == 0.0,
                Some(SUPPORT_INTERVAL) => low.is_finite() && high.is_finite() && low < high,
                _ => {
                    return Err(Error::Invalid {
                        field: "posterior support code",
                        at: supports_at + 4 * j,
                    });
                }
            };
            if !bounds_ok {
                return Err(Error::Invalid {
                    field: "posterior support bounds",
                    at: bounds_at + 16 * j,
                });
            }
        }
        let unbounded_mean = cursor.finite("posterior parameter mean", q)?;
        let scale_at = cursor.at;
        let unbounded_scale = cursor.finite("posterior parameter scale", q)?;
        if (0..q).any(|j| unbounded_scale.at(j) <= 0.0) {
            return Err(Error::Invalid {
                field: "posterior parameter scale",
                at: scale_at,
            });
        }
        let spread_at = cursor.at;
        let spread = cursor.f64("posterior spread")?;
        let log_spread = cursor.f64("posterior spread's logarithm")?;
        if spread <= 0.0 {
            return Err(Error::Invalid {
                field: "posterior spread",
                at: spread_at,
            });
        }
        let network = Network::read(cursor, features, shape.outputs())?;
        if cursor.at != end {
            return Err(Error::Invalid {
                field: "posterior section length",
                at: shape_at + 8,
            });
        }
        Ok(Self {
            shape,
            supports,
            bounds,
            unbounded_mean,
            unbounded_scale,
            spread,
            log_spread,
            network,
        })
    }

    /// Parameter `j`'s support.
    fn support(&self, j: usize) -> Support {
        match u32_at(self.supports, 4 * j) {
            Some(SUPPORT_POSITIVE) => Support::Positive,
            Some(SUPPORT_INTERVAL) => Support::Interval {
                low: self.bounds.at(2 * j),
                high: self.bounds.at(2 * j + 1),
            },
            _ => Support::Real,
        }
    }

    /// Draws given `features` into `draws` (draws x parameters, row after
    /// row; a whole number of draws, as the stream checks), from the ChaCha8 stream `record` of `seed`'s posterior key:
    /// the host's draws of record `record` with seed `seed`. `own` holds
    /// the head and one draw's normals, `scratch` the network's.
    pub(crate) fn draw(
        &self,
        features: &[f64],
        (seed, record): (u64, u64),
        (own, scratch): (&mut [f64], &mut [f64]),
        draws: &mut [f64],
    ) -> Result<(), Error> {
        let d = self.shape.dim;
        let short = Error::WorkspaceTooSmall {
            needed: self.shape.outputs() + d,
            given: own.len(),
        };
        let (head, rest) = own
            .split_at_mut_checked(self.shape.outputs())
            .ok_or(short)?;
        let normals = rest.get_mut(..d).ok_or(short)?;
        self.network.predict(features, scratch, head)?;
        self.shape.widen(head, self.spread, self.log_spread);
        let mut rng = ChaCha8Rng::from_seed(stream_key(seed, POSTERIOR_TAG));
        rng.set_stream(record);
        let mut words = || rng.next_u64();
        for draw in draws.chunks_exact_mut(d) {
            self.shape.draw_from_words(head, &mut words, normals, draw);
            unstandardize_in_place(draw, &self.unbounded_mean, &self.unbounded_scale);
            for (j, v) in draw.iter_mut().enumerate() {
                *v = self.support(j).from_unbounded(*v);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use twostage::fit::{MixtureDensity, MlpParams};
    use twostage::models::{Benchmark, Simulator, StreamPurpose, experiment_rng, stream_rng};

    use crate::Estimator;

    /// Given the host's very features, the runtime draws the host's very
    /// bits: the network, the widening, the random words, the normals and
    /// the maps back to the prior are one arithmetic.
    #[test]
    fn the_host_s_features_give_the_host_s_bits() {
        let model = Benchmark::builder().n_samples(300).build().unwrap();
        let host = twostage::TwoStage::builder(&model)
            .preset(twostage::paper_benchmark())
            .simulations(600)
            .validation(0)
            .calibration(100)
            .seed(9)
            .posterior(
                MixtureDensity::new(MlpParams::new(&[10]).unwrap().check().unwrap(), 3).unwrap(),
            )
            .train()
            .unwrap();
        let blob = host.to_runtime().unwrap();
        let runtime = Estimator::from_bytes(&blob).unwrap();
        let posterior = runtime.posterior().unwrap();
        // The spread calibrated on held-out records widens the head.
        assert!((host.posterior().unwrap().spread() - 1.0).abs() > 1e-3);
        let mut record = model.spec().new_record();
        let mut work = twostage::EstimateWorkspace::new();
        for i in 0..4u64 {
            model
                .simulate(
                    &[-0.6 + 0.4 * i as f64],
                    &mut experiment_rng(2, i),
                    &mut record,
                )
                .unwrap();
            let features = host
                .features_of(record.inputs(), record.outputs(), &mut work)
                .unwrap()
                .to_vec();
            let mut expected = [0.0; 300];
            host.posterior()
                .unwrap()
                .sample(
                    &features,
                    &mut stream_rng(17, i, StreamPurpose::Posterior),
                    &mut expected,
                )
                .unwrap();
            let mut own = [0.0; 64];
            let mut scratch = [0.0; 128];
            let mut got = [0.0; 300];
            posterior
                .draw(&features, (17, i), (&mut own, &mut scratch), &mut got)
                .unwrap();
            assert_eq!(
                got.map(f64::to_bits),
                expected.map(f64::to_bits),
                "record {i}"
            );
        }
    }
}
