"""Accuracy presets: solver and tolerances chosen from the work-precision study.

``ACCURACY_PRESETS[name]`` is a dict of keyword arguments for ``simulate``
(``solver``, ``rtol``, ``atol``). The choice comes from
``experiments/work_precision.py`` (results in ``experiments/results/``): for each
accuracy level, the fastest measured (solver, tolerance) whose end-mass error reached
it. Measured on the paper's pendulum, (eps, phi) variables, k = 40, l = 1 m,
EA = 1e6 N, 2 s, on a shared 2-core AMD EPYC (load 6-9, so absolute times are about
3x those of a quiet machine; the ratios between presets are what carry over).
Error: the largest end-mass distance over 41 save times from CVODE at
rtol = atol = 1e-12.

* ``"draft"``: Kvaerno5, rtol = atol = 1e-3 -- end-mass error 3.5e-4 m (3.5e-4 of
  the string length), 1.5 s. Kvaerno3 at 1e-3 was more accurate (1.2e-4 m) but
  twice as slow (3.0 s).
* ``"balanced"``: Kvaerno5, rtol = atol = 1e-5 -- error 4.6e-6 m, 5.7 s
  (1e-7 gives 2.6e-7 m in 7.7 s). Kvaerno3 at 1e-5: 4.9e-7 m in 19 s.
* ``"precise"``: Kvaerno5, rtol = atol = 1e-9 -- error 9.5e-9 m, 24 s.

Kvaerno5 was the fastest jaxstring solver at every accuracy level measured; on
this problem size CVODE (BDF, band Jacobian from JAX) reached the same accuracy
faster (see ``experiments/results/work_precision_headline.md``).
"""

ACCURACY_PRESETS = {
    "draft": {"solver": "kvaerno5", "rtol": 1e-3, "atol": 1e-3},
    "balanced": {"solver": "kvaerno5", "rtol": 1e-5, "atol": 1e-5},
    "precise": {"solver": "kvaerno5", "rtol": 1e-9, "atol": 1e-9},
}
