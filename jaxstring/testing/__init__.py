"""Test support: independent peers of the string pendulum, used by the tests and the
benchmarks in ``experiments/``.

* ``jaxstring.testing.peers``: the string pendulum (three formulations, optional
  slack law) and the lumped-mass tether written out in NumPy/numba, integrated by
  CVODE (scikit-sundae) and scipy's ``solve_ivp`` on the same compiled functions;
* ``jaxstring.testing.references``: scipy and SUNDIALS integrators driving a scene's
  own JAX vector field and Jacobian through Python callbacks.

Neither is imported by jaxstring itself, and neither is imported here: import the
submodule you need. They need the optional ``bench`` extra (``pip install
".[bench]"``: numba, scikit-sundae, scipy).
"""
