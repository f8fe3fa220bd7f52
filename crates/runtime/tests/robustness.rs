//! Blobs from anywhere: random, truncated and mutated (and re-sealed, so
//! that the checks behind the checksum are reached) never panic, and an
//! estimator that passes its checks estimates without panicking; streams
//! misused answer with the error that says so.

// A panic is how a test fails.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

mod common;

use std::sync::OnceLock;

use common::seal;

use proptest::prelude::*;
use twostage::TwoStage;
use twostage::models::{Benchmark, PacejkaCar, Simulator, experiment_rng};
use twostage_runtime::format::CHECKSUM_FROM;
use twostage_runtime::{Error, Estimator, Stream};

/// A network estimator, a piecewise one, one whose stage 1 ends in a
/// learned summary network, all with intervals and envelope, and one
/// whose stage 1 linearizes the car.
fn blobs() -> &'static [Vec<u8>; 4] {
    static BLOBS: OnceLock<[Vec<u8>; 4]> = OnceLock::new();
    BLOBS.get_or_init(|| {
        let benchmark = Benchmark::builder().n_samples(120).build().unwrap();
        let car = PacejkaCar::builder().n_samples(120).build().unwrap();
        let train = |model: &dyn Simulator, compress: &str, regressor: &str| {
            TwoStage::builder(model)
                .compressor(
                    compress
                        .parse::<twostage::compress::CompressorConfig>()
                        .unwrap(),
                )
                .regressor(regressor.parse().unwrap())
                .simulations(300)
                .validation(0)
                .calibration(150)
                .seed(2)
                .train()
                .unwrap()
                .to_runtime()
                .unwrap()
        };
        [
            train(&benchmark, "arx:2,2", "mlp:4"),
            train(&benchmark, "arx:2,2", "piecewise:2,3"),
            train(&benchmark, "arx:2,2+learned:3", "mlp:4"),
            train(&car, "linearized:1", "mlp:4"),
        ]
    })
}

fn record() -> (Vec<f64>, Vec<f64>) {
    let model = Benchmark::builder().n_samples(120).build().unwrap();
    let mut record = model.spec().new_record();
    model
        .simulate(&[0.5], &mut experiment_rng(5, 0), &mut record)
        .unwrap();
    (record.input(0).to_vec(), record.output(0).to_vec())
}

