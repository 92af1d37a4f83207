"""Checks of concrete user input at API boundaries, before anything is compiled.

Each check raises ``ValueError`` naming the field, the allowed range and the
first offending entry. They need concrete values; under ``jit`` invalid
states are flagged instead (e.g. :func:`sintercond.laws.neck.neck_status`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def shown(value) -> str:
    """``repr`` of a value a user gave, NumPy and JAX scalars and arrays as the plain numbers and lists they hold:
    a message says ``-0.00052``, not ``np.float64(-0.00052)``."""
    if isinstance(value, (np.generic, np.ndarray, jax.Array)):
        value = np.asarray(value).tolist()
    return repr(value)


def all_concrete(*values) -> bool:
    """No leaf of ``values`` (any pytrees) is a tracer: the input can be checked on the host."""
    return not any(isinstance(v, jax.core.Tracer) for v in jax.tree.leaves(values))


def concrete_arrays(caller: str, *values):
    """The values as broadcast float64 NumPy arrays; ``TypeError`` under tracing."""
    try:
        arrays = [np.asarray(v, dtype=np.float64) for v in values]
    except jax.errors.TracerArrayConversionError as err:
        raise TypeError(f"{caller} needs concrete values, not traced ones; validate before jit") from err
    return np.broadcast_arrays(*arrays)


def first_index(mask) -> tuple[int, ...]:
    return tuple(int(i) for i in np.argwhere(mask)[0])


def fail_where(bad, message) -> None:
    """Raise ``ValueError(message(idx))`` at the first True entry of ``bad``."""
    bad = np.asarray(bad)
    if bad.any():
        raise ValueError(message(first_index(bad)))


def require_finite(name: str, values) -> None:
    fail_where(~np.isfinite(values), lambda i: f"{name} must be finite; got {float(values[i])!r} at index {i}")


def require_positive(name: str, values, *, allow_zero: bool = False) -> None:
    """Finite and > 0 (>= 0 with ``allow_zero``); > 0 means a normal float, >= 2.2e-308."""
    if allow_zero:
        bad, rule = ~(np.isfinite(values) & (values >= 0)), ">= 0"
    else:
        bad, rule = ~(np.isfinite(values) & (values >= np.finfo(np.float64).tiny)), "> 0"
    fail_where(bad, lambda i: f"{name} must be finite and {rule}; got {float(values[i])!r} at index {i}")


def require_law_params(caller: str, law, params, label) -> None:
    """Raise ``ValueError`` unless every parameter of ``law`` (a conductance or kinetic law) is in its range.

    Finite and > 0; ``law.params_allowing_zero`` >= 0; ``law.params_any_sign``
    any finite value. ``label(name)`` is what the message calls the parameter.
    """
    for name, value in params.items():
        (value,) = concrete_arrays(caller, value)
        if name in law.params_any_sign:
            require_finite(label(name), value)
        else:
            require_positive(label(name), value, allow_zero=name in law.params_allowing_zero)


def law_params_valid(law, params, per_entry=False):
    """Under ``jit``: True where every parameter of a law is in its domain.

    Finite and > 0, except those in ``law.params_allowing_zero`` (>= 0) and
    ``law.params_any_sign`` (any finite value); the traced counterpart of the
    laws' concrete checks. One flag for all (``per_entry=False``), or per
    entry of parameters given per pair (broadcast).
    """
    combine = (lambda ok: ok) if per_entry else jnp.all
    ok = jnp.asarray(True)
    for name, value in params.items():
        value = jnp.asarray(value)
        if name in law.params_any_sign:
            ok = ok & combine(jnp.isfinite(value))
        elif name in law.params_allowing_zero:
            ok = ok & combine(jnp.isfinite(value) & (value >= 0))
        else:
            ok = ok & combine(jnp.isfinite(value) & (value > 0))
    return ok
