"""twostage: explicit parameter estimators trained on simulations.

Train once on thousands of simulated experiments, then estimate the
parameters of a recorded experiment in microseconds, with intervals, an
out-of-distribution flag and a validation certificate. The engine is
Rust; arrays go in and out as numpy float64.

>>> import numpy as np, twostage
>>> est = twostage.train(model="benchmark", sims=300, validate=100, calibrate=0)
>>> est.parameters
['theta']
>>> n = est.record_shape[0]
>>> u, y = np.random.default_rng(0).standard_normal((2, n, 1))
>>> est.estimate(u, y).shape   # one record: theta [q]
(1,)
>>> est.assess(u, y)["out_of_distribution"]
False
"""

from __future__ import annotations

import json
import sys
from os import PathLike
from typing import Any, Callable, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

from ._twostage import Estimator as _NativeEstimator
from ._twostage import __version__
from ._twostage import check_values as _check_values
from ._twostage import predict as _predict
from ._twostage import train as _train

__all__ = ["Estimator", "check", "predict", "train", "__version__"]

_Path = Optional[Union[str, PathLike[str]]]


def _path(path: _Path) -> Optional[str]:
    return None if path is None else str(path)


class Estimator:
    """A trained estimator: the same files as the ``twostage`` command line.

    >>> est = twostage.Estimator.load("bench.tsest")   # doctest: +SKIP
    >>> theta = est.estimate(u, y)                       # doctest: +SKIP
    """

    __slots__ = ("_native",)

    def __init__(self, native):
        self._native = native

    @classmethod
    def load(cls, path: Union[str, PathLike[str]]) -> Estimator:
        """Read an estimator file written by ``twostage train``, ``save``
        or any earlier version of either."""
        return cls(_NativeEstimator.load(str(path)))

    @classmethod
    def from_bytes(cls, data: bytes) -> Estimator:
        """An estimator from the bytes of a file."""
        return cls(_NativeEstimator.from_bytes(bytes(data)))

    def save(self, path: Union[str, PathLike[str]]) -> None:
        """Write the estimator file (readable by the command line)."""
        self._native.save(str(path))

    def to_bytes(self) -> bytes:
        """The bytes of the estimator file."""
        return self._native.to_bytes()

    def to_runtime(self) -> bytes:
        """The estimator as a blob for the microcontroller runtime and its C
        API, as ``twostage export --to runtime`` writes it (docs/embedded.md).
        Raises ``ValueError`` for a structure the runtime cannot stream (a
        NARX, PCA or raw compressor)."""
        return self._native.to_runtime()

    @property
    def parameters(self) -> list[str]:
        """Parameter names, in the order of theta."""
        return self._native.parameters

    @property
    def fixed(self) -> dict[str, float]:
        """The parameters held at values while it trained (``fix=``),
        name to value: not estimated, held by its checks and
        refinements."""
        return dict(self._native.fixed)

    @property
    def lower(self) -> list[float]:
        """Lower corner of the prior box."""
        return self._native.lower

    @property
    def upper(self) -> list[float]:
        """Upper corner of the prior box."""
        return self._native.upper

    @property
    def record_shape(self) -> tuple[int, int, int]:
        """(samples per record N, inputs n_u, outputs n_y)."""
        return self._native.record_shape

    @property
    def model(self) -> str:
        """The name of the model it was trained on."""
        return self._native.model

    def preset_block(self, name: str = "searched") -> Optional[str]:
        """The ``[[preset]]`` block of a model file that trains this
        structure again without searching (after ``auto=True``), or None
        when a stage has no command-line form."""
        return self._native.preset_block(name)

    def estimate(
        self, u: Optional[npt.NDArray[np.float64]], y: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        """Estimate theta from one record (``u`` [N, n_u], ``y`` [N, n_y]
        float64, giving [q]) or a batch (``u`` [b, N, n_u], ``y``
        [b, N, n_y], giving [b, q]); ``u`` is None for a model without
        input. The records of a batch run in parallel, without the GIL.
        Bad arrays raise ValueError naming the argument and index. A
        record of one input (or one output) may give that signal as a 1-D
        array [N]."""
        u, y = self._columns(u, y)
        return self._native.estimate(u, y)

    def _columns(self, u, y):
        """One record's lone signals given as 1-D arrays [N], as the [N, 1]
        columns the native side reads (views, not copies)."""
        _, n_u, n_y = self.record_shape

        def column(array, width):
            if isinstance(array, np.ndarray) and array.ndim == 1 and width == 1:
                return array.reshape(-1, 1)
            return array

        return column(u, n_u), column(y, n_y)

    def sample(
        self,
        u: Optional[npt.NDArray[np.float64]],
        y: npt.NDArray[np.float64],
        n: int,
        *,
        seed: int = 0,
    ) -> npt.NDArray[np.float64]:
        """``n`` draws from the posterior given one record (shapes as
        ``estimate``: draws [n, q]) or each record of a batch ([b, n, q]),
        every draw inside its prior's support. Record k of a batch draws
        from the stream of (``seed``, k), as ``twostage estimate --samples
        n --seed SEED`` does for the k-th record of a file: the same
        numbers. The estimator must have been trained with ``posterior=K``
        (else ValueError says so)."""
        u, y = self._columns(u, y)
        return self._native.sample(u, y, n, seed=seed)

    def region_level(
        self,
        u: Optional[npt.NDArray[np.float64]],
        y: npt.NDArray[np.float64],
        at: Sequence[float],
        n: int,
        *,
        seed: int = 0,
    ) -> Any:
        """Whether the parameter values ``at`` are ones the record allows:
        the smallest level of its posterior's joint region of highest
        density that holds them (a float for one record, [b] for a
        batch), by the ``n`` draws ``sample`` gives with the same
        ``seed``: at most 0.9 where ``at`` lies in the joint 90% region.
        ``twostage estimate --samples n --seed SEED --at`` writes the same
        numbers in its ``region_level`` column."""
        u, y = self._columns(u, y)
        return self._native.region_level(u, y, list(at), n, seed=seed)

    def assess(
        self, u: Optional[npt.NDArray[np.float64]], y: npt.NDArray[np.float64]
    ) -> dict[str, Any]:
        """Estimate with intervals and the out-of-distribution flag, for one
        record or a batch (shapes as ``estimate``). Returns a dict:

        - ``theta``: the estimates ([q] or [b, q]);
        - ``lower``, ``upper``: the 90% (or the trained level's) interval,
          inside the prior's box (never outside a parameter's support),
          adaptive where calibrated, else conformal; None when uncalibrated;
        - ``feature_distance``: the record's Mahalanobis distance from the
          training features, ``distance_threshold`` the distance 99.9% of
          them stay within, ``out_of_distribution`` whether it is beyond
          (None without a feature envelope);
        - ``untransformed_samples``: for an estimator that transforms its
          outputs (``log+...``), how many samples of the record lay outside
          the transform's domain (a zero under a logarithm) and were taken
          at the smallest training value instead; the estimate does not
          speak for them. None for an estimator without transforms.
        - ``input_in_family``: whether the record's input lies inside the
          family of inputs the estimator's held-out records spanned (its
          mean, RMS, peak and mean frequency), None for an estimator
          without one; ``input_outside_family`` says how it lies outside
          (a list of sentences per record). A record outside the family is
          out of distribution too.
        """
        u, y = self._columns(u, y)
        theta, widths, distance, threshold, floored, outside = self._native.assess(u, y)
        lower, upper = self._interval(theta, widths)
        features_out = None if distance is None else np.asarray(distance > threshold)
        input_in = None if outside is None else np.asarray(outside) == 0
        flags = [f for f in (features_out, None if input_in is None else ~input_in) if f is not None]
        out = None
        if flags:
            out = flags[0] if len(flags) == 1 else flags[0] | flags[1]
            out = bool(out) if np.ndim(out) == 0 else out
        said = None
        if input_in is not None:
            said = self._native.input_deviations(u, y)
            said = said[0] if np.ndim(input_in) == 0 else said
            input_in = bool(input_in) if np.ndim(input_in) == 0 else input_in
        result = {
            "theta": theta,
            "lower": lower,
            "upper": upper,
            "feature_distance": distance,
            "distance_threshold": threshold,
            "out_of_distribution": out,
            "untransformed_samples": floored,
            "input_in_family": input_in,
            "input_outside_family": said,
        }
        return result

    def assess_windows(
        self,
        u: Optional[npt.NDArray[np.float64]],
        y: npt.NDArray[np.float64],
        window: int,
        every: Optional[int] = None,
    ) -> dict[str, Any]:
        """``assess`` of every window of ``window`` samples of one long
        record ([N, n_u], [N, n_y]), one every ``every`` samples (default
        ``window``: side by side), as ``twostage estimate --window --every``
        writes them: the dict of ``assess`` for the batch of windows, with
        ``window_end`` the last sample of each (from 1). Each window's
        numbers are those of the window assessed alone.
        """
        u, y = self._columns(u, y)
        y = np.asarray(y, dtype=np.float64)
        n = y.shape[0]
        every = window if every is None else every
        ends = np.asarray(self._native.window_ends(n, window, every), dtype=np.int64)
        ys = np.stack([y[end - window:end] for end in ends])
        us = None
        if u is not None:
            u = np.asarray(u, dtype=np.float64)
            us = np.stack([u[end - window:end] for end in ends])
        result = self.assess(us, ys)
        result["window_end"] = ends
        return result

    def check(
        self,
        u: Optional[npt.NDArray[np.float64]],
        y: npt.NDArray[np.float64],
        theta: Optional[Any] = None,
        *,
        model_file: _Path = None,
        model_toml: Optional[str] = None,
        sims: Optional[int] = None,
        seed: int = 0,
        score_from: int = 0,
        score_to: Optional[int] = None,
        prior_starts: Optional[int] = None,
    ) -> dict[str, Any]:
        """Check one record's estimate against the record, as ``twostage
        estimate --check`` does: the model at ``theta`` (None: this
        estimator's own estimate) simulated without noise on the record's
        input, ranked among ``sims`` of the model's own records there
        (None: as many as the command's ``--check-sims`` default),
        scored from sample ``score_from`` on (``--score-from``) up to, not
        including, ``score_to`` (``--score-to``; None: the record's end), and its
        fit judged against the best fit searched from it and from
        ``prior_starts`` starts over the prior (``--prior-starts``; None:
        two per parameter and two more).
        The model is the estimator's built-in one, or its model file
        (``model_file`` or ``model_toml``). Returns a dict of the
        command's check columns (``rms``, ``fit_percent`` and
        ``best_fit_percent`` per output, ``check_tail_probability``,
        ``check_improvement_tail_probability``,
        ``check_best_fit_tail_probability``, ``model_consistent``,
        ``loss_over_best``, ``explained``,
        ``input_as_trained``, ``optima``, ``runner_up_over_best``) and the
        noise-free response ``simulated`` [N, n_y]."""
        u, y = self._columns(u, y)
        if theta is not None:
            theta = [float(t) for t in np.asarray(theta, dtype=np.float64).ravel()]
        return self._native.check(
            u,
            y,
            theta,
            model_file=_path(model_file),
            model_toml=model_toml,
            sims=sims,
            seed=seed,
            score_from=score_from,
            score_to=score_to,
            prior_starts=prior_starts,
        )

    def refine(
        self,
        u: Optional[npt.NDArray[np.float64]],
        y: npt.NDArray[np.float64],
        *,
        model_file: _Path = None,
        model_toml: Optional[str] = None,
    ) -> dict[str, Any]:
        """Refine one record's estimate through the model, as ``twostage
        estimate --refine`` does: a built-in model's posterior mean under
        its exact likelihood, or with a model file an output-error fit
        through its simulator from the estimate and two starts in its
        interval, the estimate the mean of the likelihood near its best
        fit within the prior's box (the best fit where the record pins a
        parameter down). Returns a dict: ``theta``; ``lower`` and ``upper``, the
        refined estimate's own interval at the estimator's level (None,
        with ``interval_error`` saying why, where the record does not
        determine a parameter); ``correlation`` [q, q]; ``stop``, why the
        descent stopped (None for a posterior mean); ``optima`` and
        ``runner_up_over_best``, what the output-error fit's search found
        (None for a posterior mean). The interval covers
        the record's noise about the model's best fit: where ``check``
        finds the record not ``model_consistent``, the plant's values may
        lie outside it. Raises ValueError when the model cannot be
        evaluated near the estimate."""
        u, y = self._columns(u, y)
        refined = self._native.refine(
            u, y, model_file=_path(model_file), model_toml=model_toml
        )
        widths = refined.pop("half_widths")
        refined["lower"], refined["upper"] = self._interval(refined["theta"], widths)
        return refined

    def joint(
        self,
        records: list,
        *,
        model_file: _Path = None,
        model_toml: Optional[str] = None,
        prior_starts: Optional[int] = None,
        seed: int = 0,
        fix: Optional[dict[str, float]] = None,
    ) -> dict[str, Any]:
        """One estimate of the plant behind all ``records`` (a list of
        ``(u, y)`` pairs, each of any length on its own input), as
        ``twostage estimate --joint`` gives it: the records' two-stage
        estimates pooled by their intervals, then one output-error fit of
        every record, searched from the pooled estimate, each record's
        estimate and ``prior_starts`` starts over the prior (default two
        per parameter and two more, of ``seed``). Returns a dict:
        ``theta``; ``lower`` and ``upper``, its interval at the estimator's
        level (None, with ``interval_error`` saying why); ``correlation``;
        ``stop``; ``optima`` and ``runner_up_over_best`` of the search;
        ``pooled``; ``fitted``, the indices of the records fitted, with
        ``fit_percent`` at the joint estimate; ``left_out``, pairs of an
        index and why the model could not run it; ``disagreeing``, the
        indices of records whose estimates lie beyond their intervals from
        the others'; ``between_sd`` and ``mismatch_sets_width``, the scatter
        of the records' own best fits beyond their noise; ``per_record``,
        per parameter whether it belongs to each record (``per_record =
        true`` in the model file: NaN in ``theta``), and ``records_theta``
        and ``records_half_widths``, each fitted record's whole estimate.
        ``fix={"name": value}`` holds parameters there, as ``--fix``: the
        estimate is of the others. Raises ValueError when no record can be
        fitted."""
        pairs = [self._columns(u, y) for u, y in records]
        joint = self._native.joint(
            pairs,
            model_file=_path(model_file),
            model_toml=model_toml,
            prior_starts=prior_starts,
            seed=seed,
            fix=fix,
        )
        widths = joint.pop("half_widths")
        joint["lower"], joint["upper"] = self._interval(joint["theta"], widths)
        return joint

    def read_records(self, path: Union[str, PathLike[str]]) -> dict[str, Any]:
        """The records of the CSV file at ``path`` as ``twostage estimate``
        reads them for this estimator (one record ``u,y`` or many
        ``experiment,u,y``, its signals' columns in any order, a ``time``
        column checked against the sample time): a dict of ``records``, a
        list of ``(experiment, u, y)`` ready for ``estimate_records``, and
        ``failed``, pairs of an experiment and why it could not be read
        (file, row, column). Raises OSError when the file cannot be read
        at all, ValueError (its row named) when it reads but is not a file
        of records (a header without the signals' columns, say)."""
        records, failed = self._native.read_records(str(path))
        return {"records": records, "failed": failed}

    def estimate_records(
        self,
        records: list,
        *,
        experiments: Optional[list[str]] = None,
        check: bool = False,
        refine: Optional[str] = None,
        refine_below_fit: Optional[float] = None,
        joint: bool = False,
        window: Optional[int] = None,
        every: Optional[int] = None,
        correlation: bool = False,
        model_file: _Path = None,
        model_toml: Optional[str] = None,
        sims: Optional[int] = None,
        score_from: int = 0,
        score_to: Optional[int] = None,
        prior_starts: Optional[int] = None,
        seed: int = 0,
        progress: Any = None,
        fix: Optional[dict[str, float]] = None,
    ) -> dict[str, Any]:
        """Estimate ``records`` (a list of ``(u, y)`` pairs, any lengths),
        named ``experiments`` (default their indices), as ``twostage
        estimate --estimator`` estimates a file of them with the same
        flags: ``check`` (``--check``, ranked among ``sims`` runs, scored
        from ``score_from``), ``refine`` ``"all"`` or ``"auto"``
        (``--refine``, ``--refine=auto``: check every record and refine
        those the check does not explain, or whose fit is below
        ``refine_below_fit`` percent), ``joint`` (a last row
        ``"joint"``), ``window`` and ``every`` (a row per window),
        ``correlation``, ``prior_starts`` and ``seed``. The model is the
        estimator's built-in one, or its model file (``model_file`` or
        ``model_toml``). Returns a dict: ``rows``, a dict per row with the
        keys of the command's ``--format json`` (the same numbers, bit
        for bit); ``failed``, pairs of an experiment and why it has no
        row; ``auto``, with ``refine="auto"``, a dict of ``explained``
        and ``checked`` counts and ``refined``, each refined experiment
        and why. ``fix={"name": value}`` holds parameters there, as
        ``--fix``: the rows are of the others, and the check, refinement
        and joint fit search them alone."""
        pairs = [self._columns(u, y) for u, y in records]
        rows, failed, auto = self._native.estimate_records(
            pairs,
            experiments=experiments,
            check=check,
            refine=refine,
            refine_below_fit=refine_below_fit,
            joint=joint,
            window=window,
            every=every,
            correlation=correlation,
            model_file=_path(model_file),
            model_toml=model_toml,
            sims=sims,
            score_from=score_from,
            score_to=score_to,
            prior_starts=prior_starts,
            seed=seed,
            progress=_progress(progress),
            fix=fix,
        )
        if auto is not None:
            explained, checked, refined = auto
            auto = {"explained": explained, "checked": checked, "refined": dict(refined)}
        return {"rows": json.loads(rows), "failed": failed, "auto": auto}

    def validate(
        self,
        *,
        model_file: _Path = None,
        model_toml: Optional[str] = None,
        sims: Optional[int] = None,
        gamma: Optional[float] = None,
        delta: Optional[float] = None,
        seed: Optional[int] = None,
        target_rmse: Optional[float] = None,
        max_sims: Optional[int] = None,
        progress: Any = None,
    ) -> dict[str, Any]:
        """Validate this estimator on fresh simulations of its model, as
        ``twostage validate`` does (the same settings give the same report,
        bit for bit): ``sims`` records (default 1000), or as many as
        Theorem 1 needs for accuracy ``gamma`` with confidence
        ``1 - delta`` (``delta`` default 1e-3); with ``target_rmse`` K,
        growing the records from ``sims``, each round as many as the last
        predicts, until every certified RMSE is at most K times the
        observed one, at most ``max_sims`` (default
        1,000,000). ``seed`` defaults to the command's, apart from every
        training seed. The model is the estimator's built-in one, or its
        model file (``model_file`` or ``model_toml``). ``progress`` as in
        ``train``. Returns a dict: ``report`` (as ``validation`` holds
        it; with a posterior, its calibration on the same records under
        ``posterior``: the joint region's and central intervals' coverage
        at 50/90/95% and the ranks' uniformity), ``truth`` and
        ``estimates`` [r, q], ``records`` r, and
        ``target_met`` and ``certified_over_observed`` (None without
        ``target_rmse``). A setting out of range raises ValueError naming
        it."""
        report, truth, estimates, target = self._native.validate(
            model_file=_path(model_file),
            model_toml=model_toml,
            sims=sims,
            gamma=gamma,
            delta=delta,
            seed=seed,
            target_rmse=target_rmse,
            max_sims=max_sims,
            progress=_progress(progress),
        )
        met, ratio = target if target is not None else (None, None)
        return {
            "report": json.loads(report),
            "truth": truth,
            "estimates": estimates,
            "records": truth.shape[0],
            "target_met": met,
            "certified_over_observed": ratio,
        }

    def _interval(self, theta, widths):
        """``theta +- widths`` inside the prior's box, as the command line
        writes it (``twostage::interval_in_box``): a parameter's interval
        never leaves its prior's support."""
        if widths is None:
            return None, None
        lower = np.maximum(theta - widths, np.asarray(self.lower))
        upper = np.minimum(theta + widths, np.asarray(self.upper))
        return lower, upper

    @property
    def validation(self) -> Optional[dict[str, Any]]:
        """The validation report as plain data (a dict: per-parameter RMSE,
        bias, certificates, interval coverage), or None."""
        text = self._native.validation_json()
        return None if text is None else json.loads(text)

    def to_dict(self) -> dict[str, Any]:
        """The whole estimator as plain data (what ``to_json`` holds)."""
        return json.loads(self._native.to_json())

    def __repr__(self) -> str:
        return "twostage.Estimator(model={!r}, parameters={!r})".format(
            self.model, self.parameters
        )


class _TqdmProgress:
    """One tqdm bar per stage of training (simulation, fitting,
    calibration, validation)."""

    def __init__(self, tqdm):
        self._tqdm = tqdm
        self._bars = {}

    def __call__(self, event, stage, count):
        if event == "note":
            self._tqdm.write(stage, file=sys.stderr)
        elif event == "status":
            for bar in self._bars.values():
                bar.set_postfix_str(stage, refresh=True)
        elif event == "begin":
            self._bars[stage] = self._tqdm(total=count or None, desc=stage, unit="sim")
        elif event == "advance" and stage in self._bars:
            self._bars[stage].update(count)
        elif event == "end" and stage in self._bars:
            self._bars.pop(stage).close()


def _notes_only(event, message, count):
    """Without tqdm: the run's messages still reach stderr."""
    if event == "note":
        print(message, file=sys.stderr)


def _progress(progress):
    if progress is True:
        try:
            from tqdm.auto import tqdm
        except ImportError:
            return _notes_only
        return _TqdmProgress(tqdm)
    if progress is False or progress is None:
        return None
    return progress


def train(
    model: Optional[str] = None,
    *,
    model_file: Optional[Union[str, PathLike[str]]] = None,
    model_toml: Optional[str] = None,
    simulator: Optional[Callable[..., Any]] = None,
    batch_size: int = 64,
    preset: Optional[str] = None,
    sims: Optional[int] = None,
    compress: Optional[str] = None,
    fit: Optional[str] = None,
    seed: Optional[int] = None,
    validate: Optional[int] = None,
    certify_within: Optional[float] = None,
    max_validate: Optional[int] = None,
    calibrate: Optional[int] = None,
    alpha: Optional[float] = None,
    progress: Union[bool, Callable[[str, str, int], Any]] = True,
    chart: Any = None,
    validate_chart: Any = None,
    calibrate_chart: Any = None,
    auto: bool = False,
    budget_seconds: Optional[float] = None,
    budget_sims: Optional[int] = None,
    posterior: Optional[int] = None,
    fix: Optional[dict[str, float]] = None,
) -> Estimator:
    """Train an estimator with the command line's defaults: the same
    arguments and seed give the same file, bit for bit, as ``twostage
    train``. The model is

    - a built-in one: ``model="benchmark"`` or ``"pacejka"``;
    - a model file: ``model_file="car.toml"``, or its text as
      ``model_toml``;
    - a Python simulator: ``simulator=f`` with a model file without
      ``[source]`` giving the parameter names, priors, signals and presets.
      ``f(thetas, seeds, indices)`` receives a batch (``thetas`` float64
      [b, q], ``seeds`` and ``indices`` uint64 [b]) and returns the outputs
      float64 [b, N, n_y], or the pair ``(inputs [b, N, n_u], outputs)``
      for a model with inputs. Experiment k must draw its randomness from
      ``np.random.default_rng([seeds[k], indices[k]])`` only, so that a
      chart is the same whatever the batches (the protocol's convention,
      docs/protocol.md). It is called in batches of ``batch_size`` from
      the training threads.

    ``chart`` trains on experiments simulated elsewhere instead: a tuple
    ``(theta [m, q], inputs [m, N, n_u], outputs [m, N, n_y])`` of float64
    arrays (``inputs`` None for a model without input), or a folder as
    ``twostage train --chart`` reads (CSV or ``.npy``). ``validate`` and
    ``calibrate`` records are then held out of it, unless
    ``validate_chart`` and ``calibrate_chart`` give their own.

    ``preset``, ``sims``, ``compress`` (``"arx:2,2"``...), ``fit``
    (``"mlp:10"``...) override the model's default preset as the CLI's
    flags do; ``seed``, ``validate``, ``calibrate`` and ``alpha`` left as
    None take the command line's defaults (1, 1000, 4000, 0.1), which the
    Rust side holds once. As there, ``validate`` fixes the validation's
    records; without it they grow from 1000 until every certified RMSE is
    within ``certify_within`` (default 1.2) times the observed one, at most
    ``max_validate`` (default 1,000,000) records; ``certify_within`` with
    ``validate`` grows from ``validate`` records. ``progress=True`` shows tqdm bars when tqdm is installed;
    a callable receives ``(event, stage, count)``, and ``("note", message,
    0)`` or ``("status", message, 0)`` for the run's messages. The
    simulation, compression and fitting run in Rust without the GIL.

    ``auto=True`` searches output transforms, compressors and networks by
    held-out error instead of training a preset, within ``budget_seconds``
    (default 120) or on ``budget_sims`` simulations with every candidate
    evaluated (reproducible), as ``twostage train --auto`` does; on a
    ``chart`` it fits and scores on the chart's own records. A model
    without presets searches even without ``auto``. The design found is
    ``estimator.preset_block()``, to paste into the model file.

    ``posterior=K`` also trains the posterior, a density of the parameters
    given stage 1's features (a mixture of K Gaussians with full
    covariances), that ``Estimator.sample`` draws from, as ``twostage
    train --posterior K`` does; with ``auto`` K is the most, the count of
    the lowest held-out negative log-likelihood kept.

    ``fix={"name": value}`` holds parameters at values, as ``--fix`` does:
    the estimator estimates the others (``Estimator.fixed`` says what was
    held), and its checks, refinements and validations hold them too.
    """
    native = _train(
        model,
        model_file=None if model_file is None else str(model_file),
        model_toml=model_toml,
        simulator=simulator,
        batch_size=batch_size,
        preset=preset,
        sims=sims,
        compress=compress,
        fit=fit,
        seed=seed,
        validate=validate,
        certify_within=certify_within,
        max_validate=max_validate,
        calibrate=calibrate,
        alpha=alpha,
        progress=_progress(progress),
        auto=auto,
        budget_seconds=budget_seconds,
        budget_sims=budget_sims,
        posterior=posterior,
        fix=fix,
        chart=chart,
        validate_chart=validate_chart,
        calibrate_chart=calibrate_chart,
    )
    return Estimator(native)


def _signal(array, name):
    """A lone signal given as a 1-D array [N], as the [N, 1] column the
    native side reads."""
    if isinstance(array, np.ndarray) and array.ndim == 1:
        return array.reshape(-1, 1)
    return array


def check(
    theta: Any,
    u: Optional[npt.NDArray[np.float64]],
    y: npt.NDArray[np.float64],
    *,
    model: Optional[str] = None,
    model_file: _Path = None,
    model_toml: Optional[str] = None,
    sims: Optional[int] = None,
    seed: int = 0,
    allow_outside_prior: bool = False,
    score_from: int = 0,
    score_to: Optional[int] = None,
    prior_starts: Optional[int] = None,
) -> dict[str, Any]:
    """Check given parameter values (a published value, another tool's
    fit) against one record, as ``twostage estimate --at VALUES --check``
    does; the model is ``model`` (built-in), ``model_file`` or
    ``model_toml``. Values outside the prior's box raise ValueError naming
    the parameter, unless ``allow_outside_prior``. Returns the dict of
    ``Estimator.check``."""
    theta = [float(t) for t in np.asarray(theta, dtype=np.float64).ravel()]
    return _check_values(
        theta,
        _signal(u, "u"),
        _signal(y, "y"),
        model=model,
        model_file=_path(model_file),
        model_toml=model_toml,
        sims=sims,
        seed=seed,
        allow_outside_prior=allow_outside_prior,
        score_from=score_from,
        score_to=score_to,
        prior_starts=prior_starts,
    )


def predict(
    theta: Any,
    u: Optional[npt.NDArray[np.float64]] = None,
    *,
    model: Optional[str] = None,
    model_file: _Path = None,
    model_toml: Optional[str] = None,
    noiseless: bool = True,
    seed: int = 0,
    experiment: int = 0,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The model's record at ``theta`` on the input ``u`` ([N, n_u], or
    [N] for one input; None: the model's own input design), as ``twostage
    simulate --at --input`` writes it: without noise unless
    ``noiseless=False`` (then experiment ``experiment`` of ``seed``'s
    noise, as row ``experiment`` of the command's estimates). Returns
    ``(u [N, n_u], y [N, n_y])``: compare ``y`` with a record the fit did
    not see to validate an estimate."""
    theta = [float(t) for t in np.asarray(theta, dtype=np.float64).ravel()]
    return _predict(
        theta,
        _signal(u, "u"),
        model=model,
        model_file=_path(model_file),
        model_toml=model_toml,
        noiseless=noiseless,
        seed=seed,
        experiment=experiment,
    )
