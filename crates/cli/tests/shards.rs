//! Charts simulated in shards from the command line and merged by `train
//! --chart 'DIR/shard-*'`: the estimator file is byte for byte the one
//! `train` writes on one machine.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use common::{path, scratch, text, twostage};

const MODEL: &str = r#"[model]
name = "short-benchmark"
[source]
builtin = "benchmark"
[signals]
samples = 200
"#;

fn run(args: &[&str]) -> String {
    let out = twostage(args);
    assert!(out.status.success(), "{args:?}: {}", text(&out.stderr));
    text(&out.stdout)
}

fn shard_args<'a>(model: &'a str, dir: &'a str, shard: &'a str) -> Vec<&'a str> {
    vec![
        "simulate",
        "--model-file",
        model,
        "--count",
        "300",
        "--validate",
        "100",
        "--calibrate",
        "100",
        "--seed",
        "3",
        "--shard",
        shard,
        "--out",
        dir,
    ]
}

#[test]
fn shards_merge_to_the_single_machine_estimator_file() {
    let dir = scratch("cli-shards");
    let model = dir.join("model.toml");
    std::fs::write(&model, MODEL).unwrap();
    let single = dir.join("single.tsest");
    run(&[
        "train",
        "--model-file",
        path(&model),
        "--sims",
        "300",
        "--validate",
        "100",
        "--calibrate",
        "100",
        "--seed",
        "3",
        "--compress",
        "arx:2,2",
        "--fit",
        "mlp:4",
        "--out",
        path(&single),
        "--quiet",
    ]);
    let shards = dir.join("shards");
    for i in 0..4 {
        let shard = format!("{i}/4");
        run(&shard_args(path(&model), path(&shards), &shard));
    }
    let pattern = format!("{}/shard-*", shards.display());
    let merged = dir.join("merged.tsest");
    let train_merged = |out: &Path| {
        twostage(&[
            "train",
            "--model-file",
            path(&model),
            "--chart",
            &pattern,
            "--compress",
            "arx:2,2",
            "--fit",
            "mlp:4",
            "--out",
            path(out),
            "--quiet",
        ])
    };
    let out = train_merged(&merged);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        std::fs::read(&merged).unwrap() == std::fs::read(&single).unwrap(),
        "the merged estimator file differs from the single-machine one"
    );

    // `--shard auto` reads a Slurm array task's index and count.
    let auto = dir.join("auto");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_twostage"))
        .args(shard_args(path(&model), path(&auto), "auto"))
        .env("SLURM_ARRAY_TASK_ID", "2")
        .env("SLURM_ARRAY_TASK_COUNT", "4")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let name = "shard-00002-of-00004.tsshard";
    assert!(std::fs::read(auto.join(name)).unwrap() == std::fs::read(shards.join(name)).unwrap());

    // A missing shard is named, with its records and how to re-run it.
    let aside = dir.join("shard-1.aside");
    std::fs::rename(shards.join("shard-00001-of-00004.tsshard"), &aside).unwrap();
    let out = train_merged(&dir.join("incomplete.tsest"));
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("shard 1 (training [75, 150), calibration [25, 50), validation [25, 50))"),
        "{err}"
    );
    std::fs::rename(&aside, shards.join("shard-00001-of-00004.tsshard")).unwrap();

    // Shards of another model description are refused.
    let edited = dir.join("edited.toml");
    std::fs::write(&edited, MODEL.replace("short-benchmark", "renamed")).unwrap();
    let out = twostage(&[
        "train",
        "--model-file",
        path(&edited),
        "--chart",
        &pattern,
        "--compress",
        "arx:2,2",
        "--out",
        path(&dir.join("other.tsest")),
    ]);
    let err = text(&out.stderr);
    assert!(
        !out.status.success() && err.contains("another model description"),
        "{err}"
    );
}

#[test]
fn slurm_writes_an_array_script_and_the_merge_command() {
    let dir = scratch("cli-slurm-script");
    let model = dir.join("model.toml");
    std::fs::write(&model, MODEL).unwrap();
    let charts = dir.join("charts");
    let said = run(&[
        "slurm",
        "--model-file",
        path(&model),
        "--count",
        "300",
        "--shards",
        "4",
        "--out",
        path(&charts),
        "--seed",
        "3",
        "--time",
        "00:10:00",
        "--compress",
        "arx:2,2",
    ]);
    let script = std::fs::read_to_string(charts.join("chart.sbatch")).unwrap();
    for line in [
        "#SBATCH --array=0-3",
        "#SBATCH --time=00:10:00",
        "--shard \"auto/4\"",
        "--count 300 --validate 1000 --calibrate 4000 --seed 3",
        "--compress 'arx:2,2'",
    ] {
        assert!(script.contains(line), "{line}: {script}");
    }
    assert!(
        said.contains("sbatch") && said.contains("--chart '") && said.contains("shard-*"),
        "{said}"
    );
    assert!(charts.join("logs").is_dir());
}

/// The automatic design reads raw shards' records as it reads its own
/// simulations: the searched file is the single machine's byte for byte.
#[test]
fn a_search_on_raw_shards_is_the_single_machine_search() {
    let dir = scratch("cli-shards-auto");
    let model = dir.join("model.toml");
    std::fs::write(&model, MODEL).unwrap();
    let sizes = ["--validate", "100", "--calibrate", "100", "--seed", "3"];
    let single = dir.join("single.tsest");
    let mut args = vec![
        "train",
        "--model-file",
        path(&model),
        "--auto",
        "--budget-sims",
        "300",
    ];
    args.extend(sizes);
    args.extend(["--out", path(&single), "--quiet"]);
    run(&args);
    let shards = dir.join("shards");
    for shard in ["0/2", "1/2"] {
        run(&shard_args(path(&model), path(&shards), shard));
    }
    let merged = dir.join("merged.tsest");
    let pattern = format!("{}/shard-*", path(&shards));
    run(&[
        "train",
        "--model-file",
        path(&model),
        "--chart",
        &pattern,
        "--auto",
        "--budget-sims",
        "300",
        "--out",
        path(&merged),
        "--quiet",
    ]);
    assert_eq!(
        std::fs::read(&merged).unwrap(),
        std::fs::read(&single).unwrap(),
        "the same search on the same records"
    );
}