/// Whatever the blob, reading it and (if it reads) estimating ends in a
/// value, never a panic.
fn exercise(blob: &[u8]) {
    if let Ok(estimator) = Estimator::from_bytes(blob) {
        let (u, y) = record();
        let mut work = vec![0.0; estimator.workspace_len().min(1 << 20)];
        let q = estimator.n_parameters();
        let (mut theta, mut widths) = (vec![0.0; q], vec![0.0; q]);
        if let Ok(mut stream) = Stream::new(&estimator, &mut work) {
            let (ni, no) = (estimator.n_inputs(), estimator.n_outputs());
            for k in 0..u.len() {
                let _ = stream.push(&vec![u[k]; ni], &vec![y[k]; no]);
            }
            if let Ok(a) = stream.finish(&mut theta, &mut widths) {
                let _ = a.out_of_distribution();
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        exercise(&bytes);
        // The same bytes behind a valid header reach the field checks.
        let mut sealed = b"TSRT\x01\0\0\0".to_vec();
        sealed.extend_from_slice(&[0; 8]);
        sealed.extend_from_slice(&bytes);
        seal(&mut sealed);
        exercise(&sealed);
    }

    #[test]
    fn mutated_blobs_never_panic(
        which in 0usize..4,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        cut in any::<prop::sample::Index>(),
        truncate in any::<bool>(),
    ) {
        let mut blob = blobs()[which].clone();
        for (at, value) in &edits {
            let i = at.index(blob.len());
            blob[i] = *value;
        }
        exercise(&blob); // the checksum refuses it
        if truncate {
            blob.truncate(cut.index(blob.len()));
        }
        seal(&mut blob);
        exercise(&blob);
    }

    #[test]
    fn learned_shapes_set_to_anything_never_panic(
        word in 0usize..4,
        value in prop_oneof![0u32..100, any::<u32>()],
    ) {
        // One layer of three channels, kernel 5, stride 2.
        let mut blob = blobs()[2].clone();
        let shape: Vec<u8> = [1u32, 3, 5, 2].iter().flat_map(|w| w.to_le_bytes()).collect();
        let at = blob
            .windows(shape.len())
            .position(|w| w == shape.as_slice())
            .expect("the learned section's shape");
        blob[at + 4 * word..at + 4 * word + 4].copy_from_slice(&value.to_le_bytes());
        seal(&mut blob);
        exercise(&blob);
    }

    #[test]
    fn the_cars_numbers_set_to_anything_never_panic(
        word in 0usize..twostage_kernels::linearized::CarLinearization::WORDS,
        value in prop_oneof![
            Just(0.0),
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(-1e300),
            -1e6f64..1e6,
        ],
    ) {
        // The car's section follows the header, two transform codes and
        // the box.
        let mut blob = blobs()[3].clone();
        let at = 64 + 8 + 4 * 8 + 8 * word;
        blob[at..at + 8].copy_from_slice(&value.to_le_bytes());
        seal(&mut blob);
        exercise(&blob);
    }

    #[test]
    fn counts_set_to_anything_never_panic(
        which in 0usize..4,
        field in 0usize..12,
        value in prop_oneof![0u32..300, any::<u32>()],
    ) {
        let mut blob = blobs()[which].clone();
        let at = CHECKSUM_FROM + 4 * field;
        blob[at..at + 4].copy_from_slice(&value.to_le_bytes());
        seal(&mut blob);
        exercise(&blob);
    }
}

proptest! {
    /// The runtime's table-free CRC against crc32fast's tables.
    #[test]
    fn the_checksum_is_crc32(bytes in proptest::collection::vec(any::<u8>(), 0..3000)) {
        prop_assert_eq!(twostage_runtime::format::checksum(&bytes), crc32fast::hash(&bytes));
    }
}

#[test]
fn damage_is_named() {
    let blob = &blobs()[0];
    assert_eq!(
        Estimator::from_bytes(&blob[1..]).unwrap_err(),
        Error::BadMagic
    );
    let mut flipped = blob.clone();
    let last = flipped.len() - 1;
    flipped[last] ^= 1;
    assert!(matches!(
        Estimator::from_bytes(&flipped),
        Err(Error::Checksum { .. })
    ));
    assert!(matches!(
        Estimator::from_bytes(&blob[..blob.len() - 8]),
        Err(Error::Length { declared, actual }) if declared == blob.len() && actual == blob.len() - 8
    ));
    let mut newer = blob.clone();
    newer[4] = 7;
    assert_eq!(
        Estimator::from_bytes(&newer).unwrap_err(),
        Error::UnsupportedVersion { found: 7 }
    );
    assert_eq!(
        Error::UnsupportedVersion { found: 7 }.to_string(),
        "blob format version 7, this runtime reads versions 1 to 6: export the estimator \
         again with the matching twostage"
    );
    // The summary's flag belongs to version 3 and the learned one to
    // version 4: an older blob that sets one is damaged, not a section
    // the reader would skip.
    let mut flagged = blob.clone();
    assert_eq!(flagged[4], 2, "a blob with an input family");
    flagged[44] |= twostage_runtime::format::FLAG_SIGNAL_SUMMARY as u8;
    seal(&mut flagged);
    assert!(matches!(
        Estimator::from_bytes(&flagged),
        Err(Error::Invalid { field: "flags", .. })
    ));
    flagged[4] = 3;
    seal(&mut flagged);
    assert!(
        Estimator::from_bytes(&flagged).is_err(),
        "its features outnumber the network's inputs"
    );
    let mut learned = blobs()[2].clone();
    assert_eq!(learned[4], 4, "a blob with a learned summary");
    learned[4] = 3;
    seal(&mut learned);
    assert!(matches!(
        Estimator::from_bytes(&learned),
        Err(Error::Invalid { field: "flags", .. })
    ));
    // The linearized car belongs to version 5.
    let mut linearized = blobs()[3].clone();
    assert_eq!(linearized[4], 5, "a blob with the car linearized");
    linearized[4] = 4;
    seal(&mut linearized);
    assert!(matches!(
        Estimator::from_bytes(&linearized),
        Err(Error::Invalid { field: "flags", .. })
    ));
    // Its ARX orders must be 0: na = 2 is damage, not a regression.
    let mut ordered = blobs()[3].clone();
    let na_at = CHECKSUM_FROM + 4 * 4;
    ordered[na_at] = 2;
    seal(&mut ordered);
    assert!(matches!(
        Estimator::from_bytes(&ordered),
        Err(Error::Invalid {
            field: "record shape or ARX orders",
            ..
        })
    ));
    // One more byte, sealed: read to the end, the byte is left over.
    let mut longer = blob.clone();
    longer.push(0);
    seal(&mut longer);
    assert_eq!(
        Estimator::from_bytes(&longer).unwrap_err(),
        Error::TrailingBytes { at: blob.len() }
    );
    // A layer wider than the runtime takes.
    let mut wide = blob.clone();
    let q_at = CHECKSUM_FROM;
    wide[q_at..q_at + 4].copy_from_slice(&1000u32.to_le_bytes());
    seal(&mut wide);
    assert!(matches!(
        Estimator::from_bytes(&wide),
        Err(Error::Invalid { field: "parameter count", at }) if at == q_at
    ));
}

#[test]
fn a_misused_stream_answers_with_the_reason() {
    let estimator = Estimator::from_bytes(&blobs()[0]).unwrap();
    let needed = estimator.workspace_len();
    let mut small = vec![0.0; needed - 1];
    assert_eq!(
        Stream::new(&estimator, &mut small).unwrap_err(),
        Error::WorkspaceTooSmall {
            needed,
            given: needed - 1
        }
    );
    let mut work = vec![0.0; needed];
    let mut stream = Stream::new(&estimator, &mut work).unwrap();
    let (mut theta, mut widths) = ([0.0], [0.0]);
    assert_eq!(
        stream.push(&[1.0, 2.0], &[0.0]).unwrap_err(),
        Error::SignalCount {
            inputs: 1,
            outputs: 1
        }
    );
    for k in 0..5 {
        stream.push(&[1.0], &[f64::from(k)]).unwrap();
    }
    // ARX(2, 2) needs 2 past samples and 4 equations.
    assert_eq!(
        stream.finish(&mut theta, &mut widths).unwrap_err(),
        Error::TooShort {
            samples: 5,
            needed: 6
        }
    );
    assert_eq!(
        stream.finish(&mut [], &mut widths).unwrap_err(),
        Error::OutputTooShort { needed: 1 }
    );
    stream.push(&[f64::NAN], &[0.0]).unwrap_err();
    assert_eq!(
        stream.finish(&mut theta, &mut widths).unwrap_err(),
        Error::NotFinite { sample: 5 }
    );
    stream.reset();
    // A constant input does not excite the input lags: column 3 (b2)
    // repeats column 2 (b1).
    let (_, y) = record();
    for v in &y {
        stream.push(&[1.0], &[*v]).unwrap();
    }
    assert_eq!(
        stream.finish(&mut theta, &mut widths).unwrap_err(),
        Error::RankDeficient {
            output: 0,
            column: 3
        }
    );
    stream.reset();
    let (u, y) = record();
    for (u, y) in u.iter().zip(&y) {
        stream.push(&[*u], &[*y]).unwrap();
    }
    // After the errors and resets, the record simulated at theta = 0.5
    // is estimated as from a fresh stream.
    stream.finish(&mut theta, &mut widths).unwrap();
    let mut fresh_work = vec![0.0; needed];
    let (mut fresh, mut fresh_widths) = ([0.0], [0.0]);
    estimator
        .estimate_record(&u, &y, &mut fresh_work, &mut fresh, &mut fresh_widths)
        .unwrap();
    assert_eq!(theta[0].to_bits(), fresh[0].to_bits());
    // Finishing halfway estimates the first half, as a stream of the first
    // half alone does, and the stream goes on to the whole record.
    let half = u.len() / 2;
    let mut early = Stream::new(&estimator, &mut fresh_work).unwrap();
    for k in 0..half {
        early.push(&[u[k]], &[y[k]]).unwrap();
    }
    let mut so_far = [0.0];
    early.finish(&mut so_far, &mut []).unwrap();
    for k in half..u.len() {
        early.push(&[u[k]], &[y[k]]).unwrap();
    }
    early.finish(&mut theta, &mut widths).unwrap();
    assert_eq!(theta[0].to_bits(), fresh[0].to_bits());
    let mut prefix_work = vec![0.0; needed];
    let mut prefix = [0.0];
    estimator
        .estimate_record(
            &u[..half],
            &y[..half],
            &mut prefix_work,
            &mut prefix,
            &mut [],
        )
        .unwrap();
    assert_eq!(so_far[0].to_bits(), prefix[0].to_bits());
    assert_ne!(so_far[0].to_bits(), fresh[0].to_bits());
    // A stream dropped halfway and resumed over its workspace goes on.
    let mut halves = vec![f64::NAN; needed];
    assert_eq!(
        Stream::resume(&estimator, &mut halves).unwrap_err(),
        Error::NotStarted
    );
    let mut first = Stream::new(&estimator, &mut halves).unwrap();
    for k in 0..half {
        first.push(&[u[k]], &[y[k]]).unwrap();
    }
    let mut second = Stream::resume(&estimator, &mut halves).unwrap();
    assert_eq!(second.samples(), half);
    for k in half..u.len() {
        second.push(&[u[k]], &[y[k]]).unwrap();
    }
    second.finish(&mut theta, &mut widths).unwrap();
    assert_eq!(theta[0].to_bits(), fresh[0].to_bits());
    assert!((theta[0] - 0.5).abs() < 0.3, "{theta:?}");
}
