"""Check, refine and predict from Python against the command line's
numbers on the same records: ``estimate --check``, ``estimate --refine``
(a built-in model's posterior, and an output-error fit through a model
file), ``estimate --at --check`` and ``simulate --at --input --noiseless``.

The command line binary comes from TWOSTAGE_CLI (``cargo xtask test`` sets
it to the one it built).
"""

import json

import numpy as np
import pytest

import twostage
from command_line import cli, cli_refusal



# A model file of the benchmark, shorter records: its estimates refine by
# an output-error fit through the file's simulator, not the posterior.
SHORT = """
[model]
name = "short-benchmark"
[source]
builtin = "benchmark"
[[parameter]]
name = "theta"
prior = { dist = "uniform", low = -0.9, high = 0.9 }
[signals]
samples = 300
"""


def records(folder):
    """The records of a ``simulate --count`` folder as u, y [b, N, 1], and
    the truth [b, q]."""
    data = np.loadtxt(folder / "data.csv", delimiter=",", skiprows=1)
    experiments = np.unique(data[:, 0]).astype(int)
    u = np.stack([data[data[:, 0] == e, 1:2] for e in experiments])
    y = np.stack([data[data[:, 0] == e, 2:3] for e in experiments])
    truth = np.loadtxt(folder / "truth.csv", delimiter=",", skiprows=1, ndmin=2)[:, 1:]
    return u, y, truth


CHECK_COLUMNS = [
    "check_tail_probability",
    "check_improvement_tail_probability",
    "check_best_fit_tail_probability",
    "check_runs",
    "model_consistent",
    "loss_over_best",
    "explained",
    "optima",
]


def same_check(from_python, row):
    assert from_python["rms"].tolist() == [row["y_rms"]]
    assert from_python["fit_percent"].tolist() == [row["y_fit_percent"]]
    for name in CHECK_COLUMNS:
        assert from_python[name] == row[name], name
    # The same best-fit search: the same optima, the same runner-up.
    assert from_python["runner_up_over_best"] == row.get("runner_up_over_best")


@pytest.fixture(scope="module")
def benchmark(tmp_path_factory):
    folder = tmp_path_factory.mktemp("through-model")
    estimator = twostage.train(model="benchmark", sims=300, validate=0, calibrate=200, seed=3)
    path = folder / "bench.tsest"
    estimator.save(path)
    cli("simulate", "--model", "benchmark", "--count", "3", "--seed", "17",
        "--out-dir", str(folder / "records"))
    return estimator, path, folder / "records"


def test_check_and_refine_are_the_cli_s(benchmark):
    estimator, path, folder = benchmark
    u, y, _ = records(folder)
    data = str(folder / "data.csv")
    checked = json.loads(cli("estimate", "--estimator", str(path), "--check",
                             "--check-sims", "99", "--format", "json", data))
    refined = json.loads(cli("estimate", "--estimator", str(path), "--refine",
                             "--format", "json", data))
    for k in range(3):
        same_check(estimator.check(u[k], y[k], sims=99), checked[k])
        ours = estimator.refine(u[k], y[k])
        assert ours["theta"].tolist() == [refined[k]["theta"]]
        assert ours["lower"].tolist() == [refined[k]["theta_lo"]]
        assert ours["upper"].tolist() == [refined[k]["theta_hi"]]
        assert ours["stop"] is None and ours["correlation"].tolist() == [[1.0]]
        # A check of the refined values is the command's check of them.
        again = estimator.check(u[k], y[k], ours["theta"], sims=99)
        assert again["simulated"].shape == (1000, 1)


