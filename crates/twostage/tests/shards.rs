//! Charts simulated in shards and merged: the estimator is the one a single
//! machine trains, bit for bit, and every way shards can go wrong is named.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use twostage::models::{Benchmark, Simulator};
use twostage::sources::RoleCounts;
use twostage::{
    CompressorConfig, RecordSource, RegressorConfig, ShardIndex, ShardPlan, ShardedChart, TwoStage,
    simulate_shard,
};

const SEED: u64 = 5;
const COUNTS: RoleCounts = RoleCounts {
    training: 240,
    calibration: 120,
    validation: 80,
};

fn model() -> Benchmark {
    Benchmark::builder().n_samples(200).build().unwrap()
}

fn builder<'a>(model: &'a Benchmark, compress: &str) -> TwoStage<'a, Benchmark> {
    TwoStage::builder(model)
        .compressor(compress.parse::<CompressorConfig>().unwrap())
        .regressor("mlp:4".parse::<RegressorConfig>().unwrap())
        .simulations(COUNTS.training)
        .calibration(COUNTS.calibration)
        .validation(COUNTS.validation)
        .seed(SEED)
}

fn plan(compressor: Option<&str>) -> ShardPlan {
    ShardPlan {
        model: "benchmark".into(),
        model_fingerprint: 42,
        seed: SEED,
        counts: COUNTS,
        compressor: compressor.map(str::to_string),
    }
}

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn shards(model: &Benchmark, plan: &ShardPlan, n: usize, dir: &Path) -> Vec<PathBuf> {
    (0..n)
        .map(|index| simulate_shard(model, plan, ShardIndex { index, count: n }, dir).unwrap())
        .collect()
}

fn pattern(dir: &Path) -> String {
    format!("{}/shard-*", dir.display())
}

#[test]
fn shards_merge_into_the_single_machine_estimator_bit_for_bit() {
    let model = model();
    // A learned stage 1 trains on the shards' raw records as on simulated ones.
    for compress in ["arx:2,2", "narx:2,2,2", "arx:1,1+learned:3"] {
        let single = builder(&model, compress)
            .train()
            .unwrap()
            .to_bytes()
            .unwrap();
        // Raw shards, 4 and 3 of them; compressed shards where the
        // compressor needs no fitting of its own.
        let mut variants = vec![(None, 4), (None, 3)];
        if compress.starts_with("arx") && !compress.contains("learned") {
            variants.push((Some(compress), 4));
        }
        for (stored, n) in variants {
            let dir = scratch(&format!("shards-{compress}-{n}-{}", stored.is_some()));
            shards(&model, &plan(stored), n, &dir);
            let chart = ShardedChart::open(&pattern(&dir)).unwrap();
            let merged = builder(&model, compress)
                .records(RecordSource::Shards(&chart))
                .train()
                .unwrap()
                .to_bytes()
                .unwrap();
            assert!(
                merged == single,
                "{compress}, {n} shards, stored features {stored:?}"
            );
        }
    }
}

fn open_error(pattern: &str) -> String {
    match ShardedChart::open(pattern) {
        Err(e @ twostage::sources::Error::Shards { .. }) => e.to_string(),
        other => panic!("expected a shard error, got {other:?}"),
    }
}

