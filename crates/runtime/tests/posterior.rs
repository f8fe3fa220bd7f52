//! The runtime's posterior draws against the host's: the same seed and
//! record number give the same draws (to the features' agreement through
//! a stream), inside the prior's support, with the stream's estimate and
//! flags unchanged; a blob without a posterior, a draws array of the wrong
//! length and a damaged posterior section are refused.

// A panic is how a test fails.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

mod common;

use twostage::fit::{MixtureDensity, MlpParams};
use twostage::models::{
    Benchmark, IoData, PacejkaCar, Simulator, StreamPurpose, experiment_rng, stream_rng,
};
use twostage::{Preset, TwoStage};
use twostage_runtime::format::HEADER_BYTES;
use twostage_runtime::{Error, Estimator, Stream};

fn with_posterior(model: &dyn Simulator, preset: Preset, components: usize) -> twostage::Estimator {
    TwoStage::builder(model)
        .preset(preset)
        .simulations(800)
        .validation(0)
        .calibration(150)
        .seed(3)
        .posterior(
            MixtureDensity::new(MlpParams::new(&[12]).unwrap().check().unwrap(), components)
                .unwrap(),
        )
        .train()
        .unwrap()
}

/// Push a record through a stream and draw `n` draws of seed `seed` as
/// record number `index`; the estimate too.
fn stream_draws(
    runtime: &Estimator<'_>,
    record: &IoData,
    n: usize,
    (seed, index): (u64, u64),
) -> Result<(Vec<f64>, Vec<f64>), Error> {
    let q = runtime.n_parameters();
    let mut work = vec![0.0; runtime.workspace_len()];
    let mut stream = Stream::new(runtime, &mut work)?;
    for (u, y) in record
        .inputs()
        .rows()
        .into_iter()
        .zip(record.outputs().rows())
    {
        stream.push(&u.to_vec(), &y.to_vec())?;
    }
    let (mut theta, mut draws) = (vec![0.0; q], vec![0.0; n * q]);
    stream.finish_with_draws(&mut theta, &mut [], &mut draws, seed, index)?;
    Ok((theta, draws))
}

/// Largest difference between the runtime's and the host's draws over
/// `records` fresh records, relative to each parameter's prior width; the
/// runtime's estimate is its `finish`'s.
fn largest_difference(host: &twostage::Estimator, model: &dyn Simulator, records: u64) -> f64 {
    let blob = host.to_runtime().unwrap();
    let runtime = Estimator::from_bytes(&blob).unwrap();
    assert!(runtime.has_posterior());
    let q = runtime.n_parameters();
    let n = 500;
    let mut worst = 0.0f64;
    for i in 0..records {
        let theta: Vec<f64> = (0..q)
            .map(|j| {
                let (lo, hi) = (host.lower()[j], host.upper()[j]);
                lo + (hi - lo) * (0.2 + 0.6 * ((i as f64 * 0.37 + j as f64 * 0.61) % 1.0))
            })
            .collect();
        let mut record = IoData::default();
        model
            .simulate(&theta, &mut experiment_rng(41, i), &mut record)
            .unwrap();
        let seed = 1000 + i;
        let (estimate, draws) = stream_draws(&runtime, &record, n, (seed, i)).unwrap();
        let mut expected = vec![0.0; n * q];
        host.sample_record(
            &record,
            &mut stream_rng(seed, i, StreamPurpose::Posterior),
            &mut expected,
        )
        .unwrap();
        // The draws are the estimate's stream's: finish's estimate is the
        // one a plain finish gives.
        let mut work = vec![0.0; runtime.workspace_len()];
        let (mut alone, mut widths) = (vec![0.0; q], vec![0.0; q]);
        runtime
            .estimate_record(
                record.inputs().as_slice().unwrap(),
                record.outputs().as_slice().unwrap(),
                &mut work,
                &mut alone,
                &mut widths,
            )
            .unwrap();
        assert_eq!(estimate, alone);
        for (k, (got, want)) in draws.iter().zip(&expected).enumerate() {
            let j = k % q;
            assert!(
                (host.lower()[j]..=host.upper()[j]).contains(got),
                "record {i}, draw {k}: {got} outside the prior"
            );
            let width = host.upper()[j] - host.lower()[j];
            worst = worst.max((got - want).abs() / width);
        }
    }
    worst
}

#[test]
fn the_benchmark_s_draws_are_the_host_s() {
    let model = Benchmark::builder().n_samples(300).build().unwrap();
    let host = with_posterior(&model, twostage::paper_benchmark(), 2);
    let worst = largest_difference(&host, &model, 6);
    assert!(worst < 1e-9, "{worst}");
}

