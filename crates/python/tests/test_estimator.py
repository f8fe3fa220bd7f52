"""The Python package against the command line: same files, same
estimates bit for bit, plain-data reports, and clear errors for bad arrays.

The command line binary comes from TWOSTAGE_CLI (``cargo xtask test`` sets
it to the one it built).
"""

import json

import numpy as np
import pytest

import twostage
from command_line import cli



SMALL = dict(sims=300, validate=100, calibrate=100, seed=5)


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A small benchmark estimator trained by Python, and its file."""
    estimator = twostage.train(model="benchmark", **SMALL)
    path = tmp_path_factory.mktemp("est") / "small.tsest"
    estimator.save(path)
    return estimator, path


def test_the_same_seed_gives_the_cli_s_file(small, tmp_path):
    estimator, _ = small
    out = tmp_path / "cli.tsest"
    cli(
        "train", "--model", "benchmark", "--sims", "300", "--validate", "100",
        "--calibrate", "100", "--seed", "5", "--out", str(out), "--quiet",
    )
    assert out.read_bytes() == estimator.to_bytes()
    other = twostage.train(model="benchmark", **{**SMALL, "seed": 6})
    assert other.to_bytes() != estimator.to_bytes()


def test_a_held_parameter_is_the_cli_s_and_said(tmp_path):
    """``fix=`` is ``--fix``: the same file bit for bit, the parameter held
    said by ``fixed`` and gone from ``parameters``; a name the model does
    not have is refused, naming those it has."""
    held = twostage.train(model="pacejka", fix={"pK2": -1.05}, progress=False, **SMALL)
    assert held.parameters == ["pK1"]
    assert held.fixed == {"pK2": -1.05}
    out = tmp_path / "cli.tsest"
    cli(
        "train", "--model", "pacejka", "--fix", "pK2=-1.05", "--sims", "300",
        "--validate", "100", "--calibrate", "100", "--seed", "5", "--out", str(out),
        "--quiet",
    )
    assert out.read_bytes() == held.to_bytes()
    with pytest.raises(ValueError, match=r"no parameter 'mass'.*pK1, pK2"):
        twostage.train(model="pacejka", fix={"mass": 1500.0}, progress=False, **SMALL)


ONE_REQUEST_MODEL = """
[model]
name = "one-request"
[source]
builtin = "benchmark"
[signals]
inputs = ["u"]
outputs = ["y"]
samples = 300
[[preset]]
name = "small"
compress = "arx:3,3"
fit = "mlp:6"
sims = 240
"""


def test_one_request_gives_one_file_from_every_door(tmp_path):
    """The same request, left at its defaults (seed, level) but for the
    sizes, trained from the command line, from Python, and from 4 shards
    merged by each: byte for byte one file."""
    model = tmp_path / "model.toml"
    model.write_text(ONE_REQUEST_MODEL)
    sizes = ["--validate", "60", "--calibrate", "120"]
    from_cli = tmp_path / "cli.tsest"
    cli("train", "--model-file", str(model), *sizes, "--out", str(from_cli), "--quiet")
    from_python = twostage.train(
        model_file=model, validate=60, calibrate=120, progress=False
    ).to_bytes()
    for i in range(4):
        cli(
            "simulate", "--model-file", str(model), "--count", "240", *sizes,
            "--shard", "%d/4" % i, "--out", str(tmp_path / "shards"),
        )
    pattern = str(tmp_path / "shards" / "shard-*")
    from_shards = tmp_path / "shards.tsest"
    cli(
        "train", "--model-file", str(model), "--chart", pattern,
        "--out", str(from_shards), "--quiet",
    )
    from_python_shards = twostage.train(
        model_file=model, chart=pattern, progress=False
    ).to_bytes()
    assert from_python == from_cli.read_bytes()
    assert from_shards.read_bytes() == from_cli.read_bytes()
    assert from_python_shards == from_cli.read_bytes()


def test_the_runtime_blob_is_the_cli_s_export(small, tmp_path):
    _, path = small
    blob = tmp_path / "small.tsrt"
    cli("export", "--estimator", str(path), "--to", "runtime", "--out", str(blob))
    assert twostage.Estimator.load(path).to_runtime() == blob.read_bytes()
    assert blob.read_bytes()[:4] == b"TSRT"
    narx = twostage.train(model="benchmark", compress="narx:2,2,2", fit="mlp:3",
                          sims=200, validate=0, calibrate=0)
    with pytest.raises(ValueError, match="arx:NA,NB"):
        narx.to_runtime()


def test_a_learned_stage1_is_the_cli_s_file_and_exports_to_the_runtime(tmp_path):
    """A summary network trained with the estimator: the same bytes from
    Python as from the command line, and a runtime blob of format 4; a
    network without coefficients before it is refused."""
    args = dict(model="benchmark", compress="arx:1,1+learned:3", fit="linear",
                sims=200, validate=50, calibrate=50, seed=3)
    from_cli = tmp_path / "learned.tsest"
    cli("train", "--model", "benchmark", "--compress", args["compress"], "--fit", "linear",
        "--sims", "200", "--validate", "50", "--calibrate", "50", "--seed", "3",
        "--quiet", "--out", str(from_cli))
    learned = twostage.train(progress=False, **args)
    assert learned.to_bytes() == from_cli.read_bytes()
    assert from_cli.read_bytes()[8] == 7
    blob = learned.to_runtime()
    assert blob[:4] == b"TSRT" and blob[4] == 4
    alone = twostage.train(progress=False, **dict(args, compress="learned:3"))
    with pytest.raises(ValueError, match="after ARX coefficients"):
        alone.to_runtime()


def test_estimates_are_the_cli_s_bit_for_bit(small, tmp_path):
    estimator, path = small
    charts = tmp_path / "records"
    cli("simulate", "--model", "benchmark", "--count", "7", "--seed", "11",
        "--out-dir", str(charts))
    out = cli("estimate", "--estimator", str(path), "--format", "json",
              str(charts / "data.csv"))
    from_cli = json.loads(out)
    data = np.loadtxt(charts / "data.csv", delimiter=",", skiprows=1)
    experiments = np.unique(data[:, 0]).astype(int)
    u = np.stack([data[data[:, 0] == e, 1:2] for e in experiments])
    y = np.stack([data[data[:, 0] == e, 2:3] for e in experiments])
    batch = estimator.estimate(u, y)
    assert batch.shape == (7, 1)
    assessed = estimator.assess(u, y)
    assert len(from_cli) == 7
    for k, row in enumerate(from_cli):
        assert batch[k].tolist() == [row["theta"]], (k, row)
        # One record at a time gives the same bits as the batch.
        assert estimator.estimate(u[k], y[k]).tolist() == batch[k].tolist()
        # The intervals and the flag are the CLI's too.
        assert assessed["lower"][k].tolist() == [row["theta_lo"]]
        assert assessed["upper"][k].tolist() == [row["theta_hi"]]
        assert assessed["feature_distance"][k] == row["feature_distance"]
        assert bool(assessed["out_of_distribution"][k]) == row["out_of_distribution"]
        assert bool(assessed["input_in_family"][k]) == row["input_in_family"]
    one = estimator.assess(u[0], y[0])
    assert one["theta"].shape == (1,) and isinstance(one["feature_distance"], float)
    # A record of one input and one output may give them as 1-D arrays.
    flat = estimator.assess(u[0][:, 0], y[0][:, 0])
    assert flat["theta"].tolist() == one["theta"].tolist()
    assert estimator.estimate(u[1][:, 0], y[1][:, 0]).tolist() == batch[1].tolist()


def test_a_record_from_elsewhere_is_flagged(small):
    estimator, _ = small
    n, _, _ = estimator.record_shape
    rng = np.random.default_rng(3)
    u = rng.standard_normal((n, 1))
    # A tenfold output: no benchmark system does that.
    y = 10.0 * rng.standard_normal((n, 1))
    assert estimator.assess(u, y)["out_of_distribution"]


def test_an_input_outside_the_family_is_flagged_with_its_number(small):
    """The benchmark's inputs are white of variance 1: five times louder is
    an input no training record had, whatever the outputs."""
    estimator, _ = small
    n, _, _ = estimator.record_shape
    rng = np.random.default_rng(4)
    u = rng.standard_normal((2, n, 1))
    u[1] *= 5.0
    y = rng.standard_normal((2, n, 1))
    assessed = estimator.assess(u, y)
    assert assessed["input_in_family"].tolist() == [True, False]
    assert bool(assessed["out_of_distribution"][1])
    assert assessed["input_outside_family"][0] == []
    said = assessed["input_outside_family"][1]
    assert any(s.startswith("input u: RMS") and "above" in s for s in said), said
    one = estimator.assess(u[1], y[1])
    assert one["input_in_family"] is False and one["out_of_distribution"] is True
    assert one["input_outside_family"] == said


def test_windows_of_a_long_record_are_the_cli_s(small, tmp_path):
    """``assess_windows`` gives ``estimate --window --every``'s rows."""
    estimator, path = small
    n, _, _ = estimator.record_shape
    rng = np.random.default_rng(6)
    u = rng.standard_normal((3 * n, 1))
    y = rng.standard_normal((3 * n, 1))
    record = tmp_path / "long.csv"
    np.savetxt(record, np.hstack([u, y]), delimiter=",", header="u,y", comments="",
               fmt="%.17g")
    out = cli("estimate", "--estimator", str(path), "--window", str(n), "--every",
              str(n // 2), "--format", "json", str(record))
    from_cli = json.loads(out)
    windows = estimator.assess_windows(u, y, n, n // 2)
    assert windows["window_end"].tolist() == [row["window_end"] for row in from_cli]
    assert windows["window_end"].tolist() == [n, 3 * n // 2, 2 * n, 5 * n // 2, 3 * n]
    for k, row in enumerate(from_cli):
        assert windows["theta"][k].tolist() == [row["theta"]]
        assert windows["lower"][k].tolist() == [row["theta_lo"]]
    # Refused as the request refuses windows, in its words.
    with pytest.raises(ValueError, match=f"the record: {3 * n} samples, shorter than the window of {4 * n}"):
        estimator.assess_windows(u, y, 4 * n)
    with pytest.raises(ValueError) as refused:
        estimator.assess_windows(u, y, n, 0)
    with pytest.raises(ValueError) as requested:
        estimator.estimate_records([(u, y)], window=n, every=0)
    assert str(refused.value) == str(requested.value)
    assert str(refused.value).startswith(f"the windows: a window of {n} samples every 0")


def test_a_file_round_trips_and_the_cli_reads_it(small):
    estimator, path = small
    again = twostage.Estimator.load(path)
    assert again.to_bytes() == estimator.to_bytes()
    assert twostage.Estimator.from_bytes(estimator.to_bytes()).parameters == ["theta"]
    assert "twostage estimator file" in cli("inspect", str(path))


def test_the_validation_report_is_plain_data(small):
    estimator, _ = small
    report = estimator.validation
    assert isinstance(report, dict)
    theta = report["parameters"][0]
    assert theta["name"] == "theta"
    assert 0.0 < theta["rmse"] < 0.2
    # Both certificates bound the mean squared error from above.
    certified = theta["certified"]
    assert certified["mse_bound"] >= theta["rmse"] ** 2
    assert estimator.to_dict()["training"]["seed"] == 5
    json.dumps(report)  # nothing but JSON's types


def test_validate_is_the_cli_s_to_the_last_bit(small):
    estimator, path = small
    run = estimator.validate(sims=150, seed=11)
    assert run["records"] == 150 and run["truth"].shape == (150, 1)
    printed = json.loads(cli("validate", "--estimator", str(path), "--sims", "150",
                             "--seed", "11", "--json"))
    assert run["report"] == printed
    # The report is the rows' own.
    mse = float(np.mean((run["truth"] - run["estimates"]) ** 2))
    assert abs(run["report"]["parameters"][0]["mse"] - mse) <= 1e-12 * mse
    assert run["target_met"] is None

    grown = estimator.validate(sims=100, seed=11, target_rmse=1.5)
    r = grown["records"]
    assert grown["target_met"] and grown["certified_over_observed"] <= 1.5
    said = cli("validate", "--estimator", str(path), "--sims", "100", "--seed", "11",
               "--target-rmse", "1.5")
    assert f"met with r = {r} " in said
    events = []
    estimator.validate(sims=120, seed=11, progress=lambda *e: events.append(e))
    assert events[0] == ("begin", "validating", 120) and events[-1] == ("end", "validating", 0)
    assert sum(n for event, _, n in events if event == "advance") == 120

    with pytest.raises(ValueError, match=r"target_rmse = 0.9: .*multiple above 1"):
        estimator.validate(sims=100, target_rmse=0.9)
    with pytest.raises(ValueError, match=r"sims and gamma both size the run"):
        estimator.validate(sims=100, gamma=0.1)


def test_bad_arrays_name_the_argument_and_the_index(small):
    estimator, _ = small
    n, _, _ = estimator.record_shape
    u, y = np.zeros((n, 1)), np.ones((n, 1))
    with pytest.raises(ValueError, match=r"u has dtype float32"):
        estimator.estimate(u.astype(np.float32), y)
    # A lone signal may come as a 1-D array, but not a record of two.
    with pytest.raises(ValueError, match=r"y has shape \[%d, 2\]" % n):
        estimator.estimate(u, np.ones((n, 2)))
    bad = y.copy()
    bad[17, 0] = np.nan
    with pytest.raises(ValueError, match=r"y\[17, 0\] is NaN"):
        estimator.estimate(u, bad)
    # Records 0 and 1 are fine: the bad sample of record 2 is named.
    batch, outputs = np.random.default_rng(1).standard_normal((2, 3, n, 1))
    batch[2, 5, 0] = np.inf
    with pytest.raises(ValueError, match=r"u\[2, 5, 0\] is inf"):
        estimator.estimate(batch, outputs)
    with pytest.raises(ValueError, match=r"the other array holds 3 record"):
        estimator.estimate(np.ones((2, n, 1)), np.ones((3, n, 1)))
    with pytest.raises(ValueError, match=r"u is None"):
        estimator.estimate(None, y)
    with pytest.raises(ValueError, match=r"must be a numpy array"):
        estimator.estimate([[0.0]] * n, y)


def test_files_that_cannot_be_read_say_why(tmp_path):
    with pytest.raises(OSError, match="missing.tsest"):
        twostage.Estimator.load(tmp_path / "missing.tsest")
    junk = tmp_path / "junk.tsest"
    junk.write_bytes(b"not an estimator")
    with pytest.raises(ValueError, match="TWOSTAGE"):
        twostage.Estimator.load(junk)
    with pytest.raises(ValueError, match="pendulum"):
        twostage.train(model="pendulum", sims=10)


GROWTH_MODEL = """
[model]
name = "growth"
[[parameter]]
name = "rate"
prior = { dist = "uniform", low = 0.1, high = 0.5 }
[[parameter]]
name = "size"
prior = { dist = "uniform", low = 1.0, high = 10.0 }
[signals]
inputs = []
outputs = ["n"]
samples = 10
"""


def growth_chart(m, seed):
    """Populations n_k = size * exp(rate k) with multiplicative noise: always
    positive, spanning decades (no preset in the model file)."""
    rng = np.random.default_rng(seed)
    theta = np.column_stack([rng.uniform(0.1, 0.5, m), rng.uniform(1.0, 10.0, m)])
    k = np.arange(10)
    n = theta[:, 1:2] * np.exp(theta[:, 0:1] * k) * rng.lognormal(0.0, 0.1, (m, 10))
    return theta, None, n[:, :, None]


def test_the_automatic_design_on_a_chart_is_the_cli_s(tmp_path):
    """A model file without presets and a chart from numpy: Python's
    automatic design and the command line's `--chart --auto` choose the
    same design and write the same file; the search tried the logarithm
    of the populations, and the design comes back as a [[preset]]."""
    model = tmp_path / "growth.toml"
    model.write_text(GROWTH_MODEL)
    chart = growth_chart(600, 3)
    sizes = dict(validate=100, calibrate=100)
    folder = tmp_path / "chart"
    folder.mkdir()
    for name, array in zip(("theta", "inputs", "outputs"), chart):
        if array is not None:
            np.save(folder / ("%s.npy" % name), array)
    notes = []
    from_python = twostage.train(
        model_file=model, chart=str(folder), auto=True, budget_sims=400, **sizes,
        progress=lambda event, what, count: notes.append((event, what)),
    )
    assert any(e == "status" and "search round 1" in w for e, w in notes), notes
    out = tmp_path / "cli.tsest"
    report = cli(
        "train", "--model-file", str(model), "--chart", str(folder), "--auto",
        "--budget-sims", "400", "--validate", "100", "--calibrate", "100",
        "--out", str(out),
    )
    assert "log+raw" in report and "log+pca:8" in report, report
    assert out.read_bytes() == from_python.to_bytes()
    block = from_python.preset_block()
    assert block is not None and 'compress = "' in block and "sims = 400" in block, block
    # The block trains the same structure again, with no search.
    model.write_text(GROWTH_MODEL + block)
    again = twostage.train(model_file=model, chart=chart, progress=False, **sizes)
    assert again.preset_block() == block
    with pytest.raises(ValueError, match="budget_sims: a budget is read by the automatic design only"):
        twostage.train(model_file=model, chart=chart, budget_sims=400)
    with pytest.raises(ValueError, match="budget_seconds and budget_sims: a budget is seconds or"):
        twostage.train(model_file=model, chart=chart, auto=True, budget_sims=400,
                       budget_seconds=10.0)


def test_assess_says_which_records_a_log_could_not_take(tmp_path):
    """An estimator of log-transformed outputs takes a zero at the smallest
    training value and says so per record; one without transforms says
    None."""
    model = tmp_path / "growth.toml"
    model.write_text(GROWTH_MODEL)
    theta, _, outputs = growth_chart(400, 5)
    est = twostage.train(
        model_file=model, chart=(theta, None, outputs), compress="log+raw", fit="mlp:3",
        validate=50, calibrate=50, progress=False,
    )
    clean = outputs[:2].copy()
    broken = clean.copy()
    broken[1, 3, 0] = 0.0
    assessed = est.assess(None, broken)
    assert assessed["untransformed_samples"].tolist() == [0.0, 1.0]
    assert np.all(np.isfinite(assessed["theta"]))
    one = est.assess(None, broken[1])
    assert one["untransformed_samples"] == 1.0
    plain = twostage.train(model="benchmark", sims=100, validate=0, calibrate=0,
                           progress=False)
    n = plain.record_shape[0]
    u, y = np.random.default_rng(1).standard_normal((2, n, 1))
    assert plain.assess(u, y)["untransformed_samples"] is None


def test_the_posterior_s_draws_are_the_cli_s_bit_for_bit(tmp_path):
    """``posterior=K`` trains the command line's file; ``sample`` draws
    what ``estimate --samples --draws`` writes, record for record; an
    estimator without a posterior, or no draw asked, is refused."""
    args = dict(model="benchmark", sims=400, fit="linear", validate=0,
                calibrate=0, seed=3, progress=False)
    estimator = twostage.train(posterior=2, **args)
    path = tmp_path / "posterior.tsest"
    cli("train", "--model", "benchmark", "--sims", "400", "--fit", "linear",
        "--validate", "0", "--calibrate", "0", "--seed", "3", "--posterior", "2",
        "--out", str(path), "--quiet")
    assert path.read_bytes() == estimator.to_bytes()
    charts = tmp_path / "records"
    cli("simulate", "--model", "benchmark", "--count", "4", "--seed", "8",
        "--out-dir", str(charts))
    draws_file = tmp_path / "draws.csv"
    cli("estimate", "--estimator", str(path), "--samples", "30", "--seed", "5",
        "--draws", str(draws_file), str(charts / "data.csv"))
    columns = draws_file.read_text().splitlines()[0].split(",")
    from_cli = np.loadtxt(draws_file, delimiter=",", skiprows=1,
                          usecols=(columns.index("theta"),))
    data = np.loadtxt(charts / "data.csv", delimiter=",", skiprows=1)
    experiments = np.unique(data[:, 0]).astype(int)
    u = np.stack([data[data[:, 0] == e, 1:2] for e in experiments])
    y = np.stack([data[data[:, 0] == e, 2:3] for e in experiments])
    draws = estimator.sample(u, y, 30, seed=5)
    assert draws.shape == (4, 30, 1)
    assert draws.reshape(-1).tolist() == from_cli.tolist()
    # One record alone is record 0 of its own batch: the stream of (seed, 0).
    assert estimator.sample(u[0], y[0], 30, seed=5).tolist() == draws[0].tolist()
    assert np.all((draws >= -0.9) & (draws <= 0.9))
    with pytest.raises(ValueError, match="at least 1"):
        estimator.sample(u, y, 0)
    plain = twostage.train(**args)
    with pytest.raises(ValueError, match="posterior=K"):
        plain.sample(u, y, 10)
    # region_level is the command line's --at column, record for record.
    at = tmp_path / "at.csv"
    at.write_text("theta\n0.2\n")
    table = tmp_path / "table.csv"
    cli("estimate", "--estimator", str(path), "--samples", "30", "--seed", "5",
        "--at", str(at), "--out", str(table), str(charts / "data.csv"))
    header = table.read_text().splitlines()[0].split(",")
    said = np.loadtxt(table, delimiter=",", skiprows=1,
                      usecols=(header.index("region_level"),))
    levels = estimator.region_level(u, y, [0.2], 30, seed=5)
    assert levels.tolist() == said.tolist()
    assert estimator.region_level(u[0], y[0], [0.2], 30, seed=5) == levels[0]
    with pytest.raises(ValueError, match="1 parameters"):
        estimator.region_level(u, y, [0.2, 0.3], 30)
    # validate scores the posterior on its records, as the command line's JSON does.
    validated = estimator.validate(sims=100)
    posterior = validated["report"]["posterior"]
    assert posterior["records"] == 100 and len(posterior["central"]) == 1
    assert "posterior" not in plain.validate(sims=100)["report"]
