"""A material's parameters are one field list (cpp_dem.material_fields): every parameter of
every law goes through the keywords, the attributes, the repr, the pickle, replace and the
checkpoint from that list alone, so a parameter added to a law is covered here without a new
line (docs/developing.md, "Adding a parameter to a law")."""

import math
import pickle
import struct

import pytest

import cpp_dem as dem
from cpp_dem import _core

LAWS = [law["name"] for law in dem.contact_laws()]


def _allowed_value(f) -> float:
    """A value inside the field's range that is not its default."""
    lo, hi = f["lo"], f["hi"]
    if math.isinf(lo) and math.isinf(hi):
        v = 1.2345
    elif math.isinf(hi):
        v = lo + 0.3 + abs(lo) * 0.5
    elif math.isinf(lo):
        v = hi - 0.3 - abs(hi) * 0.5
    else:
        v = lo + 0.37 * (hi - lo)
    assert v != f["default"]
    return v


def _bad_value(f) -> float:
    """A value outside the field's range (its open bound, or past its closed one)."""
    if not math.isinf(f["lo"]):
        return f["lo"] if not f["lo_closed"] else f["lo"] - 1.0
    return f["hi"] if not f["hi_closed"] else f["hi"] + 1.0


def _every_field(law: str) -> dict:
    return {f["name"]: _allowed_value(f) for f in dem.material_fields(law)}


@pytest.mark.parametrize("law", LAWS)
def test_every_parameter_goes_through_keywords_attributes_repr_pickle_and_replace(law):
    given = _every_field(law)
    if law == "linear":
        given["poisson"] = 0.21  # (the linear law's own rule: k_s/k_n in (0, 0.5])
    m = dem.Material(model=law, **given)
    back = pickle.loads(pickle.dumps(m))
    for name, value in given.items():
        assert getattr(m, name) == pytest.approx(value, rel=1e-15)
        assert getattr(back, name) == getattr(m, name)  # (bitwise: stored values pickled)
        assert f"{name}=" in repr(m)
    assert m.as_dict() == {"model": law, **{k: getattr(m, k) for k in given}}
    for name, value in given.items():
        f = next(f for f in dem.material_fields(law) if f["name"] == name)
        other = f["default"] if f["default"] is not None else value * 0.999
        r = m.replace(**{name: other})
        assert getattr(r, name) == other
        assert {k: v for k, v in r.as_dict().items() if k != name} == \
            {k: v for k, v in m.as_dict().items() if k != name}


@pytest.mark.parametrize("law", LAWS)
def test_every_parameter_is_checked_against_its_range_and_a_required_one_named(law):
    base = {f["name"]: _allowed_value(f) for f in dem.material_fields(law)}
    base["poisson"] = 0.21
    for f in dem.material_fields(law):
        bad = _bad_value(f)
        with pytest.raises(dem.ParameterError, match=rf"^{f['name']}=") as err:
            dem.Material(model=law, **{**base, f["name"]: bad})
        assert f["allowed"].split(" (")[0] in str(err.value) or f["name"] == "poisson"
        with pytest.raises(dem.ParameterError, match=rf"^{f['name']}='x': must be a number"):
            dem.Material(model=law, **{**base, f["name"]: "x"})
        if f["default"] is None:
            with pytest.raises(dem.ParameterError, match=rf"Material: {f['name']} is required"):
                dem.Material(model=law, **{k: v for k, v in base.items() if k != f["name"]})
    with pytest.raises(dem.ParameterError, match=r"damp_normal=0.1: not a parameter of a '\w+' "
                       r"material; allowed: .*did you mean damping_normal"):
        dem.Material(model=law, **base, damp_normal=0.1)


def _scene_with(material):
    s = dem.Scene()
    s.add_material(material)
    return s


@pytest.mark.parametrize("law", LAWS)
def test_the_checkpoint_stores_every_parameter_by_name(law):
    given = _every_field(law)
    given["poisson"] = 0.21
    m = dem.Material(model=law, **given)
    blob = bytes(_core._checkpoint_save(_scene_with(m)))
    t = dem.Scene()
    _core._checkpoint_load(t, blob)
    assert t.material(0).as_dict() == m.as_dict()
    # (a parameter name, then its stored value: 8 bytes)
    key = struct.pack("<Q", len(b"rolling_friction")) + b"rolling_friction"
    at = blob.index(key)
    # a blob without the parameter (a build before it existed) loads with its default
    n_at = blob.rindex(struct.pack("<Q", len(dem.material_fields(law))), 0, at)
    fewer = (blob[:n_at] + struct.pack("<Q", len(dem.material_fields(law)) - 1)
             + blob[n_at + 8:at] + blob[at + len(key) + 8:])
    u = dem.Scene()
    _core._checkpoint_load(u, fewer)
    assert u.material(0).rolling_friction == 0.0
    assert u.material(0).young == m.young
    # a parameter this build does not know is refused by name
    unknown = blob.replace(b"rolling_friction", b"rolling_frictiom")
    with pytest.raises(dem.ParameterError, match=r"material 0 \(\w+\): parameter "
                       r"'rolling_frictiom' is not one of this build's"):
        _core._checkpoint_load(dem.Scene(), unknown)


def test_a_material_of_another_law_meets_a_law_with_the_shared_parameters():
    hm = dem.Material(model="hertz_mindlin", density=2650, young=7e7, poisson=0.25,
                      friction_angle_deg=30)
    lin = dem.Material(model="linear", density=2650, young=7e7, poisson=0.25,
                       friction_angle_deg=30)
    # (different laws meet with the linear one: the same as two linear materials)
    a = dem.mix_materials(hm, lin, 0.01, 0.02, 1.0, 2.0)
    b = dem.mix_materials(lin, lin, 0.01, 0.02, 1.0, 2.0)
    assert a.model == "linear" and (a.kn, a.ks) == (b.kn, b.ks)


def test_the_material_helpers_pass_on_the_optional_parameters_only():
    m = dem.linear_material(density=2650, young=1e7, poisson=0.3, friction_angle_deg=30,
                            rolling_stiffness=0.5, rolling_friction=0.1)
    assert (m.rolling_stiffness, m.rolling_friction) == (0.5, 0.1)
    with pytest.raises(dem.ParameterError, match=r"damp_shear=0.1: not a parameter this helper "
                       r"passes on to a 'linear' material; .*did you mean damping_shear"):
        dem.linear_material(density=2650, young=1e7, poisson=0.3, friction_angle_deg=30,
                            damp_shear=0.1)
    with pytest.raises(dem.ParameterError, match=r"friction_angle_deg=30: not a parameter this"):
        dem.hertz_mindlin_material(density=2650, shear_modulus=1e7, poisson=0.3,
                                   friction_coefficient=0.5, friction_angle_deg=30)