#[test]
fn the_car_s_draws_are_the_host_s() {
    let model = PacejkaCar::builder().build().unwrap();
    let host = with_posterior(&model, twostage::paper_pacejka(), 3);
    let worst = largest_difference(&host, &model, 3);
    assert!(worst < 1e-9, "{worst}");
    // Two parameters: three numbers are no whole number of draws, refused
    // before the estimate.
    let blob = host.to_runtime().unwrap();
    let runtime = Estimator::from_bytes(&blob).unwrap();
    let mut work = vec![0.0; runtime.workspace_len()];
    let mut stream = Stream::new(&runtime, &mut work).unwrap();
    assert_eq!(
        stream
            .finish_with_draws(&mut [0.0; 2], &mut [], &mut [0.0; 3], 1, 0)
            .unwrap_err(),
        Error::DrawCount { parameters: 2 }
    );
}

#[test]
fn draws_are_refused_without_a_posterior_or_of_a_wrong_count() {
    let model = Benchmark::builder().n_samples(300).build().unwrap();
    let mut record = IoData::default();
    model
        .simulate(&[0.3], &mut experiment_rng(5, 0), &mut record)
        .unwrap();
    let plain = TwoStage::builder(&model)
        .preset(twostage::paper_benchmark())
        .simulations(300)
        .validation(0)
        .calibration(0)
        .train()
        .unwrap()
        .to_runtime()
        .unwrap();
    let plain = Estimator::from_bytes(&plain).unwrap();
    assert!(!plain.has_posterior());
    assert_eq!(
        stream_draws(&plain, &record, 10, (1, 0)).unwrap_err(),
        Error::NoPosterior
    );
    let blob = with_posterior(&model, twostage::paper_benchmark(), 1)
        .to_runtime()
        .unwrap();
    let runtime = Estimator::from_bytes(&blob).unwrap();
    // One parameter: any count is whole; the empty array draws nothing.
    assert!(
        stream_draws(&runtime, &record, 0, (1, 0))
            .unwrap()
            .1
            .is_empty()
    );
    let message = Error::DrawCount { parameters: 2 }.to_string();
    assert!(message.contains("whole number of draws of 2"), "{message}");
    assert!(Error::explain(Error::NoPosterior.code()).is_some());
    assert!(Error::explain(Error::DrawCount { parameters: 1 }.code()).is_some());
}

#[test]
fn a_damaged_posterior_section_is_refused_where_it_lies() {
    let model = Benchmark::builder().n_samples(300).build().unwrap();
    let blob = with_posterior(&model, twostage::paper_benchmark(), 2)
        .to_runtime()
        .unwrap();
    let runtime = Estimator::from_bytes(&blob).unwrap();
    // The section closes the blob: for one parameter, its counts (16
    // bytes), support code (8), interval (16), standardization (16) and
    // spread (16), then the network of layers [features, 12, 6] (two
    // components' head): counts, sizes padded, standardizations and
    // weights.
    let nf = runtime.n_features();
    let head = 6;
    let network = 8 + 16 + 16 * nf + 16 * head + 8 * (12 * (nf + 1) + head * 13);
    let at = blob.len() - (72 + network);
    assert!(at > HEADER_BYTES);
    let damaged = |offset: usize, bytes: &[u8]| {
        let mut copy = blob.clone();
        copy[at + offset..at + offset + bytes.len()].copy_from_slice(bytes);
        common::seal(&mut copy);
        Estimator::from_bytes(&copy).map(|_| ()).unwrap_err()
    };
    // No component, two parameters for one, a support code that is none,
    // an interval upside down, a spread of zero.
    let invalid = |field| Error::Invalid { field, at };
    assert_eq!(damaged(0, &0u32.to_le_bytes()), invalid("posterior shape"));
    assert_eq!(damaged(4, &2u32.to_le_bytes()), invalid("posterior shape"));
    assert_eq!(
        damaged(8, &3u32.to_le_bytes()),
        Error::Invalid {
            field: "posterior section length",
            at: at + 8
        }
    );
    assert!(matches!(
        damaged(16, &7u32.to_le_bytes()),
        Error::Invalid {
            field: "posterior support code",
            ..
        }
    ));
    assert!(matches!(
        damaged(24, &1.0f64.to_le_bytes()),
        Error::Invalid {
            field: "posterior support bounds",
            ..
        }
    ));
    assert!(matches!(
        damaged(56, &0.0f64.to_le_bytes()),
        Error::Invalid {
            field: "posterior spread",
            ..
        }
    ));
    // A version 5 blob does not know the flag.
    let mut old = blob.clone();
    old[4..8].copy_from_slice(&5u32.to_le_bytes());
    common::seal(&mut old);
    assert!(matches!(
        Estimator::from_bytes(&old).unwrap_err(),
        Error::Invalid { field: "flags", .. }
    ));
}
