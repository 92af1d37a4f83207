"""A small fitting core on optax: constrained parameters, least squares, a jitted loop, uncertainties.

Parameters are a dict ``name -> value``, or any pytree of numbers and float
arrays (nested dicts, lists, tuples): its leaves are laid out as one flat
vector in reading order (a dict's keys as inserted), one entry per scalar,
named by its tree path (``"sintering.A"``, ``"kappa[2]"``). Each leaf has a
transform from an unconstrained variable (``Free``, ``Positive`` via softplus,
``Bounded`` via a sigmoid; elementwise on an array), so optax works on
unconstrained numbers. The whole optimisation
(``lax.while_loop`` over optax updates, with stopping on the gradient norm,
the relative loss change or a step limit) is one compiled function. At the
optimum the Gauss-Newton covariance ``s^2 (J^T J)^-1`` of the parameters
(``J`` the Jacobian of the weighted residuals, ``s^2`` the residual variance)
gives standard errors.

A model run through a simulation may be invalid at some parameters without
being NaN (a neighbour list that overflowed and dropped pairs): with
``invalid=True`` the model returns ``(prediction, flag)`` and the loop ORs the
flags of every evaluation it makes (the trial steps and the Jacobians
included), so :func:`least_squares` raises :class:`InvalidEvaluation` if any
iterate was computed from an invalid state, instead of a fit that silently
used one.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np
import optax


@dataclasses.dataclass(frozen=True)
class Free:
    """An unconstrained parameter."""

    def forward(self, u):
        return u

    def inverse(self, x):
        return x

    def log_det_jacobian(self, u):
        """``ln |dx/du|`` elementwise (the change of variables of a density, :mod:`fitting.posterior`)."""
        return jnp.zeros_like(u)

    def range(self) -> tuple:
        """``(low, high)``: the values ``forward`` reaches."""
        return (-math.inf, math.inf)


@dataclasses.dataclass(frozen=True)
class Positive:
    """A parameter > 0, ``x = softplus(u)``."""

    def forward(self, u):
        return jax.nn.softplus(u)

    def inverse(self, x):
        return x + jnp.log(-jnp.expm1(-x))  # softplus^-1, stable for small and large x

    def log_det_jacobian(self, u):
        """``ln |dx/du| = ln sigmoid(u)`` elementwise."""
        return jax.nn.log_sigmoid(u)

    def range(self) -> tuple:
        return (0.0, math.inf)


@dataclasses.dataclass(frozen=True)
class Bounded:
    """A parameter in ``(low, high)``, ``x = low + (high - low) sigmoid(u)``."""

    low: float
    high: float

    def forward(self, u):
        return self.low + (self.high - self.low) * jax.nn.sigmoid(u)

    def inverse(self, x):
        p = (x - self.low) / (self.high - self.low)
        return jnp.log(p) - jnp.log1p(-p)

    def log_det_jacobian(self, u):
        """``ln |dx/du| = ln(high - low) + ln sigmoid(u) + ln sigmoid(-u)`` elementwise."""
        return math.log(self.high - self.low) + jax.nn.log_sigmoid(u) + jax.nn.log_sigmoid(-u)

    def range(self) -> tuple:
        return (float(self.low), float(self.high))


class InvalidEvaluation(RuntimeError):
    """The model flagged one of the evaluations a fit made (``least_squares(..., invalid=True)``)."""


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Outcome of :func:`least_squares`.

    Attributes:
      params: fitted parameters in ``params0``'s structure (for a flat dict, a dict of floats); a scalar leaf is a
        float, an array leaf a NumPy array of its shape.
      stderr: standard errors in the same structure, Gauss-Newton at the optimum; ``inf`` when the data do not
        determine them (as many observations as parameters, or a rank-deficient Jacobian).
      covariance: ``[p, p]`` over the ``p`` fitted scalars, in the order of ``names``.
      names: one per fitted scalar, the path of its leaf (``"a"`` for a flat dict's key, ``"sintering.A"`` in a
        nested dict, ``"kappa[2]"`` for an element of an array leaf), in reading order (a dict's keys as inserted).
      loss_history: loss per step (NaN after the stop).
      steps: optimiser steps taken.
      residual_std: ``s``, the residual standard deviation (weighted units).
      converged: the optimiser stopped on its tolerance (``grad_tol`` or ``loss_tol``), not on
        ``max_steps``; False means the fit may not be at the optimum (raise ``max_steps``).
    """

    params: dict
    stderr: dict
    covariance: np.ndarray
    names: tuple
    loss_history: np.ndarray
    steps: int
    residual_std: float
    converged: bool = True

    @property
    def flat_params(self) -> dict:
        """``name -> value`` for every fitted scalar, in the order of ``names`` (``params`` itself for a flat dict)."""
        return dict(zip(self.names, _Layout.of(self.params)[1].tolist()))

    @property
    def flat_stderr(self) -> dict:
        """``name -> standard error`` for every fitted scalar, in the order of ``names``."""
        return dict(zip(self.names, _Layout.of(self.stderr)[1].tolist()))

    def to_tree(self, vector):
        """``vector``, one value per entry of ``names`` (e.g. ``np.diag(covariance)``), in ``params``' structure."""
        layout, _ = _Layout.of(self.params)
        vector = np.asarray(vector, dtype=np.float64)
        if vector.shape != (len(self.names),):
            raise ValueError(f"vector must have one value per fitted scalar, shape ({len(self.names)},); "
                             f"got shape {vector.shape}")
        return layout.host_tree(vector)

    def intervals(self, z=1.959964):
        """``(low, high)``, each in ``params``' structure: ``params -+ z stderr`` (95 % at the default ``z`` for many
        degrees of freedom; with few, take ``z`` from Student's t with ``len(y) - len(names)`` of them)."""
        value, error = _Layout.of(self.params)[1], _Layout.of(self.stderr)[1]
        return self.to_tree(value - z * error), self.to_tree(value + z * error)


