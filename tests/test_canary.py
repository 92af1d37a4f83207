"""Canaries for the pinned JAX: jit must compute what eager computes.

jax/jaxlib 0.10.2 silently miscompiled a vmapped mat-vec followed by a
reduction on the CPU (jax-ml/jax#39103); jax-md 0.2.29 does not exclude it,
so pyproject.toml pins 0.10.1. These tests fail on a miscompiling release.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest


@pytest.mark.parametrize("dtype,n", [(jnp.float64, 16_385), (jnp.float32, 32_769)])
def test_vmapped_matvec_reduction_jit_equals_eager(dtype, n):
    # The reproducer of jax-ml/jax#39103.
    i = jnp.arange(n, dtype=dtype)
    x = jnp.stack((i, jnp.zeros_like(i), jnp.zeros_like(i)), axis=1)
    matrix = jnp.eye(3, dtype=dtype)

    def f(x):
        return jax.vmap(lambda row: jnp.sum((matrix @ row) ** 2))(x)

    # identity times a row, squared once and summed with zeros: one rounding
    expected = np.square(np.asarray(i))
    np.testing.assert_array_equal(np.asarray(f(x)), expected)
    np.testing.assert_array_equal(np.asarray(jax.jit(f)(x)), expected)


def test_jitted_scan_step_equals_eager():
    # A diffusion-like explicit step on a ring, the shape of the thermal DEM.
    n, steps = 20_000, 25
    rng = np.random.default_rng(0)
    t0 = jnp.asarray(rng.uniform(300.0, 1000.0, n))
    k = jnp.asarray(rng.uniform(0.1, 0.4, n))

    def step(t, _):
        flux = k * (jnp.roll(t, -1) - t) - jnp.roll(k, 1) * (t - jnp.roll(t, 1))
        return t + flux, jnp.sum(t)

    eager_t, eager_sums = t0, []
    for _ in range(steps):
        eager_t, s = step(eager_t, None)
        eager_sums.append(s)
    jit_t, jit_sums = jax.jit(lambda t: jax.lax.scan(step, t, None, length=steps))(t0)
    np.testing.assert_allclose(jit_t, eager_t, rtol=1e-13)
    np.testing.assert_allclose(jit_sums, np.array(eager_sums), rtol=1e-13)
    # the step conserves the total: an independent check on both
    np.testing.assert_allclose(jit_sums, float(jnp.sum(t0)), rtol=1e-12)
