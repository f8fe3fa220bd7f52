"""Type stubs of the native module (src/lib.rs); the package's public API
is twostage/__init__.py, which wraps it."""

from os import PathLike
from typing import Any, Callable, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Array = npt.NDArray[np.float64]
# A chart: its folder, or its arrays (theta [m, q], inputs [m, N, n_u] or
# None, outputs [m, N, n_y]).
_Chart = Union[str, PathLike[str], Tuple[_Array, Optional[_Array], _Array]]

class Estimator:
    """The native estimator. ``twostage.Estimator`` wraps it: use that one,
    whose ``assess`` returns a dict; this one's returns the raw tuple the
    wrapper reads."""
    @staticmethod
    def load(path: Union[str, PathLike[str]]) -> Estimator: ...
    @staticmethod
    def from_bytes(data: bytes) -> Estimator: ...
    def save(self, path: Union[str, PathLike[str]]) -> None: ...
    def to_bytes(self) -> bytes: ...
    def to_runtime(self) -> bytes: ...
    @property
    def parameters(self) -> list[str]: ...
    @property
    def fixed(self) -> list[tuple[str, float]]: ...
    @property
    def lower(self) -> list[float]: ...
    @property
    def upper(self) -> list[float]: ...
    @property
    def record_shape(self) -> Tuple[int, int, int]: ...
    @property
    def model(self) -> str: ...
    def preset_block(self, name: str = "searched") -> Optional[str]: ...
    def to_json(self) -> str: ...
    def validation_json(self) -> Optional[str]: ...
    def estimate(self, u: Optional[_Array], y: _Array) -> _Array: ...
    def sample(self, u: Optional[_Array], y: _Array, n: int, *, seed: int = 0) -> _Array: ...
    def region_level(
        self, u: Optional[_Array], y: _Array, at: list[float], n: int, *, seed: int = 0
    ) -> Union[float, _Array]: ...
    def window_ends(self, samples: int, window: int, every: int) -> list[int]: ...
    def assess(
        self, u: Optional[_Array], y: _Array
    ) -> Tuple[
        _Array,
        Optional[_Array],
        Optional[Union[float, _Array]],
        Optional[float],
        Optional[Union[float, _Array]],
        Optional[Union[float, _Array]],
    ]:
        """(theta, interval half-widths, feature distance, distance
        threshold, samples outside the output transform, ways the input
        lies outside the input family): ``twostage.Estimator.assess``
        makes the dict of these."""
        ...
    def input_deviations(self, u: Optional[_Array], y: _Array) -> list[list[str]]: ...
    def check(
        self,
        u: Optional[_Array],
        y: _Array,
        theta: Optional[list[float]] = None,
        *,
        model_file: Optional[str] = None,
        model_toml: Optional[str] = None,
        sims: Optional[int] = None,
        seed: int = 0,
        score_from: int = 0,
        score_to: Optional[int] = None,
        prior_starts: Optional[int] = None,
    ) -> dict[str, Any]: ...
    def refine(
        self,
        u: Optional[_Array],
        y: _Array,
        *,
        model_file: Optional[str] = None,
        model_toml: Optional[str] = None,
    ) -> dict[str, Any]: ...
    def joint(
        self,
        records: list[tuple[Optional[_Array], _Array]],
        *,
        model_file: Optional[str] = None,
        model_toml: Optional[str] = None,
        prior_starts: Optional[int] = None,
        seed: int = 0,
        fix: Optional[dict[str, float]] = None,
    ) -> dict[str, Any]: ...
    def read_records(
        self, path: str
    ) -> Tuple[list[Tuple[str, _Array, _Array]], list[Tuple[str, str]]]: ...
    def estimate_records(
        self,
        records: list[tuple[Optional[_Array], _Array]],
        *,
        experiments: Optional[list[str]] = None,
        check: bool = False,
        refine: Optional[str] = None,
        refine_below_fit: Optional[float] = None,
        joint: bool = False,
        window: Optional[int] = None,
        every: Optional[int] = None,
        correlation: bool = False,
        model_file: Optional[str] = None,
        model_toml: Optional[str] = None,
        sims: Optional[int] = None,
        score_from: int = 0,
        score_to: Optional[int] = None,
        prior_starts: Optional[int] = None,
        seed: int = 0,
        progress: Optional[Any] = None,
        fix: Optional[dict[str, float]] = None,
    ) -> Tuple[
        str, list[Tuple[str, str]], Optional[Tuple[int, int, list[Tuple[str, str]]]]
    ]:
        """(rows as JSON, failed records, what refine="auto" chose):
        ``twostage.Estimator.estimate_records`` reads these."""
        ...
    def validate(
        self,
        *,
        model_file: Optional[str] = None,
        model_toml: Optional[str] = None,
        sims: Optional[int] = None,
        gamma: Optional[float] = None,
        delta: Optional[float] = None,
        seed: Optional[int] = None,
        target_rmse: Optional[float] = None,
        max_sims: Optional[int] = None,
        progress: Optional[Any] = None,
    ) -> Tuple[str, _Array, _Array, Optional[Tuple[bool, float]]]:
        """(report JSON, truth [r, q], estimates [r, q], (met, ratio) or
        None): ``twostage.Estimator.validate`` makes the dict of these."""
        ...

def check_values(
    theta: list[float],
    u: Optional[_Array],
    y: _Array,
    *,
    model: Optional[str] = None,
    model_file: Optional[str] = None,
    model_toml: Optional[str] = None,
    sims: Optional[int] = None,
    seed: int = 0,
    allow_outside_prior: bool = False,
    score_from: int = 0,
    score_to: Optional[int] = None,
    prior_starts: Optional[int] = None,
) -> dict[str, Any]: ...
def predict(
    theta: list[float],
    u: Optional[_Array] = None,
    *,
    model: Optional[str] = None,
    model_file: Optional[str] = None,
    model_toml: Optional[str] = None,
    noiseless: bool = True,
    seed: int = 0,
    experiment: int = 0,
) -> Tuple[_Array, _Array]: ...

def train(
    model: Optional[str] = None,
    *,
    model_file: Optional[str] = None,
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
    progress: Optional[Callable[[str, str, int], Any]] = None,
    chart: Optional[_Chart] = None,
    validate_chart: Optional[_Chart] = None,
    calibrate_chart: Optional[_Chart] = None,
    auto: bool = False,
    budget_seconds: Optional[float] = None,
    budget_sims: Optional[int] = None,
    posterior: Optional[int] = None,
    fix: Optional[dict[str, float]] = None,
) -> Estimator: ...
