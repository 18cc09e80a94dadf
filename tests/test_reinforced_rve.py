"""The reinforced-soil RVE's sheet (issue 38): an endless woven sheet in a periodic cell
(cpp_dem.elements.reinforced). Alone, it gives its tensile stiffness per metre (the series
value of its bonds, woven.series_stiffness_per_metre); a prestress is locked into it. (The
grains around it: not yet, docs/periodic.md.)"""

import numpy as np
import pytest

from cpp_dem import ParameterError
from cpp_dem.build import woven
from cpp_dem.elements import reinforced


@pytest.mark.parametrize("preset", ["detailed", "standard"])
def test_the_sheet_alone_gives_its_series_stiffness_per_metre(preset):
    s, g, _, _, lz = reinforced.sheet_cell(preset=preset, apertures=(2, 1))
    lx0 = float(np.asarray(s.cell_matrix)[0, 0])
    assert lx0 == pytest.approx(2 * woven.preset_pitch(preset)[0])
    s.run(10)
    assert np.abs(np.asarray(s.bond_state()["force"])).max() < 1e-9  # closed, unloaded
    reinforced.stretch_x(s, 1e-4, 2000)
    eps = float(np.asarray(s.cell_matrix)[0, 0]) / lx0 - 1
    tx, ty = reinforced.sheet_tension_per_metre(s, lz)
    j = woven.series_stiffness_per_metre(preset)
    assert tx / eps == pytest.approx(j, rel=1e-4)
    # the cell stress is the sheet's alone: -sigma_xx x height is the same tension
    assert -float(np.asarray(s.cell_stress())[0, 0]) * lz == pytest.approx(tx, rel=1e-9)
    # and each longitudinal member carries its pitch's share
    f = g.member_axial_forces(s)[g.members(woven.LONGITUDINAL)]
    assert np.allclose(f, tx * woven.preset_pitch(preset)[1], rtol=1e-4)
    assert abs(ty) < 1e-6 * tx


def test_a_prestress_is_locked_into_the_sheet():
    s, g, _, _, lz = reinforced.sheet_cell(preset="detailed", prestress=2000.0)
    tx, _ = reinforced.sheet_tension_per_metre(s, lz)
    assert tx == pytest.approx(2000.0, rel=1e-3)
    s.run(20000)  # it stays: the cell holds the sheet stretched
    assert reinforced.sheet_tension_per_metre(s, lz)[0] == pytest.approx(tx, rel=1e-6)


@pytest.mark.parametrize("kw, msg", [
    (dict(apertures=(0, 1)), "apertures=(0, 1)"),
    (dict(prestress=-1.0), "prestress=-1.0: must be >= 0"),
    (dict(height=0.0), "height=0.0: must be > 0"),
])
def test_bad_sheet_cells_are_named(kw, msg):
    with pytest.raises(ParameterError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        reinforced.sheet_cell(**kw)


def test_a_sheet_needs_its_periodic_cell():
    import cpp_dem as cd

    s = cd.Scene()
    m = s.add_material(woven.woven_material("detailed"))
    with pytest.raises(ParameterError, match="no periodic cell"):
        woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=1, apertures_y=1, material=m,
                            periodic=True)
    s.set_periodic_cell(np.diag([0.03, 0.027, 0.03]))
    with pytest.raises(ParameterError, match="the sheet needs"):
        woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=1, apertures_y=1, material=m,
                            periodic=True)
