"""Parameter transforms: bounds always hold, the transform inverts, errors name the bounds."""

import jax
import numpy as np
import pytest

import socbjax as sj


@pytest.mark.parametrize(
    ("lower", "upper", "value"), [(0.0, None, 0.071), (0.0, 90.0, 70.0), (None, None, -0.3), (None, 1.0, -4.0)]
)
def test_round_trip_and_bounds(lower, upper, value):
    p = sj.Parameter("x", value, "1", lower=lower, upper=upper)
    z = p.to_z(value)
    assert float(p.to_value(z)) == pytest.approx(value, rel=1e-12, abs=1e-12)
    for far in (-50.0, 50.0):  # any unconstrained number maps inside the bounds
        v = float(p.to_value(far))
        assert (lower is None or v >= lower) and (upper is None or v <= upper)
    h = 1e-6
    fd = (float(p.to_value(z + h)) - float(p.to_value(z - h))) / (2 * h)
    assert float(jax.grad(p.to_value)(z)) == pytest.approx(fd, rel=1e-6)


def test_errors():
    with pytest.raises(ValueError, match="lower bound"):
        sj.Parameter("a", 1.0, "1", lower=2.0, upper=1.0)
    p = sj.Parameter("angle", 70.0, "deg", lower=0.0, upper=90.0)
    with pytest.raises(ValueError, match=r"outside its bounds \(0.0, 90.0\)"):
        p.check(90.0)
    with pytest.raises(ValueError, match="finite"):
        p.check(np.nan)
    assert set(sj.NUISANCE_PARAMETERS) == {"contact_point", "contact_offset", "baseline", "baseline_tilt", "force_scale"}
