"""Riemannian trust regions on ``S_M = {XᵀMX = I}`` as an ``optimistix`` minimiser (Absil, Baker,
Gallivan, Found. Comput. Math. 2007; docs/maths.md §9, eq. (9.13)).

``optx.minimise(fn, RiemannianTrustRegion(S, rtol, atol), X0, args, max_steps=...)``. Each outer
iteration builds the second-order model of ``F∘R_X`` on ``T_X`` in the M-weighted metric
``⟨a, b⟩ = tr(aᵀMb)``,

    ``m(η) = F(X) + ⟨grad F, η⟩ + ½⟨η, Hess F(X)[η]⟩``,  ``‖η‖_P ≤ Δ``,

solves it approximately by truncated CG (``stiefel.solvers.tcg``), and compares the actual with the predicted
decrease, ``ρ = (F(X) − F(R_X(η))) / (m(0) − m(η))`` (both regularised by ``10³·ε·max(1, |F|)``, as
Manopt does, so round-off near convergence does not reject good steps): the step is accepted when
``ρ > rho_prime``; the radius is quartered when ``ρ < ¼`` and doubled (up to ``max_radius``) when
``ρ > ¾`` and the step reached the boundary.

Hessian (``hessian=``): ``"exact"`` — ``P_X(M⁻¹ ∇²F[η] − η sym(XᵀG))`` with ``∇²F[η]`` by forward-over-
reverse autodiff, the gradient linearised once per outer iteration (``jax.linearize``); ``"fd"`` — the
finite difference of the Riemannian gradient along the retraction,
``(P_X grad F(R_X(tη)) − grad F(X))/t`` with ``t‖η‖ = 2⁻¹⁴`` (Manopt's default approximation; one
gradient evaluation per product, for objectives autodiff cannot differentiate twice).

Preconditioner: as in the first-order solvers, a callable ``Y ↦ PY`` with ``P`` SPD on ``R^{n×k}``
(e.g. ``stiefel.shifted_inverse(W, M, σ).solve``), applied to tangent residuals as
``r ↦ P_X(P M r)`` (SPD on ``T_X`` in ``⟨·,·⟩``); the trust region is then measured in
``‖η‖_P² = ⟨η, P⁻¹η⟩``.

Convergence: the Riemannian gradient norm (the manifold's metric) ``≤ atol + rtol·|F|`` at an accepted
iterate. ``stats["status"]`` is a ``stiefel.Status``: ``CONVERGED``, ``MAX_ITERS``, ``NON_FINITE`` (the
start, or the last rejected trial when the radius collapsed), ``TRUST_REGION_COLLAPSED`` (``Δ`` fell
below ``min_radius`` with no acceptable step), ``INDEFINITE_PRECONDITIONER`` (``⟨Pr, r⟩ ≤ 0`` in the
inner solve). Counters: ``n_fevals`` (objective values), ``n_grads`` (gradients, including one per
outer iteration for the linearisation), ``n_hvps`` (Hessian-vector products), ``n_inner``,
``n_accepted``. All numeric options are runtime values: changing them never recompiles.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..manifolds import tangent_algebra as ta
from ..runtime.compilation import host_array, is_traced
from ..errors import ParameterError, ShapeError, StiefelError
from ..manifolds.manifold import GeneralizedStiefel
from .minimisers import _budget, _check_manifold, _scalar, to_optx_result
from .preconditioning import at_point
from ..manifolds.product import Product
from ..result import History, Status
from .tcg import TCGStop, truncated_cg
from ..validation import check_count, checked_number, checked_order, is_traced_value

__all__ = ["RiemannianTrustRegion", "TRState", "HESSIANS"]

HESSIANS = ("exact", "fd")
FD_STEP = 2.0 ** -14


class TRState(NamedTuple):
    X: jax.Array
    F: jax.Array
    G: jax.Array  # Euclidean gradient ∂F/∂X
    rg: jax.Array  # Riemannian gradient of the M-weighted metric
    gnorm: jax.Array  # manifold-metric gradient norm (the reported one)
    radius: jax.Array
    it: jax.Array
    status: jax.Array  # stiefel.Status, −1 while running
    rho: jax.Array  # last ratio actual / predicted decrease
    inner_stop: jax.Array  # last TCGStop code
    n_fevals: jax.Array
    n_grads: jax.Array
    n_hvps: jax.Array
    n_inner: jax.Array
    n_accepted: jax.Array
    history: History
    aux: Any


class RiemannianTrustRegion(optx.AbstractMinimiser):
    """Riemannian trust regions with truncated CG (module docstring).

    ``RiemannianTrustRegion(S, rtol=0.0, atol=1e-6, *, hessian="exact", preconditioner=None, radius=None,
    max_radius=None, rho_prime=0.1, max_inner=None, kappa=0.1, theta=1.0, ...)``

    Fields (scalars are runtime arrays):
      manifold: the ``GeneralizedStiefel`` or ``stiefel.Product``; rtol, atol: the gradient-norm stopping test.
      hessian: ``"exact"`` (autodiff) or ``"fd"`` (finite differences of the gradient).
      preconditioner: None, ``Y ↦ PY`` (P SPD) or a ``stiefel.PointPreconditioner`` (``P_X`` at each outer
        iterate: the inner CG and the trust-region norm of that iteration use it); not with a ``Product``
        (``ParameterError``).
      radius: initial ``Δ0 > 0`` (default ``max_radius/8``); max_radius: ``Δ̄ > 0`` (default the manifold's
        ``typical_dist``, ``√k`` on S_M, Manopt's); min_radius: the collapse threshold (default
        ``10⁻¹²·max_radius``).
      rho_prime: acceptance threshold in ``[0, ¼)``; rho_regularization: the ``10³`` above.
      max_inner: inner iterations per outer one (default: the manifold dimension, at most 10⁶);
        kappa ∈ (0, 1), theta ≥ 0: the inner residual target ``‖r0‖ min(‖r0‖^θ, κ)``.
      monitor, history, budget: as in ``stiefel.RiemannianCG``.

    Options are checked on construction (``ParameterError`` naming the option, its value and the rule; a
    defaulted radius is named as one), including ``min_radius ≤ radius ≤ max_radius``; traced options when the
    program runs (``eqx.error_if``, ``stiefel.validation.checked_number``). The start ``y0`` is checked against
    the manifold's shape(s) in ``init`` (``ShapeError``).
    """

    manifold: GeneralizedStiefel | Product
    rtol: jax.Array = eqx.field(converter=_scalar, default=0.0)
    atol: jax.Array = eqx.field(converter=_scalar, default=1e-6)
    hessian: str = eqx.field(static=True, default="exact")
    preconditioner: Callable | None = None
    radius: jax.Array | None = eqx.field(default=None)
    max_radius: jax.Array | None = eqx.field(default=None)
    min_radius: jax.Array | None = eqx.field(default=None)
    rho_prime: jax.Array = eqx.field(converter=_scalar, default=0.1)
    rho_regularization: jax.Array = eqx.field(converter=_scalar, default=1e3)
    max_inner: jax.Array | None = eqx.field(default=None)
    kappa: jax.Array = eqx.field(converter=_scalar, default=0.1)
    theta: jax.Array = eqx.field(converter=_scalar, default=1.0)
    monitor: Callable | None = None
    history: int = eqx.field(static=True, default=0)
    budget: jax.Array | None = eqx.field(converter=_budget, default=None)
    norm: Any = eqx.field(static=True, default=None)

    def __post_init__(self):
        _check_manifold(self.manifold, self.preconditioner)
        if self.hessian not in HESSIANS:
            raise StiefelError(f"unknown hessian {self.hessian!r}; choose one of {HESSIANS}")
        S = self.manifold
        # the radii: each in range, then min_radius ≤ radius ≤ max_radius (a default is named as one)
        max_label, radius_label, min_label = "max_radius", "radius (initial trust-region radius)", "min_radius"
        if self.max_radius is None:
            self.max_radius, max_label = S.typical_dist, "max_radius (default: the manifold's typical_dist)"
        self.max_radius = checked_number(max_label, self.max_radius, low=0, low_open=True)
        if self.radius is None:
            self.radius, radius_label = self.max_radius / 8.0, "radius (default: max_radius/8)"
        self.radius = checked_number(radius_label, self.radius, low=0, low_open=True)
        if self.min_radius is None:
            self.min_radius, min_label = 1e-12 * self.max_radius, "min_radius (default: 1e-12·max_radius)"
        self.min_radius = checked_number(min_label, self.min_radius, low=0)
        self.radius, self.max_radius, self.min_radius = map(_scalar, (self.radius, self.max_radius, self.min_radius))
        rule = "the trust-region radii need min_radius ≤ radius ≤ max_radius"
        self.min_radius, self.max_radius = checked_order(min_label, self.min_radius, max_label, self.max_radius,
                                                         rule=rule)
        self.radius, self.max_radius = checked_order(radius_label, self.radius, max_label, self.max_radius, rule=rule)
        self.min_radius, self.radius = checked_order(min_label, self.min_radius, radius_label, self.radius, rule=rule)
        if self.max_inner is None:
            try:
                self.max_inner = min(S.dim, 10 ** 6)
            except ShapeError:  # M = None without n
                self.max_inner = 10 ** 6
        check_count("max_inner", self.max_inner)
        self.max_inner = host_array(self.max_inner, np.int32) if not is_traced_value(self.max_inner) else self.max_inner
        self.rho_prime = checked_number("rho_prime", self.rho_prime, low=0, high=0.25, high_open=True)
        self.rho_regularization = checked_number("rho_regularization", self.rho_regularization, low=0)
        self.kappa = checked_number("kappa", self.kappa, low=0, high=1.0, low_open=True, high_open=True)
        self.theta = checked_number("theta", self.theta, low=0)
        self.rtol = checked_number("rtol", self.rtol, low=0)
        self.atol = checked_number("atol", self.atol, low=0)
        check_count("history", self.history, 0)
        self._probe_preconditioner()

    def _probe_preconditioner(self):
        """Refuse a concrete preconditioner that is not positive definite on a random tangent space
        (``ParameterError``): ``⟨r, P_X(PMr)⟩ > 0`` for three random tangents ``r`` at a random point.
        A probe, not a proof: the inner solve still stops with ``INDEFINITE_PRECONDITIONER``."""
        S, P = self.manifold, self.preconditioner
        if P is None or is_traced(P):
            return
        try:
            S.n
        except ShapeError:  # M = None without n: no size to probe with
            return
        kx, *kr = jax.random.split(jax.random.PRNGKey(0), 4)
        X = S.random_point(kx)
        prec = self._precondition(X)
        for key in kr:
            r = S.random_tangent(jax.random.fold_in(key, 1), X)
            value = float(self._inner(r, prec(r)))
            if not value > 0:
                raise ParameterError(
                    f"the preconditioner is not positive definite: ⟨r, P_X(PMr)⟩ = {value:.3e} ≤ 0 for a tangent "
                    "r ≠ 0 (it must be SPD, e.g. stiefel.shifted_inverse(W, M, σ).solve with σ > 0)")

    # --- pieces ----------------------------------------------------------------------------------
    def _inner(self, a, b):
        return ta.inner(a, self.manifold.mv(b))

    def _rgrad(self, X, G):
        """The gradient of the M-weighted metric (the manifold's own for ``Grassmann``)."""
        return self.manifold.weighted_rgrad(X, G)

    def _gnorm(self, X, G, rg):
        S = self.manifold
        return S.norm(X, rg if S.metric == "euclidean" else S.egrad_to_rgrad(X, G))

    def _hessian(self, fn, args, X, G, rg):
        """``δ ↦ Hess F(X)[δ]`` and the gradient evaluations it cost to set up / per product."""
        S = self.manifold
        if self.hessian == "exact":
            _, hvp = jax.linearize(jax.grad(lambda Y: fn(Y, args)[0]), X)
            return (lambda d: S.ehess_to_rhess(X, G, hvp(d), d)), 1, 0
        grad = jax.grad(lambda Y: fn(Y, args)[0])

        def fd(d):
            nd = jnp.sqrt(jnp.maximum(self._inner(d, d), 0.0))
            t = FD_STEP / jnp.where(nd > 0, nd, 1.0)
            X1 = S.retract(X, ta.tmap(lambda e: t * e, d))
            g1 = S.proj(X, self._rgrad(X1, grad(X1)))
            return ta.tmap(lambda a, b, e: jnp.where(nd > 0, (a - b) / t, jnp.zeros_like(e)), g1, rg, d)
        return fd, 0, 1

    def _precondition(self, X):
        P = at_point(self.preconditioner, X)
        if P is None:
            return None
        S = self.manifold
        return lambda r: S.proj(X, P(S.mv(r)))

    def _converged(self, gn, F):
        return gn <= self.atol + self.rtol * jnp.abs(F)

    def _watch(self, X):
        return jnp.nan if self.monitor is None else self.monitor(X)

    # --- optimistix protocol ---------------------------------------------------------------------
    def init(self, fn, y, args, options, f_struct, aux_struct, tags) -> TRState:
        self.manifold.check_shape(y, name="y0")  # where the start enters the solver (shapes only: works traced)
        (F0, aux0), G0 = jax.value_and_grad(lambda X: fn(X, args), has_aux=True)(y)
        rg0 = self._rgrad(y, G0)
        gn0 = self._gnorm(y, G0, rg0)
        finite = jnp.isfinite(F0) & ta.all_finite(G0)
        status = jnp.where(~finite, Status.NON_FINITE, jnp.where(self._converged(gn0, F0), Status.CONVERGED, -1))
        if self.budget is not None:
            status = jnp.where((status < 0) & (self.budget <= 0), Status.MAX_ITERS, status)
        dt = ta.dtype_of(y)
        zi = jnp.zeros((), jnp.int32)
        hist = History.empty(max(self.history, 1), dt).record(0, F0, gn0, 0.0, self._watch(y))
        return TRState(X=y, F=F0, G=G0, rg=rg0, gnorm=gn0, radius=jnp.asarray(self.radius, dt), it=zi,
                       status=status.astype(jnp.int32), rho=jnp.asarray(jnp.nan, dt), inner_stop=zi,
                       n_fevals=jnp.ones((), jnp.int32), n_grads=jnp.ones((), jnp.int32), n_hvps=zi, n_inner=zi,
                       n_accepted=zi, history=hist, aux=aux0)

    def step(self, fn, y, args, options, c: TRState, tags):
        S = self.manifold
        hess, setup_grads, grads_per_hvp = self._hessian(fn, args, c.X, c.G, c.rg)
        tcg = truncated_cg(hess, self._precondition(c.X), self._inner, lambda Z: S.proj(c.X, Z), c.rg, c.radius,
                           max_inner=self.max_inner, kappa=self.kappa, theta=self.theta)
        eta = tcg.eta
        predicted = -(self._inner(c.rg, eta) + 0.5 * self._inner(eta, tcg.Heta))
        X_new = S.retract(c.X, eta)
        (F_new, aux_new), G_new = jax.value_and_grad(lambda X: fn(X, args), has_aux=True)(X_new)
        finite = jnp.isfinite(F_new) & ta.all_finite(G_new) & ta.all_finite(X_new)
        reg = self.rho_regularization * jnp.finfo(c.F.dtype).eps * jnp.maximum(1.0, jnp.abs(c.F))
        rho = (c.F - F_new + reg) / (predicted + reg)
        rho = jnp.where(finite & (predicted >= 0), rho, -jnp.inf)
        accept = (rho > self.rho_prime) & (tcg.n_inner > 0) & finite
        radius = jnp.where(rho < 0.25, 0.25 * c.radius,
                           jnp.where((rho > 0.75) & tcg.limited, jnp.minimum(2.0 * c.radius, self.max_radius),
                                     c.radius))
        rg_new = self._rgrad(X_new, G_new)
        gn_new = self._gnorm(X_new, G_new, rg_new)
        keep = lambda new, old: ta.where(accept, new, old)  # noqa: E731
        X, F, gn = keep(X_new, c.X), keep(F_new, c.F), keep(gn_new, c.gnorm)
        it = c.it + 1
        status = jnp.where(
            tcg.stop == TCGStop.INDEFINITE_PRECONDITIONER, Status.INDEFINITE_PRECONDITIONER,
            jnp.where(accept & self._converged(gn_new, F_new), Status.CONVERGED,
                      jnp.where(~accept & (radius < self.min_radius),
                                jnp.where(finite, Status.TRUST_REGION_COLLAPSED, Status.NON_FINITE), -1)))
        if self.budget is not None:
            status = jnp.where((status < 0) & (it >= self.budget), Status.MAX_ITERS, status)
        n_hvps = c.n_hvps + tcg.n_inner
        state = TRState(
            X=X, F=F, G=keep(G_new, c.G), rg=keep(rg_new, c.rg), gnorm=gn, radius=radius, it=it,
            status=status.astype(jnp.int32), rho=rho, inner_stop=tcg.stop, n_fevals=c.n_fevals + 1,
            n_grads=c.n_grads + 1 + setup_grads + grads_per_hvp * tcg.n_inner, n_hvps=n_hvps,
            n_inner=c.n_inner + tcg.n_inner, n_accepted=c.n_accepted + accept.astype(jnp.int32),
            history=c.history.record(it, F, gn, jnp.where(accept, jnp.sqrt(jnp.maximum(self._inner(eta, eta), 0.0)),
                                                          0.0), self._watch(X)),
            aux=jax.tree_util.tree_map(keep, aux_new, c.aux))
        return X, state, state.aux

    def terminate(self, fn, y, args, options, state: TRState, tags):
        return state.status >= 0, to_optx_result(state.status)

    def postprocess(self, fn, y, aux, args, options, state: TRState, tags, result):
        stats = {"value": state.F, "grad_norm": state.gnorm, "status": state.status, "radius": state.radius,
                 "n_fevals": state.n_fevals, "n_grads": state.n_grads, "n_hvps": state.n_hvps,
                 "n_inner": state.n_inner, "n_accepted": state.n_accepted, "inner_stop": state.inner_stop,
                 "dist_to_manifold": self.manifold.dist_to_manifold(state.X), "history": state.history}
        return y, aux, stats