def least_squares(model: Callable, x, y, params0, transforms=None,
                  weights=None, relative=False, learning_rate=0.05, max_steps=5000, grad_tol=1e-10,
                  loss_tol=1e-14, polish_steps=3, jacobian_model: Callable | None = None,
                  report_every=0, method="adam", invalid=False, invalid_message=None) -> FitResult:
    """Fit ``model(params, x) ~ y`` by weighted least squares: optax Adam, or Levenberg-Marquardt.

    Args:
      model: ``(params, x) -> prediction``, ``params`` in ``params0``'s structure; traceable and hashable (a
        function). The compiled loop is cached per model, parameter structure, transforms and settings, so
        repeated fits of the same kind on data of the same shapes (bootstrap, synthetic-recovery loops)
        compile once.
      x, y: data (``x`` any PyTree of arrays, or None; ``y`` an array of observations).
      params0: starting values (constrained space): a dict name -> number, or a pytree of them (nested dicts,
        lists, tuples) whose leaves are real numbers or float arrays; every scalar in it is fitted.
      transforms: ``Free()`` / ``Positive()`` / ``Bounded(lo, hi)`` in ``params0``'s structure (default Free): a
        dict may leave keys out (Free); a transform on an array leaf, or on a whole subtree, applies to each
        scalar in it.
      weights: per-observation weights ``1 / sigma`` (default 1).
      relative: residuals relative to ``y`` instead of absolute.
      learning_rate, max_steps, grad_tol, loss_tol: optimiser settings and stopping rule
        (gradient norm below ``grad_tol``, or relative loss change below ``loss_tol``).
      polish_steps: Gauss-Newton steps after Adam (accepted only if they lower the loss).
      jacobian_model: the same model in a form JAX can differentiate in forward mode, used for the
        Gauss-Newton Jacobian (default ``model``); for models whose reverse mode is a custom adjoint.
      report_every: print step, loss and gradient norm every this many optimiser steps (0: silent).
      method: ``"adam"`` (gradient descent with optax, reverse-mode gradients: any number of
        parameters) or ``"levenberg_marquardt"`` (damped Gauss-Newton on the unconstrained variables
        with forward-mode Jacobians of ``jacobian_model``: a handful of steps for a few parameters;
        ``learning_rate`` is then unused). Both loops are one compiled ``lax.while_loop``.
      invalid: the model (and ``jacobian_model``) returns ``(prediction, flag)``, ``flag`` a boolean scalar
        true where the evaluation must not be used (e.g. an overflowed pair list).
      invalid_message: what :class:`InvalidEvaluation` says to do about a flag (e.g. the setting to raise).

    Returns:
      :class:`FitResult`.

    Raises:
      ValueError: input that cannot be fitted (named: the argument, or the parameter's path), before compiling.
      InvalidEvaluation: ``invalid=True`` and any evaluation of the fit was flagged.
    """
    layout, starts, transforms = _check_fit_inputs(model, x, y, params0, transforms, weights, relative, method,
                                                   invalid)
    names = layout.names
    y = jnp.asarray(y)
    w = jnp.ones_like(y) if weights is None else jnp.broadcast_to(jnp.asarray(weights, y.dtype), y.shape)
    program = _fit_program(model, model if jacobian_model is None else jacobian_model, layout, transforms,
                           bool(relative), method, float(learning_rate), int(max_steps), float(grad_tol),
                           float(loss_tol), int(report_every), bool(invalid))
    u0 = jnp.concatenate([jnp.ravel(jnp.asarray(t.inverse(jnp.asarray(v, y.dtype)), y.dtype))
                          for v, t in zip(starts, transforms)])
    with jax.numpy_dtype_promotion("standard"):  # optax mixes its int32 step count with floats
        u, steps, history, flagged = program.run(u0, x, y, w)
    flags = [bool(flagged)]
    # Gauss-Newton covariance in the constrained parameters
    theta = program.constrained(u)

    # Adam gets close; a few Gauss-Newton steps finish the job (exact for a
    # linear model), kept only if they lower the loss and respect the bounds
    for _ in range(polish_steps):
        r, jac, flag = program.residuals_and_jacobian(theta, x, y, w)
        flags.append(bool(flag))
        candidate = theta - jnp.linalg.solve(jac.T @ jac, jac.T @ r)
        inside = all(bool(jnp.all(jnp.isfinite(t.inverse(candidate[a:b])))) for (a, b), t in zip(layout.bounds,
                                                                                                    transforms))
        r_candidate, _, flag = program.residuals_and_jacobian(candidate, x, y, w)
        flags.append(bool(flag))
        if inside and float(jnp.sum(r_candidate**2)) < float(jnp.sum(r**2)):
            theta = candidate
        else:
            break
    r, jac, flag = program.residuals_and_jacobian(theta, x, y, w)
    flags.append(bool(flag))
    if any(flags):
        where = "the optimiser's loop" if flags[0] else "the Gauss-Newton polish or the covariance"
        raise InvalidEvaluation(f"the model flagged an evaluation in {where} (parameters near "
                                f"{dict(zip(names, np.asarray(theta).tolist()))}): the fit would have used it"
                                + (f"; {invalid_message}" if invalid_message else ""))
    if not bool(jnp.all(jnp.isfinite(theta))):
        raise FloatingPointError(f"the fit diverged: parameters {dict(zip(names, np.asarray(theta).tolist()))}; "
                                 "check params0, the transforms' ranges and learning_rate")
    dof = int(r.shape[0]) - len(names)
    jtj = np.asarray(jac.T @ jac, dtype=np.float64)
    if dof == 0 or np.linalg.matrix_rank(jtj) < len(names):
        # as many observations as parameters, or parameters the data do not determine: no error estimate
        covariance = np.full((len(names), len(names)), np.inf)
        s2 = float(jnp.sum(r**2)) / max(dof, 1)
    else:
        s2 = float(jnp.sum(r**2)) / dof
        covariance = s2 * np.linalg.inv(jtj)
    params = layout.host_tree(np.asarray(theta, dtype=np.float64))
    stderr = layout.host_tree(np.sqrt(np.diag(covariance)))
    return FitResult(params, stderr, covariance, names, np.asarray(history), int(steps), float(np.sqrt(s2)),
                     int(steps) < int(max_steps))


