use super::*;
use rand::SeedableRng;

/// A problem over every row of `x` (standardized data), nothing held out.
fn problem<'a>(
    sizes: &'a [usize],
    x: &'a Array2<f64>,
    t: &'a Array2<f64>,
    rows: &'a [usize],
    decay: f64,
) -> Problem<'a> {
    let mut offsets = vec![0];
    for s in sizes {
        offsets.push(offsets.last().copied().unwrap_or(0) + s);
    }
    Problem {
        sizes,
        offsets,
        x,
        t,
        train: rows,
        held_out: &[],
        decay,
        curvature_rows: None,
    }
}

fn random(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// The back-propagated Jacobian of the outputs (the residuals against
/// zero targets) against central differences of the forward pass.
#[test]
fn backpropagation_matches_finite_differences() {
    let sizes = [3, 5, 4, 2];
    let n = n_parameters(&sizes);
    assert_eq!(n, 5 * 4 + 4 * 6 + 2 * 5);
    let params = random(n, 1);
    let x = Array2::from_shape_vec((1, 3), vec![0.3, -0.7, 0.9]).unwrap();
    let t = Array2::zeros((1, 2));
    let p = problem(&sizes, &x, &t, &[0], 0.0);
    let width = p.offsets.last().copied().unwrap();
    let mut acts = vec![0.0; width];
    let (mut jt, mut res) = (vec![0.0; n * 2], vec![0.0; 2]);
    p.jacobian(&params, &mut jt, &mut res, None);
    let output = |w: &[f64], acts: &mut [f64]| -> [f64; 2] {
        let columns = by_columns(&sizes, w);
        forward(&sizes, &columns, &[0.3, -0.7, 0.9], acts, &p.offsets);
        [acts[width - 2], acts[width - 1]]
    };
    let h = 1e-6;
    for j in 0..n {
        let (mut plus, mut minus) = (params.clone(), params.clone());
        plus[j] += h;
        minus[j] -= h;
        let (fp, fm) = (output(&plus, &mut acts), output(&minus, &mut acts));
        for k in 0..2 {
            let fd = (fp[k] - fm[k]) / (2.0 * h);
            assert!(
                (fd - jt[k * n + j]).abs() < 1e-8,
                "output {k}, parameter {j}: {fd} vs {}",
                jt[k * n + j]
            );
        }
    }
}

/// The forward pass over transposed weights against the estimate
/// path's one dot product a unit ([`dense_layer`]), and the backward
/// step against one dot product an input: the same bits, zeros of
/// either sign included (an input of zero makes products of -0.0).
#[test]
fn a_layer_at_a_time_gives_the_bits_of_a_unit_at_a_time() {
    let sizes = [5, 7, 6, 3];
    let n = n_parameters(&sizes);
    let mut params = random(n, 51);
    params[3] = -0.0;
    params[n - 1] = 0.0;
    let mut offsets = vec![0];
    for s in sizes {
        offsets.push(offsets.last().copied().unwrap() + s);
    }
    let columns = by_columns(&sizes, &params);
    for (seed, zeros) in [(52, 0), (53, 2), (54, 5)] {
        let mut x = random(5, seed);
        x[..zeros].fill(-0.0);
        let mut acts = vec![0.0; offsets[4]];
        forward(&sizes, &columns, &x, &mut acts, &offsets);
        // A unit at a time, as the estimate path computes it.
        let (mut input, mut p) = (x.clone(), 0);
        for l in 0..3 {
            let (n_in, n_out) = (sizes[l], sizes[l + 1]);
            let mut out = vec![0.0; n_out];
            let (w, b) = params[p..p + n_out * (n_in + 1)].split_at(n_out * n_in);
            dense_layer(w, b, &input, activation(l, 3), &mut out);
            let got = &acts[offsets[l + 1]..offsets[l + 2]];
            let bits = |v: &[f64]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(got), bits(&out), "layer {l}, {zeros} zero inputs");
            (input, p) = (out, p + n_out * (n_in + 1));
        }
        // Back from the last hidden layer (6 units) to the first (7).
        let w = &params[7 * 6..7 * 6 + 6 * 7];
        let hidden = &acts[offsets[1]..offsets[2]];
        let mut delta = vec![0.0; 2 * MAX_WIDTH];
        delta[..6].copy_from_slice(&random(6, seed + 10));
        let expected: Vec<u64> = (0..7)
            .map(|c| {
                let mut acc = 0.0;
                for a in 0..6 {
                    acc += w[a * 7 + c] * delta[a];
                }
                (acc * (1.0 - hidden[c] * hidden[c])).to_bits()
            })
            .collect();
        backward(w, hidden, 6, &mut delta);
        let got: Vec<u64> = delta[..7].iter().map(|v| v.to_bits()).collect();
        assert_eq!(got, expected);
    }
}

