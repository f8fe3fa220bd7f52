//! The exported estimator's byte layout, version 6: what
//! `twostage export --to runtime` writes and [`crate::Estimator`] reads.
//!
//! Every number is little-endian; counts are `u32`, trained values `f64`.
//! Each section starts at a multiple of 8 bytes from the blob's start (a
//! list of `u32` is padded with zero bytes), so a blob placed at an
//! 8-aligned address can be read with aligned loads, though the reader
//! does not need it.
//!
//! | bytes | field |
//! |---|---|
//! | 0..4 | magic `TSRT` |
//! | 4..8 | format version (6 with a posterior; 5 for a linearized stage 1; 4 for a learned one; 3 without it, 2 without the signals' summary either, 1 without an input family) |
//! | 8..12 | the blob's length in bytes |
//! | 12..16 | CRC-32 (IEEE) of bytes 16..length |
//! | 16..64 | twelve `u32`: q, inputs, outputs, trained record length, na, nb, delay, flags, regressor kind, experts, 0, 0 |
//!
//! Then, in order: q transform codes (`u32`); q lower and q upper bounds;
//! the learned stage 1 (flag 64) or the linearized one (flag 128); for a piecewise regressor its start and width; the networks (one, or
//! the global one and each expert); the conformal half-widths (flag 1);
//! the adaptive floors, quantiles and difficulty network (flag 2); the
//! envelope's threshold, mean and row-major lower Cholesky factor (flag
//! 4); the output signals' transform codes (`u32`, one per output) and
//! their floors (`f64`, one per output: what a sample outside the
//! transform's domain is replaced by) (flag 8); the input family (flag
//! 16, version 2): the sample time, then per input signal the low and
//! high end of each summary number's range (mean, RMS, peak, mean
//! frequency: eight `f64`). Flag 32 (version 3) has no section: stage 1
//! appends each input's, then each output's mean, RMS, peak and mean
//! frequency in cycles per sample to the ARX coefficients (the host's
//! `arx:NA,NB+summary`). The learned stage 1 (flag 64, version 4)
//! is its layer count L (`u32`), then each layer's channels out,
//! kernel and stride (`u32`; the first layer's inputs are the signals,
//! inputs first, each next one's the channels before), each signal's
//! scale, then each layer's taps (out x in x kernel, row-major) and
//! biases; stage 1 appends the last layer's time averages and average
//! squares (the host's `+learned`). The linearized stage 1 (flag 128,
//! version 5; one input, one output, two parameters, ARX orders 0) is
//! the car and its linearization as
//! `twostage_kernels::linearized::CarLinearization::to_words` writes
//! them (38 `f64`): its features are the kernels' eight (the host's
//! `linearized`). The posterior (flag 256, version 6) closes the blob:
//! its components, parameters and length in bytes from the section's
//! start (`u32`; a runtime built without draws steps over it by that
//! length), each parameter's support code
//! (`u32`: 0 the real line, 1 positive numbers, 2 an interval), each
//! parameter's interval as low and high (`f64`; zeros for the other
//! supports), the mean and scale that standardize the parameters mapped
//! to the real line, the spread and its natural logarithm, then the
//! density network (one member, target mean 0 and scale 1) from the
//! features to the mixture's head
//! (`twostage_kernels::mixture`). A network is: the count of its layer sizes and of its ensemble
//! members (`u32`), the sizes (`u32`), the feature means and scales, the
//! target means and scales, then each member's weights and biases, layer
//! by layer (row-major weights, then biases). A linear map is a network
//! with no hidden layer and zero biases.

/// The first four bytes.
pub const MAGIC: [u8; 4] = *b"TSRT";
/// The newest version this crate reads, which the exporter writes for an
/// estimator with a posterior. Versions 5 (a linearized stage 1), 4 (a
/// learned stage 1), 3 (the signals' summary, no network), 2 (an input
/// family, no summary) and 1 (no family) are read too, and written for
/// estimators without them, so that a runtime of before reads them.
pub const VERSION: u32 = 6;
/// The version of a blob without a posterior whose stage 1 linearizes.
pub const VERSION_WITHOUT_POSTERIOR: u32 = 5;
/// The version of a blob whose stage 1 learns and does not linearize.
pub const VERSION_WITHOUT_LINEARIZED: u32 = 4;
/// The version of a blob whose stage 1 appends the signals' summary and
/// does not learn.
pub const VERSION_WITHOUT_LEARNED: u32 = 3;
/// The version of a blob with an input family and no signals' summary.
pub const VERSION_WITHOUT_SUMMARY: u32 = 2;
/// The version of a blob without an input family.
pub const VERSION_WITHOUT_FAMILY: u32 = 1;
/// Bytes before the first section.
pub const HEADER_BYTES: usize = 64;
/// The checksum covers the blob from here to its end.
pub const CHECKSUM_FROM: usize = 16;