def _check_fit_inputs(model, x, y, params0, transforms, weights, relative, method, invalid=False):
    """Raise ``ValueError`` naming the argument or the parameter's path for input :func:`least_squares` cannot fit
    (before compiling); else ``(layout, starting leaves, each leaf's transform)``, leaves in reading order."""
    from sintercond._validation import fail_where

    if method not in ("adam", "levenberg_marquardt"):
        raise ValueError(f"method must be 'adam' or 'levenberg_marquardt'; got {method!r}")
    if _children(params0) is None:
        raise ValueError("params0 must be a non-empty dict name -> starting value (or a pytree of them: nested dicts, "
                         f"lists, tuples); got {params0!r}")
    leaves = _walk(params0)[1]
    if not leaves:
        raise ValueError(f"params0 must be a non-empty dict name -> starting value; got {params0!r}: no parameters")
    for path, leaf in leaves:
        _check_start(f"params0{jax.tree_util.keystr(path)}", leaf)
    layout, _ = _Layout.of(params0)
    starts = [leaf for _, leaf in leaves]
    seen = {}
    for name, where in zip(layout.names, layout.scalar_paths()):
        if name in seen:
            raise ValueError(f"params0{seen[name]} and params0{where} have the same name {name!r} in the fit's "
                             "report: rename one key")
        seen[name] = where
    leaf_transforms = _leaf_transforms(params0, Free() if transforms is None else transforms)
    y_np = np.asarray(y, dtype=np.float64)
    if y_np.ndim == 0 or y_np.size == 0:
        raise ValueError(f"y must be a non-empty array of observations; got shape {y_np.shape}")
    fail_where(~np.isfinite(y_np), lambda i: f"y must be finite; got {y_np[i]!r} at index {i}")
    if relative:
        fail_where(y_np == 0, lambda i: f"y must be nonzero for relative=True (residuals are divided by y); "
                                        f"got 0 at index {i}")
    if y_np.size < len(layout.names):
        raise ValueError(f"y has {y_np.size} observations for {len(layout.names)} parameters: an underdetermined fit; "
                         "y needs at least as many observations as params0 has parameters")
    if weights is not None:
        w = np.asarray(weights, dtype=np.float64)
        try:
            w = np.broadcast_to(w, y_np.shape)
        except ValueError:
            raise ValueError(f"weights must broadcast to y's shape {y_np.shape}; got shape {w.shape}") from None
        fail_where(~(np.isfinite(w) & (w > 0)), lambda i: f"weights must be finite and > 0; got {w[i]!r} at index {i}")
    for path, leaf, t in zip(layout.paths, starts, leaf_transforms):
        _check_in_range(f"params0{path}", np.asarray(leaf, dtype=np.float64), t)
    try:
        # the tree is built inside, as the fit builds it: eval_shape's own flattening would sort a dict's keys
        out = jax.eval_shape(lambda theta, x: model(layout.unflatten(theta), x),
                             jnp.concatenate([jnp.ravel(jnp.asarray(v, y_np.dtype)) for v in starts]), x)
    except Exception as err:  # noqa: BLE001 - any failure to trace the model is the caller's to see, named
        raise ValueError(f"model(params0, x) cannot be evaluated: {type(err).__name__}: {err}") from None
    if invalid:
        if not (isinstance(out, tuple) and len(out) == 2 and getattr(out[1], "shape", None) == ()):
            raise ValueError("with invalid=True, model(params0, x) must return (prediction, flag), flag a boolean "
                             f"scalar; got {out!r}")
        out = out[0]
    if getattr(out, "shape", None) != y_np.shape:
        raise ValueError(f"model(params0, x) has shape {getattr(out, 'shape', None)} but y has shape {y_np.shape}; "
                         "they must be equal")
    return layout, starts, leaf_transforms


