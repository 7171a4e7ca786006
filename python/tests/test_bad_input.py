"""Every bad input raises ValueError or TypeError with a message that names the culprit."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import mtpcr

from conftest import QUICK


@pytest.fixture(scope="module")
def good(small_views):
    return list(small_views.clouds)


def with_cloud(good, index, cloud):
    clouds = list(good)
    clouds[index] = cloud
    return clouds


def nan_at(c, i, k, value=math.nan):
    c = np.array(c, dtype=np.float64)
    c[i, k] = value
    return c


BAD_CLOUDS = [
    # (description, make(good cloud) -> bad cloud, expected message fragment)
    ("empty (0, 3)", lambda c: np.empty((0, 3)), "empty"),
    ("empty list", lambda c: [], "shape (N, 3), got (0,)"),
    ("shape (N, 2)", lambda c: c[:5, :2], "shape (N, 3), got (5, 2)"),
    ("shape (N, 4)", lambda c: np.hstack([c, c[:, :1]]), "shape (N, 3), got"),
    ("transposed", lambda c: c.T, "shape (N, 3), got (3,"),
    ("1-D", lambda c: c[:, 0], "shape (N, 3), got ("),
    ("3-D", lambda c: c[None], "shape (N, 3), got (1,"),
    ("scalar", lambda c: 3.0, "shape (N, 3), got ()"),
    ("NaN", lambda c: nan_at(c, 7, 1), "point 7 has a non-finite coordinate"),
    ("inf", lambda c: nan_at(c, 3, 2, math.inf), "point 3 has a non-finite coordinate"),
    ("-inf", lambda c: nan_at(c, 0, 0, -math.inf), "non-finite"),
    ("too few points", lambda c: c[:4], "at least"),
    ("all identical", lambda c: np.ones((50, 3)), "identical"),
    ("ragged list", lambda c: [[0.0, 1.0, 2.0], [1.0, 2.0]], "must be an (N, 3) array"),
    ("strings", lambda c: [["a", "b", "c"]] * 20, "must be an (N, 3) array"),
    ("huge coordinate", lambda c: nan_at(c, 9, 0, 1e308), "point 9 has a coordinate too large"),
    ("scaled by 1e300", lambda c: np.asarray(c) * 1e300, "too large to register"),
    ("collinear", lambda c: np.outer(np.linspace(0, 1, 200), [1.0, 2.0, -0.5]), "on one line"),
    ("None", lambda c: None, "cloud"),
    ("dict", lambda c: {"x": 1}, "cloud"),
]


@pytest.mark.parametrize("index", [0, 1, 2])
@pytest.mark.parametrize("description, make, fragment", BAD_CLOUDS, ids=[b[0] for b in BAD_CLOUDS])
def test_bad_cloud_is_a_value_error_naming_the_argument(good, index, description, make, fragment):
    name = f"cloud{index + 1}"
    clouds = with_cloud(good, index, make(good[index]))
    with pytest.raises(ValueError) as info:
        mtpcr.register(*clouds, seed=1, **QUICK)
    message = str(info.value)
    assert name in message, f"{description}: {message!r} does not name {name}"
    assert fragment in message, f"{description}: {message!r} lacks {fragment!r}"


# Arrays numpy would cast to float64 without a word: refused, naming the dtype.
BAD_DTYPES = [
    ("bool", lambda c: np.asarray(c) > 0, "dtype bool"),
    ("bool list", lambda c: (np.asarray(c) > 0).tolist(), "dtype bool"),
    ("complex", lambda c: np.asarray(c) + 0j, "dtype complex128"),
    ("complex64", lambda c: (np.asarray(c) + 1j).astype(np.complex64), "dtype complex64"),
    ("numeric str", lambda c: np.asarray(c).astype(str), "dtype <U"),
    ("numeric str list", lambda c: np.asarray(c).astype(str).tolist(), "dtype <U"),
    ("bytes", lambda c: np.asarray(c).astype(bytes), "dtype |S"),
    ("object of str", lambda c: np.asarray(c).astype(str).astype(object), "dtype object"),
    ("object of mixed", lambda c: np.array([[1.0, "2", 3.0]] * 20, dtype=object), "dtype object"),
    ("datetime", lambda c: np.zeros((20, 3), dtype="datetime64[s]"), "dtype datetime64[s]"),
]


@pytest.mark.parametrize("index", [0, 2])
@pytest.mark.parametrize("description, make, fragment", BAD_DTYPES, ids=[b[0] for b in BAD_DTYPES])
def test_arrays_that_are_not_real_numbers_are_refused(good, index, description, make, fragment):
    name = f"cloud{index + 1}"
    clouds = with_cloud(good, index, make(good[index]))
    with pytest.raises(ValueError) as info:
        mtpcr.register(*clouds, seed=1, **QUICK)
    message = str(info.value)
    assert f"{name} must be an (N, 3) array of real numbers" in message, message
    assert fragment in message, f"{description}: {message!r} lacks {fragment!r}"


def test_numbers_of_any_real_dtype_or_as_objects_are_accepted(good, recwarn):
    expected = mtpcr.register(*good, seed=3, **QUICK).transforms
    for convert in (
        lambda c: c.astype(object),
        np.asfortranarray,
        lambda c: [[float(v) for v in row] for row in c],
    ):
        clouds = [convert(np.asarray(c)) for c in good]
        got = mtpcr.register(*clouds, seed=3, **QUICK).transforms
        np.testing.assert_array_equal(got, expected)
    assert not recwarn.list, [str(w.message) for w in recwarn.list]
    # Integer coordinates (millimetres, say) are numbers too.
    ints = [np.round(np.asarray(c) * 1e4).astype(np.int32) for c in good]
    assert mtpcr.register(*ints, seed=3, **QUICK).transforms.shape == (3, 4, 4)
    with pytest.raises(
        ValueError, match=r"points must be an \(N, 3\) array of real numbers.*got dtype bool"
    ):
        mtpcr.write_ply("unused.ply", np.ones((20, 3), dtype=bool))


def test_a_planar_cloud_is_registered_with_a_user_warning(good):
    flat = np.array(good[1], dtype=np.float64)
    flat[:, 2] = 0.25
    with pytest.warns(UserWarning) as caught:
        result = mtpcr.register(good[0], flat, good[2], seed=1, **QUICK)
    messages = [str(w.message) for w in caught]
    assert messages == [
        "cloud2 is planar: its rotation about the plane normal is weakly determined"
    ], messages
    assert caught[0].filename == __file__, "the warning points at the caller"
    assert np.isfinite(result.transforms).all()
    # Warnings turned into errors stop the run.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match="cloud2 is planar"):
            mtpcr.register(good[0], flat, good[2], seed=1, **QUICK)


BAD_SETTINGS = [
    ("population_size", 2, "population_size"),
    ("population_size", -5, "population_size"),
    ("population_size", 10.5, "population_size"),
    ("population_size", "many", "population_size"),
    ("generations", -1, "generations"),
    ("sample_ratio", 0.0, "sample_ratio"),
    ("sample_ratio", 1.5, "sample_ratio"),
    ("sample_ratio", math.nan, "sample_ratio"),
    ("sampling", "best", "sampling"),
    ("sampling", 3, "sampling"),
    ("p_intra", 1.5, "p_intra"),
    ("p_inter", -0.1, "p_inter"),
    ("top_ratio", 0.0, "top_ratio"),
    ("scale_factor", 3.0, "scale_factor"),
    ("sbx_eta_start", -1.0, "sbx_eta_start"),
    ("sbx_eta_end", math.inf, "sbx_eta_end"),
    ("alpha", -0.5, "alpha"),
    ("alpha", "0.05", "alpha"),
    ("aiding_cap_ratio", 0.0, "aiding_cap_ratio"),
    ("two_way_aiding", "yes", "two_way_aiding"),
    ("two_way_aiding", 1, "two_way_aiding"),
    ("unit_free_loop_term", None, "unit_free_loop_term"),
    ("search", "slow", "search"),
    ("num_threads", 100000, "num_threads"),
    ("seed", -1, "seed"),
    ("seed", 2**64, "seed"),
    ("seed", 1.5, "seed"),
]


@pytest.mark.parametrize(
    "field, value, fragment", BAD_SETTINGS, ids=[f"{f}={v!r}" for f, v, _ in BAD_SETTINGS]
)
def test_bad_setting_is_a_value_error_naming_the_field(good, field, value, fragment):
    with pytest.raises(ValueError, match=fragment):
        mtpcr.register(*good, **{**QUICK, field: value})
    with pytest.raises(ValueError, match=fragment):
        mtpcr.Config(**{field: value})
    with pytest.raises(ValueError, match=fragment):
        mtpcr.Config().replace(**{field: value})


def test_settings_of_the_wrong_kind_are_type_errors(good):
    with pytest.raises(TypeError, match="alpha"):
        mtpcr.Config(alpha=[0.1])
    with pytest.raises(TypeError, match="config must be an mtpcr.Config"):
        mtpcr.register(*good, config={"generations": 3})
    with pytest.raises(TypeError, match="on_generation must be callable"):
        mtpcr.register(*good, on_generation=3, **QUICK)


@pytest.mark.parametrize("call", ["register", "Config", "replace"])
def test_unknown_setting_is_a_type_error_naming_it(good, call):
    with pytest.raises(TypeError, match="generatoins"):
        if call == "register":
            mtpcr.register(*good, generatoins=3)
        elif call == "Config":
            mtpcr.Config(generatoins=3)
        else:
            mtpcr.Config().replace(generatoins=3)


def test_fewer_than_two_clouds_or_a_stray_argument_is_an_error(good):
    with pytest.raises(TypeError, match="at least two clouds"):
        mtpcr.register(good[0])
    with pytest.raises(TypeError, match="at least two clouds"):
        mtpcr.register()
    with pytest.raises(ValueError, match="cloud4"):
        mtpcr.register(*good, 5)
    with pytest.raises(TypeError, match="at least two clouds"):
        mtpcr.register(list(good))  # one list is one argument, not three clouds


def test_bad_ply_arguments(tmp_path):
    points = np.random.default_rng(0).normal(size=(20, 3))
    with pytest.raises(ValueError, match="points must have shape"):
        mtpcr.write_ply(tmp_path / "a.ply", points[:, :2])
    with pytest.raises(ValueError, match=r"colors must have shape \(20, 3\)"):
        mtpcr.write_ply(tmp_path / "a.ply", points, colors=np.zeros((19, 3), np.uint8))
    with pytest.raises(ValueError, match="colors must hold integers"):
        mtpcr.write_ply(tmp_path / "a.ply", points, colors=np.zeros((20, 3)))
    with pytest.raises(ValueError, match=r"colors\[2, 1\] = 256 is outside"):
        c = np.zeros((20, 3), np.int64)
        c[2, 1] = 256
        mtpcr.write_ply(tmp_path / "a.ply", points, colors=c)
    with pytest.raises(TypeError):
        mtpcr.read_ply(42)  # type: ignore[arg-type]
