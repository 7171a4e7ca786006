"""Type stubs of the compiled extension ``mtpcr._mtpcr`` (import from ``mtpcr``).

Kept in step with the extension by ``python/tests/test_stubs.py``: every public name here
exists at runtime and vice versa, and the keyword arguments of ``Config`` and ``register``
are exactly the fields of the Rust ``Config``.
"""

from os import PathLike
from typing import Any, Callable, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

_Path = str | PathLike[str]
_Sampling = Literal["farthest", "random"]
_Search = Literal["fast", "exact"]
_Method = Literal["mtpcr", "mfea", "gmfea"]
_Callback = Callable[[int, dict[str, float]], bool | None]

__version__: str
"""The package version (the Cargo workspace version)."""

TASK_NAMES: tuple[str, str, str, str, str, str]
"""The six tasks: ``("J1-a", "J2-a", "J3-a", "J1-o", "J2-o", "J3-o")``; aiding tasks ``-a``,
original tasks ``-o``, for the pairs 1->2, 2->3, 3->1. Keys of ``best_costs``, columns of
``history``."""

MIN_POINTS: int
"""Fewest points a cloud may have."""

class Config:
    """Every setting of a registration run, validated on construction.

    ``Config()`` (or ``Config.default()``) is the recommended setting, ``Config.paper()`` the
    paper's reference setting; keyword arguments override single fields. The names are those
    of the Rust ``Config``, the CLI flags and config-file keys. A bad value raises
    ``ValueError`` naming the field, an unknown name ``TypeError``. Immutable; equal when all
    fields are equal.
    """

    def __init__(
        self,
        *,
        method: _Method = ...,
        population_size: int = ...,
        generations: int = ...,
        sample_ratio: float = ...,
        sampling: _Sampling = ...,
        p_intra: float = ...,
        p_inter: float = ...,
        top_ratio: float = ...,
        scale_factor: float = ...,
        sbx_eta_start: float = ...,
        sbx_eta_end: float = ...,
        alpha: float = ...,
        aiding_cap_ratio: float = ...,
        two_way_aiding: bool = ...,
        unit_free_loop_term: bool = ...,
        refresh_loop_term: bool = ...,
        search: _Search = ...,
        restarts: int = ...,
        refine_iterations: int = ...,
        num_threads: int = ...,
        seed: int | None = ...,
    ) -> None: ...
    @staticmethod
    def default() -> Config:
        """The recommended setting (the same as ``Config()``)."""
    @staticmethod
    def paper() -> Config:
        """The authors' reference setting (the paper's Section IV-C)."""
    def replace(self, **changes: Any) -> Config:
        """A copy with the given fields changed (validated like the constructor)."""
    def to_dict(self) -> dict[str, Any]:
        """Every field and its value, in declaration order (``Config(**c.to_dict()) == c``)."""
    def __eq__(self, other: object) -> bool: ...
    @property
    def method(self) -> _Method:
        """The evolutionary algorithm: ``"mtpcr"`` (the paper's method) or the baselines
        ``"mfea"``, ``"gmfea"``."""
    @property
    def population_size(self) -> int:
        """Individuals per population (six populations). At least 4. Paper: 100."""
    @property
    def generations(self) -> int:
        """Generations after the initial one. Paper: 60."""
    @property
    def sample_ratio(self) -> float:
        """Fraction of each cloud's points kept by downsampling, in (0, 1]. Paper: 0.05."""
    @property
    def sampling(self) -> _Sampling:
        """Downsampling method, ``"farthest"`` (paper) or ``"random"``."""
    @property
    def p_intra(self) -> float:
        """Probability of intra-task sharing (aiding <-> original elites), in [0, 1]. Paper: 0.5."""
    @property
    def p_inter(self) -> float:
        """Probability of inter-task sharing (estimate composed around the loop), in [0, 1].
        Paper: 0.5."""
    @property
    def top_ratio(self) -> float:
        """Fraction of a population kept as elites, in (0, 1]. Paper: 0.1."""
    @property
    def scale_factor(self) -> float:
        """Differential-evolution scale factor F, in (0, 2]. Paper: 0.5."""
    @property
    def sbx_eta_start(self) -> float:
        """SBX distribution index at the first generation, in [0, 1000]. Paper: 2."""
    @property
    def sbx_eta_end(self) -> float:
        """SBX distribution index approached at the last generation, in [0, 1000]. Paper: 10."""
    @property
    def alpha(self) -> float:
        """Weight of the loop-closure term ``alpha * tanh(||C - I||_F)``, >= 0. Paper: 0.05."""
    @property
    def aiding_cap_ratio(self) -> float:
        """Aiding loss distance cap as a fraction of the largest bounding-box side, in (0, 10].
        Paper: 0.1."""
    @property
    def two_way_aiding(self) -> bool:
        """Aiding loss in both directions. Paper: False."""
    @property
    def unit_free_loop_term(self) -> bool:
        """Divide the loop term's translations by the shift so it has no unit. Paper: False."""
    @property
    def refresh_loop_term(self) -> bool:
        """Recompute the parents' loop terms every generation. Paper: False."""
    @property
    def search(self) -> _Search:
        """Search structure of the losses, ``"fast"`` or ``"exact"`` (same inlier counts)."""
    @property
    def restarts(self) -> int:
        """Independent evolutions; the best is kept (beyond the paper). At least 1. Paper: 1."""
    @property
    def refine_iterations(self) -> int:
        """Joint trimmed-ICP iterations of the three clouds (closes the loop); 0 = off. Paper: 0."""
    @property
    def num_threads(self) -> int:
        """Worker threads; 0 = all cores. The result does not depend on it."""
    @property
    def seed(self) -> int | None:
        """Seed of the run; None draws one (reported in the result)."""