def _check_start(where, leaf):
    """Raise ``ValueError`` naming ``where`` unless ``leaf`` is a finite real number or a non-empty float array."""
    from sintercond._validation import fail_where

    v = np.asarray(leaf)
    if v.dtype.kind in "biu":
        raise ValueError(f"{where} is {'a bool' if v.dtype.kind == 'b' else 'an integer'} ({leaf!r}): a fitted "
                         "parameter is real, so write it as a float; a fixed setting belongs in the model, not in "
                         "params0")
    if v.dtype.kind != "f":
        raise ValueError(f"{where} must be a finite number or an array of them; got {leaf!r}")
    if v.size == 0:
        raise ValueError(f"{where} is an empty array: nothing to fit")
    fail_where(~np.isfinite(v), lambda i: f"{where}{_index(i)} must be a finite number; got {v[i]!r}")


def _check_in_range(where, v, t):
    """Raise ``ValueError`` naming ``where`` and the element unless the start ``v`` lies in ``t``'s range."""
    from sintercond._validation import fail_where

    if isinstance(t, Positive):
        fail_where(~(v > 0), lambda i: f"{where}{_index(i)} must be > 0 for its Positive transform; got {float(v[i])!r}")
    if isinstance(t, Bounded):
        fail_where(~((t.low < v) & (v < t.high)), lambda i: f"{where}{_index(i)} must be in ({t.low:g}, {t.high:g}) "
                                                            f"for its Bounded transform; got {float(v[i])!r}")


