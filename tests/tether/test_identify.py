"""Identifying the tether's normal drag coefficient c_n from the running-end force
(experiments/identify_tether.py): data from a finer chain plus noise, fit with a
coarser chain; c_n recovered within 5 % with a Gauss-Newton standard deviation."""

import identify_tether as it
import jax.numpy as jnp
import numpy as np
import pytest


@pytest.mark.slow
def test_c_n_recovered_from_end_force():
    # The end force converges like 1/N, and c_n absorbs about twice its relative
    # error: data from 50 elements, fit with 40 (about 1 % force bias).
    N_fit, N_data, noise, c_n = 40, 50, 1.0, 1.0
    t1 = float(it.scenario(4).t1)
    ts = jnp.linspace(0.0, t1, 41)
    clean, data = it.measurement(N_data, ts, noise, c_n=c_n, seed=1)
    # The end force must carry information on c_n: it is tens of N, above the noise.
    assert np.sqrt(np.mean(clean**2)) > 10 * noise
    r, gn, _ = it.identify(N_fit, ts, data, noise, 0.7 * c_n, steps=8, print_every=None)
    value, std = float(gn["values"][0]), float(gn["std"][0])
    assert abs(value / c_n - 1) < 0.05, (value, std)
    # The fitted value is a minimum of the loss: no lower loss along the run, and the
    # Gauss-Newton standard deviation resolves c_n far better than the 5 % band.
    assert r.losses[-1] <= r.losses[0]
    assert 0 < std < 0.05 * c_n
