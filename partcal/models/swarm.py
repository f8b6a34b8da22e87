"""Particle swarm optimisation, vectorised over the whole swarm.

The objective takes every particle at once, ``fun(X) -> f`` with ``X`` of
shape ``(particles, dims)``, so there is no Python loop over particles.
Randomness comes from one ``random_state``.

Update rules (``SwarmConfig.rule``):

``constriction`` (default)
    Clerc and Kennedy (2002): ``v = chi (v + c1 r1 (p - x) + c2 r2 (g - x))``
    with ``chi = 2 / |2 - phi - sqrt(phi^2 - 4 phi)|``, ``phi = c1 + c2 > 4``
    (``chi = 0.7298`` for ``c1 = c2 = 2.05``).
``inertia``
    Shi and Eberhart: ``v = w v + c1 r1 (p - x) + c2 r2 (g - x)``, ``w``
    falling linearly from ``inertia[0]`` to ``inertia[1]``.
``paper``
    The basic update of Kennedy and Eberhart used in the paper,
    ``v = v + c1 r1 (p - x) + c2 r2 (g - x)``.

Without damping the basic update diverges (the "swarm explosion"). Here every
rule clamps each velocity component to ``vmax`` times the width of the search
box, and ``vmax`` cannot be switched off, so no setting can explode.

Boundary rule: a coordinate that leaves the box is put on the wall and its
velocity component set to zero (absorbing walls).

Topologies: ``global`` (every particle follows the swarm's best) and ``ring``
(each follows the best of itself and ``neighbours`` particles on either side
in index order; slower to converge, less prone to premature collapse).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .._validation import check_choice, check_int, check_real, param_error

RULES = ("constriction", "inertia", "paper")
TOPOLOGIES = ("global", "ring")


@dataclass(frozen=True)
class SwarmConfig:
    """Settings of the particle swarm.

    Attributes
    ----------
    particles : int
        Swarm size.
    iterations : int
        Maximum number of iterations (velocity updates).
    c1, c2 : float
        Cognitive (own best) and social (neighbourhood best) coefficients.
    rule : {"constriction", "inertia", "paper"}
    topology : {"global", "ring"}
    neighbours : int
        Ring topology: particles on each side in a neighbourhood.
    inertia : (float, float)
        Start and end inertia weight for ``rule="inertia"``.
    vmax : float
        Velocity clamp as a fraction of the search box width, in (0, 1].
    bound_scale : float
        For error models: half-width of the search box in the orthonormal
        coefficient coordinates, in units of the norm of the target data. With
        1 or more the box provably contains the least-squares optimum.
    stop_fitness : float or None
        Stop as soon as the best fitness is at or below this value.
    patience, ftol : int or None, float
        Stop when the best fitness improved by less than ``ftol`` (relative)
        over the last ``patience`` iterations; ``patience=None`` disables it.
    """

    particles: int = 50
    iterations: int = 1000
    c1: float = 2.05
    c2: float = 2.05
    rule: str = "constriction"
    topology: str = "global"
    neighbours: int = 1
    inertia: tuple[float, float] = (0.9, 0.4)
    vmax: float = 0.5
    bound_scale: float = 1.0
    stop_fitness: float | None = None
    patience: int | None = 100
    ftol: float = 1e-8

    def __post_init__(self):
        own = "SwarmConfig"
        check_int(own, "particles", self.particles, 2, 100_000)
        check_int(own, "iterations", self.iterations, 1, 10_000_000)
        check_real(own, "c1", self.c1, 0.0, 10.0)
        check_real(own, "c2", self.c2, 0.0, 10.0)
        check_choice(own, "rule", self.rule, RULES)
        check_choice(own, "topology", self.topology, TOPOLOGIES)
        check_int(own, "neighbours", self.neighbours, 1, max(1, (self.particles - 1) // 2))
        check_real(own, "vmax", self.vmax, 0.0, 1.0, low_open=True)
        check_real(own, "bound_scale", self.bound_scale, 0.0, 1e6, low_open=True)
        check_real(own, "ftol", self.ftol, 0.0, 1.0)
        if self.patience is not None:
            check_int(own, "patience", self.patience, 1)
        if self.stop_fitness is not None:
            check_real(own, "stop_fitness", self.stop_fitness)
        if self.rule == "constriction" and self.c1 + self.c2 <= 4.0:
            raise param_error(own, "c1 + c2", "greater than 4 for the constriction rule", self.c1 + self.c2)
        if (not isinstance(self.inertia, (tuple, list)) or len(self.inertia) != 2
                or not all(isinstance(w, (int, float)) and 0.0 <= w <= 1.2 for w in self.inertia)):
            raise param_error(own, "inertia", "a pair (start, end) of weights in [0, 1.2]", self.inertia)

    @classmethod
    def paper(cls, rule: str = "constriction") -> "SwarmConfig":
        """The paper's settings: 100 particles, 200 iterations, c1 = c2 = 2.05, no early stop."""
        return cls(particles=100, iterations=200, c1=2.05, c2=2.05, rule=rule, patience=None)

    @property
    def chi(self) -> float:
        """The constriction factor for ``c1 + c2``."""
        phi = self.c1 + self.c2
        return 2.0 / abs(2.0 - phi - np.sqrt(phi * phi - 4.0 * phi))