_TRANSFORMS = (Free, Positive, Bounded)


def _leaf_transforms(params0, transforms, default=None) -> tuple:
    """Each leaf's transform, in reading order: ``transforms`` has ``params0``'s structure, or a prefix of it (a
    transform on a subtree applies to each of its leaves); a dict may leave keys out (``default``: ``Free()``)."""

    def check(where, t):
        if isinstance(t, Bounded) and not (all(isinstance(b, numbers.Real) and not isinstance(b, bool)
                                               and math.isfinite(b) for b in (t.low, t.high)) and t.low < t.high):
            raise ValueError(f"{where} must have finite numbers low < high; got {t!r}")

    return _per_leaf(params0, transforms, "transforms", lambda t: isinstance(t, _TRANSFORMS),
                     "Free(), Positive() or Bounded(low, high)", check, Free() if default is None else default)


def _per_leaf(params0, spec, argument, is_item, what, check, default) -> tuple:
    """Each leaf's item of ``spec`` (a transform, a prior), in reading order: ``spec`` has ``params0``'s structure,
    or a prefix of it (an item on a subtree applies to each of its leaves); a dict may leave keys out
    (``default``). Errors name ``argument`` and the path; ``check(where, item)`` validates an item."""
    found = []

    def assign(node, t, path):
        where = f"{argument}{jax.tree_util.keystr(path)}"
        if is_item(t):
            check(where, t)
            found.extend([t] * len(_walk(node)[1]))
            return
        kids = _children(node)
        if kids is None:  # a parameter, and t is not an item
            if _children(t):
                raise ValueError(f"{where} is a {type(t).__name__} but params0{jax.tree_util.keystr(path)} is one "
                                 f"parameter (on an array, one item of {argument} applies to each element)")
            raise ValueError(f"{where} must be {what}; got {t!r}")
        if isinstance(node, Mapping) and isinstance(t, Mapping):
            unknown = [k for k in t if k not in node]
            if unknown:
                raise ValueError(f"{where} has keys that are not in params0{jax.tree_util.keystr(path)}: {unknown}; "
                                 f"it has {list(node)}")
            for key, child in kids:
                if isinstance(key, jax.tree_util.DictKey) and key.key in t:
                    assign(child, t[key.key], (*path, key))
                else:
                    found.extend([default] * len(_walk(child)[1]))
            return
        t_kids = _children(t)
        if t_kids is None or [k for k, _ in t_kids] != [k for k, _ in kids] or type(t) is not type(node):
            raise ValueError(f"{where} does not match params0{jax.tree_util.keystr(path)}'s structure: a "
                             f"{type(node).__name__} of {len(kids)}; got {t!r}")
        for (key, child), (_, t_child) in zip(kids, t_kids):
            assign(child, t_child, (*path, key))

    assign(params0, spec, ())
    return tuple(found)


