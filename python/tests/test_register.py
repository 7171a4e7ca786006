"""register(): accuracy on a synthetic loop, determinism, input forms, the callback."""

from __future__ import annotations

import pickle
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import mtpcr

from conftest import (
    QUICK,
    SYNTHETIC_MAX_ROTATION_ERROR_DEG,
    apply,
    rotation_error_deg,
    three_views,
)


def test_default_settings_recover_a_synthetic_loop(views):
    # One seeded instance. Measured with the current default settings (4 restarts, joint
    # refinement): the tolerance was met on 11 of 12 (shape seed, run seed) pairs of this
    # generator (shape seeds 1-6, run seeds 1-2); the miss (shape 2, run 2) had one view
    # flipped by 178 degrees. If a core change makes this instance fail, measure that rate
    # again before choosing another seed.
    r = mtpcr.register(*views.clouds, seed=1)
    errors = [rotation_error_deg(r.transforms[k], views.ground_truth[k]) for k in range(3)]
    assert max(errors) < SYNTHETIC_MAX_ROTATION_ERROR_DEG, f"rotation errors {errors} deg"
    for name, est, k in (("T12", r.T12, 0), ("T23", r.T23, 1), ("T31", r.T31, 2)):
        np.testing.assert_array_equal(est, r.transforms[k], err_msg=name)
    # Translations too: cloud 1 mapped by T12 lands on the true positions in cloud 2's frame.
    p = views.clouds[0][:500]
    moved_error = np.linalg.norm(apply(r.T12, p) - apply(views.ground_truth[0], p), axis=1)
    assert moved_error.mean() < 0.05 * 0.15, moved_error.mean()
    assert r.loop_residual < 0.05
    assert r.completed
    generations = r.settings["generations"]
    assert r.history.shape == (generations + 1, 6)
    assert r.history.dtype == np.float64
    assert r.task_names == mtpcr.TASK_NAMES
    assert list(r.best_costs) == list(mtpcr.TASK_NAMES)
    # Aiding costs never get worse (elitist selection on a fixed loss; the original tasks'
    # loop term moves with the other tasks' bests).
    assert np.all(np.diff(r.history[:, :3], axis=0) <= 0.0)
    assert r.settings["seed"] == r.seed == 1
    assert r.evaluations > 0 and r.seconds > 0


def test_result_is_read_only_and_self_describing(small_views):
    r = mtpcr.register(*small_views.clouds, seed=1, **QUICK)
    for shape, value in (((4, 4), r.T12), ((3, 4, 4), r.transforms), ((3, 4, 4), r.poses)):
        assert value.shape == shape and value.dtype == np.float64
    np.testing.assert_allclose(r.poses[0], np.eye(4))
    assert r.reference_cloud == 0
    # Without refinement the loop is not closed: the poses follow two of the three edges
    # (all but the one of highest cost).
    agree = [
        np.allclose(
            np.linalg.inv(r.poses[e["target"]]) @ r.poses[e["source"]], e["t_target_source"]
        )
        for e in r.edges
    ]
    assert sum(agree) >= 2, agree
    assert [e["name"] for e in r.edges] == ["T12", "T23", "T31"]
    np.testing.assert_array_equal(r.edges[0]["t_target_source"], r.T12)
    np.testing.assert_allclose(r.t_target_source(1, 0), r.T12)
    np.testing.assert_allclose(r.t_target_source(0, 1), np.linalg.inv(r.T12), atol=1e-12)
    with pytest.raises(AttributeError, match="T12, T23, T31"):
        r.T13  # noqa: B018
    assert r.generations_run == QUICK["generations"]
    with pytest.raises(AttributeError):
        r.seed = 5  # type: ignore[misc]
    # Mutating a returned array does not change the result.
    r.T12[0, 0] = 42.0
    assert r.T12[0, 0] != 42.0
    text = repr(r)
    assert text.startswith("Registration(") and "seed=1" in text and "J1-o" in text
    # The settings reproduce the run.
    again = mtpcr.register(*small_views.clouds, config=mtpcr.Config(**r.settings))
    np.testing.assert_array_equal(again.transforms, r.transforms)