@dataclass
class SwarmResult:
    """Outcome of :func:`minimize` (like ``scipy.optimize.OptimizeResult``)."""

    x: NDArray[np.float64]
    fun: float
    nit: int
    nfev: int
    success: bool
    message: str
    history: NDArray[np.float64] = field(repr=False)   # best fitness after each iteration (index 0: start)


def minimize(
    fun: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    lower, upper, config: SwarmConfig | None = None, *, random_state=None,
    callback: Callable[[int, NDArray[np.float64], float], bool | None] | None = None, x0=None,
) -> SwarmResult:
    """Minimise ``fun`` over the box ``[lower, upper]`` with a particle swarm.

    Parameters
    ----------
    fun : callable
        ``fun(X)`` with ``X`` of shape ``(particles, dims)`` returns the
        fitness of every particle, shape ``(particles,)``. NaN counts as +inf.
    lower, upper : array-like, shape (dims,)
    config : SwarmConfig, optional
    random_state : None, int or numpy.random.Generator
    callback : callable, optional
        ``callback(iteration, best_x, best_fun)``; returning True stops.
    x0 : array-like, shape (dims,), optional
        Placed as the first particle (clipped to the box).

    Examples
    --------
    >>> res = minimize(lambda X: np.sum((X - 1.5) ** 2, axis=1), [-5, -5], [5, 5], random_state=0)
    >>> res.x.round(6).tolist(), res.success
    ([1.5, 1.5], True)
    """
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    if lo.shape != hi.shape or lo.ndim != 1:
        raise param_error("minimize", "lower/upper", "1-D bounds of equal length with upper > lower",
                          (lo.tolist(), hi.tolist()))
    batch_cb = None
    if callback is not None:
        def batch_cb(it, best_x, best_f):
            return callback(it, best_x[0], float(best_f[0]))
    return minimize_batch(lambda X, which: fun(X[0])[None], lo[None], hi[None], config,
                          random_states=[random_state], callback=batch_cb,
                          x0=None if x0 is None else np.asarray(x0, dtype=float)[None])[0]