def _children(node):
    """``[(key, child)]`` of a pytree node in reading order (a dict's keys as inserted: JAX sorts them), or None
    for a leaf."""
    if type(node) is dict:
        return [(jax.tree_util.DictKey(k), v) for k, v in node.items()]
    flat, treedef = jax.tree_util.tree_flatten_with_path(node, is_leaf=lambda child: child is not node)
    if treedef.num_nodes == 1 and treedef.num_leaves == 1:  # (treedef_is_leaf is also true of None and [])
        return None
    return [(path[0], child) for path, child in flat]


def _walk(node, path=()):
    """``(skeleton, [(path, leaf)])``: the hashable shape of a pytree (what :meth:`_Layout.unflatten` rebuilds) and
    its leaves in reading order."""
    kids = _children(node)
    if kids is None:
        return ("leaf",), [(path, node)]
    skeletons, leaves = [], []
    for key, child in kids:
        skeleton, below = _walk(child, (*path, key))
        skeletons.append(skeleton)
        leaves += below
    if type(node) is dict:
        return ("dict", tuple(key.key for key, _ in kids), tuple(skeletons)), leaves
    return ("node", jax.tree_util.tree_structure(node, is_leaf=lambda child: child is not node),
            tuple(skeletons)), leaves


def _index(i) -> str:
    """``"[2]"``, ``"[1,0]"`` for an element of an array leaf; ``""`` for a scalar."""
    return f"[{','.join(str(int(k)) for k in i)}]" if len(i) else ""


def _name(path) -> str:
    """A leaf's readable name: ``"sintering.A"``, ``"layers[1].kappa"``."""
    name = ""
    for key in path:
        if isinstance(key, jax.tree_util.DictKey):
            name += f"{'.' if name else ''}{key.key}"
        elif isinstance(key, jax.tree_util.GetAttrKey):
            name += f"{'.' if name else ''}{key.name}"
        elif isinstance(key, jax.tree_util.SequenceKey):
            name += f"[{key.idx}]"
        else:
            name += f"[{key.key}]"
    return name


@dataclasses.dataclass(frozen=True)
class _Layout:
    """Where each leaf of a parameter pytree sits in the flat vector the optimisers work on (hashable: part of the
    compiled fit's cache key). Leaves in reading order, a dict's keys as inserted, so a flat dict keeps its
    order in ``names`` and in the covariance."""

    skeleton: tuple  # the tree's nodes (_walk)
    paths: tuple  # per leaf, as jax.tree_util.keystr writes it: "['sintering']['A']"
    shapes: tuple  # per leaf
    names: tuple  # per scalar: "sintering.A", "kappa[2]"

    @staticmethod
    def of(tree) -> tuple[_Layout, np.ndarray]:
        """``(layout, the leaves' values as one float64 vector)``."""
        skeleton, leaves = _walk(tree)
        shapes = tuple(np.shape(leaf) for _, leaf in leaves)
        names = tuple(_name(path) + _index(i) for (path, _), shape in zip(leaves, shapes) for i in np.ndindex(shape))
        layout = _Layout(skeleton, tuple(jax.tree_util.keystr(path) for path, _ in leaves), shapes, names)
        vector = [np.ravel(np.asarray(leaf, dtype=np.float64)) for _, leaf in leaves if np.size(leaf)]
        return layout, np.concatenate(vector) if vector else np.zeros(0)

    @property
    def bounds(self) -> tuple:
        """``(start, stop)`` of each leaf in the flat vector."""
        stops = np.cumsum([int(np.prod(shape)) for shape in self.shapes], dtype=int).tolist()
        return tuple(zip([0, *stops[:-1]], stops))

    def scalar_paths(self) -> tuple:
        """Each scalar's path, as the error messages write it: ``"['kappa'][2]"``."""
        return tuple(path + _index(i) for path, shape in zip(self.paths, self.shapes) for i in np.ndindex(shape))

    def unflatten(self, vector, leaf=lambda v: v):
        """The flat ``vector`` (JAX or NumPy) in the tree's structure, each leaf passed through ``leaf``."""
        leaves = iter([leaf(vector[a:b].reshape(shape)) for (a, b), shape in zip(self.bounds, self.shapes)])

        def build(skeleton):
            if skeleton[0] == "leaf":
                return next(leaves)
            children = [build(child) for child in skeleton[2]]
            if skeleton[0] == "dict":
                return dict(zip(skeleton[1], children))
            return jax.tree_util.tree_unflatten(skeleton[1], children)

        return build(self.skeleton)

    def host_tree(self, vector):
        """A NumPy ``vector`` in the tree's structure: floats for scalar leaves, arrays for array leaves."""
        return self.unflatten(vector, lambda v: float(v) if v.shape == () else np.array(v))


