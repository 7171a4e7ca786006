"""Type stubs of the compiled extension ``mtpcr._mtpcr`` (import from ``mtpcr``).

Kept in step with the extension by ``python/tests/test_stubs.py``: every public name here
exists at runtime and vice versa, and the keyword arguments of ``Config`` and ``register``
are exactly the fields of the Rust ``Config``.
"""

from collections.abc import Sequence
from os import PathLike
from typing import Any, Callable, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

_Path = str | PathLike[str]
_Sampling = Literal["farthest", "random"]
_Search = Literal["fast", "exact"]
_Method = Literal["mtpcr", "mfea", "gmfea"]
_Order = Literal["auto", "given"]
_Callback = Callable[[int, dict[str, float]], bool | None]
_Viewpoints = Literal["origin"] | Sequence[ArrayLike | None] | None
_Screening = dict[str, Any] | Sequence[dict[str, Any]]

__version__: str
"""The package version (the Cargo workspace version)."""

TASK_NAMES: tuple[str, ...]
"""The six tasks of three clouds: ``("J1-a", "J2-a", "J3-a", "J1-o", "J2-o", "J3-o")``;
aiding tasks ``-a``, original tasks ``-o``, for the pairs 1->2, 2->3, 3->1. (A registration of
N clouds has its own, ``Registration.task_names``.)"""

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
        order: _Order = ...,
        population_size: int = ...,
        generations: int = ...,
        sample_ratio: float = ...,
        max_sample_points: int = ...,
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
        stop_when_restarts_agree: bool = ...,
        refine_iterations: int = ...,
        hypotheses: int = ...,
        second_look: bool = ...,
        feature_voxel_ratio: float = ...,
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
    @staticmethod
    def field_docs() -> dict[str, str]:
        """The documentation of every field, by name, in declaration order (the same text as
        the Rust docs and the CLI help)."""
    def __eq__(self, other: object) -> bool: ...
    @property
    def method(self) -> _Method:
        """The evolutionary algorithm: `mtpcr` (the paper's method), or the baselines
        `mfea`, `gmfea`. Paper: mtpcr."""
    @property
    def order(self) -> _Order:
        """How the clouds relate: `auto` (two: a pair; three: the paper's loop; four or
        more: a set in no known order, its overlapping pairs found and joined where
        loops through them close) or `given` (three or more given in loop order,
        searched jointly as one loop). Paper: given."""
    @property
    def population_size(self) -> int:
        """Individuals per population (`n`; two populations per edge of the view graph).
        In 4..=1000000. Paper: 100."""
    @property
    def generations(self) -> int:
        """Generations after the initial one (`G`), at most 1000000; 0: the feature
        hypotheses, refined, are the answer (needs `hypotheses` > 0). Paper: 60."""
    @property
    def sample_ratio(self) -> float:
        """Fraction of each cloud's points kept by downsampling, in (0, 1]. Paper: 0.05."""
    @property
    def max_sample_points(self) -> int:
        """Most points kept per cloud by downsampling (0 = no limit, only
        `sample_ratio`); with a limit, dense clouds are thinned evenly before
        farthest-point sampling, so the cost no longer grows with the scan's size
        (beyond the paper). Paper: 0."""
    @property
    def sampling(self) -> _Sampling:
        """Downsampling method: `farthest` (farthest-point sampling) or `random`. Paper:
        farthest."""
    @property
    def p_intra(self) -> float:
        """Probability per generation and edge of intra-task sharing (aiding <->
        original elites), in [0, 1]. Paper: 0.5."""
    @property
    def p_inter(self) -> float:
        """Probability per generation and edge of inter-task sharing (the estimate
        composed from the rest of the loop), in [0, 1]. Paper: 0.5."""
    @property
    def top_ratio(self) -> float:
        """Fraction of a population kept as elites (and shared per channel), in (0, 1].
        Paper: 0.1."""
    @property
    def scale_factor(self) -> float:
        """Differential-evolution scale factor `F`, in (0, 2]. Paper: 0.5."""
    @property
    def sbx_eta_start(self) -> float:
        """SBX distribution index at the first generation, in [0, 1000]. Paper: 2."""
    @property
    def sbx_eta_end(self) -> float:
        """SBX distribution index approached at the last generation, in [0, 1000].
        Paper: 10."""
    @property
    def alpha(self) -> float:
        """Weight of the loop-closure term `alpha * tanh(||C - I||_F)` in the original
        tasks' loss, finite and >= 0. Paper: 0.05."""
    @property
    def aiding_cap_ratio(self) -> float:
        """The aiding loss caps each point's distance at this fraction of `shift` (the
        largest bounding-box side), in (0, 10]. Paper: 0.1."""
    @property
    def two_way_aiding(self) -> bool:
        """Aiding loss in both directions (source -> target and target -> source).
        Paper: false."""
    @property
    def unit_free_loop_term(self) -> bool:
        """Divide the loop term's translations by `shift` so the term has no unit.
        Paper: false."""
    @property
    def refresh_loop_term(self) -> bool:
        """Recompute the parents' loop terms each generation from the new bests. Paper:
        false (parents keep the loss they were scored with)."""
    @property
    def search(self) -> _Search:
        """Search structure of the losses: `fast` (occupancy grid and distance field;
        the same inlier counts as `exact`) or `exact` (KD-tree; the reference). Paper:
        fast."""
    @property
    def restarts(self) -> int:
        """Independent evolutions (each with its own seed derived from `seed`); the one
        with the lowest sum of final original-task costs is kept (beyond the paper). In
        1..=1000. Paper: 1."""
    @property
    def stop_when_restarts_agree(self) -> bool:
        """Stop the restarts as soon as two of them end on the same transforms (every
        edge within 5 degrees; beyond the paper): more restarts would change the cost,
        not the answer. Paper: false."""
    @property
    def refine_iterations(self) -> int:
        """Iterations of the joint trimmed, residual-weighted point-to-plane ICP of all
        clouds after the evolution, which closes the loop exactly (beyond the paper); 0
        = off, at most 10000. Paper: 0."""
    @property
    def hypotheses(self) -> int:
        """Pose hypotheses per edge from local features (FPFH keypoints matched both
        ways, verified by RANSAC and refined by ICP; beyond the paper), placed in the
        edge's initial populations; 0 = off, at most 100. Paper: 0."""
    @property
    def second_look(self) -> bool:
        """A pair registered alone whose scans carry viewpoints (scenes) and whose
        answer the verdict doubts is registered again from keypoints 0.75 times as far
        apart, and the answer the verdict trusts more is kept (beyond the paper): on 300
        3DLoMatch pairs 62.7 % registered instead of 53.0, for a median 0.35 s a pair
        instead of 0.22 (RESULTS.md). Loops, sets of scans and scans without viewpoints
        are not affected. Paper: false."""
    @property
    def feature_voxel_ratio(self) -> float:
        """Spacing of the feature keypoints, as a fraction of the clouds' mean
        principal-axes box diagonal, in (0, 0.5]. Paper: unused."""
    @property
    def num_threads(self) -> int:
        """Worker threads for the loss evaluations; 0 = all cores, at most 4096 (more
        than four per core are not started). The result does not depend on it."""
    @property
    def seed(self) -> int | None:
        """Seed of the run; none draws one (reported in the result)."""

