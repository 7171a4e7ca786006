"""Measures mtpcr.distributed on Ray (BENCHMARK.md, "Batches on Ray").

The work: the paper setting (``Config.paper()``, variant ``mtpcr-paper``) on every problem file
given, seeds 0..N-1. Steps, each timed:

1. ``--local``: the reference, plain ``mtpcr.register`` calls one after the other on this
   process (``num_threads`` = ``--local-threads``); transforms kept in ``OUT/local.npz``
   (reused when present).
2. ``register_batch`` of the same registrations on Ray (one thread, one Ray CPU per task):
   transforms compared with the reference bit for bit; Ray's overhead per task.
3. ``mtpcr.distributed.evaluate("accuracy", ..., variants=["mtpcr-paper"])``: the records of
   ``mtpcr experiment accuracy`` for the same problems and seeds; with ``--cli-runs FILE``
   (a runs.jsonl of the CLI) compared record for record (all fields but ``seconds``).
4. 200 empty Ray tasks: the bare round trip.

``--address`` connects to a running cluster (``ray start``); without it a local instance with
``--num-cpus`` CPUs is started on 127.0.0.1 (``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``).
Prints one JSON summary.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import mtpcr
from mtpcr import distributed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("problems", nargs="+")
    parser.add_argument("--seeds", type=int, default=7)
    parser.add_argument("--out", required=True)
    parser.add_argument("--address")
    parser.add_argument("--num-cpus", type=int, default=2)
    parser.add_argument("--local", action="store_true")
    parser.add_argument("--local-threads", type=int, default=2)
    parser.add_argument("--cli-runs")
    parser.add_argument("--skip", nargs="*", default=[], help="steps to skip: batch evaluate")
    args = parser.parse_args()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if not args.address:  # a single-node instance on 127.0.0.1
        os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary: dict = {"runs": len(args.problems) * args.seeds}
    seeds = list(range(args.seeds))
    work = [(p, s) for p in args.problems for s in seeds]

    reference = out / "local.npz"
    if args.local and not reference.is_file():
        start = time.perf_counter()
        transforms, seconds = {}, []
        for p in args.problems:
            scans = mtpcr.load_problem(p).read_scans()
            for s in seeds:
                r = mtpcr.register(
                    *scans, config=mtpcr.Config.paper(), seed=s, num_threads=args.local_threads
                )
                transforms[f"{Path(p).stem}-{s}"] = r.transforms
                seconds.append(r.seconds)
        wall = time.perf_counter() - start
        np.savez(reference, **transforms)
        summary["local"] = {
            "threads": args.local_threads,
            "wall_s": wall,
            "runs_per_min": 60 * len(work) / wall,
            "mean_run_s": float(np.mean(seconds)),
        }

    import ray

    start = time.perf_counter()
    if args.address:
        ray.init(address=args.address, log_to_driver=False)
    else:
        ray.init(num_cpus=args.num_cpus, include_dashboard=False, log_to_driver=False)
    summary["ray_init_s"] = time.perf_counter() - start
    summary["ray_cpus"] = ray.cluster_resources().get("CPU")
    summary["ray_nodes"] = len([n for n in ray.nodes() if n["Alive"]])

    if "batch" not in args.skip:
        batch_file = out / "batch.jsonl"
        batch_file.unlink(missing_ok=True)
        items = [distributed.Item(p, seed=s) for p, s in work]
        start = time.perf_counter()
        results = distributed.register_batch(
            items, config=mtpcr.Config.paper(), num_threads=1, results=batch_file, progress=False
        )
        wall = time.perf_counter() - start
        ok = [r for r in results if r.ok]
        cpus = summary["ray_cpus"]
        batch = {
            "wall_s": wall,
            "runs_per_min": 60 * len(work) / wall,
            "failures": len(results) - len(ok),
            "mean_run_s": float(np.mean([r.seconds for r in ok])),
            "mean_task_minus_run_ms": 1000
            * float(np.mean([r.task_seconds - r.seconds for r in ok])),
            # Wall-clock CPU time not spent in registrations, per task (scheduling, transfer,
            # result handling, idle CPUs at the tail).
            "overhead_per_task_ms": 1000
            * (wall * cpus - sum(r.task_seconds for r in ok))
            / len(ok),
            "nodes": sorted({r.node for r in ok}),
        }
        if reference.is_file():
            local = np.load(reference)
            same = [
                np.array_equal(r.transforms, local[f"{Path(p).stem}-{s}"])
                for r, (p, s) in zip(results, work)
                if r.ok
            ]
            batch["identical_to_local"] = f"{sum(same)}/{len(work)}"
        summary["register_batch"] = batch

    if "evaluate" not in args.skip:
        eval_dir = out / "ray-eval"
        (eval_dir / "runs.jsonl").unlink(missing_ok=True)
        start = time.perf_counter()
        records = distributed.evaluate(
            "accuracy",
            args.problems,
            seeds=seeds,
            variants=["mtpcr-paper"],
            out=eval_dir,
            progress=False,
        )
        wall = time.perf_counter() - start
        ev = {
            "wall_s": wall,
            "runs_per_min": 60 * len(records) / wall,
            "mean_run_s": float(np.mean([r["seconds"] for r in records])),
            "successes": sum(r["success"] for r in records),
        }
        if args.cli_runs:
            cli = {}
            for line in Path(args.cli_runs).read_text().splitlines():
                r = json.loads(line)
                if r["variant"] == "mtpcr-paper":
                    cli[(r["problem"], r["seed"])] = r
            same = 0
            for r in records:
                other = cli.get((r["problem"], r["seed"]))
                if other is not None and all(r[k] == other[k] for k in r if k != "seconds"):
                    same += 1
            ev["identical_to_cli"] = f"{same}/{len(records)}"
        summary["evaluate"] = ev

    @ray.remote(num_cpus=1)
    def empty(x):
        return x

    ray.get([empty.remote(i) for i in range(20)])  # warm the workers
    start = time.perf_counter()
    ray.get([empty.remote(i) for i in range(200)])
    summary["empty_task_ms"] = 1000 * (time.perf_counter() - start) / 200
    ray.shutdown()
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
