use ndarray::Array2;

use super::*;

/// A pseudo-random number in [-1, 1) from an index (no generator needed).
fn wobble(i: usize) -> f64 {
    let x = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11;
    x as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

fn network(signals: usize, channels: &[usize], kernel: usize, stride: usize) -> SummaryNetwork {
    let shape = LearnedShape {
        channels: channels.to_vec(),
        kernel,
        stride,
    };
    let layers = shape.layers(signals);
    let count: usize = layers.iter().map(ConvShape::n_weights).sum();
    let weights = (0..count).map(|i| 0.6 * wobble(i + 7)).collect();
    let scales = (0..signals).map(|s| 0.5 + s as f64).collect();
    SummaryNetwork::new(scales, layers, weights).unwrap()
}

/// The forward pass written out index by index over a samples x signals
/// record, with the platform's tanh: a second computation of `summarize`.
fn by_hand(net: &SummaryNetwork, record: &Array2<f64>) -> Vec<f64> {
    let mut act: Vec<Vec<f64>> = (0..record.ncols())
        .map(|s| {
            record
                .column(s)
                .iter()
                .map(|v| v / net.scales()[s])
                .collect()
        })
        .collect();
    let mut offset = 0;
    for l in net.layers() {
        let w = &net.weights()[offset..offset + l.n_weights()];
        offset += l.n_weights();
        let positions = (act[0].len() - l.kernel) / l.stride + 1;
        act = (0..l.outputs)
            .map(|o| {
                (0..positions)
                    .map(|t| {
                        let mut z = w[l.outputs * l.inputs * l.kernel + o];
                        for c in 0..l.inputs {
                            for k in 0..l.kernel {
                                z +=
                                    w[(o * l.inputs + c) * l.kernel + k] * act[c][t * l.stride + k];
                            }
                        }
                        z.tanh()
                    })
                    .collect()
            })
            .collect();
    }
    let n = act[0].len() as f64;
    let means = act.iter().map(|a| a.iter().sum::<f64>() / n);
    let squares = act.iter().map(|a| a.iter().map(|v| v * v).sum::<f64>() / n);
    means.chain(squares).collect()
}

fn record(samples: usize, signals: usize) -> Array2<f64> {
    Array2::from_shape_fn((samples, signals), |(k, s)| {
        (0.07 * (s + 1) as f64 * k as f64).sin() + 0.3 * wobble(k * 5 + s)
    })
}

#[test]
fn the_summary_is_the_forward_pass_written_out() {
    let net = network(3, &[4, 5, 3], 4, 2);
    let r = record(120, 3);
    let (u, y) = (r.slice(ndarray::s![.., ..1]), r.slice(ndarray::s![.., 1..]));
    let mut out = vec![0.0; net.n_features()];
    net.summarize(u, y, &mut Workspace::new(), &mut out)
        .unwrap();
    let want = by_hand(&net, &r);
    assert_eq!(out.len(), 6);
    for (got, want) in out.iter().zip(&want) {
        assert!((got - want).abs() < 1e-12, "{got} against {want}");
    }
    // A record of another length has a summary too (the pooling averages).
    let longer = record(333, 3);
    let (u, y) = (
        longer.slice(ndarray::s![.., ..1]),
        longer.slice(ndarray::s![.., 1..]),
    );
    net.summarize(u, y, &mut Workspace::new(), &mut out)
        .unwrap();
    for (got, want) in out.iter().zip(by_hand(&net, &longer)) {
        assert!((got - want).abs() < 1e-12, "{got} against {want}");
    }
}

#[test]
fn a_trained_wrapper_appends_the_summary_to_the_inner_features() {
    let inner: CompressorConfig = "arx:2,2".parse().unwrap();
    let inner = inner.for_shape(1, 1, 200).unwrap();
    let c: CompressorConfig = "arx:2,2+learned:4,2".parse().unwrap();
    let c = c.for_shape(1, 1, 200).unwrap();
    assert_eq!(c.untrained_summary().map(|s| s.kernel), Some(5));
    let net = network(2, &[4, 2], 5, 2);
    let trained = c.with_trained_summary(net.clone()).unwrap();
    assert!(trained.untrained_summary().is_none());
    assert_eq!(trained.n_features(), 4 + 4);
    let r = record(200, 2);
    let (u, y) = (r.slice(ndarray::s![.., ..1]), r.slice(ndarray::s![.., 1..]));
    let alpha = trained.compress(u, y).unwrap();
    assert_eq!(alpha[..4], inner.compress(u, y).unwrap()[..]);
    for (got, want) in alpha[4..].iter().zip(by_hand(&net, &r)) {
        assert!((got - want).abs() < 1e-12);
    }
    let mut fast = vec![0.0; 8];
    trained
        .compress_fast_into(u, y, &mut Workspace::new(), &mut fast)
        .unwrap();
    for (a, b) in fast.iter().zip(&alpha) {
        assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0));
    }
    assert_eq!(trained.feature_names()[4], "learned_mean_0");
    // What `inspect` says: the architecture, its size and the shortest record.
    let said = trained.to_string();
    assert!(said.contains("4,2 channels, kernel 5, stride 2"), "{said}");
    assert!(
        said.contains("86 weights, records of 13 samples or more"),
        "{said}"
    );
    assert!(c.to_string().contains("untrained"));
    assert_eq!(trained.feature_names()[7], "learned_square_1");
    // Stored and read back whole.
    let bytes = postcard::to_allocvec(&trained).unwrap();
    let back: CompressorConfig = postcard::from_bytes(&bytes).unwrap();
    assert_eq!(back, trained);
    // A damaged file is refused as it is read, not when it is run: one
    // weight short, or a layer that does not chain.
    let good = network(2, &[4, 2], 5, 2);
    let fields = |weights: Vec<f64>, layers: Vec<ConvShape>| {
        postcard::to_allocvec(&(good.scales().to_vec(), layers, weights)).unwrap()
    };
    let intact = fields(good.weights().to_vec(), good.layers().to_vec());
    assert_eq!(
        postcard::from_bytes::<SummaryNetwork>(&intact).unwrap(),
        good
    );
    let short = fields(good.weights()[1..].to_vec(), good.layers().to_vec());
    assert!(postcard::from_bytes::<SummaryNetwork>(&short).is_err());
    let mut unchained = good.layers().to_vec();
    unchained[1].inputs = 3;
    let unchained = fields(good.weights().to_vec(), unchained);
    assert!(postcard::from_bytes::<SummaryNetwork>(&unchained).is_err());
    // A network of other channels than the specification is refused.
    assert!(c.with_trained_summary(network(2, &[4, 3], 5, 2)).is_err());
    let arx: CompressorConfig = "arx:2,2".parse().unwrap();
    assert!(arx.with_trained_summary(net).is_err());
}