class Registration:
    """The result of :func:`register`. Read-only.

    ``T_ij`` maps points of cloud i into the frame of cloud j: ``x_j = T_ij @ [x_i, 1]``.
    """

    @property
    def T12(self) -> NDArray[np.float64]:
        """4x4 transform mapping cloud 1 into cloud 2's frame."""
    @property
    def T23(self) -> NDArray[np.float64]:
        """4x4 transform mapping cloud 2 into cloud 3's frame."""
    @property
    def T31(self) -> NDArray[np.float64]:
        """4x4 transform mapping cloud 3 into cloud 1's frame."""
    @property
    def transforms(self) -> NDArray[np.float64]:
        """``[T12, T23, T31]``, shape (3, 4, 4)."""
    @property
    def poses(self) -> NDArray[np.float64]:
        """Each cloud into cloud 1's frame, ``[I, inv(T12), T31]``, shape (3, 4, 4)."""
    @property
    def loop_residual(self) -> float:
        """``||T31 @ T23 @ T12 - I||_F``."""
    @property
    def best_costs(self) -> dict[str, float]:
        """Best final cost of each task, keyed by ``TASK_NAMES``."""
    @property
    def history(self) -> NDArray[np.float64]:
        """Best costs after the initial population and every generation, shape (rows, 6),
        columns in ``TASK_NAMES`` order."""
    @property
    def task_names(self) -> tuple[str, str, str, str, str, str]:
        """``TASK_NAMES``."""
    @property
    def evaluations(self) -> int:
        """Loss evaluations made."""
    @property
    def generations_run(self) -> int:
        """Generations run (fewer than configured when the run was stopped)."""
    @property
    def completed(self) -> bool:
        """False when ``on_generation`` stopped the run early."""
    @property
    def seconds(self) -> float:
        """Wall-clock seconds of the call."""
    @property
    def seed(self) -> int:
        """The seed that reproduces this result."""
    @property
    def eps(self) -> float:
        """Inlier radius of the losses, in the clouds' units."""
    @property
    def shift(self) -> float:
        """Largest bounding-box side of the downsampled clouds, in the clouds' units."""
    @property
    def settings(self) -> dict[str, Any]:
        """The Config of the run as a dict, seed included."""

class Problem:
    """A three-view problem with ground truth (from :func:`load_problem`). Read-only."""

    @property
    def name(self) -> str:
        """Short name (``"bunny-a"``)."""
    @property
    def scans(self) -> list[str]:
        """The three scan files, resolved against the data root."""
    @property
    def poses(self) -> NDArray[np.float64]:
        """Ground-truth scan-to-world poses, shape (3, 4, 4)."""
    @property
    def ground_truth(self) -> NDArray[np.float64]:
        """Ground truth ``[T12, T23, T31]``, shape (3, 4, 4)."""
    def read_scans(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Reads the three scans as (N, 3) float64 arrays."""

def register(
    cloud1: ArrayLike,
    cloud2: ArrayLike,
    cloud3: ArrayLike,
    *,
    seed: int | None = None,
    on_generation: _Callback | None = None,
    config: Config | None = None,
    method: _Method = ...,
    population_size: int = ...,
    generations: int = ...,
    sample_ratio: float = ...,
    sampling: _Sampling = ...,
    p_intra: float = ...,
    p_inter: float = ...,
    top_ratio: float = ...,
    scale_factor: float = ...,
    sbx_eta_start: float = ...,
    sbx_eta_end: float = ...,
    alpha: float = ...,
    aiding_cap_ratio: float = ...,
    two_way_aiding: bool = ...,
    unit_free_loop_term: bool = ...,
    refresh_loop_term: bool = ...,
    search: _Search = ...,
    restarts: int = ...,
    refine_iterations: int = ...,
    num_threads: int = ...,
) -> Registration:
    """Registers three overlapping (N, 3) clouds that form a loop, with no initial guess.

    Settings are ``Config`` fields as keywords, over ``config`` (default ``Config()``).
    ``on_generation(generation, best_costs)`` is called after every generation
    (``generation`` counts 1, 2, ... across restarts; ``best_costs`` maps ``TASK_NAMES`` to
    the best cost so far); returning False stops the run (``completed=False``), None or True
    continues; an exception in it, or Ctrl-C, stops the run and propagates.
    """

def read_ply(path: _Path) -> NDArray[np.float64]:
    """Reads a PLY file's vertex ``x y z`` as an (N, 3) float64 array."""

def write_ply(path: _Path, points: ArrayLike, colors: ArrayLike | None = None) -> None:
    """Writes points (and optional (N, 3) uint8 colours) as a binary PLY file."""

def load_problem(path: _Path, data_root: _Path | None = None) -> Problem:
    """Reads a problem file (``shared/problems/*.json``)."""
