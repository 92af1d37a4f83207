"""Self-adjoint linear maps with a cheap transpose, for every JAX transformation.

JAX transposes a gather ``x[idx]`` into a scatter-add, which on a CPU costs
several times the gather. The network Laplacian is symmetric, so its
transpose is the same gather; :func:`self_adjoint` tells JAX so through
``jax.custom_derivatives.linear_call`` (the function is its own transpose).
``linear_call`` has no batching rule in JAX 0.10, which ``jax.jacfwd``,
``jax.hessian`` and ``vmap`` of gradients need, so one is registered here: a
batched call is again a ``linear_call``, of the vmapped function, whose
transpose is the vmapped transpose.
"""

from __future__ import annotations

import jax
from jax._src import core
from jax._src.custom_derivatives import linear_call_p
from jax._src.interpreters import batching
from jax.custom_derivatives import linear_call


def self_adjoint(fn, residuals, x, transpose_fn=None):
    """``fn(residuals, x)``, linear in ``x`` and symmetric: its transpose is ``fn(residuals, .)`` itself.

    ``transpose_fn(residuals, ct)``: the same map written for cotangents
    (e.g. with its input materialised first, :func:`sintercond._numerics.materialized`); default ``fn``.
    """
    return linear_call(fn, fn if transpose_fn is None else transpose_fn, residuals, x)


def _eval(jaxpr, consts, args):
    return core.eval_jaxpr(jaxpr.jaxpr, jaxpr.consts, *consts, *args)


def _linear_call_batch(args, dims, *, callee, transpose_thunk, num_callee_consts, num_res):
    size = next(a.shape[d] for a, d in zip(args, dims) if d is not batching.not_mapped)
    args = [a if d is batching.not_mapped else batching.moveaxis(a, d, 0) for a, d in zip(args, dims)]
    axes = [None if d is batching.not_mapped else 0 for d in dims]
    split = (num_callee_consts, num_callee_consts + num_res)
    consts, res, lin = args[:split[0]], args[split[0]:split[1]], args[split[1]:]
    c_axes, r_axes, l_axes = axes[:split[0]], axes[split[0]:split[1]], axes[split[1]:]
    # linear inputs not batched are broadcast, so that the call stays linear in all of them
    lin = [x if ax == 0 else jax.numpy.broadcast_to(x, (size,) + x.shape) for x, ax in zip(lin, l_axes)]

    def forward(residuals, linear):
        c, r = residuals
        return jax.vmap(lambda c, r, lin: _eval(callee, c, (*r, *lin)), in_axes=(c_axes, r_axes, 0))(c, r, linear)

    def transpose(residuals, cotangents):
        c, r = residuals
        t_jaxpr, t_consts = transpose_thunk()
        return jax.vmap(lambda r, ct: _eval(t_jaxpr, t_consts, (*r, *ct)), in_axes=(r_axes, 0))(r, cotangents)

    out = linear_call(forward, transpose, (list(consts), list(res)), list(lin))
    return out, [0] * len(out)


batching.primitive_batchers[linear_call_p] = _linear_call_batch
