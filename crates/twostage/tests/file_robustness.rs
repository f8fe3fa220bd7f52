//! The estimator-file reader never panics, whatever the bytes.
//!
//! Random bytes rarely get past the magic and the checksum, so the
//! properties also mutate real payloads and then re-seal them with a
//! correct length and checksum: that is what a buggy writer or a malicious
//! file would look like, and it reaches the decoder and the estimator.
#![allow(clippy::unwrap_used)]

use std::sync::OnceLock;

use proptest::prelude::*;
use twostage::compress::{Arx, Narx, OutputPca};
use twostage::fit::MlpParams;
use twostage::models::{Benchmark, IoData, Simulator, experiment_rng};
use twostage::{CompressorConfig, Estimator, RegressorConfig, TwoStage};

const HEADER: usize = 24;

/// Bit-by-bit CRC-32 (IEEE), a second algorithm beside the library's table.
fn crc32_bitwise(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

fn seal(payload: &[u8]) -> Vec<u8> {
    seal_version(payload, twostage::FORMAT_VERSION)
}

fn seal_version(payload: &[u8], version: u32) -> Vec<u8> {
    let mut bytes = b"TWOSTAGE".to_vec();
    bytes.extend_from_slice(&version.to_le_bytes());
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&crc32_bitwise(payload).to_le_bytes());
    bytes.extend_from_slice(payload);
    bytes
}

fn model() -> Benchmark {
    Benchmark::builder().n_samples(120).build().unwrap()
}

/// Five small estimators covering every stored component: linear, MLP and
/// piecewise stage 2, ARX, NARX and PCA stage 1, intervals and a validation report.
fn files() -> &'static [Vec<u8>] {
    static FILES: OnceLock<Vec<Vec<u8>>> = OnceLock::new();
    FILES.get_or_init(|| {
        let model = model();
        let mlp = RegressorConfig::Mlp(
            MlpParams::new(&[3])
                .unwrap()
                .max_iterations(5)
                .check()
                .unwrap(),
        );
        let small = MlpParams::new(&[2])
            .unwrap()
            .max_iterations(5)
            .check()
            .unwrap();
        let pieces = RegressorConfig::Piecewise(
            twostage::fit::Piecewise::new(small.clone(), small, 2).unwrap(),
        );
        let configs: [(CompressorConfig, Option<RegressorConfig>); 6] = [
            (Arx::new(2, 2).unwrap().into(), None),
            ("arx:1,1+learned:2".parse().unwrap(), None),
            (Arx::new(2, 1).unwrap().into(), Some(mlp.clone())),
            (Narx::new(1, 1, 2).unwrap().into(), Some(mlp)),
            (OutputPca::new(3).unwrap().into(), None),
            (Arx::new(1, 1).unwrap().into(), Some(pieces)),
        ];
        configs
            .into_iter()
            .map(|(compressor, regressor)| {
                let builder = TwoStage::builder(&model)
                    .compressor(compressor)
                    .simulations(40)
                    .calibration(20)
                    .validation(20)
                    .seed(3);
                let builder = match regressor {
                    Some(r) => builder.regressor(r),
                    None => builder.linear(1e-6).unwrap(),
                };
                builder.train().unwrap().to_bytes().unwrap()
            })
            .collect()
    })
}

fn record() -> IoData {
    let model = model();
    let mut record = model.spec().new_record();
    model
        .simulate(&[0.3], &mut experiment_rng(5, 0), &mut record)
        .unwrap();
    record
}

