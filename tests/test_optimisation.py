"""Tests for calibration.optimisation (NSGA-II target matching, acceptable set)."""

import numpy as np
import pytest

from calibration.designs import ParameterSpace
from calibration.optimisation import NSGA2Settings, calibrate, evaluate_point, plot_acceptable_set
from calibration.paper_data import PAPER_OPTIMUM, RESPONSE_NAMES, TABLE8_NSGA2, TARGETS_DEG, load_paper_data
from calibration.surrogates import CVSurrogate, GaussianProcessRegressor

TARGETS = [TARGETS_DEG[n] for n in RESPONSE_NAMES]


@pytest.fixture(scope="module")
def data():
    return load_paper_data()


@pytest.fixture(scope="module")
def surrogate(data):
    # One fixed GP family (the CV winner of test_surrogates) to keep this file fast.
    gp = GaussianProcessRegressor(nu=1.5, warp=0.5, space=data.space)
    return CVSurrogate({"gp": gp}, space=data.space, n_repeats=1).fit(data.X_train, data.Y_train)


@pytest.fixture(scope="module")
def result(data, surrogate):
    return calibrate(surrogate, TARGETS, data.space, tolerance=1.0,
                     settings=NSGA2Settings(pop_size=100, n_generations=100, seed=1),
                     n_dense=20_000, response_names=list(RESPONSE_NAMES), support_X=data.X_train)


def test_defaults_are_table8():
    s = NSGA2Settings()
    assert (s.pop_size, s.n_generations, s.crossover_prob, s.crossover_eta, s.mutation_eta) == (
        TABLE8_NSGA2["pop_size"], TABLE8_NSGA2["n_generations"], TABLE8_NSGA2["crossover_prob"],
        TABLE8_NSGA2["crossover_eta"], TABLE8_NSGA2["mutation_eta"])


def test_compromise_hits_targets(result, surrogate):
    assert np.all(np.abs(result.compromise_y - TARGETS) <= 0.5)
    np.testing.assert_allclose(surrogate.predict(result.compromise_x[None])[0], result.compromise_y)
    assert result.space.contains(result.compromise_x)[0]


def test_acceptable_set_nonempty_and_within_tolerance(result, surrogate):
    A = result.acceptable_X
    assert len(A) > 0 and result.n_acceptable_from_nsga2 > 0
    Y = surrogate.predict(A)
    np.testing.assert_allclose(Y, result.acceptable_Y)
    assert np.all(np.abs(Y - TARGETS) <= 1.0)
    assert np.all(result.space.contains(A))
    for k, n in enumerate(result.space.names):
        assert result.acceptable_ranges[n] == (A[:, k].min(), A[:, k].max())
    # archive covers all generations: far more evaluations than one population
    assert 100 * 50 < result.n_evaluations <= 100 * 100
    assert result.acceptable_supported.shape == (len(A),)
    d = result.to_dict()
    assert d["acceptable_set_size"] == len(A) and "compromise_x" in d


def test_evaluate_paper_optimum(result, surrogate, data):
    out = evaluate_point(surrogate, PAPER_OPTIMUM, TARGETS, 5.0, data.space, result.acceptable_ranges)
    assert set(out) >= {"predicted", "abs_error", "within_tolerance", "inside_ranges"}
    assert out["within_tolerance"] == bool(np.all(np.abs(np.array(out["predicted"]) - TARGETS) <= 5.0))


def test_acceptable_ranges_on_analytic_problem():
    # y = (x0, x1): solutions x0 in [0.25, 0.35], x1 in [0.55, 0.65], x2 free.
    class Identity:
        def predict(self, X):
            return np.asarray(X)[:, :2]

    sp = ParameterSpace.from_bounds(["x0", "x1", "x2"], [0, 0, 0], [1, 1, 1])
    r = calibrate(Identity(), [0.3, 0.6], sp, tolerance=0.05,
                  settings=NSGA2Settings(pop_size=40, n_generations=30, seed=2), n_dense=5000)
    np.testing.assert_allclose(r.compromise_x[:2], [0.3, 0.6], atol=1e-2)
    lo = np.array([v[0] for v in r.acceptable_ranges.values()])
    hi = np.array([v[1] for v in r.acceptable_ranges.values()])
    np.testing.assert_allclose(lo, [0.25, 0.55, 0.0], atol=0.01)
    np.testing.assert_allclose(hi, [0.35, 0.65, 1.0], atol=0.01)
    # default tolerance = 5 % of the targets (paper Section 4.2)
    r5 = calibrate(Identity(), [0.3, 0.6], sp, settings=NSGA2Settings(pop_size=20, n_generations=5), n_dense=0)
    np.testing.assert_allclose(r5.tolerance, [0.015, 0.03])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(targets=[32.5]), "1 targets"),
        (dict(targets=[32.5, np.nan]), "NaN"),
        (dict(tolerance=0.0), "tolerance"),
        (dict(tolerance=[1.0, -1.0]), "tolerance"),
        (dict(compromise="median"), "compromise"),
        (dict(targets={"alpha_static_deg": 32.5}, response_names=list(RESPONSE_NAMES)), "missing"),
    ],
)
def test_bad_input_messages(surrogate, data, kwargs, match):
    args = dict(targets=TARGETS, settings=NSGA2Settings(pop_size=10, n_generations=2), n_dense=0)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        calibrate(surrogate, space=data.space, **args)


def test_settings_validation():
    with pytest.raises(ValueError, match="pop_size"):
        NSGA2Settings(pop_size=2)
    with pytest.raises(ValueError, match="crossover_prob"):
        NSGA2Settings(crossover_prob=1.5)


def test_plot_writes_png(result, tmp_path):
    p = tmp_path / "acc.png"
    plot_acceptable_set(result, str(p), reference=PAPER_OPTIMUM)
    assert p.stat().st_size > 10_000


class _LinearAngles:
    """Two angles linear in one friction coefficient [deg]."""

    def predict(self, X):
        x = np.asarray(X, float)[:, 0]
        return np.column_stack([20.0 + 20.0 * x, 35.0 + 10.0 * x])


def test_one_parameter_calibration_plots_its_acceptable_interval(tmp_path):
    """A campaign of one calibrated parameter ends with a plot too (the pairwise grid has no panel)."""
    space = ParameterSpace.from_bounds(["mu_s_pp"], [0.1], [0.9], units=["-"])
    res = calibrate(_LinearAngles(), [30.0, 40.0], space, tolerance=1.0,
                    settings=NSGA2Settings(pop_size=20, n_generations=10, seed=0), n_dense=2000,
                    response_names=["alpha", "beta"])
    assert len(res.acceptable_X) > 0
    p = tmp_path / "acc1.png"
    plot_acceptable_set(res, str(p))
    assert p.stat().st_size > 10_000
