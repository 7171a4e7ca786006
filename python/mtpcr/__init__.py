"""mtpcr: multi-view point cloud registration by evolutionary multitasking (MTPCR).

Overlapping scans are registered with no initial guess: two scans as one pair, three or more
given in loop order as a loop. Each pair is a pair of tasks (the original one, with a
loop-closure term, and an easier aiding one); their populations evolve together and share
what they find inside each pair and around the loop.

Convention: ``T_ij`` maps points of cloud i into the frame of cloud j,
``x_j = T_ij @ [x_i, 1]``; three clouds give ``T12``, ``T23`` and ``T31``.

Example::

    import mtpcr

    a, b, c = (mtpcr.read_ply(p) for p in ("a.ply", "b.ply", "c.ply"))
    result = mtpcr.register(a, b, c, seed=7)           # defaults: Config()
    print(result)                                      # summary, costs, seconds
    T12 = result.T12                                   # 4x4, cloud 1 -> cloud 2
    fast = mtpcr.register(a, b, c, generations=20)     # any Config field as a keyword

Errors: ``ValueError`` for bad clouds, settings or file content (the message names the
argument or setting), ``TypeError`` for an unknown setting, ``OSError`` for files that cannot
be read or written, ``RuntimeError`` for anything else.

The engine is Rust (``mtpcr._mtpcr``); it runs without holding the GIL.

Benchmarks against ground truth: ``mtpcr.evaluate(suite, problem_files)`` runs an experiment
suite of the paper (the records of ``mtpcr experiment``); ``mtpcr.evaluate_pairs(folder,
pairs=20)`` runs the pairs of a 3DMatch-layout benchmark (``gt.log`` per scene: 3DMatch,
3DLoMatch) as ``mtpcr eval FOLDER`` does, and returns the records and their summary
(registration recall, RE, TE, the verdict's confusion)::

    report = mtpcr.evaluate_pairs("shared/data/3dmatch/benchmarks/3DMatch", pairs=20, seed=0)
    print(report["summary"]["recall"], report["records"][0]["pair"])

Many registrations, or the experiment suites, on Ray (this machine or a cluster):
``mtpcr.distributed`` (``pip install "mtpcr[ray]"``; not imported by ``import mtpcr``).
"""

from ._mtpcr import (
    MIN_POINTS,
    TASK_NAMES,
    Config,
    Problem,
    Registration,
    __version__,
    describe_suite,
    evaluate,
    evaluate_pairs,
    find_shared_dir,
    load_problem,
    read_ply,
    read_points,
    read_scans,
    register,
    screen_pairs,
    write_ply,
)

__all__ = [
    "MIN_POINTS",
    "TASK_NAMES",
    "Config",
    "Problem",
    "Registration",
    "__version__",
    "describe_suite",
    "evaluate",
    "evaluate_pairs",
    "find_shared_dir",
    "load_problem",
    "read_ply",
    "read_points",
    "read_scans",
    "register",
    "screen_pairs",
    "write_ply",
]