@dataclasses.dataclass(frozen=True)
class _FitProgram:
    """The compiled pieces of one kind of fit (cached: calling least_squares again on data of the same
    shapes reuses them instead of compiling anew)."""

    run: Callable  # (u0, x, y, w) -> (u, steps, loss history, any evaluation flagged)
    constrained: Callable  # u -> theta
    residuals_and_jacobian: Callable  # (theta, x, y, w) -> (weighted residuals, d/dtheta, flagged), forward mode
    residuals: Callable  # (theta, x, y, w) -> (weighted residuals, flagged) of the model (any mode; not jitted)


@functools.lru_cache(maxsize=16)
def _fit_program(model, forward_model, layout, transforms, relative, method, learning_rate, max_steps, grad_tol,
                 loss_tol, report_every, invalid=False) -> _FitProgram:
    """``layout`` places the parameters in the flat vector, ``transforms`` holds each leaf's transform."""

    def constrained(u):
        return jnp.concatenate([jnp.ravel(t.forward(u[a:b])) for (a, b), t in zip(layout.bounds, transforms)])

    def weighted_residuals(fn, theta, x, y, w):
        """``(weighted residuals, flag)``; the flag is False for a model without one."""
        scale = jnp.abs(y) if relative else 1.0
        out = fn(layout.unflatten(theta), x)
        prediction, flag = out if invalid else (out, jnp.asarray(False))
        return jnp.ravel(w * (prediction - y) / scale), jnp.asarray(flag, bool)

    def report(k, value, g_norm):
        if report_every:
            jax.lax.cond(k % report_every == 0,
                         lambda: jax.debug.print("step {k}: loss {v:.6e}, |grad| {g:.3e}", k=k, v=value, g=g_norm),
                         lambda: None)

    def run(u0, x, y, w):
        if method == "adam":
            def loss(u):
                r, flag = weighted_residuals(model, constrained(u), x, y, w)
                return 0.5 * jnp.mean(r**2), flag

            loop = _adam_loop(loss, optax.adam(learning_rate), max_steps, grad_tol, loss_tol, report, y.dtype)
        else:
            loop = _levenberg_marquardt_loop(lambda u: weighted_residuals(forward_model, constrained(u), x, y, w),
                                             max_steps, grad_tol, loss_tol, report, y.dtype)
        return loop(u0)

    @jax.jit
    def residuals_and_jacobian(theta, x, y, w):
        def r(t):
            return weighted_residuals(forward_model, t, x, y, w)

        jac, (residual, flag) = jax.jacfwd(_with_itself_as_aux(r), has_aux=True)(theta)
        return residual, jac, flag

    return _FitProgram(jax.jit(run), jax.jit(constrained), residuals_and_jacobian,
                       functools.partial(weighted_residuals, model))


def _with_itself_as_aux(residuals):
    """``u -> (r, (r, flag))`` from ``residuals(u) -> (r, flag)``: one evaluation gives the Jacobian's primal and aux."""

    def f(u):
        r, flag = residuals(u)
        return r, (r, flag)

    return f