#[test]
fn missing_doubled_mixed_and_damaged_shards_are_named() {
    let model = model();
    let dir = scratch("shards-broken");
    let files = shards(&model, &plan(None), 4, &dir);

    // A missing shard: its ranges in every chart and how to re-run it.
    let aside = dir.join("aside");
    std::fs::create_dir_all(&aside).unwrap();
    std::fs::rename(&files[2], aside.join("kept")).unwrap();
    let err = open_error(&pattern(&dir));
    assert!(err.contains("1 of 4 shard(s) missing: shard 2 (training [120, 180), calibration [60, 90), validation [40, 60))"), "{err}");
    assert!(err.contains("--array=2"), "{err}");
    // What a task killed while writing leaves behind is not a shard.
    let partial = dir.join("shard-00002-of-00004.tsshard.partial");
    std::fs::write(&partial, &std::fs::read(aside.join("kept")).unwrap()[..300]).unwrap();
    assert!(open_error(&pattern(&dir)).contains("shard 2 ("));
    std::fs::remove_file(&partial).unwrap();
    std::fs::rename(aside.join("kept"), &files[2]).unwrap();
    ShardedChart::open(&pattern(&dir)).unwrap();

    // The same shard twice.
    let twice = dir.join("shard-copy.tsshard");
    std::fs::copy(&files[1], &twice).unwrap();
    let err = open_error(&pattern(&dir));
    assert!(err.contains("shard 1 of 4 is there twice"), "{err}");
    std::fs::remove_file(&twice).unwrap();

    // A shard of another chart (another seed).
    let other = scratch("shards-other-seed");
    let mut other_plan = plan(None);
    other_plan.seed = SEED + 1;
    let stray = shards(&model, &other_plan, 4, &other);
    let mixed = dir.join("shard-stray.tsshard");
    std::fs::copy(&stray[3], &mixed).unwrap();
    let err = open_error(&pattern(&dir));
    assert!(
        err.contains("its seed differs") && err.contains("shard-stray"),
        "{err}"
    );
    std::fs::remove_file(&mixed).unwrap();

    // A flipped byte in a record: found by the checksum when training.
    let original = std::fs::read(&files[0]).unwrap();
    let mut damaged = original.clone();
    let at = damaged.len() - 100;
    damaged[at] ^= 0x40;
    std::fs::write(&files[0], &damaged).unwrap();
    let chart = ShardedChart::open(&pattern(&dir)).unwrap();
    let err = builder(&model, "arx:2,2")
        .records(RecordSource::Shards(&chart))
        .train()
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("shard-00000-of-00004")
            && (err.contains("checksum") || err.contains("cannot be read")),
        "{err}"
    );

    // A file cut short, as a killed task might leave behind.
    std::fs::write(&files[0], &original[..original.len() / 2]).unwrap();
    let chart = ShardedChart::open(&pattern(&dir)).unwrap();
    let err = builder(&model, "arx:2,2")
        .records(RecordSource::Shards(&chart))
        .train()
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("shard-00000-of-00004") && err.contains("ends"),
        "{err}"
    );

    // A shard of an older format (its header's first byte, after the
    // magic and the header's length, is the format): named by it, with
    // what to do, not misread.
    let mut older = original.clone();
    assert_eq!(older[16], 4, "the format this test knows");
    older[16] = 2;
    std::fs::write(&files[0], &older).unwrap();
    let err = open_error(&pattern(&dir));
    assert!(
        err.contains("shard format 2, this twostage reads 4") && err.contains("simulate"),
        "{err}"
    );

    // A length word that claims a gigabyte in a file of a few hundred
    // bytes: found at the file's end, nothing of that size taken.
    let mut claiming = original.clone();
    claiming[8..16].copy_from_slice(&((1u64 << 30) - 1).to_le_bytes());
    std::fs::write(&files[0], &claiming).unwrap();
    let err = open_error(&pattern(&dir));
    assert!(
        err.contains("the file ends inside the header")
            && err.contains("of its 1073741823 bytes are there"),
        "{err}"
    );

    // Not a shard at all.
    std::fs::write(&files[0], "experiment,u,y\n").unwrap();
    let err = open_error(&pattern(&dir));
    assert!(err.contains("not a twostage shard file"), "{err}");
    std::fs::write(&files[0], &original).unwrap();

    // Nothing there.
    let err = open_error(&format!("{}/nothing-*", dir.display()));
    assert!(err.contains("no shard file matches"), "{err}");
}

#[test]
fn shards_refuse_another_seed_or_compressor_at_training() {
    let model = model();
    let dir = scratch("shards-refuse");
    shards(&model, &plan(Some("arx:2,2")), 2, &dir);
    let chart = ShardedChart::open(&pattern(&dir)).unwrap();
    let err = builder(&model, "arx:2,2")
        .seed(9)
        .records(RecordSource::Shards(&chart))
        .train()
        .unwrap_err()
        .to_string();
    assert!(err.contains("seed 5") && err.contains("--seed 5"), "{err}");
    let err = builder(&model, "arx:3,3")
        .records(RecordSource::Shards(&chart))
        .train()
        .unwrap_err()
        .to_string();
    assert!(err.contains("features of arx:2,2"), "{err}");
    // A compressor fitted on the whole chart cannot compress a shard.
    let err = simulate_shard(
        &model,
        &plan(Some("pca:3")),
        ShardIndex { index: 0, count: 2 },
        &dir,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("shard raw records"), "{err}");
    // Another model.
    let longer = Benchmark::builder().n_samples(300).build().unwrap();
    let err = TwoStage::builder(&longer)
        .seed(SEED)
        .records(RecordSource::Shards(&chart))
        .train()
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("200 samples") && err.contains("300 samples"),
        "{err}"
    );
    let _ = model.spec();
}