/// Everything a user can do with a loaded estimator must return, not panic.
fn exercise(estimator: &Estimator, record: &IoData) {
    if let Ok(theta) = estimator.estimate_record(record) {
        assert_eq!(theta.len(), estimator.param_names().len());
        for ((t, lo), hi) in theta.iter().zip(estimator.lower()).zip(estimator.upper()) {
            assert!(
                t.is_nan() || (lo <= t && t <= hi) || lo > hi,
                "{t} outside [{lo}, {hi}]"
            );
        }
    }
    let _ = estimator.estimate_batch(std::slice::from_ref(record));
    if let Ok(a) = estimator.assess(record) {
        let _ = a.out_of_distribution();
    }
    let _ = estimator.to_json();
    let _ = format!("{estimator:?}");
    if let Some(report) = estimator.validation() {
        let _ = report.to_string();
    }
    if let Some(intervals) = estimator.intervals() {
        let _ = format!("{intervals:?}");
    }
    // Whatever decoded writes back to the same bytes. (Compared as bytes: a
    // resealed mutation may put a NaN into a report's numbers, which the
    // estimate never reads and `==` never equals.)
    let bytes = estimator.to_bytes().unwrap();
    let again = Estimator::from_bytes(&bytes).unwrap().to_bytes().unwrap();
    assert!(again == bytes, "a decoded estimator re-encodes differently");
}

#[test]
fn the_bitwise_crc_agrees_with_the_files_we_write() {
    for file in files() {
        // Each file carries the version it needs (7 only for a learned stage 1).
        let version = u32::from_le_bytes([file[8], file[9], file[10], file[11]]);
        assert_eq!(seal_version(&file[HEADER..], version), *file);
    }
}

#[test]
fn version_1_and_2_files_load_with_uniform_priors_and_without_an_envelope() {
    // Version 3 appended the priors and the signal names, version 2 the
    // envelope and the adaptive intervals, each as the last fields. One uniform prior is postcard's
    // length 1, variant 0 and two f64 (17 bytes after the length); an
    // estimator without envelope and adaptive intervals encodes each as a
    // single 0 byte (None). Dropping those gives what versions 2 and 1 wrote.
    let model = model();
    let estimator = TwoStage::builder(&model)
        .compressor(Arx::new(5, 5).unwrap())
        .simulations(10)
        .calibration(0)
        .validation(0)
        .linear(1e-6)
        .unwrap()
        .train()
        .unwrap();
    assert!(
        estimator.envelope().is_none(),
        "10 rows cannot fit an envelope of 10 features"
    );
    // Without a validation report, version 4 writes what version 3 did,
    // and without held-out records versions 5 and 6 add one None each (no
    // input family, no input shapes) to it.
    let v6 = estimator.to_bytes().unwrap();
    assert!(estimator.input_family().is_none() && estimator.input_shapes().is_none());
    assert_eq!(&v6[v6.len() - 2..], &[0, 0]);
    let v3 = &v6[..v6.len() - 2];
    // Then the signal names: Some, ["u"], ["y"] (lengths and bytes).
    let names = [1, 1, 1, b'u', 1, 1, b'y'];
    assert_eq!(&v3[v3.len() - names.len()..], &names);
    let priors = 1 + 17 + names.len();
    let v2_payload = &v3[HEADER..v3.len() - priors];
    assert_eq!(&v3[v3.len() - priors..v3.len() - priors + 2], &[1, 0]);
    // An older file is the same estimator: without stored names it reads
    // columns u and y, which is what this one stores.
    let same = |old: &Estimator| {
        assert_eq!(old.signal_names(), estimator.signal_names());
        // Re-encoded with the names a version-3 file would hold (and no
        // input family, no input shapes).
        let mut bytes = old.to_bytes().unwrap();
        bytes.truncate(bytes.len() - 3);
        bytes.extend_from_slice(&names);
        assert_eq!(bytes.len(), v3.len());
        assert_eq!(bytes[HEADER..], v3[HEADER..]);
    };
    same(&Estimator::from_bytes(&seal_version(v2_payload, 2)).unwrap());
    assert_eq!(&v2_payload[v2_payload.len() - 2..], &[0, 0]);
    let v1_payload = &v2_payload[..v2_payload.len() - 2];
    same(&Estimator::from_bytes(&seal_version(v1_payload, 1)).unwrap());
    // And each reader refuses the older bytes under its own header.
    assert!(Estimator::from_bytes(&seal_version(v1_payload, 2)).is_err());
    assert!(Estimator::from_bytes(&seal_version(v2_payload, 3)).is_err());
}

