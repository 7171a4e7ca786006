"""Batches of registrations and the experiment suites on Ray (``pip install "mtpcr[ray]"``).

Ray runs the tasks on this machine (``ray.init()``, started for you when needed) or on a
cluster (``ray start --head`` on one machine, ``ray start --address=HEAD:6379`` on the others,
then ``address="auto"`` here on the head, or ``RAY_ADDRESS``). mtpcr (with the same version)
must be installed on every node; data files need not be shared: clouds and scans go through
Ray's object store, each put there once and passed to the tasks by reference.

Three entry points:

- :func:`register_scene`: one whole scene (the fragments of a room), its pair screening
  spread over the cluster; exactly the poses of a local ``mtpcr.register``.
- :func:`register_batch`: many registrations (a scanning line, a sweep of settings). Each item
  is a scan set (a sequence of (N, 3) arrays or objects with ``.points``), a problem file, or
  an :class:`Item` with its own seed and settings. Results come back in the items' order as
  plain, picklable :class:`RegistrationRecord` objects, or a :class:`Failure` in the slot of an
  item that failed (the other items are not affected).
- :func:`evaluate`: ``mtpcr.evaluate`` fanned out one task per (variant, problem, seed); the
  same records, appended to ``OUT/runs.jsonl`` as they arrive, which ``mtpcr experiment
  SUITE --report-only --out OUT`` turns into tables. From a shell::

      python -m mtpcr.distributed accuracy quality --out experiments/ --address auto

Both are resumable like ``mtpcr experiment``: with a results file, every result is appended
to it as one JSON line when it arrives, and a rerun skips the work already there. mtpcr is
deterministic for a given seed whatever the thread count, so Ray gives exactly the numbers of a
local run. Each task reserves ``num_threads`` Ray CPUs and runs mtpcr on as many threads.

Importing ``mtpcr`` does not import this module, and this module imports ``ray`` only when a
function needs it.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import os
import socket
import sys
import tempfile
import time
import traceback
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable, Union

import numpy as np

import mtpcr

__all__ = [
    "EvaluationError",
    "Failure",
    "Item",
    "RegistrationRecord",
    "evaluate",
    "main",
    "read_results",
    "register_batch",
    "register_scene",
    "SceneError",
]

PathType = Union[str, "os.PathLike[str]"]


# --------------------------------------------------------------------------------------------
# Plain results


@dataclass(eq=False)
class RegistrationRecord:
    """One registration as plain data (a picklable copy of :class:`mtpcr.Registration`).

    ``transforms`` (K, 4, 4) holds the edge transforms in edge order (``T12, T23, T31`` for
    three clouds, also readable as attributes: ``record.T12``); ``poses`` (N, 4, 4) maps every
    cloud into cloud 1's frame (NaN for a cloud not placed). ``seconds`` is the registration's
    own wall time, ``task_seconds`` the task's (conversions included), ``node`` the host that
    ran it. ``index`` is the item's position in the batch, ``key`` what resuming matches on.
    """

    index: int
    key: str
    name: str | None
    seed: int
    transforms: np.ndarray
    poses: np.ndarray
    edges: list
    unplaced: list
    loop_residual: float | None
    best_costs: dict
    task_names: tuple
    history: np.ndarray
    evaluations: int
    generations_run: int
    completed: bool
    seconds: float
    eps: float
    shift: float
    settings: dict
    node: str = ""
    task_seconds: float = 0.0

    @property
    def ok(self) -> bool:
        """True: a result (a :class:`Failure` has ``ok == False``)."""
        return True

    def __getattr__(self, name: str) -> np.ndarray:
        if name.startswith("T"):
            for k, edge in enumerate(self.__dict__.get("edges", ())):
                if edge.get("name") == name:
                    return self.transforms[k]
        raise AttributeError(f"{type(self).__name__} has no attribute {name!r}")

    @classmethod
    def from_registration(
        cls,
        result: mtpcr.Registration,
        *,
        index: int = 0,
        key: str = "",
        name: str | None = None,
    ) -> RegistrationRecord:
        """The plain copy of a :class:`mtpcr.Registration` (what a Ray task sends back)."""
        return cls(
            index=index,
            key=key,
            name=name,
            seed=int(result.seed),
            transforms=np.array(result.transforms, dtype=np.float64),
            poses=np.array(result.poses, dtype=np.float64),
            edges=[dict(e) for e in result.edges],
            unplaced=[dict(u) for u in result.unplaced],
            loop_residual=result.loop_residual,
            best_costs=dict(result.best_costs),
            task_names=tuple(result.task_names),
            history=np.array(result.history, dtype=np.float64),
            evaluations=int(result.evaluations),
            generations_run=int(result.generations_run),
            completed=bool(result.completed),
            seconds=float(result.seconds),
            eps=float(result.eps),
            shift=float(result.shift),
            settings=dict(result.settings),
        )

    def to_json(self) -> dict:
        """A JSON-ready dict (arrays as nested lists, non-finite numbers as null)."""
        out = {"ok": True}
        out.update({f.name: _jsonable(getattr(self, f.name)) for f in fields(self)})
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RegistrationRecord:
        """The inverse of :meth:`to_json` (the same numbers, bit for bit)."""
        names = {f.name for f in fields(cls)}
        values = {k: v for k, v in data.items() if k in names}
        tasks = tuple(values.get("task_names") or ())
        values["task_names"] = tasks
        values["transforms"] = _array(values["transforms"]).reshape(-1, 4, 4)
        values["poses"] = _array(values["poses"]).reshape(-1, 4, 4)
        values["history"] = _array(values["history"]).reshape(-1, max(len(tasks), 1))
        values["edges"] = [
            {**e, "t_target_source": _array(e["t_target_source"]).reshape(4, 4)}
            if "t_target_source" in e
            else dict(e)
            for e in values["edges"]
        ]
        values["best_costs"] = {
            k: (math.nan if v is None else v) for k, v in values["best_costs"].items()
        }
        return cls(**values)


@dataclass(eq=False)
class Failure:
    """An item that failed: ``error`` is the exception's type name (``ValueError`` for a bad
    cloud or setting, ``OSError`` for an unreadable file, a Ray error name when a worker
    died), ``message`` its text, ``traceback`` where it was raised (on the worker).
    :meth:`exception` rebuilds an exception to raise."""

    index: int
    key: str
    name: str | None
    seed: int | None
    error: str
    message: str
    traceback: str = ""
    node: str = ""

    @property
    def ok(self) -> bool:
        """False: no result."""
        return False

    def exception(self) -> Exception:
        """An exception of the original type when it is a builtin one, else RuntimeError."""
        import builtins

        kind = getattr(builtins, self.error, None)
        if not (isinstance(kind, type) and issubclass(kind, Exception)):
            kind = RuntimeError
        try:
            return kind(f"item {self.index} ({self.key}): {self.message}")
        except Exception:
            return RuntimeError(f"item {self.index} ({self.key}): {self.error}: {self.message}")

    @classmethod
    def of(
        cls,
        error: BaseException,
        *,
        index: int,
        key: str,
        name: str | None,
        seed: int | None,
        node: str = "",
    ) -> Failure:
        return cls(
            index=index,
            key=key,
            name=name,
            seed=seed,
            error=type(error).__name__,
            message=str(error),
            traceback="".join(traceback.format_exception(type(error), error, error.__traceback__)),
            node=node,
        )

    def to_json(self) -> dict:
        out = {"ok": False}
        out.update({f.name: _jsonable(getattr(self, f.name)) for f in fields(self)})
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Failure:
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})


Result = Union[RegistrationRecord, Failure]


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def _array(value: Any) -> np.ndarray:
    return np.array(value, dtype=np.float64)


# --------------------------------------------------------------------------------------------
# Batch input


@dataclass
class Item:
    """One registration of a batch: ``clouds`` (a sequence of (N, 3) arrays or objects with
    ``.points``, or the path of a problem file whose scans are read), its ``seed`` and
    ``settings`` (``Config`` fields over the batch's ``config``), and optionally the ``key``
    that resuming matches on (default: a digest of the clouds, settings and seed) and a
    ``name`` carried into the result (default: the problem's name for a problem file)."""

    clouds: Any
    seed: int | None = None
    settings: Mapping[str, Any] | None = None
    key: str | None = None
    name: str | None = None


def _as_item(entry: Any) -> Item:
    if isinstance(entry, Item):
        return entry
    if isinstance(entry, Mapping):
        unknown = set(entry) - {"clouds", "seed", "settings", "key", "name"}
        if unknown or "clouds" not in entry:
            raise TypeError(
                "an item given as a dict needs `clouds` and may have `seed`, `settings`, "
                f"`key`, `name`; got {sorted(entry)}"
            )
        return Item(**entry)
    return Item(clouds=entry)


def _settings_of(config: Any) -> dict:
    if config is None:
        return {}
    if isinstance(config, mtpcr.Config):
        return config.to_dict()
    if isinstance(config, Mapping):
        return dict(config)
    raise TypeError(f"config must be an mtpcr.Config or a dict, got {type(config).__name__}")


def _points(cloud: Any) -> np.ndarray:
    """The (N, 3) float64 array of a cloud (an array, a nested list or an object with
    ``.points``), as register() takes it."""
    if not isinstance(cloud, (np.ndarray, list, tuple)) and hasattr(cloud, "points"):
        cloud = cloud.points
    return np.ascontiguousarray(np.asarray(cloud, dtype=np.float64))


def _digest(arrays: Sequence[np.ndarray], settings: Mapping[str, Any]) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    canonical = {k: v for k, v in settings.items() if k != "num_threads"}
    h.update(json.dumps(_jsonable(canonical), sort_keys=True).encode())
    return "sha256:" + h.hexdigest()[:32]


def _node() -> str:
    """The host, and the Ray node's id (its first 8 digits) inside a Ray worker: several
    nodes may share a host."""
    name = socket.gethostname()
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        try:
            name += "/" + ray.get_runtime_context().get_node_id()[:8]
        except Exception:
            pass
    return name


# --------------------------------------------------------------------------------------------
# Results files


def _read_lines(path: Path, *, repair: bool) -> list[dict]:
    """The complete JSON lines of ``path`` (none when it does not exist). With ``repair``, a
    truncated last line (an interrupted write) is cut off, as ``mtpcr experiment`` does."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return []
    complete = text.rfind("\n") + 1
    if complete < len(text):
        if repair:
            with open(path, "r+b") as f:
                f.truncate(len(text[:complete].encode()))
        print(f"{path}: ignoring a truncated last line", file=sys.stderr)
    out = []
    for n, line in enumerate(text[:complete].splitlines(), start=1):
        if not line.strip():
            continue
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError as e:
            print(f"{path}:{n}: ignoring an unreadable line: {e}", file=sys.stderr)
    return out


def read_results(path: PathType) -> dict[str, Result]:
    """The results in a :func:`register_batch` results file, by key (the last line of a key
    wins, so a success written after a failure of the same item replaces it)."""
    out: dict[str, Result] = {}
    for data in _read_lines(Path(path), repair=False):
        try:
            record = (RegistrationRecord if data.get("ok") else Failure).from_json(data)
        except (KeyError, TypeError, ValueError) as e:
            print(f"{path}: ignoring a line that is no result: {e}", file=sys.stderr)
            continue
        out[record.key] = record
    return out


class _Appender:
    """Appends JSON lines to a file, flushed one by one (or does nothing without a path)."""

    def __init__(self, path: Path | None):
        self.file = None
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.file = open(path, "a", encoding="utf-8")

    def write(self, data: dict) -> None:
        if self.file is not None:
            self.file.write(json.dumps(data, allow_nan=False) + "\n")
            self.file.flush()

    def close(self) -> None:
        if self.file is not None:
            self.file.close()


# --------------------------------------------------------------------------------------------
# Ray plumbing


def _import_ray():
    try:
        import ray
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            'mtpcr.distributed needs Ray: pip install "mtpcr[ray]" (or pip install ray)'
        ) from e
    return ray


def _connect(address: str | None):
    """Ray, initialised: an existing connection is kept; else ``ray.init(address=address)``
    (None: ``RAY_ADDRESS`` or a new local instance; ``"auto"``: the cluster this machine
    belongs to)."""
    ray = _import_ray()
    if not ray.is_initialized():
        ray.init(address=address)
    return ray


_REMOTES: dict[str, Any] = {}


def _remote(name: str):
    """The Ray remote function of a module-level task function (made once per process)."""
    if name not in _REMOTES:
        ray = _import_ray()
        _REMOTES[name] = ray.remote(globals()[name])
    return _REMOTES[name]


def _register_task(
    index: int,
    key: str,
    name: str | None,
    settings: dict,
    num_threads: int,
    *clouds: np.ndarray,
) -> Result:
    """A Ray task: one registration, returned as plain data (never raises)."""
    start = time.perf_counter()
    try:
        result = mtpcr.register(*clouds, **{**settings, "num_threads": num_threads})
        record = RegistrationRecord.from_registration(result, index=index, key=key, name=name)
    except Exception as e:
        return Failure.of(
            e, index=index, key=key, name=name, seed=settings.get("seed"), node=_node()
        )
    record.node = _node()
    record.task_seconds = time.perf_counter() - start
    return record


class _Progress:
    def __init__(self, total: int, enabled: bool, what: str):
        self.total, self.enabled, self.what, self.done = total, enabled, what, 0
        self.start = time.perf_counter()

    def step(self, text: str) -> None:
        self.done += 1
        if self.enabled:
            print(f"[{self.done}/{self.total}] {text}", file=sys.stderr, flush=True)

    def note(self, text: str) -> None:
        if self.enabled:
            print(f"{self.what}: {text}", file=sys.stderr, flush=True)


def _drain(ray, pending: dict, on_ready: Callable[[Any, Any], None]) -> None:
    """Waits for every task of ``pending`` (ref -> tag), calling ``on_ready(tag, value)`` as
    each arrives (``value`` the exception when ``ray.get`` raised). On Ctrl-C the tasks not
    done yet are cancelled; on any other error they are left to finish (their results
    dropped): cancelling a task that is just completing aborts the driver inside Ray ("Check
    failed: it != submissible_tasks_.end()", ray-project/ray#54846; it killed this module's
    scene test once in CI with Ray 2.60), and a failed scene must not take the caller's
    process with it."""
    try:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            ready, _ = ray.wait(list(pending), num_returns=len(pending), timeout=0)
            for ref in ready:
                tag = pending.pop(ref)
                try:
                    value = ray.get(ref)
                except Exception as e:  # a worker that died, a cancelled task, ...
                    value = e
                on_ready(tag, value)
    except KeyboardInterrupt:
        for ref in pending:
            try:
                ray.cancel(ref)
            except Exception:
                pass
        raise


# --------------------------------------------------------------------------------------------
# register_batch


def register_batch(
    items: Iterable[Any],
    *,
    config: Any = None,
    num_threads: int = 1,
    results: PathType | None = None,
    on_result: Callable[[Result, int, int], Any] | None = None,
    progress: bool = True,
    data_root: PathType | None = None,
    address: str | None = None,
) -> list[Result]:
    """Runs many registrations on Ray; returns one result per item, in the items' order.

    ``items``: each a sequence of clouds ((N, 3) arrays, nested lists or objects with
    ``.points``), the path of a problem file (its scans are read here, with ``data_root``), a
    dict with the fields of :class:`Item`, or an :class:`Item`. ``config`` (an
    :class:`mtpcr.Config` or a dict of its fields) is the base setting of every item; an item's
    ``settings`` and ``seed`` go over it. ``num_threads``: threads of each registration and
    Ray CPUs each task reserves.

    Each slot holds a :class:`RegistrationRecord` or, when that item failed (a bad cloud or
    setting, an unreadable file, a worker that died), a :class:`Failure`; the other items
    are not affected. ``results``: a JSON-lines file each result is appended to as it
    arrives; items whose key is already there as a success are not run again (failures are
    retried). ``on_result(result, done, total)`` is called as results arrive (an exception
    in it propagates; what is still running finishes and is dropped, while Ctrl-C cancels
    it); ``progress`` prints a count to stderr. ``address``: the Ray cluster (see
    :func:`ray.init`), used only when Ray is not initialised yet.
    """
    if not isinstance(num_threads, int) or num_threads < 1:
        raise ValueError(f"num_threads must be an integer of at least 1, got {num_threads!r}")
    base = _settings_of(config)
    base.pop("num_threads", None)
    entries = [_as_item(e) for e in items]
    total = len(entries)
    out: list[Result | None] = [None] * total
    path = Path(results) if results is not None else None
    done: dict[str, Result] = {}
    if path is not None:
        _read_lines(path, repair=True)
        done = read_results(path)

    # Prepare every item here: clouds as float64 arrays (a problem file read once), settings
    # checked, the key. An item that cannot be prepared fails in its own slot.
    files: dict[str, tuple[str, list[np.ndarray]]] = {}
    arrays: dict[int, tuple[Any, np.ndarray]] = {}  # id(cloud) -> (cloud kept alive, array)
    work = []  # (index, key, name, settings, [arrays])
    for index, item in enumerate(entries):
        settings = {**base, **dict(item.settings or {})}
        if item.seed is not None:
            settings["seed"] = item.seed
        settings.pop("num_threads", None)
        name = item.name
        key = item.key or f"item-{index}"
        try:
            if isinstance(item.clouds, (str, os.PathLike)):
                source = os.fspath(item.clouds)
                if source not in files:
                    problem = mtpcr.load_problem(source, data_root)
                    scans = [np.ascontiguousarray(s) for s in problem.read_scans()]
                    files[source] = (problem.name, scans)
                problem_name, clouds = files[source]
                name = name if name is not None else problem_name
            else:
                clouds = []
                for cloud in item.clouds:
                    if id(cloud) not in arrays:
                        arrays[id(cloud)] = (cloud, _points(cloud))
                    clouds.append(arrays[id(cloud)][1])
            canonical = mtpcr.Config(**settings).to_dict()
            if item.key is None:
                key = _digest(clouds, canonical)
        except Exception as e:
            out[index] = Failure.of(e, index=index, key=key, name=name, seed=item.seed)
            continue
        work.append((index, key, name, settings, clouds))

    bar = _Progress(total, progress, "register_batch")
    appender = _Appender(path)
    try:
        for index in range(total):
            if out[index] is not None:  # failed while preparing
                appender.write(out[index].to_json())
                bar.step(f"item {index}: FAIL {out[index].error}: {out[index].message}")
                if on_result is not None:
                    on_result(out[index], bar.done, total)
        todo = []
        for index, key, name, settings, clouds in work:
            previous = done.get(key)
            if previous is not None and previous.ok:
                out[index] = dataclasses.replace(previous, index=index)
                bar.done += 1
            else:
                todo.append((index, key, name, settings, clouds))
        bar.note(
            f"{total} items, {total - len(todo)} done already"
            + (f" (in {path})" if path is not None else "")
            + f", {len(todo)} to run"
        )
        if todo:
            ray = _connect(address)
            task = _remote("_register_task").options(num_cpus=num_threads)
            refs: dict[int, Any] = {}  # id(array) -> ObjectRef: every cloud put once
            pending = {}
            for index, key, name, settings, clouds in todo:
                cloud_refs = []
                for cloud in clouds:
                    if id(cloud) not in refs:
                        refs[id(cloud)] = ray.put(cloud)
                    cloud_refs.append(refs[id(cloud)])
                ref = task.remote(index, key, name, settings, num_threads, *cloud_refs)
                pending[ref] = (index, key, name, settings.get("seed"))

            def arrived(tag, value):
                index, key, name, seed = tag
                if isinstance(value, BaseException):
                    value = Failure.of(value, index=index, key=key, name=name, seed=seed)
                out[index] = value
                appender.write(value.to_json())
                if value.ok:
                    bar.step(
                        f"item {index}{f' {name}' if name else ''} seed {value.seed}: ok, "
                        f"{value.seconds:.2f} s on {value.node}"
                    )
                else:
                    bar.step(f"item {index}: FAIL {value.error}: {value.message}")
                if on_result is not None:
                    on_result(value, bar.done, total)

            _drain(ray, pending, arrived)
    finally:
        appender.close()
    return out  # type: ignore[return-value]


# --------------------------------------------------------------------------------------------
# register_scene


class SceneError(RuntimeError):
    """A screening task of :func:`register_scene` failed (its :class:`Failure` is
    ``failure``); nothing was registered."""

    def __init__(self, failure: Failure):
        super().__init__(f"a pair screening task failed: {failure.error}: {failure.message}")
        self.failure = failure


def _screen_task(
    index: int,
    pairs: list[tuple[int, int]],
    settings: dict,
    viewpoints: Any,
    num_threads: int,
    *clouds: np.ndarray,
) -> dict | Failure:
    """A Ray task: the screening of some pairs of a scene, plain data (never raises)."""
    start = time.perf_counter()
    try:
        screening = mtpcr.screen_pairs(
            *clouds,
            pairs=pairs,
            viewpoints=viewpoints,
            **{**settings, "num_threads": num_threads},
        )
    except Exception as e:
        return Failure.of(
            e,
            index=index,
            key=f"screening-{index}",
            name=None,
            seed=settings.get("seed"),
            node=_node(),
        )
    screening["node"] = _node()
    screening["task_seconds"] = time.perf_counter() - start
    return screening


def register_scene(
    clouds: Sequence[Any],
    *,
    seed: int | None = None,
    config: Any = None,
    viewpoints: Any = None,
    tasks: int | None = None,
    num_threads: int = 1,
    on_task: Callable[[dict], Any] | None = None,
    progress: bool = True,
    address: str | None = None,
) -> mtpcr.Registration:
    """Registers the scans of a whole scene (four or more, in no known order: the fragments of
    a room) with the pair screening, most of the time of a room, spread over Ray.

    The pairs are dealt round-robin to ``tasks`` Ray tasks (default: as many as the cluster
    has CPUs for tasks of ``num_threads`` threads, spread over its nodes); each prepares the
    clouds and screens its pairs (:func:`mtpcr.screen_pairs`); this process then registers
    with their screenings (``mtpcr.register(*clouds, screening=...)``). The result is exactly
    ``mtpcr.register(*clouds, seed=seed, config=config, viewpoints=viewpoints)``'s, bit for
    bit, whatever the cluster. ``seed``: drawn when None and reported as
    ``Registration.seed``. ``config``: an :class:`mtpcr.Config` or a dict of its fields (its
    ``num_threads`` is used for the final registration here). ``on_task(info)`` is called as
    each task's screening arrives (``info``: ``task``, ``tasks``, ``pairs`` screened so far,
    ``total`` pairs, ``node``, ``seconds``); ``progress`` prints the same to stderr.
    ``address`` as for :func:`register_batch`.

    Each task prepares every cloud (the screening depends on all of them), which costs a few
    seconds a task on a room: more tasks balance the load better but repeat that work.
    Raises :class:`SceneError` when a task fails, ``ValueError`` for bad clouds or settings.
    """
    if not isinstance(num_threads, int) or num_threads < 1:
        raise ValueError(f"num_threads must be an integer of at least 1, got {num_threads!r}")
    if tasks is not None and (not isinstance(tasks, int) or tasks < 1):
        raise ValueError(f"tasks must be None or an integer of at least 1, got {tasks!r}")
    arrays = [_points(c) for c in clouds]
    if len(arrays) < 4:
        raise ValueError(
            f"register_scene is for four or more scans in no known order, got {len(arrays)} "
            "(use mtpcr.register)"
        )
    settings = _settings_of(config)
    if seed is None:
        seed = settings.get("seed")
    if seed is None:
        seed = int.from_bytes(os.urandom(8), "little")
    settings["seed"] = seed
    final_threads = settings.pop("num_threads", None)
    if settings.get("order", "auto") != "auto":
        raise ValueError('register_scene needs order "auto" (scans in no known order)')
    mtpcr.Config(**settings)  # bad settings fail here, before any task starts
    n = len(arrays)
    pairs = [(s, t) for s in range(n) for t in range(s + 1, n)]

    ray = _connect(address)
    if tasks is None:
        cpus = int(ray.cluster_resources().get("CPU", 1))
        tasks = max(1, cpus // num_threads)
    tasks = min(tasks, len(pairs))
    task = _remote("_screen_task").options(num_cpus=num_threads, scheduling_strategy="SPREAD")
    refs = [ray.put(a) for a in arrays]
    pending = {}
    for k in range(tasks):
        chunk = pairs[k::tasks]
        ref = task.remote(k, chunk, settings, viewpoints, num_threads, *refs)
        pending[ref] = (k, len(chunk))
    parts: list[dict | None] = [None] * tasks
    bar = _Progress(tasks, progress, "register_scene")
    bar.note(f"{n} scans, {len(pairs)} pairs screened in {tasks} tasks")
    screened = 0

    def arrived(tag, value):
        nonlocal screened
        k, count = tag
        if isinstance(value, BaseException):
            value = Failure.of(value, index=k, key=f"screening-{k}", name=None, seed=seed)
        if isinstance(value, Failure):
            raise SceneError(value)
        parts[k] = value
        screened += count
        info = {
            "task": k,
            "tasks": tasks,
            "pairs": screened,
            "total": len(pairs),
            "node": value["node"],
            "seconds": value["task_seconds"],
        }
        bar.step(f"{screened}/{len(pairs)} pairs, {info['seconds']:.1f} s on {info['node']}")
        if on_task is not None:
            on_task(info)

    _drain(ray, pending, arrived)
    if final_threads is not None:
        settings["num_threads"] = final_threads
    return mtpcr.register(*arrays, viewpoints=viewpoints, screening=parts, **settings)


# --------------------------------------------------------------------------------------------
# evaluate


class EvaluationError(RuntimeError):
    """Some runs of :func:`evaluate` failed: ``records`` holds the runs that succeeded (also
    in runs.jsonl), ``failures`` one :class:`Failure` per failed run."""

    def __init__(self, records: list, failures: list):
        self.records, self.failures = records, failures
        first = failures[0]
        super().__init__(
            f"{len(failures)} of {len(records) + len(failures)} runs failed; first: "
            f"{first.key}: {first.error}: {first.message}"
        )


@dataclass
class _ProblemPayload:
    """A problem file and its scan files, as bytes: what a worker needs to run it anywhere."""

    name: str
    digest: str
    problem: dict  # the problem file's JSON, scans renamed to the keys of `files`
    files: dict = field(default_factory=dict)  # file name -> bytes


def _pack_problem(path: PathType, data_root: PathType | None) -> _ProblemPayload:
    problem = mtpcr.load_problem(path, data_root)
    data = json.loads(Path(path).read_text())
    files = {}
    h = hashlib.sha256()
    for k, scan in enumerate(problem.scans):
        content = Path(scan).read_bytes()
        local = f"{k}-{Path(scan).name}"
        files[local] = content
        h.update(local.encode() + b"\0" + hashlib.sha256(content).digest())
    data["scans"] = list(files)
    h.update(json.dumps(data, sort_keys=True).encode())
    return _ProblemPayload(name=problem.name, digest=h.hexdigest()[:32], problem=data, files=files)


_MATERIALIZED: dict[str, str] = {}


def _materialize(digest: str, box: list) -> str:
    """The local path of a problem file written from its payload (``box[0]``, an ObjectRef
    fetched only when this node has not written it yet), under the temporary folder."""
    if digest in _MATERIALIZED and Path(_MATERIALIZED[digest]).is_file():
        return _MATERIALIZED[digest]
    root = Path(tempfile.gettempdir()) / "mtpcr-ray-problems"
    folder = root / digest
    target = folder / "problem.json"
    if not target.is_file():
        import ray

        payload: _ProblemPayload = ray.get(box[0])
        root.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(dir=root, prefix=f".{digest}-"))
        for local, content in payload.files.items():
            (staging / local).write_bytes(content)
        problem = dict(payload.problem)
        problem["scans"] = [str(folder / local) for local in payload.files]
        (staging / "problem.json").write_text(json.dumps(problem))
        try:
            os.rename(staging, folder)
        except OSError:  # another worker of this node wrote it first
            for f in staging.iterdir():
                f.unlink()
            staging.rmdir()
    _MATERIALIZED[digest] = str(target)
    return str(target)


def _evaluate_task(
    suite: str, variant: str, seed: int, generations: int | None, digest: str, box: list
) -> Any:
    """A Ray task: one run of the protocol (``mtpcr.evaluate`` of one variant, problem and
    seed); returns its record, or a Failure (never raises)."""
    key = f"{suite} {variant} seed {seed}"
    try:
        path = _materialize(digest, box)
        records = mtpcr.evaluate(
            suite, [path], seeds=[seed], variants=[variant], generations=generations
        )
        return records[0]
    except Exception as e:
        return Failure.of(e, index=-1, key=key, name=None, seed=seed, node=_node())


def _run_key(record: Mapping[str, Any]) -> tuple:
    return (record["suite"], record["variant"], record["problem"], int(record["seed"]))


def _plan(
    suite: str,
    payloads: Sequence[_ProblemPayload],
    *,
    runs: int | None,
    seeds: Sequence[int] | None,
    variants: Sequence[str] | None,
    paper_problems_only: bool = False,
) -> list[tuple]:
    """The runs of a suite in ``mtpcr.evaluate``'s order (variant, problem, seed):
    (suite, variant, problem index, seed)."""
    info = mtpcr.describe_suite(suite)
    keys = [v["key"] for v in info["variants"]]
    if variants is not None:
        for k in variants:
            if k not in keys:
                raise ValueError(
                    f"suite {info['name']} has no variant `{k}` (variants: {', '.join(keys)})"
                )
        keys = [k for k in keys if k in variants]
    if runs is not None and runs < 1:
        raise ValueError("runs must be at least 1")
    if seeds is None:
        seeds = range(runs if runs is not None else info["default_runs"])
    chosen = range(len(payloads))
    if paper_problems_only and info["paper_problems"] is not None:
        chosen = [i for i in chosen if payloads[i].name in info["paper_problems"]]
    return [(info["name"], v, p, int(s)) for v in keys for p in chosen for s in seeds]


def _run_plan(
    plan: list[tuple],
    payloads: Sequence[_ProblemPayload],
    *,
    generations: int | None,
    out: PathType | None,
    on_run: Callable[[dict], Any] | None,
    progress: bool,
    address: str | None,
) -> list[dict]:
    path = Path(out) / "runs.jsonl" if out is not None else None
    stored: dict[tuple, dict] = {}
    if path is not None:
        for record in _read_lines(path, repair=True):
            try:
                stored[_run_key(record)] = record
            except (KeyError, TypeError, ValueError):
                continue
    keys = [(s, v, payloads[p].name, seed) for s, v, p, seed in plan]
    results: dict[tuple, dict] = {k: stored[k] for k in keys if k in stored}
    todo = [(entry, k) for entry, k in zip(plan, keys) if k not in results]
    bar = _Progress(len(set(keys)), progress, "evaluate")
    bar.done = len(results)
    bar.note(
        f"{len(set(keys))} runs planned, {len(results)} already"
        + (f" in {path}" if path is not None else "")
        + f", {len(todo)} to do"
    )
    failures: list[Failure] = []
    if todo:
        ray = _connect(address)
        task = _remote("_evaluate_task").options(num_cpus=1)
        boxes = {}
        pending = {}
        for (suite, variant, p, seed), k in todo:
            if p not in boxes:
                boxes[p] = [ray.put(payloads[p])]  # each problem's files put once
            ref = task.remote(suite, variant, seed, generations, payloads[p].digest, boxes[p])
            pending[ref] = k
        appender = _Appender(path)

        def arrived(k, value):
            suite, variant, name, seed = k
            label = f"{suite} {variant} {name} seed {seed}"
            if isinstance(value, BaseException):
                value = Failure.of(value, index=-1, key=label, name=name, seed=seed)
            if isinstance(value, Failure):
                value.key, value.name = label, name
                failures.append(value)
                bar.step(f"{label}: FAIL {value.error}: {value.message}")
                return
            results[k] = value
            appender.write(value)
            bar.step(
                f"{label}: {'ok  ' if value['success'] else 'FAIL'} Err_R x1000 "
                f"{value['err_r'] * 1000:.2f}, {value['seconds']:.1f} s"
            )
            if on_run is not None:
                on_run(value)

        try:
            _drain(ray, pending, arrived)
        finally:
            appender.close()
    records = []
    seen = set()
    for k in keys:
        if k in results and k not in seen:
            seen.add(k)
            records.append(results[k])
    if failures:
        raise EvaluationError(records, failures)
    return records


def evaluate(
    suite: str,
    problems: Sequence[PathType],
    *,
    runs: int | None = None,
    seeds: Sequence[int] | None = None,
    variants: Sequence[str] | None = None,
    generations: int | None = None,
    data_root: PathType | None = None,
    out: PathType | None = None,
    on_run: Callable[[dict], Any] | None = None,
    progress: bool = True,
    address: str | None = None,
) -> list[dict]:
    """:func:`mtpcr.evaluate` on Ray: one task (one CPU) per (variant, problem, seed); the
    same records in the same order (variant, problem, seed), only ``seconds`` differs.

    The problem files and their scans are read here and put in Ray's object store once per
    problem; each node writes them to its temporary folder when it first needs them, so the
    nodes need no shared file system. ``out``: a folder whose ``runs.jsonl`` gets each record
    as it arrives (the format of ``mtpcr experiment``; ``mtpcr experiment SUITE --report-only
    --out OUT`` writes the tables); runs already there are not run again and their stored
    records are returned. ``on_run(record)`` is called as records arrive. Runs that fail
    raise :class:`EvaluationError` once all others are done (their records kept).
    """
    payloads = [_pack_problem(p, data_root) for p in problems]
    plan = _plan(suite, payloads, runs=runs, seeds=seeds, variants=variants)
    return _run_plan(
        plan,
        payloads,
        generations=generations,
        out=out,
        on_run=on_run,
        progress=progress,
        address=address,
    )


# --------------------------------------------------------------------------------------------
# python -m mtpcr.distributed


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m mtpcr.distributed SUITE... --out DIR``: ``mtpcr experiment`` on Ray."""
    parser = argparse.ArgumentParser(
        prog="python -m mtpcr.distributed",
        description=(
            "Runs experiment suites of mtpcr on Ray, one task per run, appending the records "
            "to DIR/runs.jsonl (resumable; the format of `mtpcr experiment`). Then "
            "`mtpcr experiment SUITE... --report-only --out DIR` (same --problems and --runs) "
            "writes RESULTS.md."
        ),
    )
    parser.add_argument(
        "suites", nargs="+", metavar="SUITE", help="accuracy, quality, noise, alpha, ..."
    )
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--runs", type=int, metavar="N", help="seeds 0..N per problem and variant")
    parser.add_argument(
        "--problems",
        nargs="+",
        metavar="FILE",
        help="problem files (default: the shared data's problems/*.json)",
    )
    parser.add_argument("--data-root", metavar="DIR", help="folder scan paths are relative to")
    parser.add_argument("--generations", type=int, metavar="G", help="override generations")
    parser.add_argument("--variants", nargs="+", metavar="KEY", help="only these variants")
    parser.add_argument(
        "--address",
        metavar="ADDR",
        help='Ray cluster ("auto": the one this machine belongs to; default: RAY_ADDRESS '
        "or a new local instance)",
    )
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    args = parser.parse_args(argv)

    if args.problems:
        files = list(args.problems)
    else:
        shared = mtpcr.find_shared_dir()
        if shared is None:
            parser.error("no shared data found; pass --problems FILE...")
        files = sorted(str(p) for p in (Path(shared) / "problems").glob("*.json"))
    try:
        payloads = [_pack_problem(f, args.data_root) for f in files]
        plan = []
        known = set()
        for suite in dict.fromkeys(args.suites):
            keys = [v["key"] for v in mtpcr.describe_suite(suite)["variants"]]
            known.update(keys)
            chosen = [k for k in keys if k in args.variants] if args.variants else None
            if chosen == []:
                continue
            plan += _plan(
                suite,
                payloads,
                runs=args.runs,
                seeds=None,
                variants=chosen,
                paper_problems_only=not args.problems,
            )
        unknown = sorted(set(args.variants or ()) - known)
        if unknown:
            parser.error(f"no variant {', '.join(unknown)} in {', '.join(args.suites)}")
        records = _run_plan(
            plan,
            payloads,
            generations=args.generations,
            out=args.out,
            on_run=None,
            progress=not args.quiet,
            address=args.address,
        )
    except EvaluationError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except (ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    report = ["mtpcr", "experiment", *dict.fromkeys(args.suites), "--report-only"]
    report += ["--out", args.out]
    if args.problems:
        report += ["--problems", *args.problems]
    if args.runs:
        report += ["--runs", str(args.runs)]
    if args.data_root:
        report += ["--data-root", args.data_root]
    print(f"{len(records)} records in {Path(args.out) / 'runs.jsonl'}")
    print("tables: " + " ".join(report))
    return 0


if __name__ == "__main__":
    # Run as `python -m mtpcr.distributed`: use the module imported under its own name, so
    # that Ray workers find the task functions and result classes at mtpcr.distributed.
    from mtpcr.distributed import main as _main

    sys.exit(_main())
