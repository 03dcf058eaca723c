"""The Runge-Kutta tableaus kept as constants are scipy's, exactly."""

import numpy as np
import pytest
from scipy.integrate import DOP853, RK23, RK45

from ppod_ros.physics._rk import INTEGRATORS


@pytest.mark.parametrize("name, cls", [("bs3", RK23), ("dopri5", RK45), ("dop853", DOP853)])
def test_constant_tableaus_equal_scipys(name, cls):
    tab = INTEGRATORS[name]
    s = cls.n_stages
    assert np.array_equal(tab.A, np.asarray(cls.A, float)[:s, :s])
    assert np.array_equal(tab.B, np.asarray(cls.B, float)[:s])
    assert np.array_equal(tab.C, np.asarray(cls.C, float)[:s])
    if hasattr(cls, "E5"):
        assert tab.combined_error
        assert np.array_equal(tab.E, np.asarray(cls.E5, float))
        assert np.array_equal(tab.E3, np.asarray(cls.E3, float))
    else:
        assert not tab.combined_error
        assert np.array_equal(tab.E, np.asarray(cls.E, float))
    assert (tab.order, tab.error_order) == (cls.order, cls.error_estimator_order)


def test_the_solver_does_not_import_scipy_integrate():
    import subprocess
    import sys

    code = "import sys, ppod_ros.physics; print('scipy.integrate' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