def _adam_loop(loss, optimizer, max_steps, grad_tol, loss_tol, report, dtype):
    """Optax loop: ``u0 -> (u, steps, loss history, flagged)`` (traced inside the compiled fit program).

    ``loss(u) -> (value, flag)``; ``flagged`` is the OR of the flags of every evaluation."""

    def run(u0):
        state = optimizer.init(u0)
        history = jnp.full(max_steps, jnp.nan, dtype)

        def cond(carry):
            _, _, k, _, g_norm, change, _ = carry
            return (k < max_steps) & (g_norm > grad_tol) & (change > loss_tol)

        def body(carry):
            u, state, k, history, _, _, flagged = carry
            (value, flag), grad = jax.value_and_grad(loss, has_aux=True)(u)
            updates, state = optimizer.update(grad, state, u)
            u_new = optax.apply_updates(u, updates)
            previous = jnp.where(k > 0, history[jnp.maximum(k - 1, 0)], jnp.inf)
            change = jnp.abs(previous - value) / jnp.maximum(jnp.abs(value), 1e-300)
            report(k, value, jnp.linalg.norm(grad))
            return u_new, state, k + 1, history.at[k].set(value), jnp.linalg.norm(grad), change, flagged | flag

        init = (u0, state, 0, history, jnp.inf, jnp.inf, jnp.asarray(False))
        u, _, k, history, _, _, flagged = jax.lax.while_loop(cond, body, init)
        return u, k, history, flagged

    return run


def _levenberg_marquardt_loop(residuals, max_steps, grad_tol, loss_tol, report, dtype):
    """Compiled Levenberg-Marquardt (Marquardt's diagonal scaling, damping x1/3 on success, x2 on failure).

    The loss history records the loss after every iteration (accepted or not). ``residuals(u) -> (r, flag)``;
    the loop also returns the OR of the flags of every evaluation (trial steps included)."""

    def loss_and_jacobian(u):
        jac, (r, flag) = jax.jacfwd(_with_itself_as_aux(residuals), has_aux=True)(u)
        return r, jac, flag

    def run(u0):
        history = jnp.full(max_steps, jnp.nan, dtype)
        r, jac, flag0 = loss_and_jacobian(u0)

        def cond(carry):
            *_, k, _, g_norm, change, _ = carry
            return (k < max_steps) & (g_norm > grad_tol) & (change > loss_tol)

        def body(carry):
            u, r, jac, damping, k, history, _, _, flagged = carry
            value = 0.5 * jnp.mean(r**2)
            grad = jac.T @ r / r.shape[0]
            a = jac.T @ jac
            diag = jnp.maximum(jnp.diag(a), 1e-12 * jnp.max(jnp.diag(a)))
            step = -jnp.linalg.solve(a + damping * jnp.diag(diag), jac.T @ r)
            r_new, jac_new, flag = loss_and_jacobian(u + step)
            new_value = 0.5 * jnp.mean(r_new**2)
            better = jnp.isfinite(new_value) & (new_value < value)
            u, r, jac = (jnp.where(better, u + step, u), jnp.where(better, r_new, r),
                         jnp.where(better, jac_new, jac))
            damping = jnp.where(better, damping / 3.0, damping * 2.0)
            # converged when a step, taken or not, changes the loss by less than loss_tol (relative)
            change = jnp.where(jnp.isfinite(new_value), jnp.abs(value - new_value) / jnp.maximum(value, 1e-300),
                               jnp.inf)
            change = jnp.where(damping > 1e12, 0.0, change)  # no step lowers the loss any more
            report(k, jnp.minimum(value, new_value), jnp.linalg.norm(grad))
            return (u, r, jac, damping, k + 1, history.at[k].set(jnp.minimum(value, new_value)),
                    jnp.linalg.norm(grad), change, flagged | flag)

        init = (u0, r, jac, jnp.asarray(1e-3, dtype), 0, history, jnp.asarray(jnp.inf, dtype),
                jnp.asarray(jnp.inf, dtype), flag0)
        u, _, _, _, k, history, _, _, flagged = jax.lax.while_loop(cond, body, init)
        return u, k, history, flagged

    return run