/// Adam's gradient of the loss (mean squared error plus weight decay)
/// against central differences of the loss.
#[test]
fn the_loss_gradient_matches_finite_differences() {
    let sizes = [2, 4, 3, 2];
    let n = n_parameters(&sizes);
    let params = random(n, 31);
    let x = Array2::from_shape_vec((7, 2), random(14, 32)).unwrap();
    let t = Array2::from_shape_vec((7, 2), random(14, 33)).unwrap();
    let rows: Vec<usize> = (0..7).collect();
    let p = problem(&sizes, &x, &t, &rows, 0.01);
    let loss = |w: &[f64]| p.mse(w, &rows) + p.penalty(w) / 14.0;
    let mut grad = vec![0.0; n];
    p.gradient(&params, &rows, &mut grad);
    let h = 1e-6;
    for j in 0..n {
        let (mut plus, mut minus) = (params.clone(), params.clone());
        plus[j] += h;
        minus[j] -= h;
        let fd = (loss(&plus) - loss(&minus)) / (2.0 * h);
        assert!(
            (fd - grad[j]).abs() < 1e-8,
            "parameter {j}: {fd} vs {}",
            grad[j]
        );
    }
}

/// Several blocks of rows: the parallel Jacobian, residuals, loss and
/// gradient against the same quantities built one row at a time from
/// single-row problems, on 1 and 3 threads (same bits on both).
#[test]
fn blocks_of_rows_add_up_to_the_row_by_row_quantities() {
    let sizes = [3, 4, 2];
    let n = n_parameters(&sizes);
    let samples = 2 * BLOCK_SAMPLES + 37;
    let x = Array2::from_shape_vec((samples, 3), random(3 * samples, 41)).unwrap();
    let t = Array2::from_shape_vec((samples, 2), random(2 * samples, 42)).unwrap();
    let params = random(n, 43);
    // Shuffled rows, as the training split gives them.
    let mut rows: Vec<usize> = (0..samples).collect();
    rows.reverse();
    rows.swap(3, 400);
    let p = problem(&sizes, &x, &t, &rows, 0.02);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (mut jt, mut res, mut r) = (
                vec![0.0; n * samples * 2],
                vec![0.0; samples * 2],
                vec![0.0; samples * 2],
            );
            p.jacobian(&params, &mut jt, &mut res, None);
            p.residuals_keeping(&params, &mut r, None);
            let mut grad = vec![0.0; n];
            p.gradient(&params, &rows, &mut grad);
            (jt, res, r, grad, p.mse(&params, &rows))
        })
    };
    let (jt, res, r, grad, mse) = run(1);
    let three = run(3);
    assert!(jt == three.0 && res == three.1 && r == three.2 && grad == three.3);
    assert_eq!(mse.to_bits(), three.4.to_bits());
    assert_eq!(res, r);
    let (mut sse, mut expected_grad) = (0.0, vec![0.0; n]);
    for (sample, &i) in rows.iter().enumerate() {
        let one = problem(&sizes, &x, &t, std::slice::from_ref(&i), 0.0);
        let (mut jt1, mut res1) = (vec![0.0; n * 2], vec![0.0; 2]);
        one.jacobian(&params, &mut jt1, &mut res1, None);
        assert_eq!(&jt[sample * 2 * n..(sample + 1) * 2 * n], &jt1[..]);
        assert_eq!(&res[sample * 2..sample * 2 + 2], &res1[..]);
        sse += res1.iter().map(|v| v * v).sum::<f64>();
        // The gradient of the squared errors is 2 J' r.
        for k in 0..2 {
            for j in 0..n {
                expected_grad[j] += 2.0 * jt1[k * n + j] * res1[k];
            }
        }
    }
    let values = (2 * samples) as f64;
    assert!(
        (mse - sse / values).abs() <= 1e-13 * mse,
        "{mse} vs {}",
        sse / values
    );
    for j in 0..n {
        let expected = expected_grad[j] / values + 2.0 * 0.02 * params[j] / values;
        assert!(
            (grad[j] - expected).abs() <= 1e-12 * (1.0 + expected.abs()),
            "parameter {j}: {} vs {expected}",
            grad[j]
        );
    }
}
