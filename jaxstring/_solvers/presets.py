"""Accuracy presets: solver and tolerances chosen from the work-precision study.

``ACCURACY_PRESETS[name]`` is a dict of keyword arguments for ``simulate``
(``solver``, ``rtol``, ``atol``). The choice comes from
``experiments/work_precision.py`` (``experiments/results/work_precision.md``): for
each accuracy level, the fastest measured (solver, tolerance) whose end-mass error
reached it. Measured on the paper's pendulum in (eps, phi) variables, k = 40,
l = 1 m, EA = 1e6 N, 2 s, on a shared 2-core AMD EPYC (load 6-14, so absolute times
are several times those of a quiet machine; the ratios are what carry over). Error:
the largest end-mass distance over 41 save times from CVODE at rtol = atol = 1e-12.
CVODE (BDF, band Jacobian from JAX) needed 1.1 s, 1.6 s and 3.9 s for errors of
1e-3, 1e-5 and 1e-7 m in the same run.

* ``"draft"``: Rodas5P, rtol = atol = 1e-3 -- end-mass error 1.5e-4 m, 0.25 s
  (Kvaerno5 at 1e-3: 3.0e-4 m, 0.35 s).
* ``"balanced"``: Rodas5P, rtol = atol = 1e-5 -- error 2.0e-6 m, 0.53 s
  (Kvaerno5: 1.7e-6 m, 0.97 s).
* ``"precise"``: Rodas5P, rtol = atol = 1e-9 -- error 3.2e-10 m, 3.7 s
  (Kvaerno5: 9.5e-9 m, 2.5 s).

At EA = 1e9 in (eps, phi) the same settings give 1.3e-4, 1.5e-6 and 1.1e-10 m in
0.39, 0.86 and 4.3 s. In displacement variables Rosenbrock methods lose accuracy on
the stiff geometric nonlinearity (Rodas5P at rtol 1e-3, EA = 1e9: 1.5e-2 m in 45 s);
there pass ``solver="bdf"`` instead of a preset (EA = 1e6, rtol 1e-7: 2.2e-6 m in
0.47 s, 0.17x CVODE's time for the same error).
"""

ACCURACY_PRESETS = {
    "draft": {"solver": "rodas5p", "rtol": 1e-3, "atol": 1e-3},
    "balanced": {"solver": "rodas5p", "rtol": 1e-5, "atol": 1e-5},
    "precise": {"solver": "rodas5p", "rtol": 1e-9, "atol": 1e-9},
}
