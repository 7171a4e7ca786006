"""``mtpcr.evaluate`` runs the protocol of ``mtpcr experiment``: the same records for the same
suite, variant, problem and seed (only the run time differs)."""

from __future__ import annotations

import json
import subprocess

import pytest

import mtpcr

from conftest import mtpcr_binary


def test_evaluate_gives_the_records_of_mtpcr_experiment(problem_file, tmp_path):
    records = mtpcr.evaluate(
        "accuracy", [problem_file], seeds=[0, 1], variants=["mtpcr-default"], generations=3
    )
    assert [(r["variant"], r["problem"], r["seed"]) for r in records] == [
        ("mtpcr-default", "synthetic", 0),
        ("mtpcr-default", "synthetic", 1),
    ]
    out = tmp_path / "exp"
    subprocess.run(
        [
            str(mtpcr_binary()),
            "experiment",
            "accuracy",
            "--problems",
            str(problem_file),
            "--runs",
            "2",
            "--generations",
            "3",
            "--out",
            str(out),
            "--quiet",
        ],
        check=True,
    )
    lines = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    cli = {(r["variant"], r["seed"]): r for r in lines}
    for record in records:
        other = cli[(record["variant"], record["seed"])]
        for key in record:
            if key != "seconds":
                assert record[key] == other[key], key


def test_evaluate_rejects_unknown_suites_and_variants(problem_file):
    with pytest.raises(ValueError, match="unknown suite `acuracy`"):
        mtpcr.evaluate("acuracy", [problem_file])
    with pytest.raises(ValueError, match="no variant `fast`"):
        mtpcr.evaluate("accuracy", [problem_file], variants=["fast"])
    stops = mtpcr.evaluate(
        "accuracy", [problem_file], runs=3, generations=1, on_run=lambda record: False
    )
    assert len(stops) == 1, "on_run returning False stops after the first run"


def test_describe_suite_lists_the_variants_in_run_order():
    info = mtpcr.describe_suite("accuracy")
    assert info["name"] == "accuracy" and info["default_runs"] == 10
    assert [v["key"] for v in info["variants"]] == ["mtpcr-default", "mtpcr-paper"]
    assert info["variants"][1]["settings"] == mtpcr.Config.paper().to_dict()
    assert info["paper_problems"] is None
    assert mtpcr.describe_suite("sharing")["paper_problems"] == ["bunny-c"]
    assert mtpcr.describe_suite("noise")["variants"][1]["noise"] == 0.02
    with pytest.raises(ValueError, match="unknown suite"):
        mtpcr.describe_suite("acuracy")
