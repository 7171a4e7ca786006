"""Measures ``mtpcr.distributed.register_scene`` on Ray against a local run (RESULTS.md).

For one scene problem file (``scripts/make_scene_problems.py``): ``mtpcr.register`` of all its
scans here (``--local-threads`` threads), then ``register_scene`` on Ray (``--tasks`` tasks of
one thread; a local instance of ``--num-cpus`` CPUs on 127.0.0.1, or ``--address``), both with
``--seed``. Prints one JSON summary: both wall times, the Ray run's throughput per core
against the local run's, and whether the poses are bit-identical.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

import mtpcr
from mtpcr import distributed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("problem")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--local-threads", type=int, default=2)
    parser.add_argument("--num-cpus", type=int, default=2)
    parser.add_argument("--tasks", type=int)
    parser.add_argument("--address")
    args = parser.parse_args()

    problem = mtpcr.load_problem(args.problem)
    clouds = problem.read_scans()
    with open(args.problem) as f:
        viewpoints = json.load(f).get("viewpoints")

    start = time.perf_counter()
    local = mtpcr.register(
        *clouds, seed=args.seed, viewpoints=viewpoints, num_threads=args.local_threads
    )
    local_seconds = time.perf_counter() - start

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    import ray

    if args.address:
        ray.init(address=args.address, log_to_driver=False)
    else:
        ray.init(num_cpus=args.num_cpus, include_dashboard=False, log_to_driver=False)
    cores = int(ray.cluster_resources().get("CPU", 1))
    tasks = []
    start = time.perf_counter()
    remote = distributed.register_scene(
        clouds,
        seed=args.seed,
        viewpoints=viewpoints,
        tasks=args.tasks,
        on_task=tasks.append,
        config={"num_threads": args.local_threads},
    )
    ray_seconds = time.perf_counter() - start
    ray.shutdown()
    summary = {
        "problem": problem.name,
        "scans": len(clouds),
        "seed": args.seed,
        "local_threads": args.local_threads,
        "local_seconds": round(local_seconds, 2),
        "ray_cores": cores,
        "ray_tasks": len(tasks),
        "ray_seconds": round(ray_seconds, 2),
        "task_seconds": [round(t["seconds"], 2) for t in tasks],
        # Scenes per second per core, Ray over local.
        "throughput_per_core_vs_local": round(
            (local_seconds * args.local_threads) / (ray_seconds * cores), 3
        ),
        "bit_identical": bool(
            np.array_equal(local.poses, remote.poses, equal_nan=True)
            and np.array_equal(local.transforms, remote.transforms)
        ),
        "placed": int(np.isfinite(local.poses[:, 0, 0]).sum()),
    }
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