def test_a_file_of_records_is_estimated_as_the_cli_estimates_it(benchmark):
    estimator, path, folder = benchmark
    u, y, _ = records(folder)
    pairs = [(u[k], y[k]) for k in range(3)]
    data = str(folder / "data.csv")
    # Checked, refined where the check does not explain (or the fit is
    # below 99.9%, so that some are), with the correlations.
    from_cli = json.loads(cli("estimate", "--estimator", str(path), "--refine=auto",
                              "--refine-below-fit", "99.9", "--check-sims", "99",
                              "--format", "json", data))
    read = estimator.read_records(data)
    assert read["failed"] == [] and [r[0] for r in read["records"]] == ["0", "1", "2"]
    # A file that reads but holds no records is the caller's data: its
    # row named in a ValueError; one that cannot be read, an OSError.
    headless = folder / "headless.csv"
    headless.write_text("speed,angle\n1,2\n")
    with pytest.raises(ValueError, match="headless.csv.*(line|row) 1"):
        estimator.read_records(headless)
    with pytest.raises(OSError):
        estimator.read_records(folder / "missing.csv")
    assert all(np.array_equal(r[2], y[k]) for k, r in enumerate(read["records"]))
    ours = estimator.estimate_records([(u_, y_) for _, u_, y_ in read["records"]],
                                      experiments=[r[0] for r in read["records"]],
                                      refine="auto", refine_below_fit=99.9, sims=99)
    assert ours["rows"] == from_cli and ours["failed"] == []
    assert ours["auto"]["checked"] == 3
    # Refined rows left their two-stage estimate; the others kept it.
    moved = {row["experiment"] for row in from_cli
             if row["theta"] != estimator.estimate(*pairs[int(row["experiment"])])[0]}
    assert set(ours["auto"]["refined"]) == moved and moved
    # Windows, then one estimate of every window together, by name.
    from_cli = json.loads(cli("estimate", "--estimator", str(path), "--window", "500",
                              "--every", "250", "--joint", "--format", "json", data))
    ours = estimator.estimate_records(pairs, window=500, every=250, joint=True,
                                      experiments=["0", "1", "2"])
    assert ours["rows"] == from_cli
    assert [row.get("window_end") for row in ours["rows"]][:3] == [500, 750, 1000]
    assert ours["rows"][-1]["experiment"] == "joint"
    # Windows the estimator cannot read alone are named, the others kept.
    ours = estimator.estimate_records(pairs[:1], window=500)
    assert ours["rows"] == [] and len(ours["failed"]) == 2
    assert "records: experiment 0: " in ours["failed"][0][1]
    with pytest.raises(ValueError, match="refine_below_fit: the fit below which to refine is read when refining auto only"):
        estimator.estimate_records(pairs, refine_below_fit=50.0)
    with pytest.raises(ValueError, match="experiments has 1 names for 3 records"):
        estimator.estimate_records(pairs, experiments=["a"])


def words_after(spelling, message):
    """What a door says of a refusal after its own name of the setting."""
    assert message.startswith(spelling + ": "), message
    return message[len(spelling) + 2:]


def test_each_refusal_is_the_request_s_through_both_doors(benchmark, tmp_path):
    estimator, path, folder = benchmark
    u, y, _ = records(folder)
    pairs = [(u[k], y[k]) for k in range(3)]
    data = str(folder / "data.csv")
    model = tmp_path / "short.toml"
    model.write_text(SHORT)
    est = ("estimate", "--estimator", str(path))

    def python_refusal(**kwargs):
        with pytest.raises(ValueError) as refused:
            estimator.estimate_records(pairs, **kwargs)
        return str(refused.value)

    # Each door names the setting its way; the words after are the
    # request's, the same through both.
    cases = [
        (("--refine=all", "--refine-below-fit", "5"), "--refine-below-fit",
         dict(refine="all", refine_below_fit=5.0), "refine_below_fit"),
        (("--model-file", str(model)), "--model-file",
         dict(model_file=str(model)), "the model"),
        (("--window", "100", "--every", "0"), "--window",
         dict(window=100, every=0), "the windows"),
    ]
    for flags, flag, kwargs, name in cases:
        from_cli = words_after(flag, cli_refusal(*est, *flags, data))
        from_python = words_after(name, python_refusal(**kwargs))
        assert from_cli == from_python, (flags, kwargs)
    # A window longer than the records: each record is named, not
    # estimated, in the request's words through both doors.
    refused = cli_refusal(*est, "--window", "5000", data)
    ours = estimator.estimate_records(pairs, window=5000, experiments=["0", "1", "2"])
    assert ours["rows"] == [] and len(ours["failed"]) == 3
    assert refused.endswith(ours["failed"][0][1].split(": ", 1)[1]), (refused, ours["failed"][0])


