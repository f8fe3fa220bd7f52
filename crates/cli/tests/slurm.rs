//! A real Slurm: `twostage slurm` writes the array script, sbatch runs its 4
//! shards, `train --chart 'DIR/shard-*'` merges them into the very bytes a
//! single machine writes; a shard killed on purpose is named at merge time
//! and re-submitting it alone completes the chart.
//!
//! Needs a running Slurm (`.ci/slurm start`, which `.ci/run` does, and
//! SLURM_CONF in the environment). Without one the test says so loudly and
//! passes, unless TWOSTAGE_REQUIRE_SLURM=1 (as in CI), where it fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::process::Command;
use std::time::{Duration, Instant};

use common::{path, scratch, text, twostage};

const MODEL: &str = r#"[model]
name = "slurm-benchmark"
[source]
builtin = "benchmark"
[signals]
samples = 300
"#;

fn slurm_is_up() -> bool {
    std::env::var_os("SLURM_CONF").is_some()
        && Command::new("sinfo")
            .args(["-h", "-o", "%t"])
            .output()
            .is_ok_and(|o| o.status.success() && !o.stdout.is_empty())
}

fn run(command: &str, args: &[&str]) -> String {
    let out = Command::new(command).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{command} {args:?}: {}",
        text(&out.stderr)
    );
    text(&out.stdout)
}

/// Submit `script` (with extra sbatch options) and wait for the array;
/// returns each task's (index, state, exit code).
fn submit_and_wait(
    script: &str,
    options: &[&str],
    before_release: impl FnOnce(&str),
) -> Vec<(usize, String, String)> {
    let mut args = vec!["--parsable"];
    args.extend_from_slice(options);
    args.push(script);
    let id = run("sbatch", &args)
        .trim()
        .split(';')
        .next()
        .unwrap()
        .to_string();
    before_release(&id);
    let start = Instant::now();
    // Polling squeue: `sbatch --wait` would poll every 32 s.
    while !run("squeue", &["-h", "-j", &id]).trim().is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "job {id} still queued after 300 s"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let mut tasks: Vec<(usize, String, String)> = run("scontrol", &["-o", "show", "job", &id])
        .lines()
        .filter_map(|line| {
            let field = |key: &str| {
                line.split_whitespace()
                    .find_map(|f| f.strip_prefix(key))
                    .map(str::to_string)
            };
            Some((
                field("ArrayTaskId=")?.parse().ok()?,
                field("JobState=")?,
                field("ExitCode=")?,
            ))
        })
        .collect();
    tasks.sort();
    tasks
}

#[test]
fn a_slurm_array_of_shards_merges_to_the_single_machine_estimator() {
    if !slurm_is_up() {
        assert!(
            std::env::var("TWOSTAGE_REQUIRE_SLURM").as_deref() != Ok("1"),
            "TWOSTAGE_REQUIRE_SLURM=1 but no Slurm answers (SLURM_CONF unset or sinfo fails): \
             start one with `eval \"$(.ci/slurm start)\"`"
        );
        eprintln!(
            "\n*** SKIPPED a_slurm_array_of_shards_merges_to_the_single_machine_estimator: no \
             running Slurm (start one with `eval \"$(.ci/slurm start)\"`; CI does) ***\n"
        );
        return;
    }
    let dir = scratch("slurm");
    let model = dir.join("model.toml");
    std::fs::write(&model, MODEL).unwrap();
    let training = ["--compress", "arx:2,2", "--fit", "mlp:4"];

    let local = Instant::now();
    let single = dir.join("single.tsest");
    let mut args = vec![
        "train",
        "--model-file",
        path(&model),
        "--sims",
        "400",
        "--validate",
        "100",
        "--calibrate",
        "100",
        "--seed",
        "3",
        "--out",
        path(&single),
        "--quiet",
    ];
    args.extend_from_slice(&training);
    let out = twostage(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let local = local.elapsed();

    let merge = |charts: &std::path::Path, out: &std::path::Path| {
        let pattern = format!("{}/shard-*", charts.display());
        let mut args = vec![
            "train",
            "--model-file",
            path(&model),
            "--chart",
            &pattern,
            "--out",
            path(out),
            "--quiet",
        ];
        args.extend_from_slice(&training);
        twostage(&args)
    };
    let script_for = |charts: &std::path::Path| {
        let out = twostage(&[
            "slurm",
            "--model-file",
            path(&model),
            "--count",
            "400",
            "--validate",
            "100",
            "--calibrate",
            "100",
            "--seed",
            "3",
            "--shards",
            "4",
            "--out",
            path(charts),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        charts.join("chart.sbatch").display().to_string()
    };

    // The whole array.
    let charts = dir.join("charts");
    let script = script_for(&charts);
    let sharded = Instant::now();
    let tasks = submit_and_wait(&script, &[], |_| {});
    let merged = dir.join("merged.tsest");
    let out = merge(&charts, &merged);
    let sharded = sharded.elapsed();
    assert_eq!(tasks.len(), 4, "{tasks:?}");
    assert!(
        tasks
            .iter()
            .all(|(_, state, code)| state == "COMPLETED" && code == "0:0"),
        "{tasks:?}"
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        std::fs::read(&merged).unwrap() == std::fs::read(&single).unwrap(),
        "the estimator merged from Slurm's shards differs from the single-machine one"
    );
    eprintln!(
        "slurm: 4 shards and the merge in {:.2} s; the same training on this machine in {:.2} s",
        sharded.as_secs_f64(),
        local.as_secs_f64()
    );

    // Shard 2 killed on purpose (cancelled while the array is held).
    let charts = dir.join("charts-killed");
    let script = script_for(&charts);
    let tasks = submit_and_wait(&script, &["--hold"], |id| {
        run("scancel", &[&format!("{id}_2")]);
        run("scontrol", &["release", id]);
    });
    assert!(
        tasks
            .iter()
            .all(|(i, state, _)| *i != 2 || state != "COMPLETED"),
        "{tasks:?}"
    );
    assert!(!charts.join("shard-00002-of-00004.tsshard").exists());
    let out = merge(&charts, &dir.join("killed.tsest"));
    let err = text(&out.stderr);
    assert!(
        !out.status.success() && err.contains("1 of 4 shard(s) missing: shard 2 ("),
        "{err}"
    );
    assert!(err.contains("--array=2"), "{err}");
    // Re-submitting that shard alone completes the chart.
    let tasks = submit_and_wait(&script, &["--array=2"], |_| {});
    assert_eq!(tasks.len(), 1, "{tasks:?}");
    let completed = dir.join("completed.tsest");
    let out = merge(&charts, &completed);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(std::fs::read(&completed).unwrap() == std::fs::read(&single).unwrap());
}
