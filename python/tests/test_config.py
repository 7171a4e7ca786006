"""mtpcr.Config: defaults, the paper's setting, attribute access, equality, round trips."""

from __future__ import annotations

import copy
import pickle

import pytest

import mtpcr

# The Rust Config's fields at the time of writing; new fields may be added (the bindings pick
# them up through serde), none of these may disappear.
KNOWN_FIELDS = [
    "population_size",
    "generations",
    "sample_ratio",
    "sampling",
    "p_intra",
    "p_inter",
    "top_ratio",
    "scale_factor",
    "sbx_eta_start",
    "sbx_eta_end",
    "alpha",
    "aiding_cap_ratio",
    "two_way_aiding",
    "unit_free_loop_term",
    "refresh_loop_term",
    "search",
    "num_threads",
    "seed",
]


def test_paper_setting():
    p = mtpcr.Config.paper()
    assert (p.population_size, p.generations, p.sample_ratio) == (100, 60, 0.05)
    assert (p.sampling, p.search) == ("farthest", "fast")
    assert (p.p_intra, p.p_inter, p.top_ratio, p.scale_factor) == (0.5, 0.5, 0.1, 0.5)
    assert (p.sbx_eta_start, p.sbx_eta_end, p.alpha, p.aiding_cap_ratio) == (2.0, 10.0, 0.05, 0.1)
    assert p.seed is None and p.two_way_aiding is False


def test_default_is_config_and_every_field_is_an_attribute():
    c = mtpcr.Config()
    assert c == mtpcr.Config.default()
    d = c.to_dict()
    assert [k for k in d if k in KNOWN_FIELDS] == KNOWN_FIELDS, "declaration order"
    for key, value in d.items():
        assert getattr(c, key) == value
        assert key in dir(c)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        c.nope  # noqa: B018


def test_keywords_override_and_round_trip():
    c = mtpcr.Config(
        generations=12, sampling="random", alpha=0, seed=2**64 - 1, two_way_aiding=True
    )
    assert c.generations == 12 and c.sampling == "random" and c.alpha == 0.0
    assert c.seed == 2**64 - 1 and c.two_way_aiding is True
    assert mtpcr.Config(**c.to_dict()) == c
    assert c != mtpcr.Config()
    assert c != "not a config"
    r = c.replace(generations=3)
    assert r.generations == 3 and c.generations == 12 and r.sampling == "random"
    assert repr(c).startswith("Config(") and "generations=12" in repr(c)
    assert "sampling='random'" in repr(c)
    assert eval(repr(c), {"Config": mtpcr.Config}) == c  # noqa: S307


def test_config_pickles_and_copies():
    c = mtpcr.Config(generations=7, search="exact", seed=3)
    assert pickle.loads(pickle.dumps(c)) == c
    assert copy.copy(c) == c and copy.deepcopy(c) == c


def test_config_is_immutable_and_unhashable():
    c = mtpcr.Config()
    with pytest.raises(AttributeError):
        c.generations = 3  # type: ignore[misc]
    with pytest.raises(TypeError):
        hash(c)


def test_module_metadata():
    assert isinstance(mtpcr.__version__, str) and mtpcr.__version__.count(".") == 2
    assert mtpcr.TASK_NAMES == ("J1-a", "J2-a", "J3-a", "J1-o", "J2-o", "J3-o")
    assert mtpcr.MIN_POINTS >= 3
    for name in mtpcr.__all__:
        obj = getattr(mtpcr, name)
        if callable(obj):
            assert obj.__doc__, f"{name} has no docstring"