#[test]
fn version_3_files_load_their_report_without_a_certificate() {
    // Version 4 added the betting certificate, an Option after each
    // parameter's Theorem 1 bound and after the whole vector's. Cutting the
    // encoded certificates out of a version-4 payload (each Some(bound) is
    // postcard's 1 and the bound's fields, unique bytes here) gives what
    // version 3 wrote.
    let model = model();
    let estimator = TwoStage::builder(&model)
        .compressor(Arx::new(3, 3).unwrap())
        .simulations(40)
        .calibration(0)
        .validation(30)
        .linear(1e-6)
        .unwrap()
        .train()
        .unwrap();
    // Versions 5 and 6 append the input family and its shapes: without
    // them, a 0 byte each.
    let estimator = estimator.with_input_family(None);
    let report = estimator.validation().unwrap();
    let v6 = estimator.to_bytes().unwrap();
    let v4 = seal_version(&v6[HEADER..v6.len() - 2], 4);
    // Version 3 has no such field; version 4 without certificates has a
    // None, a single 0 byte, in its place.
    let (mut payload, mut without) = (v4[HEADER..].to_vec(), v4[HEADER..].to_vec());
    let certificates = report
        .parameters
        .iter()
        .map(|p| p.certified)
        .chain([report.certified_total]);
    for certificate in certificates {
        assert!(certificate.is_some());
        let encoded = postcard::to_allocvec(&certificate).unwrap();
        let find = |bytes: &[u8]| {
            bytes
                .windows(encoded.len())
                .position(|w| w == encoded.as_slice())
                .unwrap()
        };
        let at = find(&payload);
        payload.splice(at..at + encoded.len(), []);
        let at = find(&without);
        without.splice(at..at + encoded.len(), [0]);
    }
    let old = Estimator::from_bytes(&seal_version(&payload, 3)).unwrap();
    let old_report = old.validation().unwrap();
    assert!(old_report.certified_total.is_none());
    assert!(old_report.parameters.iter().all(|p| p.certified.is_none()));
    assert_eq!(old_report.total, report.total);
    assert_eq!(
        old_report.parameters[0].hoeffding,
        report.parameters[0].hoeffding
    );
    // Everything else is the same estimator: written again, it is the
    // version-6 file of a report without certificates, no family and no
    // shapes.
    let mut again = without.clone();
    again.extend([0, 0]);
    assert_eq!(old.to_bytes().unwrap(), seal_version(&again, 6));
    assert!(Estimator::from_bytes(&seal_version(&v4[HEADER..], 3)).is_err());
}

