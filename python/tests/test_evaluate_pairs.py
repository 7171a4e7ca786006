"""``mtpcr.evaluate_pairs`` runs the pairs of a 3DMatch-layout benchmark as ``mtpcr eval FOLDER``
does: the same records (only the run time differs) and a summary consistent with them.

The real-data tests use ``shared/data/3dmatch/benchmarks/3DMatch`` and skip with the reason
when it is absent; the bad-input tests need no data.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

import mtpcr

from conftest import QUICK, mtpcr_binary, shared_dir

RECORD_FIELDS = {
    "benchmark",
    "pair",
    "seed",
    "moved",
    "re_deg",
    "te",
    "registered",
    "confident",
    "reasons",
    "overlap",
    "residual",
    "constraint",
    "support",
    "rival_support",
    "free_space",
    "free_share",
    "landed",
    "tight_support",
    "seconds",
    "t_target_source",
}


def three_d_match() -> Path:
    folder = shared_dir() / "data" / "3dmatch" / "benchmarks" / "3DMatch"
    if not folder.is_dir():
        pytest.skip(f"no 3DMatch pair benchmark at {folder}")
    return folder


@pytest.fixture(scope="module")
def three_pairs():
    folder = three_d_match()
    heard = []
    report = mtpcr.evaluate_pairs(folder, pairs=3, seed=0, on_pair=heard.append)
    return folder, report, heard


def test_records_and_summary_agree(three_pairs):
    _, report, heard = three_pairs
    records, summary = report["records"], report["summary"]
    assert report["benchmark"] == "3DMatch"
    assert len(records) == 3 and heard == records, "on_pair hears every record, in order"
    assert len({r["pair"] for r in records}) == 3
    for r in records:
        assert set(r) == RECORD_FIELDS
        assert (r["benchmark"], r["seed"], r["moved"]) == ("3DMatch", 0, False)
        assert r["registered"] == (r["re_deg"] < 15.0 and r["te"] < 0.3), r
        assert r["confident"] == (r["reasons"] == []), r
        assert len(r["t_target_source"]) == 4 and all(len(row) == 4 for row in r["t_target_source"])
        assert r["t_target_source"][3] == [0.0, 0.0, 0.0, 1.0]
    ok = [r for r in records if r["registered"]]
    failed = [r for r in records if not r["registered"]]
    assert summary["pairs"] == 3
    assert summary["registered"] == len(ok)
    assert summary["failed"] == len(failed)
    assert summary["recall"] == pytest.approx(100.0 * len(ok) / 3)
    assert summary["failed_confident"] == sum(r["confident"] for r in failed)
    assert summary["registered_doubted"] == sum(not r["confident"] for r in ok)
    if ok:
        assert summary["re_deg"] == pytest.approx(sum(r["re_deg"] for r in ok) / len(ok))
        assert summary["te"] == pytest.approx(sum(r["te"] for r in ok) / len(ok))
    else:
        assert summary["re_deg"] is None and summary["te"] is None
    seconds = sorted(r["seconds"] for r in records)
    assert summary["median_seconds"] == seconds[1]


def test_records_are_those_of_mtpcr_eval(three_pairs, tmp_path):
    folder, report, _ = three_pairs
    lines = tmp_path / "records.jsonl"
    subprocess.run(
        [str(mtpcr_binary()), "eval", str(folder), "--pairs", "3", "--seed", "0"]
        + ["--records", str(lines), "--quiet"],
        check=True,
        capture_output=True,
    )
    cli = [json.loads(line) for line in lines.read_text().splitlines()]
    assert [r["pair"] for r in cli] == [r["pair"] for r in report["records"]]
    for ours, theirs in zip(report["records"], cli):
        for key in RECORD_FIELDS - {"seconds"}:
            assert ours[key] == theirs[key], (ours["pair"], key)


def test_on_pair_returning_false_stops_after_that_pair():
    folder = three_d_match()
    stopped = mtpcr.evaluate_pairs(folder, pairs=3, seed=0, on_pair=lambda record: False, **QUICK)
    assert len(stopped["records"]) == 1
    assert stopped["summary"]["pairs"] == 1


def test_a_missing_folder_is_an_oserror_naming_it(tmp_path):
    missing = tmp_path / "no-such-benchmark"
    with pytest.raises(FileNotFoundError) as caught:
        mtpcr.evaluate_pairs(missing)
    assert caught.value.filename == str(missing)
    assert str(missing) in str(caught.value)


def test_a_folder_without_gt_log_is_a_valueerror_naming_it(tmp_path):
    (tmp_path / "scene").mkdir()
    with pytest.raises(ValueError, match="no gt.log") as caught:
        mtpcr.evaluate_pairs(tmp_path)
    assert str(tmp_path) in str(caught.value)


def test_bad_arguments_name_the_culprit(tmp_path):
    scene = tmp_path / "bench" / "kitchen"
    scene.mkdir(parents=True)
    (scene / "gt.log").write_text("0 1 2\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")
    with pytest.raises(ValueError, match="pairs must be at least 1"):
        mtpcr.evaluate_pairs(tmp_path / "bench", pairs=0)
    with pytest.raises(TypeError, match="on_pair must be callable"):
        mtpcr.evaluate_pairs(tmp_path / "bench", on_pair=3)
    with pytest.raises(TypeError, match="unexpected keyword argument 'generation'"):
        mtpcr.evaluate_pairs(tmp_path / "bench", generation=3)
    with pytest.raises(ValueError, match="population_size"):
        mtpcr.evaluate_pairs(tmp_path / "bench", population_size=0)
    with pytest.raises(TypeError, match="config must be an mtpcr.Config"):
        mtpcr.evaluate_pairs(tmp_path / "bench", config={"generations": 3})
    with pytest.raises(ValueError, match="no scene of bench matches office"):
        mtpcr.evaluate_pairs(tmp_path / "bench", scenes=["office"])
    # The fragments are not there: the first pair's file is named.
    with pytest.raises(FileNotFoundError, match="cloud_bin_1.ply"):
        mtpcr.evaluate_pairs(tmp_path / "bench")