def minimize_batch(
    fun: Callable[[NDArray[np.float64], NDArray[np.intp]], NDArray[np.float64]],
    lower, upper, config: SwarmConfig | None = None, *, random_states,
    callback: Callable[[int, NDArray[np.float64], NDArray[np.float64]], bool | None] | None = None,
    x0=None,
) -> list[SwarmResult]:
    """Run independent swarms for ``B`` problems of equal dimension in one vectorised loop.

    Small swarms spend most of their time in Python overhead per iteration;
    running several problems (the x, y, z outputs of a model, or every region
    of a partitioned model) together shares that overhead. Each problem draws
    from its own random stream and stops on its own criteria, so its result
    is the same alone or in a batch.

    Parameters
    ----------
    fun : callable
        ``fun(X, which)`` with ``X`` of shape ``(b, particles, dims)`` for the
        problems ``which`` (indices into the batch, shape ``(b,)``) returns
        shape ``(b, particles)``. Problems that have stopped are not evaluated.
    lower, upper : array-like, shape (B, dims)
    random_states : sequence of B seeds or Generators
    callback : callable, optional
        ``callback(iteration, best_x (B, dims), best_fun (B,))``; True stops all.
    x0 : array-like, shape (B, dims), optional
        Placed as the first particle of each swarm.
    """
    cfg = config or SwarmConfig()
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    if lo.shape != hi.shape or lo.ndim != 2 or not np.all(hi > lo):
        raise param_error("minimize", "lower/upper", "bounds of equal shape with upper > lower",
                          (lo.tolist(), hi.tolist()))
    n_prob, n, dims = lo.shape[0], cfg.particles, lo.shape[1]
    if len(random_states) != n_prob:
        raise param_error("minimize_batch", "random_states", f"{n_prob} seeds, one per problem",
                          len(random_states))
    rngs = [np.random.default_rng(r) for r in random_states]
    x = np.stack([g.uniform(lo[b], hi[b], size=(n, dims)) for b, g in enumerate(rngs)])
    if x0 is not None:
        x[:, 0] = np.clip(np.asarray(x0, dtype=float), lo, hi)
    s = _Swarm.start(x, _evaluate(fun, x, np.arange(n_prob)))
    active = np.arange(n_prob)
    for it in range(1, cfg.iterations + 1):
        # while every problem runs, work on views; afterwards on copies of the running ones
        sel = slice(None) if active.size == n_prob else active
        r = np.stack([rngs[b].random((2, n, dims)) for b in active], axis=1)
        s.step(sel, r, cfg, it, lo[:, None, :], hi[:, None, :], lambda xa: _evaluate(fun, xa, active))
        s.nit[active] = it
        done = s.check_stops(active, it, cfg)
        if callback is not None and callback(it, *s.best()):
            for b in active[~done]:
                s.messages[b], s.success[b] = "stopped by the callback", True
            break
        active = active[~done]
        if active.size == 0:
            break
    return s.results(n)


