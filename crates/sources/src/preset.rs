//! A preset: the structure and size of one training run.

use twostage_compress::CompressorConfig;
use twostage_fit::RegressorConfig;

/// The choices of one training run, reusable across simulators: as a model
/// file's `[[preset]]` writes them, or as the per-model table holds them.
///
/// ```
/// use twostage_sources::Preset;
/// let preset = Preset {
///     compressor: "arx:2,2".parse()?,
///     regressor: "mlp:20".parse()?,
///     simulations: 4000,
/// };
/// assert_eq!(preset.compressor.to_string(), "ARX(2, 2)");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Preset {
    /// Stage-1 compressor.
    pub compressor: CompressorConfig,
    /// Stage-2 method.
    pub regressor: RegressorConfig,
    /// Training simulations m.
    pub simulations: usize,
}
