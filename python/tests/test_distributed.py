"""``mtpcr.distributed`` on a local Ray instance: batches give exactly the local results, a
failing item fails alone, results files resume, and ``evaluate`` gives ``mtpcr.evaluate``'s
records in a runs.jsonl that ``mtpcr experiment --report-only`` reads.

Marked ``ray`` (``pytest -m ray`` runs just these); skipped when Ray is not installed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mtpcr

from conftest import REPO_ROOT, three_views

# No usage report to Ray's servers, from this process or the workers it starts; and a
# single-node instance on 127.0.0.1 (else Ray binds and connects to the machine's address).
# Read when ray is imported.
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'mtpcr[ray]')")

from mtpcr import distributed  # noqa: E402

pytestmark = pytest.mark.ray

#: One short evolution: these tests check plumbing, not accuracy.
SMALL = {
    "population_size": 12,
    "generations": 4,
    "restarts": 1,
    "refine_iterations": 0,
    "hypotheses": 0,
}


@pytest.fixture(scope="module", autouse=True)
def ray_session():
    """One local Ray instance (two CPUs, on 127.0.0.1) for the whole module."""
    if ray.is_initialized():
        ray.shutdown()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def scan_sets() -> list[tuple[np.ndarray, ...]]:
    return [three_views(seed=s, points_per_view=600).clouds for s in (11, 12, 13)]


def local(clouds, seed, **settings) -> distributed.RegistrationRecord:
    return distributed.RegistrationRecord.from_registration(
        mtpcr.register(*clouds, seed=seed, **{**SMALL, **settings})
    )


def assert_same(record, expected) -> None:
    assert record.ok, f"{record.error}: {record.message}"
    assert record.seed == expected.seed
    assert np.array_equal(record.transforms, expected.transforms)
    assert np.array_equal(record.poses, expected.poses, equal_nan=True)
    assert np.array_equal(record.history, expected.history)
    assert record.best_costs == expected.best_costs
    assert record.task_names == expected.task_names
    assert record.evaluations == expected.evaluations


def test_importing_mtpcr_does_not_import_ray():
    code = (
        "import sys, mtpcr; assert 'ray' not in sys.modules; "
        "import mtpcr.distributed; assert 'ray' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_a_batch_gives_the_local_results_bit_for_bit(scan_sets):
    a, b, c = scan_sets[0]
    items = [
        scan_sets[0],
        distributed.Item(scan_sets[1], seed=4),
        {"clouds": scan_sets[2], "seed": 5, "settings": {"generations": 3}},
        distributed.Item([a, b], seed=6),  # a pair; the same arrays, put once
        distributed.Item(scan_sets[0], seed=8, settings={"method": "mfea"}),
    ]
    seen = []
    results = distributed.register_batch(
        items,
        config=SMALL,
        num_threads=1,
        on_result=lambda r, done, total: seen.append((r.index, done, total)),
        progress=False,
    )
    assert [r.index for r in results] == [0, 1, 2, 3, 4]
    assert sorted(i for i, _, _ in seen) == [0, 1, 2, 3, 4]
    assert [d for _, d, _ in seen] == [1, 2, 3, 4, 5]
    assert {t for _, _, t in seen} == {5}
    # Item 0 had no seed: the drawn one reproduces it.
    assert_same(results[0], local(scan_sets[0], results[0].seed))
    assert_same(results[1], local(scan_sets[1], 4))
    assert_same(results[2], local(scan_sets[2], 5, generations=3))
    assert_same(results[3], local([a, b], 6))
    assert_same(results[4], local(scan_sets[0], 8, method="mfea"))
    assert results[1].T12.shape == (4, 4)
    assert np.array_equal(results[1].T31, results[1].transforms[2])
    assert results[3].settings["num_threads"] == 1
    assert results[1].node and results[1].task_seconds >= results[1].seconds * 0.5
    # Plain data: pickles, and survives its JSON form bit for bit.
    import pickle

    again = pickle.loads(pickle.dumps(results[1]))
    assert_same(again, results[1])
    via_json = distributed.RegistrationRecord.from_json(
        json.loads(json.dumps(results[1].to_json()))
    )
    assert_same(via_json, results[1])
    assert np.array_equal(via_json.edges[0]["t_target_source"], results[1].T12)


def test_two_threads_per_task_give_the_same_result(scan_sets):
    (result,) = distributed.register_batch(
        [distributed.Item(scan_sets[1], seed=4)], config=SMALL, num_threads=2, progress=False
    )
    assert result.settings["num_threads"] == 2
    assert_same(result, local(scan_sets[1], 4))


def test_a_failing_item_leaves_the_others_intact(scan_sets):
    nan = scan_sets[0][0].copy()
    nan[7, 1] = np.nan
    tiny = scan_sets[0][1][:3]
    items = [
        distributed.Item(scan_sets[0], seed=1),
        distributed.Item((nan, scan_sets[0][1], scan_sets[0][2]), seed=1),  # fails in the task
        distributed.Item((scan_sets[0][0], tiny), seed=1),  # too few points
        distributed.Item(scan_sets[1], seed=1, settings={"population_size": 1}),  # bad setting
        distributed.Item(scan_sets[1], seed=2, settings={"no_such_setting": 1}),
        distributed.Item([scan_sets[0][0], [[1.0, 2.0]]], seed=1),  # not (N, 3)
        distributed.Item(scan_sets[2], seed=1),
    ]
    results = distributed.register_batch(items, config=SMALL, progress=False)
    assert [r.ok for r in results] == [True, False, False, False, False, False, True]
    assert (results[1].error, results[1].index) == ("ValueError", 1)
    assert "non-finite" in results[1].message
    assert "cloud1" in results[1].message
    assert results[2].error == "ValueError" and "cloud2" in results[2].message
    assert results[3].error == "ValueError" and "population_size" in results[3].message
    assert results[4].error == "TypeError"
    assert results[5].error == "ValueError"
    assert isinstance(results[1].exception(), ValueError)
    assert_same(results[0], local(scan_sets[0], 1))
    assert_same(results[6], local(scan_sets[2], 1))


def test_a_results_file_resumes(scan_sets, tmp_path):
    path = tmp_path / "batch.jsonl"
    nan = scan_sets[1][0].copy()
    nan[0, 0] = np.nan
    first = [
        distributed.Item(scan_sets[0], seed=1),
        distributed.Item(scan_sets[1], seed=2, key="line-2"),
        distributed.Item((nan, scan_sets[1][1], scan_sets[1][2]), seed=3),
    ]
    results = distributed.register_batch(first, config=SMALL, results=path, progress=False)
    lines = [json.loads(x) for x in path.read_text().splitlines()]
    assert [x["ok"] for x in lines].count(True) == 2 and len(lines) == 3
    assert results[1].key == "line-2"
    # An interrupted write leaves half a line: it is cut off.
    with open(path, "a") as f:
        f.write('{"ok": true, "key": "half')
    calls = []
    second = [first[2], distributed.Item(scan_sets[2], seed=4), *first[:2], first[0]]
    again = distributed.register_batch(
        second,
        config=SMALL,
        results=path,
        progress=False,
        on_result=lambda r, done, total: calls.append(r.index),
    )
    # Only the new item and the failed one ran again; the others came from the file.
    assert sorted(calls) == [0, 1]
    assert [r.ok for r in again] == [False, True, True, True, True]
    assert [r.index for r in again] == [0, 1, 2, 3, 4]
    assert_same(again[2], results[0])
    assert_same(again[4], results[0])
    assert_same(again[3], results[1])
    assert_same(again[1], local(scan_sets[2], 4))
    stored = distributed.read_results(path)
    assert len(stored) == 4 and stored["line-2"].ok
    assert all(line.endswith("}") for line in path.read_text().splitlines())
    # Other settings are other work: a different key.
    (other,) = distributed.register_batch(
        [first[0]], config={**SMALL, "generations": 3}, results=path, progress=False
    )
    assert other.key != results[0].key and other.history.shape[0] == 4


def test_problem_files_as_items(problem_file):
    results = distributed.register_batch(
        [distributed.Item(problem_file, seed=s) for s in (1, 2)] + [str(problem_file)],
        config=SMALL,
        progress=False,
    )
    scans = mtpcr.load_problem(problem_file).read_scans()
    assert [r.name for r in results] == ["synthetic"] * 3
    assert_same(results[0], local(scans, 1))
    assert_same(results[1], local(scans, 2))
    assert results[2].ok
    (missing,) = distributed.register_batch([str(problem_file) + ".nope"], progress=False)
    assert isinstance(missing.exception(), OSError), missing.error


def without_seconds(record: dict) -> dict:
    return {k: v for k, v in record.items() if k != "seconds"}


def test_evaluate_gives_the_records_of_mtpcr_evaluate(problem_file, tmp_path):
    kwargs = {"seeds": [0, 1], "variants": ["mtpcr-paper"], "generations": 2}
    expected = mtpcr.evaluate("accuracy", [problem_file], **kwargs)
    arrived = []
    records = distributed.evaluate(
        "accuracy", [problem_file], out=tmp_path, progress=False, on_run=arrived.append, **kwargs
    )
    assert len(arrived) == 2
    assert [without_seconds(r) for r in records] == [without_seconds(r) for r in expected]
    lines = [json.loads(x) for x in (tmp_path / "runs.jsonl").read_text().splitlines()]
    assert sorted(r["seed"] for r in lines) == [0, 1]
    # A rerun runs nothing and returns the stored records; a new seed runs alone.
    arrived.clear()
    again = distributed.evaluate(
        "accuracy",
        [problem_file],
        out=tmp_path,
        progress=False,
        on_run=arrived.append,
        **{**kwargs, "seeds": [0, 1, 2]},
    )
    assert [r["seed"] for r in arrived] == [2]
    assert [without_seconds(r) for r in again[:2]] == [without_seconds(r) for r in expected]
    with pytest.raises(ValueError, match="no variant `fast`"):
        distributed.evaluate("accuracy", [problem_file], variants=["fast"], progress=False)

    binary = Path(os.environ.get("MTPCR_BIN", REPO_ROOT / "target" / "release" / "mtpcr"))
    if binary.is_file():
        subprocess.run(
            [str(binary), "experiment", "accuracy", "--report-only", "--out", str(tmp_path)]
            + ["--problems", str(problem_file), "--runs", "3", "--quiet"],
            check=True,
        )
        report = (tmp_path / "RESULTS.md").read_text()
        assert "MTPCR (paper)" in report


def test_the_module_runs_the_suites(problem_file, tmp_path, capsys):
    code = distributed.main(
        ["accuracy", "--problems", str(problem_file), "--runs", "1", "--generations", "1"]
        + ["--variants", "mtpcr-paper", "--out", str(tmp_path), "--quiet"]
    )
    assert code == 0
    (line,) = (tmp_path / "runs.jsonl").read_text().splitlines()
    assert json.loads(line)["variant"] == "mtpcr-paper"
    assert "--report-only" in capsys.readouterr().out
    help_text = subprocess.run(
        [sys.executable, "-m", "mtpcr.distributed", "--help"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    assert "runs.jsonl" in help_text