class Registration:
    """The result of :func:`register`. Read-only.

    ``T_ij`` maps points of cloud i into the frame of cloud j: ``x_j = T_ij @ [x_i, 1]``. Each
    edge's transform is an attribute named so: ``T12`` for two clouds; ``T12``, ``T23``,
    ``T31`` for three; ``T12`` ... ``Tn1`` for n in a loop (``T3_10`` style beyond nine).
    Costs are the evolution's, before the refinement.
    """

    def __getattr__(self, name: str) -> NDArray[np.float64]:
        """The 4x4 transform of the edge named ``name`` (``"T12"``, ...)."""
    @property
    def transforms(self) -> NDArray[np.float64]:
        """The edge transforms in edge order, shape (K, 4, 4) (``[T12, T23, T31]`` for three
        clouds)."""
    @property
    def edges(self) -> list[dict[str, Any]]:
        """One dict per edge: ``name``, ``source``, ``target`` (clouds numbered from 0),
        ``t_target_source`` (4x4), ``original_cost``, ``aiding_cost``."""
    def t_target_source(self, target: int, source: int) -> NDArray[np.float64]:
        """The 4x4 transform mapping cloud ``source`` into cloud ``target``'s frame (clouds
        numbered from 0)."""
    @property
    def poses(self) -> NDArray[np.float64]:
        """Each cloud into cloud 1's frame (``poses[0]`` is the identity; see
        ``reference_cloud`` when cloud 1 is not placed), shape (N, 4, 4);
        all NaN for a cloud that could not be placed."""
    def transform_points(self, cloud: int, points: ArrayLike) -> NDArray[np.float64]:
        """``points`` of cloud ``cloud`` (numbered from 0; an (N, 3) array or anything with
        ``.points``) mapped into cloud 1's frame by its pose; ValueError when that cloud was
        not placed."""
    def merge(self, *clouds: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """The clouds given to ``register`` (same order) merged in cloud 1's frame: (M, 3)
        points and the (M,) cloud index (from 0) of each; unplaced clouds left out."""
    def trajectory_log(self) -> str:
        """Each placed cloud's pose in cloud 1's frame as a ``.log`` trajectory (3DMatch /
        Redwood format: a line ``k k n``, then the 4x4 pose); unplaced clouds left out."""
    def pose_graph(self) -> dict[str, Any]:
        """Open3D's pose graph as a dict (``json.dump`` it, then
        ``open3d.io.read_pose_graph``): a node per cloud, an edge per pair used."""
    @property
    def confident(self) -> bool:
        """Whether the result can be believed (every pair overlaps and its surfaces lie on
        each other; every cloud placed)."""
    @property
    def verdict(self) -> dict[str, Any]:
        """``confident``, ``reasons`` and per pair ``overlap``, ``residual``,
        ``self_residual``, ``constraint`` (how firmly the overlap holds the pose against a
        slide), ``support``, ``rival_support``, ``free_space``, ``free_share``, ``landed``
        and ``tight_support`` (None when not measured)."""
    @property
    def reference_cloud(self) -> int | None:
        """The cloud (from 0) whose frame ``poses`` are in: 0, or the first placed cloud when
        cloud 0 could not be placed; None when none is placed."""
    @property
    def unplaced(self) -> list[dict[str, Any]]:
        """Clouds that could not be placed: dicts with ``cloud`` (from 0) and ``reason``."""
    @property
    def loop_residual(self) -> float | None:
        """``||T_n1 ... T23 @ T12 - I||_F`` for a loop of three or more clouds, else None."""
    @property
    def best_costs(self) -> dict[str, float]:
        """The evolution's final best cost of each task, keyed by ``task_names``."""
    @property
    def history(self) -> NDArray[np.float64]:
        """Best costs of the kept evolution after its initial population and every
        generation, shape (rows, tasks), columns in ``task_names`` order."""
    @property
    def task_names(self) -> tuple[str, ...]:
        """``J1-a``, ``J2-a``, ..., then ``J1-o``, ``J2-o``, ...: the aiding and original task
        of each edge."""
    @property
    def evaluations(self) -> int:
        """Loss evaluations made (all restarts)."""
    @property
    def generations_run(self) -> int:
        """Generations run, all restarts together (fewer when the run was stopped)."""
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
    """A problem with ground truth (from :func:`load_problem`). Read-only."""

    @property
    def name(self) -> str:
        """Short name (``"bunny-a"``)."""
    @property
    def scans(self) -> list[str]:
        """The scan files, resolved against the data root."""
    @property
    def poses(self) -> NDArray[np.float64]:
        """Ground-truth scan-to-world poses, shape (N, 4, 4)."""
    @property
    def ground_truth(self) -> NDArray[np.float64]:
        """Ground truth of each edge (``[T12, T23, T31]`` for three scans), shape (K, 4, 4)."""
    @property
    def notes(self) -> list[str]:
        """What loading changed (poses re-orthonormalised)."""
    def read_scans(self) -> tuple[NDArray[np.float64], ...]:
        """Reads the scans as (N, 3) float64 arrays."""

def register(
    *clouds: ArrayLike,
    seed: int | None = None,
    on_generation: _Callback | None = None,
    on_pair_screening: Callable[[int, int], bool | None] | None = None,
    config: Config | None = None,
    viewpoints: _Viewpoints = None,
    screening: _Screening | None = None,
    method: _Method = ...,
    order: _Order = ...,
    population_size: int = ...,
    generations: int = ...,
    sample_ratio: float = ...,
    max_sample_points: int = ...,
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
    stop_when_restarts_agree: bool = ...,
    refine_iterations: int = ...,
    hypotheses: int = ...,
    second_look: bool = ...,
    feature_voxel_ratio: float = ...,
    num_threads: int = ...,
) -> Registration:
    """Registers overlapping (N, 3) clouds with no initial guess: ``register(a, b)`` for two,
    ``register(a, b, c, ...)`` or ``register(*clouds)`` for three or more in loop order.

    Settings are ``Config`` fields as keywords, over ``config`` (default ``Config()``).
    ``on_generation(generation, best_costs)`` is called after every generation
    (``generation`` counts 1, 2, ... across restarts; ``best_costs`` maps the task names to
    the best cost so far); returning False stops the run (``completed=False``), None or True
    continues; an exception in it, or Ctrl-C, stops the run and propagates.

    ``viewpoints``: where each scanner stood in its cloud's frame, for the free-space check (a
    right pose puts no surface where another scanner saw through; absent without them):
    ``None`` (unknown), ``"origin"`` (every cloud taken from its own origin: depth-camera
    frames, 3DMatch fragments) or one entry per cloud, each None or 3 finite numbers. Any other
    form raises ``ValueError``.

    ``screening``: the pair screening of these clouds made already by :func:`screen_pairs`
    (its dict, or a list of them for disjoint sets of pairs; four or more clouds in no known
    order): the registration skips screening and gives exactly the result it gives screening
    every pair itself. From other clouds or settings it raises ``ValueError``.

    Each cloud holds real numbers (float or int; booleans, complex numbers and strings raise
    ``ValueError``), at least ``MIN_POINTS`` finite points of magnitude at most 1e30, not
    all on one line. A planar cloud is registered with a ``UserWarning``: its rotation about
    the plane normal is weakly determined.
    """

def screen_pairs(
    *clouds: ArrayLike,
    pairs: Sequence[tuple[int, int]] | None = None,
    seed: int | None = None,
    on_pair_screening: Callable[[int, int], bool | None] | None = None,
    config: Config | None = None,
    viewpoints: _Viewpoints = None,
    method: _Method = ...,
    order: _Order = ...,
    population_size: int = ...,
    generations: int = ...,
    sample_ratio: float = ...,
    max_sample_points: int = ...,
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
    stop_when_restarts_agree: bool = ...,
    refine_iterations: int = ...,
    hypotheses: int = ...,
    second_look: bool = ...,
    feature_voxel_ratio: float = ...,
    num_threads: int = ...,
) -> dict[str, Any]:
    """The pair screening of four or more clouds in no known order (the slow first step of
    ``register`` for a whole room): each pair's pose hypotheses, for the ``pairs`` given
    (``(source, target)``, clouds numbered from 0, ``source < target``; None: every pair).

    Screen disjoint sets of pairs anywhere and pass the results, as a list, to
    ``register(*clouds, screening=...)`` with the same clouds, seed and settings: its result is
    exactly the one ``register`` gives screening every pair itself
    (``mtpcr.distributed.register_scene`` does this on Ray). Returns plain, picklable data: a
    dict with ``fingerprint``, ``clouds`` (their number) and ``pairs`` (dicts with ``source``,
    ``target``, ``poses`` (H, 4, 4, in the prepared centred frames), ``overlaps`` (H) and
    ``supports`` (H)). Clouds and keywords as for ``register``; the return value of
    ``on_pair_screening`` is ignored (a screening is all or nothing).
    """

def read_ply(path: _Path) -> NDArray[np.float64]:
    """Reads a PLY file's vertex ``x y z`` as an (N, 3) float64 array."""

def read_points(path: _Path) -> NDArray[np.float64]:
    """Reads the one scan of a PLY, PCD, E57, LAS/LAZ, XYZ/TXT/CSV or PTS file as an (N, 3)
    float64 array (format told by content, then extension)."""

def read_scans(path: _Path) -> list[dict[str, Any]]:
    """Reads every scan of a file (an E57 file may hold several): dicts with ``name``,
    ``points`` ((N, 3) float64), ``pose`` (4x4 stored with an E57 scan, else None) and
    ``viewpoint`` (the scanner's position, 3 floats, from a PCD's non-default VIEWPOINT, else
    None)."""

def write_ply(path: _Path, points: ArrayLike, colors: ArrayLike | None = None) -> None:
    """Writes points (and optional (N, 3) uint8 colours) as a binary PLY file."""

def load_problem(path: _Path, data_root: _Path | None = None) -> Problem:
    """Reads a problem file (``shared/problems/*.json``): two or more scans with poses."""

def evaluate(
    suite: str,
    problems: list[_Path],
    *,
    runs: int | None = None,
    seeds: list[int] | None = None,
    variants: list[str] | None = None,
    generations: int | None = None,
    data_root: _Path | None = None,
    on_run: Callable[[dict[str, Any]], bool | None] | None = None,
) -> list[dict[str, Any]]:
    """Runs an experiment suite (``"accuracy"``, ``"quality"``, ``"noise"``, ``"alpha"``,
    ``"sharing"``, ``"sampling"``) on problem files: one record per run, the same as the
    lines ``mtpcr experiment`` writes to ``runs.jsonl``."""

def evaluate_pairs(
    benchmark: _Path,
    *,
    pairs: int | None = None,
    scenes: list[str] | None = None,
    seed: int | None = None,
    moved: bool = False,
    data_root: _Path | None = None,
    config: Config | None = None,
    on_pair: Callable[[dict[str, Any]], bool | None] | None = None,
    **settings: Any,
) -> dict[str, Any]:
    """Runs the pairs of a pair benchmark folder in the 3DMatch layout (one folder per scene
    with a ``gt.log``: 3DMatch, 3DLoMatch; or one scene's folder) as ``mtpcr eval FOLDER``
    does: each pair registered with no initial guess and scored against ``gt.log``
    (registered when RE < 15 degrees and TE < 0.3).

    Returns ``{"benchmark": name, "records": [...], "summary": {...}}``: one record per pair
    in the benchmark's order (the lines of ``mtpcr eval --records``: ``benchmark``, ``pair``
    (``scene/target-source``), ``seed``, ``moved``, ``re_deg``, ``te``, ``registered``,
    ``confident``, ``reasons``, ``overlap``, ``residual``, ``constraint``, ``support``,
    ``rival_support``, ``free_space``, ``free_share``, ``landed``, ``tight_support``,
    ``seconds``, ``t_target_source``) and their summary
    (``pairs``, ``registered``, ``recall`` in percent, ``re_deg`` and ``te`` over the
    registered pairs or None, ``median_seconds``, ``failed``, ``failed_confident``,
    ``registered_doubted``).

    ``pairs``: a seeded sample of that many pairs (default all); ``scenes``: only scenes
    whose name contains one of these; ``seed`` (default: the config's, else 0) seeds the
    sample and the runs; ``moved``: each source moved by a seeded rigid motion first;
    ``data_root`` holds ``<scene>/cloud_bin_<k>.ply`` (default: the folder's grandparent).
    Settings are ``Config`` fields as keywords, over ``config``. ``on_pair(record)`` is
    called after each pair; returning False stops (the records so far are returned). A
    missing folder raises ``FileNotFoundError``, a folder that is not a benchmark
    ``ValueError``.
    """

def describe_suite(suite: str) -> dict[str, Any]:
    """What an experiment suite runs: ``name``, ``default_runs``, ``paper_problems`` (problem
    names, or None for every problem) and ``variants`` in run order (dicts with ``key``,
    ``label``, ``settings`` and ``noise``)."""

def find_shared_dir() -> str | None:
    """The shared data folder (``$MTPCR_SHARED_DIR``, else the nearest ``shared/`` beside the
    current directory or an ancestor), or None."""
