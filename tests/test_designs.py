"""Tests for calibration.designs (parameter spaces, Latin hypercube, data support)."""

import numpy as np
import pytest

from calibration.designs import (
    Parameter,
    ParameterSpace,
    latin_hypercube,
    pairwise_support,
    paper_parameter_space,
)


def _space():
    return ParameterSpace.from_bounds(["a", "b", "c"], [0.0, -1.0, 10.0], [0.8, 1.0, 20.0], ["-", "m", "Pa"])


@pytest.mark.parametrize("optimization", ["random-cd", None])
@pytest.mark.parametrize("n", [1, 7, 140])
def test_lhs_each_stratum_hit_once_and_bounds(n, optimization):
    sp = _space()
    X = latin_hypercube(sp, n, seed=3, optimization=optimization)
    assert X.shape == (n, sp.dim)
    assert np.all(X >= sp.lower) and np.all(X <= sp.upper)
    U = sp.to_unit(X)
    strata = np.floor(U * n).astype(int)
    for k in range(sp.dim):
        assert sorted(strata[:, k].tolist()) == list(range(n)), f"dimension {k} not stratified"


def test_lhs_reproducible_and_seed_dependent():
    sp = paper_parameter_space()
    a = latin_hypercube(sp, 20, seed=1)
    assert np.array_equal(a, latin_hypercube(sp, 20, seed=1))
    assert not np.allclose(a, latin_hypercube(sp, 20, seed=2))


def test_random_cd_lowers_discrepancy():
    from scipy.stats import qmc

    sp = paper_parameter_space()
    plain = qmc.discrepancy(sp.to_unit(latin_hypercube(sp, 64, seed=0, optimization=None)))
    opt = qmc.discrepancy(sp.to_unit(latin_hypercube(sp, 64, seed=0, optimization="random-cd")))
    assert opt < plain


def test_unit_roundtrip_and_accessors():
    sp = _space()
    X = np.array([[0.4, 0.0, 15.0], [0.0, -1.0, 20.0]])
    U = sp.to_unit(X)
    np.testing.assert_allclose(U, [[0.5, 0.5, 0.5], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(sp.from_unit(U), X)
    assert sp.names == ["a", "b", "c"] and sp.units == ["-", "m", "Pa"] and len(sp) == 3
    assert sp.as_dict([0.1, 0.2, 11.0]) == {"a": 0.1, "b": 0.2, "c": 11.0}
    assert sp.contains([[0.1, 0.0, 12.0], [0.9, 0.0, 12.0]]).tolist() == [True, False]


def test_paper_space_matches_table6():
    sp = paper_parameter_space()
    assert sp.names == ["mu_s_pp", "mu_r_pp", "mu_s_pw", "mu_r_pw"]
    np.testing.assert_array_equal(sp.lower, 0.0)
    np.testing.assert_array_equal(sp.upper, 0.8)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: Parameter("x", 1.0, 1.0), "lower bound"),
        (lambda: Parameter("x", 2.0, 1.0), "lower bound"),
        (lambda: Parameter("x", 0.0, np.nan), "finite"),
        (lambda: Parameter("", 0.0, 1.0), "name"),
        (lambda: ParameterSpace((Parameter("x", 0, 1), Parameter("x", 0, 2))), "unique"),
        (lambda: ParameterSpace(()), "at least one"),
        (lambda: ParameterSpace.from_bounds(["a", "b"], [0, 0], [1]), "same length"),
        (lambda: latin_hypercube(paper_parameter_space(), 0), "n"),
        (lambda: latin_hypercube(paper_parameter_space(), 2.5), "integer"),
        (lambda: latin_hypercube(paper_parameter_space(), 5, optimization="best"), "optimization"),
        (lambda: paper_parameter_space().to_unit(np.zeros((3, 3))), "4 columns"),
        (lambda: paper_parameter_space().to_unit([[0.1, np.nan, 0.1, 0.1]]), "NaN"),
    ],
)
def test_bad_input_messages(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_pairwise_support_detects_unsampled_combination():
    sp = ParameterSpace.from_bounds(["a", "b", "c"], [0, 0, 0], [1, 1, 1])
    # design only covers a+b <= 1 (lower-left triangle in the a-b projection)
    rng = np.random.default_rng(0)
    D = rng.random((400, 3))
    D = D[D[:, 0] + D[:, 1] <= 1.0]
    counts, pairs = pairwise_support(np.array([[0.2, 0.2, 0.5], [0.9, 0.9, 0.5]]), D, sp, half_width=0.05)
    assert pairs[0] == ("a", "b")
    assert counts[0].min() > 0
    assert counts[1, 0] == 0 and counts[1, 1] > 0