#[test]
fn version_4_files_load_without_an_input_family() {
    // Version 5 appended the family of inputs the held-out records
    // spanned: the last field, postcard's Some and the family. Cutting it
    // gives what version 4 wrote.
    let model = model();
    let estimator = TwoStage::builder(&model)
        .compressor(Arx::new(3, 3).unwrap())
        .simulations(40)
        .calibration(30)
        .validation(30)
        .linear(1e-6)
        .unwrap()
        .train()
        .unwrap();
    let family = estimator.input_family().unwrap();
    assert_eq!(family.records(), 60);
    // Version 6 appends the shapes' density: of 60 records, none (a 0).
    assert!(estimator.input_shapes().is_none());
    let v6 = estimator.to_bytes().unwrap();
    assert_eq!(v6.last(), Some(&0));
    let v5 = seal_version(&v6[HEADER..v6.len() - 1], 5);
    assert_eq!(Estimator::from_bytes(&v5).unwrap(), estimator);
    let encoded = postcard::to_allocvec(&Some(family)).unwrap();
    assert!(v5.ends_with(&encoded));
    let v4_payload = &v5[HEADER..v5.len() - encoded.len()];
    let old = Estimator::from_bytes(&seal_version(v4_payload, 4)).unwrap();
    assert!(old.input_family().is_none());
    assert_eq!(old, estimator.clone().with_input_family(None));
    // The version-4 reader refuses a version-5 payload, and back.
    assert!(Estimator::from_bytes(&seal_version(&v5[HEADER..], 4)).is_err());
    assert!(Estimator::from_bytes(&seal_version(v4_payload, 5)).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_are_rejected_or_decoded(bytes in proptest::collection::vec(any::<u8>(), 0..256)) {
        let _ = Estimator::from_bytes(&bytes);
        let mut with_magic = b"TWOSTAGE".to_vec();
        with_magic.extend_from_slice(&bytes);
        let _ = Estimator::from_bytes(&with_magic);
        if let Ok(e) = Estimator::from_bytes(&seal(&bytes)) {
            exercise(&e, &record());
        }
    }

    #[test]
    fn resealed_mutations_of_real_files_never_panic(
        which in 0usize..6,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        cut in proptest::option::of(any::<prop::sample::Index>()),
    ) {
        let file = &files()[which];
        let mut payload = file[HEADER..].to_vec();
        for (at, byte) in &edits {
            let i = at.index(payload.len());
            payload[i] = *byte;
        }
        if let Some(cut) = cut {
            payload.truncate(cut.index(payload.len()));
        }
        // Under the file's own version, whose layout the payload is.
        let version = u32::from_le_bytes([file[8], file[9], file[10], file[11]]);
        if let Ok(e) = Estimator::from_bytes(&seal_version(&payload, version)) {
            exercise(&e, &record());
        }
    }

    #[test]
    fn unsealed_corruption_is_always_caught(which in 0usize..6, at in any::<prop::sample::Index>(), flip in 1u8..=255) {
        let mut file = files()[which].clone();
        let i = at.index(file.len());
        file[i] ^= flip;
        prop_assert!(Estimator::from_bytes(&file).is_err());
    }
}

#[test]
fn a_save_that_fails_leaves_the_file_it_would_replace_and_no_debris() {
    let dir = std::env::temp_dir().join(format!("save-whole-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let estimator = Estimator::from_bytes(&files()[0]).unwrap();
    let path = dir.join("kept.tsest");
    estimator.save(&path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), estimator.to_bytes().unwrap());
    // A save that cannot be renamed into place (a folder is there) fails,
    // names the path, and leaves no temporary file behind.
    let blocked = dir.join("blocked.tsest");
    std::fs::create_dir(&blocked).unwrap();
    let err = estimator.save(&blocked).unwrap_err();
    assert!(
        matches!(&err, twostage::estimator::Error::Io { path, .. } if path.ends_with("blocked.tsest")),
        "{err}"
    );
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["blocked.tsest", "kept.tsest"]);
    // The file a save replaces is still whole until the new one is.
    assert_eq!(
        Estimator::load(&path).unwrap().to_bytes().unwrap(),
        estimator.to_bytes().unwrap()
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Files far larger than any estimator or model file (sparse: nothing is
/// written) are refused by their size before they are read.
#[test]
#[cfg(target_os = "linux")]
fn files_larger_than_their_kind_are_refused_before_they_are_read() {
    let dir = std::env::temp_dir().join(format!("huge-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let sparse = |name: &str, size: u64| {
        let path = dir.join(name);
        std::fs::File::create(&path).unwrap().set_len(size).unwrap();
        path
    };
    let model = sparse("model.toml", 100_000_000);
    let e = twostage::ModelFile::load(&model).unwrap_err().to_string();
    assert!(
        e.contains("a file of 100.0 MB, where a model file takes at most 16.8 MB"),
        "{e}"
    );
    let estimator = sparse("huge.tsest", 100_000_000_000);
    let e = Estimator::load(&estimator).unwrap_err().to_string();
    if twostage::models::available_memory().is_some_and(|bytes| bytes < 100_000_000_000) {
        assert!(
            e.contains("a file of 100.0 GB, where this process has") && e.contains("huge.tsest"),
            "{e}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