@dataclass
class _Swarm:
    """The state of ``B`` swarms of ``n`` particles: positions, velocities, personal bests, history."""

    x: NDArray[np.float64]            # (B, n, dims)
    v: NDArray[np.float64]
    best_x: NDArray[np.float64]
    best_f: NDArray[np.float64]       # (B, n)
    history: list                     # per problem: best fitness after each iteration
    nit: NDArray[np.int_]
    messages: list
    success: NDArray[np.bool_]

    @classmethod
    def start(cls, x: NDArray[np.float64], f: NDArray[np.float64]) -> "_Swarm":
        b = x.shape[0]
        return cls(x, np.zeros_like(x), x.copy(), f.copy(), [[row.min()] for row in f], np.zeros(b, dtype=int),
                   ["reached the iteration limit"] * b, np.zeros(b, dtype=bool))

    def step(self, sel, r, cfg: SwarmConfig, it: int, lo3, hi3, evaluate) -> None:
        """One velocity and position update of the selected swarms, absorbing walls, new personal bests."""
        xa, va, pa, fa = self.x[sel], self.v[sel], self.best_x[sel], self.best_f[sel]
        lo3, hi3 = lo3[sel], hi3[sel]
        pull = cfg.c1 * r[0] * (pa - xa) + cfg.c2 * r[1] * (_guides(pa, fa, cfg) - xa)
        if cfg.rule == "inertia":
            w = cfg.inertia[0] + (cfg.inertia[1] - cfg.inertia[0]) * (it - 1) / max(cfg.iterations - 1, 1)
            va = w * va + pull
        else:
            va = (cfg.chi if cfg.rule == "constriction" else 1.0) * (va + pull)
        vmax = cfg.vmax * (hi3 - lo3)
        np.clip(va, -vmax, vmax, out=va)
        xa = xa + va
        outside = (xa < lo3) | (xa > hi3)
        if outside.any():
            np.clip(xa, lo3, hi3, out=xa)
            va[outside] = 0.0
        fa_new = evaluate(xa)
        better = fa_new < fa
        pa[better], fa[better] = xa[better], fa_new[better]
        self.x[sel], self.v[sel], self.best_x[sel], self.best_f[sel] = xa, va, pa, fa

    def check_stops(self, active: NDArray[np.intp], it: int, cfg: SwarmConfig) -> NDArray[np.bool_]:
        """Record each running problem's best; return which of them stop now (threshold or patience)."""
        done = np.zeros(active.size, dtype=bool)
        for k, b in enumerate(active):
            self.history[b].append(self.best_f[b].min())
            if cfg.stop_fitness is not None and self.history[b][-1] <= cfg.stop_fitness:
                self.messages[b], self.success[b], done[k] = "reached the stop threshold", True, True
            elif cfg.patience is not None and it >= cfg.patience:
                best_now, past = self.history[b][-1], self.history[b][-cfg.patience - 1]
                if past - best_now <= cfg.ftol * max(abs(best_now), 1e-300):
                    self.messages[b] = f"converged: improvement below ftol over {cfg.patience} iterations"
                    self.success[b], done[k] = True, True
        return done

    def best(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The best position ``(B, dims)`` and fitness ``(B,)`` of every swarm (copies)."""
        g = np.argmin(self.best_f, axis=1)
        rows = np.arange(self.best_f.shape[0])
        return self.best_x[rows, g].copy(), self.best_f[rows, g].copy()

    def results(self, particles: int) -> list[SwarmResult]:
        best_x, best_f = self.best()
        return [SwarmResult(x=best_x[b], fun=float(best_f[b]), nit=int(self.nit[b]),
                            nfev=particles * (int(self.nit[b]) + 1), success=bool(self.success[b]),
                            message=self.messages[b], history=np.asarray(self.history[b]))
                for b in range(len(best_f))]


def _evaluate(fun, x: NDArray[np.float64], which: NDArray[np.intp]) -> NDArray[np.float64]:
    f = np.asarray(fun(x, which), dtype=float)
    if f.shape != x.shape[:2]:
        want = f"({x.shape[1]},)" if x.shape[0] == 1 else str(x.shape[:2])
        raise param_error("minimize", "fun", f"a function returning shape {want}",
                          f.shape[1:] if x.shape[0] == 1 else f.shape)
    return np.where(np.isnan(f), np.inf, f)


def _guides(best_x: NDArray[np.float64], best_f: NDArray[np.float64], cfg: SwarmConfig) -> NDArray[np.float64]:
    """The neighbourhood best each particle is pulled towards, shape (B, n, dims)."""
    if cfg.topology == "global":
        return best_x[np.arange(best_f.shape[0]), np.argmin(best_f, axis=1)][:, None, :]
    return np.take_along_axis(best_x, _neighbourhood_best(best_f, cfg)[:, :, None], axis=1)


def _neighbourhood_best(best_f: NDArray[np.float64], cfg: SwarmConfig) -> NDArray[np.intp]:
    """Index of the best personal best in each particle's neighbourhood, shape (B, n)."""
    n_prob, n = best_f.shape
    if cfg.topology == "global":
        return np.repeat(np.argmin(best_f, axis=1)[:, None], n, axis=1)
    offsets = np.arange(-cfg.neighbours, cfg.neighbours + 1)
    idx = (np.arange(n)[None, :] + offsets[:, None]) % n          # (2k+1, n)
    choice = np.argmin(best_f[:, idx], axis=1)                     # (B, n)
    return idx[choice, np.arange(n)[None, :]]
