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
    assert {"side_liner_front", "side_liner_back", "casing_behind_shroud", "casing_behind_hub"} <= set(names_c)


def test_liners_and_sectors_lie_where_their_names_say(geo):
    reg = np.asarray(REGIONS)[pump_regions(geo)["casing"]]
    cen = geo.casing.centroids()
    r = np.hypot(cen[:, 0], cen[:, 1])
    d = geo.design
    behind = np.isin(reg, ["casing_behind_shroud", "casing_behind_hub"])
    liner = np.isin(reg, ["side_liner_front", "side_liner_back"])
    assert np.all(r[behind] <= d.r2) and np.all(r[liner] > d.r2)
    assert np.all(cen[reg == "casing_behind_shroud", 2] > d.b2) and np.all(cen[reg == "casing_behind_hub", 2] < 0)
    theta = np.degrees(np.mod(np.arctan2(cen[:, 1], cen[:, 0]), 2 * np.pi))
    for name in volute_sector_names():
        sel = reg == name
        lo, hi = int(name[7:10]), int(name[11:14])
        assert np.all((theta[sel] >= lo - 1e-9) & (theta[sel] < hi + 1e-9)), name
    # the discs' shadow is a large share of the casing's side walls, which no particle reaches
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
