//! A design's settings changed after it is built: its offset drawn per
//! experiment, its lines shaped.

use super::{InputSignal, Kind};
use crate::InvalidSetting;
use crate::error::{Result, SimError};
use crate::input_design::{Design, Drawn, Spectrum};

impl InputSignal {
    /// The same design about an offset drawn per experiment from
    /// `offset`'s range (a family of operating points), instead of its own.
    ///
    /// ```
    /// use twostage_models::{Drawn, ExperimentRng, InputSignal, experiment_rng};
    /// let sweep = InputSignal::sweep(0.1, Drawn::fixed(2.0), Drawn::fixed(1.0), 0.0)?;
    /// let around = sweep.with_offset(Drawn::between(4.0, 6.0)?)?;
    /// let mean = |k: u64| {
    ///     let mut u = vec![0.0; 1000];
    ///     around.fill(0.01, &mut experiment_rng(3, k), &mut u).map(|()| u.iter().sum::<f64>() / 1000.0)
    /// };
    /// let (a, b) = (mean(0)?, mean(1)?);
    /// assert!((3.9..6.1).contains(&a) && (3.9..6.1).contains(&b) && (a - b).abs() > 1e-6);
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for a signal that is no design (white
    /// noise, the chicane, a fixed signal, a sum, mixture or sequence: give
    /// the offset to its parts).
    pub fn with_offset(self, offset: Drawn) -> Result<Self> {
        match self.kind {
            Kind::Designed { design, .. } => Ok(Self {
                kind: Kind::Designed { design, offset },
            }),
            _ => Err(SimError::InvalidSetting(InvalidSetting {
                name: "input offset",
                value: format!("{:?}", offset.range()),
                reason: "a drawn offset is for a design (multisine, binary, prbs, sweep, \
                         gaussian, bursts, ramps): give it to the parts of a sum, mixture or \
                         sequence"
                    .into(),
            })),
        }
    }

    /// The same multisine or band noise with its lines' amplitudes shaped
    /// by `spectrum` (a table, or a measured record's shape): a family of
    /// inputs that looks like the one a plant was measured with. A band
    /// noise becomes Gaussian lines on the record's full grid (periodic
    /// over the record), its filters' order no longer used.
    ///
    /// ```
    /// use twostage_models::{Drawn, Grid, InputSignal, Level, Phases, Spectrum, experiment_rng};
    /// let falling = Spectrum::table(vec![[0.0, 1.0], [50.0, 0.25]])?;
    /// let u = InputSignal::multisine(0.0, Drawn::fixed(50.0), Grid::Full, Phases::Random,
    ///     Level::Rms(Drawn::fixed(1.0)), 0.0)?
    ///     .with_spectrum(falling)?;
    /// let mut x = vec![0.0; 1000];
    /// u.fill(0.01, &mut experiment_rng(1, 0), &mut x)?;
    /// // The shape, read back from the record, falls as the table does.
    /// let read = Spectrum::like(&x)?;
    /// let ratio = read.level_at(45.0, 0.01) / read.level_at(5.0, 0.01);
    /// assert!((ratio - 0.325 / 0.925).abs() < 0.01, "{ratio}");
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for any other signal (give the shape to
    /// the multisine or noise part of a sum, mixture or sequence).
    pub fn with_spectrum(self, spectrum: Spectrum) -> Result<Self> {
        let refused = || {
            Err(SimError::InvalidSetting(InvalidSetting {
                name: "input spectrum",
                value: spectrum.describe(),
                reason: "shapes a multisine's or a band noise's lines: give it to that design \
                         (or to such a part of a sum, mixture or sequence)"
                    .into(),
            }))
        };
        let Kind::Designed { design, offset } = self.kind else {
            return refused();
        };
        let design = match *design {
            Design::Multisine {
                band,
                grid,
                phases,
                level,
                ..
            } => Design::Multisine {
                band,
                grid,
                phases,
                level,
                spectrum: Some(spectrum),
            },
            Design::FilteredNoise { band, rms, .. } | Design::ShapedNoise { band, rms, .. } => {
                Design::ShapedNoise {
                    band,
                    spectrum,
                    rms,
                }
            }
            _ => return refused(),
        };
        design.check(0.0)?;
        Ok(Self {
            kind: Kind::Designed {
                design: Box::new(design),
                offset,
            },
        })
    }
}
