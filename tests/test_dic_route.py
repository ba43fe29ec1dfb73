"""The DIC route of the data: FE field -> speckle images -> IC-GN -> measured grid."""

import numpy as np
import pytest

from problems.inverse.data import make_data


@pytest.mark.slow
def test_dic_route_reproduces_the_fe_field_within_its_stated_uncertainty():
    fe = make_data("linear-compression", mesh="coarse", resolution_um=0)
    dic = make_data("linear-compression", mesh="coarse", route="dic")
    assert np.isfinite(dic.std_u_mm).mean() > 0.99  # nearly every subset converged
    z = np.concatenate(
        [
            ((dic.u_h - fe.u_h) / dic.std_u_mm[0]).ravel(),
            ((dic.u_v - fe.u_v) / dic.std_u_mm[1]).ravel(),
        ]
    )
    z = z[np.isfinite(z)]
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.5  # stated std is calibrated
    assert np.abs(z).max() < 6.0
    assert 5e-4 < np.median(dic.std_u_mm) < 5e-3  # ~1.6 um: 0.01 px at 0.15 mm/px
    assert np.array_equal(dic.reaction_kN, np.round(fe.reaction_kN / 0.1) * 0.1)