def test_same_seed_same_result_different_seed_different_result(small_views):
    settings = dict(population_size=16, generations=8)
    a = mtpcr.register(*small_views.clouds, seed=42, **settings)
    b = mtpcr.register(*small_views.clouds, seed=42, **settings)
    for name in ("T12", "T23", "T31", "history"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.best_costs == b.best_costs
    # The result does not depend on the number of worker threads.
    one = mtpcr.register(*small_views.clouds, seed=42, num_threads=1, **settings)
    two = mtpcr.register(*small_views.clouds, seed=42, num_threads=2, **settings)
    np.testing.assert_array_equal(one.transforms, a.transforms)
    np.testing.assert_array_equal(two.history, a.history)
    c = mtpcr.register(*small_views.clouds, seed=43, **settings)
    assert not np.array_equal(a.history, c.history)
    # Without a seed one is drawn and reported; it reproduces the run.
    d = mtpcr.register(*small_views.clouds, **settings)
    e = mtpcr.register(*small_views.clouds, seed=d.seed, **settings)
    np.testing.assert_array_equal(d.transforms, e.transforms)


def strided_view(c: np.ndarray) -> np.ndarray:
    """The same values as a non-contiguous view (every other column of a wider array)."""
    wide = np.zeros((c.shape[0], 6))
    wide[:, ::2] = c
    view = wide[:, ::2]
    assert not view.flags.c_contiguous and not view.flags.f_contiguous
    return view


def test_every_input_form_gives_the_same_result(small_views):
    c64 = [np.ascontiguousarray(c, dtype=np.float64) for c in small_views.clouds]
    expected = mtpcr.register(*c64, seed=9, **QUICK)
    forms = {
        "fortran order": [np.asfortranarray(c) for c in c64],
        "nested lists": [c.tolist() for c in c64],
        "strided view": [strided_view(c) for c in c64],
        "tuple of tuples": [tuple(map(tuple, c)) for c in c64],
        "big-endian": [c.astype(">f8") for c in c64],
        "negative strides": [np.flipud(np.ascontiguousarray(c[::-1])) for c in c64],
    }
    for name, clouds in forms.items():
        r = mtpcr.register(*clouds, seed=9, **QUICK)
        np.testing.assert_array_equal(r.transforms, expected.transforms, err_msg=name)
        np.testing.assert_array_equal(r.history, expected.history, err_msg=name)
    # float32 is widened exactly: the same result as the float32 values given as float64,
    # in either memory order.
    c32 = [c.astype(np.float32) for c in c64]
    widened = mtpcr.register(*[c.astype(np.float64) for c in c32], seed=9, **QUICK)
    for name, clouds in (
        ("float32", c32),
        ("float32 fortran", [np.asfortranarray(c) for c in c32]),
    ):
        r = mtpcr.register(*clouds, seed=9, **QUICK)
        np.testing.assert_array_equal(r.transforms, widened.transforms, err_msg=name)
    # Integer coordinates are numbers too.
    ints = [np.round(c * 1e4).astype(np.int32) for c in c64]
    r = mtpcr.register(*ints, seed=9, **QUICK)
    assert r.transforms.shape == (3, 4, 4)


def test_settings_by_keyword_and_by_config_agree(small_views):
    cfg = mtpcr.Config(seed=8, **QUICK)
    a = mtpcr.register(*small_views.clouds, config=cfg)
    b = mtpcr.register(*small_views.clouds, seed=8, **QUICK)
    np.testing.assert_array_equal(a.transforms, b.transforms)
    # Keywords override the config; the explicit seed overrides the config's seed.
    c = mtpcr.register(*small_views.clouds, config=cfg, generations=2, seed=1)
    assert c.generations_run == 2 and c.seed == 1
    assert c.settings["population_size"] == 12
    # numpy scalars are accepted as settings.
    d = mtpcr.register(
        *small_views.clouds,
        seed=np.int64(8),
        population_size=np.int32(12),
        generations=4,
        restarts=1,
        refine_iterations=0,
        alpha=np.float32(0.05),
    )
    np.testing.assert_array_equal(d.transforms, b.transforms)


def test_callback_sees_every_generation_and_false_stops(small_views):
    seen = []

    def record(generation, best_costs):
        assert list(best_costs) == list(mtpcr.TASK_NAMES)
        assert all(isinstance(v, float) for v in best_costs.values())
        seen.append((generation, dict(best_costs)))

    r = mtpcr.register(
        *small_views.clouds,
        seed=2,
        on_generation=record,
        population_size=12,
        generations=6,
        restarts=1,
    )
    total = r.settings["generations"] * r.settings.get("restarts", 1)
    assert [g for g, _ in seen] == list(range(1, total + 1))
    assert r.completed
    # The last report is the final best.
    assert seen[-1][1] == r.best_costs

    def stop_after_three(generation, best_costs):
        return generation < 3

    s = mtpcr.register(
        *small_views.clouds,
        seed=2,
        on_generation=stop_after_three,
        population_size=12,
        generations=6,
        restarts=1,
    )
    assert not s.completed
    assert s.generations_run == 3
    assert s.history.shape[0] == 4
    # Stopping changes nothing before the stop.
    np.testing.assert_array_equal(s.history, r.history[:4])


def test_exception_in_callback_propagates(small_views):
    calls = []

    class Boom(Exception):
        pass

    def explode(generation, best_costs):
        calls.append(generation)
        raise Boom(f"at generation {generation}")

    with pytest.raises(Boom, match="at generation 1"):
        mtpcr.register(*small_views.clouds, seed=2, on_generation=explode, **QUICK)
    assert calls == [1], "the run stops at the first exception"


def test_keyboard_interrupt_stops_the_run(small_views):
    def interrupt(generation, best_costs):
        if generation == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        mtpcr.register(*small_views.clouds, seed=2, on_generation=interrupt, **QUICK)


def test_the_gil_is_released_during_a_run(small_views):
    # While the engine runs (no callback), another thread keeps running Python code.
    ticks = []
    done = threading.Event()

    def ticker():
        while not done.is_set():
            ticks.append(1)
            done.wait(0.0005)

    t = threading.Thread(target=ticker)
    t.start()
    try:
        before = len(ticks)
        r = mtpcr.register(*small_views.clouds, seed=2, population_size=60, generations=20)
        during = len(ticks) - before
    finally:
        done.set()
        t.join()
    assert during >= 5, f"the other thread ran {during} times in {r.seconds:.3f} s"


@pytest.mark.skipif(sys.platform == "win32", reason="needs POSIX signals")
def test_ctrl_c_stops_a_long_run_with_keyboard_interrupt():
    # A real SIGINT to a process running a practically endless registration, without a callback.
    code = textwrap.dedent(
        """
        import signal
        import sys
        import numpy as np
        import mtpcr
        # Ctrl-C as at a terminal: a child of a shell's background job starts with SIGINT
        # ignored, and Python then never raises KeyboardInterrupt.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        rng = np.random.default_rng(0)
        clouds = [rng.normal(size=(3000, 3)) for _ in range(3)]
        print("ready", flush=True)
        try:
            mtpcr.register(*clouds, seed=1, generations=1_000_000)
        except KeyboardInterrupt:
            print("interrupted", flush=True)
            sys.exit(0)
        sys.exit(3)
        """
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.5)
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        latency = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, f"exit {proc.returncode}: {err}"
    assert "interrupted" in out
    assert latency < 10, f"took {latency:.1f} s to stop"


def test_two_clouds_and_four_in_a_loop(small_views):
    """Two clouds are one pair (T12, no loop); four clouds given in loop order are a loop."""
    a, b, c = small_views.clouds
    r = mtpcr.register(a, b, seed=2, **QUICK)
    assert r.transforms.shape == (1, 4, 4) and r.poses.shape == (2, 4, 4)
    assert r.task_names == ("J1-a", "J1-o")
    assert r.loop_residual is None
    np.testing.assert_allclose(r.poses[1], np.linalg.inv(r.T12), atol=1e-12)
    with pytest.raises(AttributeError):
        r.T23  # noqa: B018
    r4 = mtpcr.register(a, b, c, a[::2], seed=2, order="given", **QUICK)
    assert [e["name"] for e in r4.edges] == ["T12", "T23", "T34", "T41"]
    assert r4.history.shape[1] == 8 and r4.poses.shape == (4, 4, 4)
    assert r4.loop_residual is not None


def test_points_are_placed_and_merged_in_cloud_1s_frame(small_views):
    clouds = small_views.clouds
    r = mtpcr.register(*clouds, seed=3, **QUICK)
    # Cloud 1 stays where it is; cloud 2's points move by its pose.
    np.testing.assert_array_equal(r.transform_points(0, clouds[0]), clouds[0])
    np.testing.assert_allclose(r.transform_points(1, clouds[1]), apply(r.poses[1], clouds[1]))
    points, cloud = r.merge(*clouds)
    assert points.shape == (sum(len(c) for c in clouds), 3)
    assert cloud.dtype == np.int64
    for k, c in enumerate(clouds):
        np.testing.assert_allclose(points[cloud == k], apply(r.poses[k], c))
    with pytest.raises(ValueError, match="cloud 3 out of range: 3 clouds"):
        r.transform_points(3, clouds[0])
    with pytest.raises(ValueError, match="shape"):
        r.transform_points(1, clouds[1][:, :2])
    with pytest.raises(ValueError, match="2 clouds given, the registration has 3"):
        r.merge(*clouds[:2])


def test_poses_are_exported_for_the_next_tool(small_views):
    """The trajectory and the Open3D pose graph carry the same poses as ``poses``."""
    clouds = small_views.clouds
    r = mtpcr.register(*clouds, seed=3, **QUICK)
    lines = r.trajectory_log().splitlines()
    assert len(lines) == 5 * 3 and lines[0].split() == ["0", "0", "3"]
    pose2 = np.array([[float(v) for v in line.split()] for line in lines[11:15]])
    np.testing.assert_allclose(pose2, r.poses[2], atol=1e-9)
    graph = r.pose_graph()
    assert graph["class_name"] == "PoseGraph" and len(graph["nodes"]) == 3
    # Open3D lists matrices column by column.
    node2 = np.array(graph["nodes"][2]["pose"]).reshape(4, 4).T
    np.testing.assert_allclose(node2, r.poses[2], atol=1e-12)
    ends = [(e["source_node_id"], e["target_node_id"]) for e in graph["edges"]]
    assert ends == [(e["source"], e["target"]) for e in r.edges]


def test_screening_of_clouds_in_no_known_order_reports_progress(small_views):
    """Four clouds in no known order are screened pair by pair; ``on_pair_screening`` sees
    the count up to all six pairs, and returning False leaves an incomplete result."""
    a, b, c = small_views.clouds
    clouds = (a, b, c, a[::2])
    calls = []

    def seen(done, total):
        calls.append((done, total))

    r = mtpcr.register(*clouds, seed=1, on_pair_screening=seen)
    assert r.completed and calls and calls[-1] == (6, 6)
    r = mtpcr.register(*clouds, seed=1, on_pair_screening=lambda done, total: False)
    assert not r.completed
    with pytest.raises(TypeError, match="on_pair_screening must be callable"):
        mtpcr.register(*clouds, on_pair_screening=3)


def test_a_screening_made_in_pieces_gives_register_bit_for_bit():
    clouds = three_views(seed=21, points_per_view=2000, count=6, step_deg=60.0).clouds
    whole = mtpcr.register(*clouds, seed=3)
    assert whole.unplaced == [] and whole.confident
    pairs = [(s, t) for s in range(6) for t in range(s + 1, 6)]
    seen = []
    pieces = [
        mtpcr.screen_pairs(*clouds, pairs=pairs[:7], seed=3),
        mtpcr.screen_pairs(
            *clouds, pairs=pairs[7:], seed=3, on_pair_screening=lambda d, t: seen.append((d, t))
        ),
    ]
    assert seen[-1] == (8, 8)
    # A screening is all or nothing: a callback's False does not cut it short.
    stopped = mtpcr.screen_pairs(
        *clouds, pairs=pairs[7:], seed=3, on_pair_screening=lambda d, t: False
    )
    assert len(stopped["pairs"]) == 8
    assert [(p["source"], p["target"]) for p in pieces[0]["pairs"]] == pairs[:7]
    first = pieces[0]["pairs"][0]
    assert first["poses"].shape[1:] == (4, 4) and first["poses"].dtype == np.float64
    assert first["overlaps"].shape == first["supports"].shape == (len(first["poses"]),)
    # Plain data: it pickles (Ray and multiprocessing carry it).
    pieces = pickle.loads(pickle.dumps(pieces))
    split = mtpcr.register(*clouds, seed=3, screening=pieces)
    assert np.array_equal(split.poses, whole.poses)
    assert np.array_equal(split.transforms, whole.transforms)
    assert split.confident == whole.confident and split.unplaced == whole.unplaced
    # All pairs in one screening, as well.
    one = mtpcr.screen_pairs(*clouds, seed=3)
    assert len(one["pairs"]) == 15 and one["clouds"] == 6
    assert np.array_equal(mtpcr.register(*clouds, seed=3, screening=one).poses, whole.poses)


def test_a_screening_that_does_not_fit_is_refused_with_the_reason():
    clouds = three_views(seed=22, points_per_view=1500, count=5, step_deg=70.0).clouds
    screening = mtpcr.screen_pairs(*clouds, seed=1, pairs=[(0, 1), (1, 2)])
    other = three_views(seed=23, points_per_view=1500, count=5, step_deg=70.0).clouds
    with pytest.raises(ValueError, match="fingerprint differs"):
        mtpcr.register(*other, seed=1, screening=screening)
    with pytest.raises(ValueError, match=r"\(0, 1\) is screened more than once"):
        mtpcr.register(*clouds, seed=1, screening=[screening, screening])
    with pytest.raises(TypeError, match="screening must be the dict"):
        mtpcr.register(*clouds, seed=1, screening=3)
    broken = {**screening, "pairs": [{**screening["pairs"][0], "poses": np.zeros((2, 3, 3))}]}
    with pytest.raises(ValueError, match=r"pair 0: `poses` must have shape \(H, 4, 4\)"):
        mtpcr.register(*clouds, seed=1, screening=broken)
    with pytest.raises(ValueError, match="has no `supports`"):
        pair = {k: v for k, v in screening["pairs"][0].items() if k != "supports"}
        mtpcr.register(*clouds, seed=1, screening={**screening, "pairs": [pair]})
    with pytest.raises(ValueError, match=r"\(3, 1\) is not a pair"):
        mtpcr.screen_pairs(*clouds, pairs=[(3, 1)])
    with pytest.raises(ValueError, match="pairs must be a sequence"):
        mtpcr.screen_pairs(*clouds, pairs=[(0, 1, 2)])
    with pytest.raises(ValueError, match="four or more scans"):
        mtpcr.screen_pairs(*clouds[:3])
