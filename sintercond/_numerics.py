"""NaN-safe elementary functions (the double-``where`` trick).

``jnp.sqrt`` has an infinite derivative at 0, and ``jnp.where`` does not stop
it: the cotangent of the branch not taken is 0, and ``0 * inf`` is NaN. The
functions here substitute a harmless argument where the input is singular,
evaluate, and select again, so values *and* gradients stay finite
(jax-md ``util.safe_mask``, optax ``safe_norm``).
"""

import jax
import jax.numpy as jnp


def materialized(x):
    """``x`` unchanged (bitwise, but ``-0.0`` becomes ``0.0``), computed into its own buffer before its consumers run.

    XLA's CPU fusion copies cheap elementwise producers into every consumer
    that reads them. A gather of ``a * b`` then reads both ``a`` and ``b`` at
    every gathered index (docs/devlog/thermal_gradient.md), and a per-contact scalar
    chain (a force magnitude, a stiffness) is evaluated again in each
    ``[c, 3]`` output that uses it, once per component (the contact laws,
    :func:`sintercond.sim.mechanics.pair_loads`). ``optimization_barrier`` is
    removed before fusion on the CPU; a reduction is not fused into its
    consumers, so ``x`` goes through a two-term sum with zero (``x + 0 = x``).
    float32 is summed in float64 (exact both ways): XLA:CPU gives float32
    reductions to its YNNPACK library fusions, which write the stacked pair
    out and sum it in a second kernel (docs/devlog/coupled_step.md, branch mat).
    """
    wide = x.dtype == jnp.float32 and jax.config.read("jax_enable_x64")
    y = x.astype(jnp.float64) if wide else x
    return jnp.sum(jnp.stack([y, jnp.zeros_like(y)], axis=-1), axis=-1).astype(x.dtype)


def safe_sqrt(x):
    """``sqrt(max(x, 0))`` whose gradient is 0, not NaN/inf, where ``x <= 0``."""
    positive = x > 0
    x_safe = jnp.where(positive, x, jnp.ones_like(x))
    return jnp.where(positive, jnp.sqrt(x_safe), jnp.zeros_like(x))


def sqrt_difference_of_squares(r, x):
    """``sqrt(r**2 - x**2)`` as ``sqrt((r - x)(r + x))``, NaN-safe at ``|x| = r``.

    The factored form keeps full relative accuracy when ``x << r`` (no
    cancellation in ``r**2 - x**2``) and when ``x -> r``.
    """
    return safe_sqrt((r - x) * (r + x))


def safe_divide(numerator, denominator, fill=0.0):
    """``numerator / denominator`` with ``fill`` (and zero gradient) where the denominator is 0."""
    nonzero = denominator != 0
    safe_den = jnp.where(nonzero, denominator, jnp.ones_like(denominator))
    return jnp.where(nonzero, numerator / safe_den, fill)


def as_float_arrays(*values):
    """Broadcast ``values`` to one shape and one floating dtype.

    The dtype follows JAX's promotion rules (a float32 array with Python
    scalars stays float32); integer-only input becomes the default float
    (float64 once ``sintercond`` is imported).
    """
    arrays = [jnp.asarray(v) for v in values]
    dtype = jnp.result_type(*arrays)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    return jnp.broadcast_arrays(*(a.astype(dtype) for a in arrays))


def safe_power(x, exponent):
    """``x**exponent`` for ``x > 0`` and 0 (with zero gradient) for ``x <= 0``.

    For fractional exponents (Hertz's ``delta^(3/2)``, ``delta^(1/4)``): the
    derivative ``exponent x^(exponent - 1)`` is finite at every positive
    float, and the substituted argument keeps it from reaching ``0**negative``
    at ``x = 0``.
    """
    positive = x > 0
    x_safe = jnp.where(positive, x, jnp.ones_like(x))
    return jnp.where(positive, x_safe**exponent, jnp.zeros_like(x))


def safe_norm(vectors, keepdims=False):
    """Euclidean norm over the last axis, with zero gradient (not NaN) at the zero vector."""
    return safe_sqrt(jnp.sum(vectors * vectors, axis=-1, keepdims=keepdims))
