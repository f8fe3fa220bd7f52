//! The cost of the simulator protocol (docs/protocol.md): one record of N
//! samples (one input, one output) from a Python process that does no
//! simulation at all, so that what is timed is the exchange itself.
//!
//! - `protocol/reference_client`: the pure-Python reference client
//!   (docs/protocol/twostage_protocol.py), formatting each record anew: the
//!   overhead a Python simulator pays per record.
//! - `protocol/preformatted`: a responder that writes one text it made
//!   once: the cost on twostage's side (pipe, parsing) alone.
//!
//! Needs `python3` (or `TWOSTAGE_PYTHON`).

use std::path::PathBuf;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use twostage::models::{ExternalSimulator, IoData, ModelSpec, Prior, Simulator, experiment_rng};
use twostage_benches::config;

fn protocol_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/protocol")
}

fn python() -> String {
    std::env::var("TWOSTAGE_PYTHON").unwrap_or_else(|_| "python3".into())
}

fn simulator(n: usize, script: &str) -> ExternalSimulator {
    let spec = ModelSpec::new(
        "protocol",
        &["k"],
        Prior::uniform_box(&[0.0], &[1.0]).unwrap_or_else(|e| panic!("{e}")),
        1.0,
        n,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let dir = std::env::temp_dir().join(format!("twostage-protocol-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
    std::fs::write(dir.join("sim.py"), script).unwrap_or_else(|e| panic!("{e}"));
    ExternalSimulator::new(spec, vec![python(), "sim.py".into()])
        .unwrap_or_else(|e| panic!("{e}"))
        .current_dir(dir)
}

fn protocol(c: &mut Criterion) {
    let client = format!(
        "import sys\nsys.path.insert(0, {:?})\nfrom twostage_protocol import serve\n\
         def simulate(theta, seed, index):\n    n = SAMPLES\n    \
         return [[0.25]] * n, [[theta[0]]] * n\nserve(simulate)\n",
        protocol_dir()
            .to_str()
            .unwrap_or_else(|| panic!("a UTF-8 path"))
    );
    let preformatted = "import sys\nhead = sys.stdin.readline().split()\nn = int(head[5])\n\
        body = '0.25 0.5\\n' * n\nsys.stdout.write('ready\\n'); sys.stdout.flush()\n\
        while True:\n    line = sys.stdin.readline()\n    if not line or line.startswith('quit'):\n        break\n    \
        b = int(line.split()[1])\n    out = []\n    for _ in range(b):\n        \
        out.append('record ' + sys.stdin.readline().split()[0] + '\\n' + body)\n    \
        sys.stdout.write(''.join(out)); sys.stdout.flush()\n";
    let mut group = c.benchmark_group("protocol");
    for n in [100usize, 1000] {
        group.throughput(Throughput::Elements(1));
        for (name, script) in [
            (
                "reference_client",
                client.replace("SAMPLES", &n.to_string()),
            ),
            ("preformatted", preformatted.to_string()),
        ] {
            let sim = simulator(n, &script);
            let mut record = IoData::default();
            let mut index = 0u64;
            group.bench_function(BenchmarkId::new(name, n), |b| {
                b.iter(|| {
                    index += 1;
                    sim.simulate(&[0.5], &mut experiment_rng(1, index), &mut record)
                        .unwrap_or_else(|e| panic!("{e}"));
                })
            });
        }
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = config();
    targets = protocol
}
criterion_main!(benches);