#[test]
fn bad_records_are_refused_saying_what_and_where() {
    let net = network(2, &[3, 3], 5, 2);
    assert_eq!(net.min_samples(), 13);
    let mut work = Workspace::new();
    let mut out = vec![0.0; 6];
    let short = record(12, 2);
    let err = net
        .summarize(
            short.slice(ndarray::s![.., ..1]),
            short.slice(ndarray::s![.., 1..]),
            &mut work,
            &mut out,
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("12 samples") && err.contains("13"), "{err}");
    let mut bad = record(40, 2);
    bad[[17, 1]] = f64::NAN;
    let err = net
        .summarize(
            bad.slice(ndarray::s![.., ..1]),
            bad.slice(ndarray::s![.., 1..]),
            &mut work,
            &mut out,
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("sample 17") && err.contains('y'), "{err}");
    let three = record(40, 3);
    let err = net
        .summarize(
            three.slice(ndarray::s![.., ..1]),
            three.slice(ndarray::s![.., 1..]),
            &mut work,
            &mut out,
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("2 signals"), "{err}");
    // Output-only: a network over the outputs alone works without inputs.
    let alone = network(1, &[2], 3, 1);
    let y = record(30, 1);
    let none = Array2::<f64>::zeros((0, 0));
    let mut two = [0.0; 4];
    alone
        .summarize(none.view(), y.view(), &mut work, &mut two)
        .unwrap();
    for (got, want) in two.iter().zip(by_hand(&alone, &y)) {
        assert!((got - want).abs() < 1e-12);
    }
}

#[test]
fn specifications_round_trip_and_bad_ones_name_the_fix() {
    for (spec, written) in [
        ("learned", "learned:8,8,8"),
        ("learned:4,4", "learned:4,4"),
        ("arx:2,2+summary+learned", "arx:2,2+summary+learned:8,8,8"),
        ("log+arx:1,1+learned:2", "log+arx:1,1+learned:2"),
    ] {
        let c: CompressorConfig = spec.parse().unwrap();
        assert_eq!(c.spec().as_deref(), Some(written), "{spec}");
        let again: CompressorConfig = written.parse().unwrap();
        assert_eq!(again, c);
    }
    for (spec, says) in [
        ("learned:0,4", "1 to 64 channels"),
        ("learned:8,x", "whole numbers"),
        ("learned:65", "1 to 64 channels"),
        ("arx:2,2+learned+learned", "one `+learned`"),
    ] {
        let err = spec.parse::<CompressorConfig>().unwrap_err().to_string();
        assert!(err.contains(says), "{spec}: {err}");
    }
    let untrained: CompressorConfig = "learned:2".parse().unwrap();
    let u = record(50, 1);
    let err = untrained
        .compress(u.view(), u.view())
        .unwrap_err()
        .to_string();
    assert!(err.contains("trained with the estimator"), "{err}");
}