/// Flag: conformal half-widths follow.
pub const FLAG_CONFORMAL: u32 = 1;
/// Flag: adaptive intervals follow.
pub const FLAG_ADAPTIVE: u32 = 2;
/// Flag: a feature envelope follows.
pub const FLAG_ENVELOPE: u32 = 4;

/// Flag: the output signals are transformed before stage 1.
pub const FLAG_OUTPUT_TRANSFORMS: u32 = 8;

/// Flag (version 2): the input family follows, and a stream judges each
/// record's input against it.
pub const FLAG_INPUT_FAMILY: u32 = 16;

/// Flag (version 3): stage 1 appends each signal's summary (mean, RMS,
/// peak, mean frequency in cycles per sample) to the ARX coefficients.
pub const FLAG_SIGNAL_SUMMARY: u32 = 32;

/// Flag (version 4): a learned stage 1's network follows, and its
/// summary numbers close the features.
pub const FLAG_LEARNED_SUMMARY: u32 = 64;

/// Flag (version 5): stage 1 linearizes the car; its constants and
/// linearization follow the prior's box.
pub const FLAG_LINEARIZED: u32 = 128;

/// Flag (version 6): the posterior's density network follows, last.
pub const FLAG_POSTERIOR: u32 = 256;

/// Support code: a parameter on the whole real line.
pub const SUPPORT_REAL: u32 = 0;
/// Support code: a positive parameter (its logarithm is unbounded).
pub const SUPPORT_POSITIVE: u32 = 1;
/// Support code: a parameter within an interval (its logit is unbounded).
pub const SUPPORT_INTERVAL: u32 = 2;

/// Regressor kind: one network (an MLP ensemble, or a linear map).
pub const REGRESSOR_NETWORK: u32 = 1;
/// Regressor kind: a global network routing to experts by pieces of the
/// first parameter's range.
pub const REGRESSOR_PIECEWISE: u32 = 2;

/// Transform code: the network learned the parameter itself.
pub const TRANSFORM_IDENTITY: u32 = 0;
/// Transform code: the network learned its logarithm.
pub const TRANSFORM_LOG: u32 = 1;

/// Output transform code: the signal as it is.
pub const SIGNAL_IDENTITY: u32 = 0;
/// Output transform code: its natural logarithm (positive samples).
pub const SIGNAL_LOG: u32 = 1;
/// Output transform code: `ln(1 + y)` (samples above -1).
pub const SIGNAL_LOG1P: u32 = 2;

/// Most parameters.
pub const MAX_PARAMETERS: usize = 64;
/// Most input (and most output) signals.
pub const MAX_SIGNALS: usize = 16;
/// Largest ARX order or delay.
pub const MAX_ORDER: usize = 64;
/// Widest network layer.
pub const MAX_WIDTH: usize = 256;
/// Most layer sizes of a network (inputs, hidden layers, outputs).
pub const MAX_SIZES: usize = 10;
/// Most ensemble members of a network.
pub const MAX_MEMBERS: usize = 64;
/// Most components of a posterior's mixture.
pub const MAX_COMPONENTS: usize = 16;
/// Most experts of a piecewise regressor.
pub const MAX_EXPERTS: usize = 16;
/// Most convolutions of a learned stage 1.
pub const MAX_LAYERS: usize = 6;
/// Most channels of a learned stage 1's layer (and of its signals).
pub const MAX_CHANNELS: usize = 32;
/// Widest kernel of a learned stage 1, in samples.
pub const MAX_KERNEL: usize = 64;

/// The blob's checksum: CRC-32 (IEEE 802.3, as zip and PNG use it),
/// computed bit by bit, without a table: it runs once per load, and a
/// table would cost a microcontroller 1 to 16 KiB of flash.
///
/// ```
/// // The standard check value of CRC-32.
/// assert_eq!(twostage_runtime::format::checksum(b"123456789"), 0xCBF4_3926);
/// ```
pub fn checksum(bytes: &[u8]) -> u32 {
    const CRC: crc::Crc<u32, crc::NoTable> =
        crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);
    CRC.checksum(bytes)
}