def test_an_output_error_refinement_through_a_model_file_is_the_cli_s(tmp_path):
    model = tmp_path / "short.toml"
    model.write_text(SHORT)
    estimator = twostage.train(model_toml=SHORT, sims=300, validate=0, calibrate=200, seed=4)
    path = tmp_path / "short.tsest"
    estimator.save(path)
    cli("simulate", "--model-file", str(model), "--count", "2", "--seed", "8",
        "--out-dir", str(tmp_path / "records"))
    u, y, _ = records(tmp_path / "records")
    refined = json.loads(cli("estimate", "--estimator", str(path), "--model-file", str(model),
                             "--refine", "--correlation", "--format", "json",
                             str(tmp_path / "records" / "data.csv")))
    for k in range(2):
        ours = estimator.refine(u[k], y[k], model_file=model)
        assert ours["theta"].tolist() == [refined[k]["theta"]]
        assert ours["lower"].tolist() == [refined[k]["theta_lo"]]
        assert ours["upper"].tolist() == [refined[k]["theta_hi"]]
        assert ours["stop"] == refined[k]["refine_stop"]
        assert ours["optima"] == refined[k]["optima"]
        assert ours["runner_up_over_best"] == refined[k].get("runner_up_over_best")
    # Both records jointly: the command line's joint row, bit for bit.
    joint = json.loads(cli("estimate", "--estimator", str(path), "--model-file", str(model),
                           "--joint", "--format", "json",
                           str(tmp_path / "records" / "data.csv")))[-1]
    ours = estimator.joint([(u[0], y[0]), (u[1], y[1])], model_file=model)
    assert joint["experiment"] == "joint"
    assert ours["theta"].tolist() == [joint["theta"]]
    assert ours["lower"].tolist() == [joint["theta_lo"]]
    assert ours["upper"].tolist() == [joint["theta_hi"]]
    assert ours["stop"] == joint["refine_stop"]
    assert ours["fitted"] == [0, 1] and ours["left_out"] == []
    assert ours["optima"] == joint["optima"]
    assert ours["fit_percent"].shape == (2,)
    # The scatter of the two records' own best fits beyond their noise.
    assert ours["between_sd"].shape == (1,) and ours["between_sd"][0] >= 0
    assert len(ours["mismatch_sets_width"]) == 1
    # No parameter of the records' own: each record's whole estimate is the joint one.
    assert ours["per_record"] == [False]
    assert ours["records_theta"].tolist() == [[joint["theta"]]] * 2
    # Holding the only parameter leaves nothing to estimate; a name the
    # estimator lacks is refused with those it has.
    with pytest.raises(ValueError, match="every parameter is fixed"):
        estimator.joint([(u[0], y[0]), (u[1], y[1])], model_file=model, fix={"theta": 0.3})
    with pytest.raises(ValueError, match="its parameters are theta"):
        estimator.estimate_records([(u[0], y[0])], refine="all", model_file=model,
                                   fix={"mass": 1.0})
    # A record the model cannot run (the wrong number of outputs) is refused, named.
    with pytest.raises(ValueError, match=r"records\[1\]"):
        estimator.joint([(u[0], y[0]), (u[1], np.hstack([y[1], y[1]]))], model_file=model)
    # The file's text does as well as the file.
    assert estimator.refine(u[0], y[0], model_toml=SHORT)["theta"].tolist() == [refined[0]["theta"]]
    # Without the model file the estimator's model is unknown: said.
    with pytest.raises(ValueError, match="give the model file it was trained from"):
        estimator.refine(u[0], y[0])


