"""Wear regions of the pump walls (pump/regions.py) and the verdict logic of the re-tested
findings (pump/findings.py)."""
import math

import numpy as np
import pytest

from pump.design import PumpDesign
from pump.findings import CANNOT_TELL, NOT_REPRODUCED, REPRODUCED, samples_needed, verdict
from pump.geometry import COMPONENTS, build_pump
from pump.regions import CASING_REGIONS, IMPELLER_REGIONS, REGIONS, estimate, pump_regions, volute_sector_names


@pytest.fixture(scope="module")
def geo():
    return build_pump(PumpDesign(inlet_length=0.06), resolution=0.5)


def test_every_triangle_has_a_region_of_its_component(geo):
    reg = pump_regions(geo)
    imp, cas = geo.impeller, geo.casing
    assert reg["impeller"].shape == (imp.num_triangles,) and reg["casing"].shape == (cas.num_triangles,)
    names_i = np.asarray(REGIONS)[reg["impeller"]]
    names_c = np.asarray(REGIONS)[reg["casing"]]
    assert set(names_i) <= set(IMPELLER_REGIONS) and set(names_c) <= set(CASING_REGIONS)
    comp_i = np.asarray(COMPONENTS)[imp.component]
    assert np.all(np.char.startswith(names_i[comp_i == "blade"].astype(str), "blade_"))
    assert set(names_i[comp_i == "hub"]) == {"hub"} and set(names_i[comp_i == "shroud"]) == {"shroud"}
    comp_c = np.asarray(COMPONENTS)[cas.component]
    assert set(names_c[comp_c == "tongue"]) == {"cutwater"}
    assert set(names_c[comp_c == "inlet"]) == {"suction_pipe"} and set(names_c[comp_c == "outlet"]) == {"discharge"}
    # every blade zone, every volute sector and every liner is present
    assert {"blade_leading_edge", "blade_pressure_side", "blade_suction_side", "blade_trailing_edge"} <= set(names_i)
    assert set(volute_sector_names()) - {"volute_000_045"} <= set(names_c)
    assert {"volute_side_front", "volute_side_back", "suction_liner", "back_liner"} <= set(names_c)


def test_liners_and_sectors_lie_where_their_names_say(geo):
    reg = np.asarray(REGIONS)[pump_regions(geo)["casing"]]
    cen = geo.casing.centroids()
    r = np.hypot(cen[:, 0], cen[:, 1])
    d = geo.design
    behind = np.isin(reg, ["suction_liner", "back_liner"])
    liner = np.isin(reg, ["volute_side_front", "volute_side_back"])
    # split at r2: every triangle of a side-room liner lies inside r2, every volute side triangle outside
    tri = geo.casing.vertices[geo.casing.faces]
    r_tri = np.hypot(tri[..., 0], tri[..., 1])
    assert np.all(r_tri[behind] <= d.r2 + 1e-12) and np.all(r_tri[liner] >= d.r2 - 1e-12)
    assert np.all(cen[reg == "suction_liner", 2] == pytest.approx(d.b2 + d.side_gap))
    assert np.all(cen[reg == "back_liner", 2] == pytest.approx(-d.side_gap))
    theta = np.degrees(np.mod(np.arctan2(cen[:, 1], cen[:, 0]), 2 * np.pi))
    for name in volute_sector_names():
        sel = reg == name
        lo, hi = int(name[7:10]), int(name[11:14])
        assert np.all((theta[sel] >= lo - 1e-9) & (theta[sel] < hi + 1e-9)), name
    # the side-room liners are a large share of the casing's side walls
    area = geo.casing.areas()
    assert area[behind].sum() > 0.5 * area[liner].sum()


def test_verdicts_follow_the_paired_differences():
    up = estimate(np.array([1.0, 1.2, 0.9, 1.1]))
    down = estimate(-np.array([1.0, 1.2, 0.9, 1.1]))
    wide = estimate(np.array([1.0, -1.0, 0.8, -0.6]))
    assert verdict({"a": up, "b": up}) == REPRODUCED
    assert verdict({"a": up, "b": down}) == NOT_REPRODUCED
    assert verdict({"a": up, "b": wide}) == CANNOT_TELL
    assert verdict({}) == CANNOT_TELL
    assert samples_needed({"a": up}) is None
    n = samples_needed({"a": wide})
    assert n > wide.n  # more samples than there are
    assert n == math.ceil(wide.n * (wide.half_width / abs(wide.mean)) ** 2)
    assert samples_needed({"a": estimate(np.array([1.0]))}) == -1


@pytest.mark.parametrize("phi,expected,absent", [
    (0.04, "pass at least 4x fewer particles per revolution", "about as many"),
    (0.01, "are at about this run's solids loading", "fewer particles"),
    (0.012, "are at about this run's solids loading", "1x"),
    (0.004, "are at a higher solids loading than this run", "fewer particles"),
    (0.025, "pass at least 2.5x fewer particles", "about as many")])
def test_report_says_plainly_how_the_paper_loading_compares(phi, expected, absent):
    """The report's sentence on what the paper's conditions (1 % solids) need: a factor where the
    loadings differ, plain words at about the paper's loading (no 'at least 1x fewer particles')."""
    from pump.outputs import _paper_needs

    for needs in (None, 120):
        results = {"wear": {"solids": {"volume_fraction": phi}, "window": {"samples": 40}},
                   "findings": {"f": {"per_area": {"samples_needed": needs}}}}
        text = _paper_needs(results)
        assert expected in text and absent not in text, text
        assert " 1x " not in text, text