def test_given_values_are_checked_and_predicted_as_the_cli_does(benchmark, tmp_path):
    _, _, folder = benchmark
    u, y, truth = records(folder)
    checked = json.loads(cli("estimate", "--model", "benchmark", "--at",
                             str(folder / "truth.csv"), "--check", "--check-sims", "99",
                             "--format", "json", str(folder / "data.csv")))
    predicted = tmp_path / "predicted.csv"
    cli("simulate", "--model", "benchmark", "--at", str(folder / "truth.csv"), "--input",
        str(folder / "data.csv"), "--noiseless", "--out", str(predicted))
    from_cli = np.loadtxt(predicted, delimiter=",", skiprows=1)
    windowed = json.loads(cli("estimate", "--model", "benchmark", "--at",
                              str(folder / "truth.csv"), "--check", "--check-sims", "99",
                              "--score-from", "100", "--format", "json",
                              str(folder / "data.csv")))
    ended = json.loads(cli("estimate", "--model", "benchmark", "--at",
                           str(folder / "truth.csv"), "--check", "--check-sims", "99",
                           "--score-from", "100", "--score-to", "600", "--format", "json",
                           str(folder / "data.csv")))
    for k in range(3):
        same_check(twostage.check(truth[k], u[k], y[k], model="benchmark", sims=99), checked[k])
        same_check(
            twostage.check(truth[k], u[k], y[k], model="benchmark", sims=99, score_from=100),
            windowed[k],
        )
        same_check(
            twostage.check(truth[k], u[k], y[k], model="benchmark", sims=99, score_from=100,
                           score_to=600),
            ended[k],
        )
        assert windowed[k]["y_rms"] != checked[k]["y_rms"]
        assert ended[k]["y_rms"] != windowed[k]["y_rms"]
        given_u, simulated = twostage.predict(truth[k], u[k], model="benchmark")
        rows = from_cli[from_cli[:, 0] == k]
        assert given_u[:, 0].tolist() == u[k][:, 0].tolist()
        assert simulated[:, 0].tolist() == rows[:, 2].tolist()
    # The model's own input design, and its noise, as the command draws them.
    own_u, own_y = twostage.predict([0.3], model="benchmark", noiseless=False, seed=2)
    assert own_u.shape == (1000, 1) and own_y.shape == (1000, 1)
    again = twostage.predict([0.3], model="benchmark", noiseless=False, seed=2)
    assert again[1].tolist() == own_y.tolist()


def test_bad_values_and_arrays_are_named(benchmark):
    estimator, _, folder = benchmark
    u, y, _ = records(folder)
    with pytest.raises(ValueError) as refused:
        twostage.check([1.5], u[0], y[0], model="benchmark")
    from_python = words_after("theta without allow_outside_prior=True", str(refused.value))
    assert from_python.startswith("theta, experiment 0: parameter theta = 1.5 lies outside"), \
        from_python
    # The command line refuses them in the request's words, naming its file.
    values = folder / "outside.csv"
    values.write_text("experiment,theta\n0,1.5\n")
    from_cli = words_after("--at without --allow-outside-prior",
                           cli_refusal("estimate", "--model", "benchmark", "--at", str(values),
                                       "--check", str(folder / "data.csv")))
    assert from_cli == from_python.replace("theta, experiment", str(values) + ", experiment", 1)
    simulated = words_after("--at without --allow-outside-prior",
                            cli_refusal("simulate", "--model", "benchmark", "--at", str(values)))
    assert simulated == from_cli
    outside = twostage.check([1.5], u[0], y[0], model="benchmark", allow_outside_prior=True,
                             sims=49)
    assert outside["explained"] in (True, False)
    with pytest.raises(ValueError, match="theta has 2 values, the model has 1"):
        twostage.predict([0.1, 0.2], u[0], model="benchmark")
    with pytest.raises(ValueError, match="theta's theta is NaN: give finite values"):
        estimator.check(u[0], y[0], [float("nan")])
    with pytest.raises(ValueError, match="theta has 2 values, the model has 1"):
        estimator.check(u[0], y[0], [0.1, 0.2])
    with pytest.raises(ValueError, match="u is a batch"):
        estimator.refine(u, y)
    bad = y[0].copy()
    bad[7, 0] = np.nan
    with pytest.raises(ValueError, match=r"y\[7, 0\] is NaN"):
        estimator.check(u[0], bad)
    with pytest.raises(ValueError, match="give model=, model_file= or model_toml="):
        twostage.predict([0.1], u[0])
    # The two-stage estimate keeps the estimator's length, as on the
    # command line; a refinement fits the record at its own.
    with pytest.raises(ValueError, match="this estimator reads records of N = 1000"):
        estimator.estimate(u[0][:300], y[0][:300])
    longer_u = np.concatenate([u[0], u[0]])
    longer_y = np.concatenate([y[0], y[0]])
    assert estimator.refine(longer_u, longer_y)["theta"].shape == (1,)
