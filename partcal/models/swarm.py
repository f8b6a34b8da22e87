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
        1 or more the box provably contains the least-squares optimum; the
        default 2 keeps it at least a quarter of the box width from every
        wall (with 1 it can lie next to a wall, where absorbing walls
        sometimes trap the swarm).
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
    bound_scale: float = 2.0
    stop_fitness: float | None = None
    patience: int | None = 50
    ftol: float = 1e-7

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
    is the same alone or in a batch, provided ``fun`` computes each problem's
    fitness from that problem's particles alone.

    Parameters
    ----------
    fun : callable
        ``fun(X, which)`` with ``X`` of shape ``(b, particles, dims)`` for the
        problems ``which`` (increasing indices into the batch, shape ``(b,)``)
        returns shape ``(b, particles)``. ``X`` is a read-only view of the
        swarm's memory, laid out ``(b, dims, particles)``. A problem that has
        stopped may still be evaluated for a few iterations; its result is
        fixed when it stops.
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
    x = np.empty((n_prob, dims, n))                        # particles vary fastest
    for b, g in enumerate(rngs):
        x[b] = g.uniform(lo[b], hi[b], size=(n, dims)).T
    if x0 is not None:
        x[:, :, 0] = np.clip(np.asarray(x0, dtype=float), lo, hi)
    f = _evaluate(fun, _read_only_view(x), np.arange(n_prob))
    run = _Run(cfg, x, np.where(np.isnan(f), np.inf, f), lo, hi, rngs)   # later NaNs never win: f < pf, fmin
    for it in range(1, cfg.iterations + 1):
        if run.n_live == 0:
            break
        run.step(it, fun)
        done = run.stops(it)
        if callback is not None and callback(it, *run.best_all()):
            run.finish(run.live, it, "stopped by the callback", True)
            break
        if done is not None:
            run.finish(done, it)
    run.finish(run.live, cfg.iterations, "reached the iteration limit", False)
    return run.results


_RANDOM_BLOCK_BYTES = 4 << 20     # raw random words drawn ahead for all running swarms


class _Run:
    """The swarms of :func:`minimize_batch` while they run.

    Arrays hold ``b`` problems (``idx`` maps them to the batch): positions
    ``x``, velocities ``v`` and personal bests ``p``, all ``(b, dims, n)`` with
    the particles innermost (bounds and the guide then broadcast over long
    contiguous runs), and the personal-best fitness ``pf`` ``(b, n)``.

    Random numbers are 16-bit uniforms, four from each raw 64-bit word of a
    problem's own bit generator, drawn in blocks of several iterations and
    used in order: a problem sees the same numbers alone or in any batch. A
    problem that stops has its result recorded at once; its rows stay in the
    arrays (still moved and evaluated, but ignored) until the block is used
    up or half the rows have stopped, when the arrays are compacted:
    compacting at every stop would copy the whole batch, block included, for
    each problem.
    """

    def __init__(self, cfg: SwarmConfig, x, f, lo, hi, rngs):
        b, dims, n = x.shape
        self.cfg, self.bits = cfg, [g.bit_generator for g in rngs]
        self.idx, self.live, self.n_live = np.arange(b), np.ones(b, dtype=bool), b
        self.rows = np.arange(b)
        self.x, self.v, self.p, self.pf = x, np.zeros_like(x), x.copy(), f.copy()
        # bounds as full arrays: broadcasting over the particles costs more than reading them
        self.lo = np.repeat(lo[:, :, None], n, axis=2)
        self.hi = np.repeat(hi[:, :, None], n, axis=2)
        self.vmax = cfg.vmax * (self.hi - self.lo)
        self.vmin = -self.vmax
        self.tmp, self.mask, self.better = np.empty_like(x), np.empty(x.shape, dtype=bool), np.empty((b, n), bool)
        chi = cfg.chi if cfg.rule == "constriction" else 1.0
        self.scale = chi
        self.pull = (chi * cfg.c1 * 2.0**-16, chi * cfg.c2 * 2.0**-16)
        self.count, self.words = 2 * dims * n, -(-2 * dims * n // 4)
        self.block = int(min(32, max(1, _RANDOM_BLOCK_BYTES // (max(b, 1) * self.words * 8))))
        self.raw, self.used = np.empty((b, self.block * self.words), dtype=np.uint64), self.block
        self.r1, self.r2 = np.empty_like(x), np.empty_like(x)
        self.history = np.empty((min(cfg.iterations, 1024) + 1, b))
        self.history[0] = f.min(axis=1) if n else np.inf
        self.gbest = self.pf.argmin(axis=1)             # each swarm's best particle
        # the first iteration at which each swarm's patience test can pass (see ``stops``)
        self.next_check = np.full(b, cfg.patience or 0)
        self.check_at = cfg.patience
        self.inertia_rule, self.global_best = cfg.rule == "inertia", cfg.topology == "global"
        self.results: list = [None] * b
        self.x_of_view = self.view = None

    def _views(self) -> NDArray[np.float64]:
        """The read-only view of the current position array (made again when the array changes)."""
        self.x_of_view, self.view = self.x, _read_only_view(self.x)
        return self.view

    def _compact(self) -> None:
        """Drop the rows of stopped problems (with their unused random numbers)."""
        keep = self.live
        for name in ("idx", "live", "x", "v", "p", "pf", "lo", "hi", "vmax", "vmin", "tmp", "mask", "better", "r1", "r2",
                     "gbest", "next_check"):
            setattr(self, name, getattr(self, name)[keep])
        self.rows = np.arange(self.idx.size)
        self.raw = self.raw[keep] if self.used < self.block else np.empty((keep.sum(),) + self.raw.shape[1:], np.uint64)
        self._unpack()

    def _refill(self) -> None:
        """Draw the next block of random numbers: per problem and iteration, r1 then r2, ``dims * n`` each.

        Four 16-bit uniforms from each raw 64-bit word: random numbers are a
        fifth of an iteration's time, and their resolution does not limit the
        search (each scales a continuous pull ``c r (p - x)``; steps of 2^-16
        are far finer than the spread a swarm needs). Every iteration takes
        the same whole number of words from the problem's stream, so which
        number lands where does not depend on the block length (which depends
        on the batch). The block holds the raw words (a quarter of the bytes
        of floats, so it stays in cache); each iteration turns its own into
        floats for all problems at once, scaled by the pull coefficients (and
        2^-16), so the update multiplies once.
        """
        size = self.raw.shape[1]
        for k, b in enumerate(self.idx):
            self.raw[k] = self.bits[b].random_raw(size)
        self.used = 0
        self._unpack()

    def _unpack(self) -> None:
        """The 16-bit uniforms of the block as ``(b, block, 2, dims, n)`` (a view of the raw words)."""
        b, dims, n = self.x.shape
        self.u16 = self.raw.view(np.uint16).reshape(b, self.block, 4 * self.words)[:, :, :self.count].reshape(
            b, self.block, 2, dims, n)

    def step(self, it: int, fun) -> None:
        """One velocity and position update, absorbing walls, new personal bests."""
        if self.n_live < self.idx.size and (self.used == self.block or 2 * self.n_live < self.idx.size):
            self._compact()                        # at a block's end, or once half the rows have stopped
        if self.used == self.block:
            self._refill()
        cfg, x, v, t, p, mask = self.cfg, self.x, self.v, self.tmp, self.p, self.mask
        r1, r2 = self.r1, self.r2
        np.multiply(self.u16[:, self.used, 0], self.pull[0], out=r1)
        np.multiply(self.u16[:, self.used, 1], self.pull[1], out=r2)
        self.used += 1
        if self.inertia_rule:
            v *= cfg.inertia[0] + (cfg.inertia[1] - cfg.inertia[0]) * (it - 1) / max(cfg.iterations - 1, 1)
        elif self.scale != 1.0:
            v *= self.scale
        np.subtract(p, x, out=t)
        t *= r1
        v += t
        if self.global_best:
            guide = p[self.rows, :, self.gbest][:, :, None]
        else:
            guide = p[self.rows[:, None], :, _neighbourhood_best(self.pf, cfg)].transpose(0, 2, 1)
        np.subtract(guide, x, out=t)
        t *= r2
        v += t
        np.minimum(v, self.vmax, out=v)
        np.maximum(v, self.vmin, out=v)
        x += v
        np.maximum(x, self.lo, out=t)
        np.minimum(t, self.hi, out=t)
        np.not_equal(t, x, out=mask)
        if np.count_nonzero(mask):                # absorbing walls: on the wall, that velocity zero
            v[mask] = 0.0
            self.x, self.tmp = x, t = t, x
        f = _evaluate(fun, self.view if x is self.x_of_view else self._views(), self.idx)
        np.less(f, self.pf, out=self.better)
        np.copyto(mask, self.better[:, None, :])
        np.putmask(p, mask, x)                    # a full mask: about 3 times faster than copyto(where=)
        np.fmin(self.pf, f, out=self.pf)
        self.gbest = self.pf.argmin(axis=1)       # argmin and a gather: faster than min(axis=1)

    def stops(self, it: int) -> NDArray[np.bool_]:
        """Record each problem's best; return which of the live ones stop now (threshold or patience), or None.

        The patience test ``history[it - patience] <= best + ftol |best|`` runs
        only from the iteration where it can first pass: after a test at
        iteration ``i``, with ``j`` the first iteration in ``(i - patience, i]``
        whose best was already at most ``floor = best_i + ftol |best_i|``, no
        iteration before ``j + patience`` can pass it (earlier bests are all
        above ``floor``, and the floor only falls as the best does). While a
        swarm still improves fast that skips ``patience`` iterations at a time;
        the iteration it stops at is the same as with a test every iteration.
        Rows whose best is negative (where rounding might not keep the floor
        monotonic) are tested every iteration.
        """
        cfg, history = self.cfg, self.history
        if it >= history.shape[0]:
            history = np.empty((min(2 * history.shape[0], cfg.iterations + 1), history.shape[1]))
            history[:it] = self.history[:it]
            self.history = history
        full = self.idx.size == history.shape[1]
        best = self.pf[self.rows, self.gbest]
        if full:
            history[it] = best
        else:
            history[it, self.idx] = best             # stopped rows too: their history was copied already
        done = None
        if cfg.patience is not None and it >= self.check_at:
            patience = cfg.patience
            floor = np.abs(best)
            floor *= cfg.ftol
            floor += best
            window = history[it - patience:it + 1] if full else history[it - patience:it + 1, self.idx]
            below = window <= floor                          # (patience + 1, b); the last row is all True
            done = below[0] & (self.next_check <= it)         # improved by ftol * |best| at most
            first = np.argmax(below[1:], axis=0)             # j - (it - patience + 1)
            self.next_check = np.maximum(self.next_check, np.where(best >= 0, it + 1 + first, it + 1))
            live = self.next_check if self.n_live == self.live.size else self.next_check[self.live]
            self.check_at = live.min() if live.size else it + 1
        if cfg.stop_fitness is not None:
            reached = best <= cfg.stop_fitness
            done = reached if done is None else done | reached
        if done is None:
            return None
        if self.n_live < self.live.size:
            done &= self.live
        return done if np.count_nonzero(done) else None

    def best_all(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The best position ``(B, dims)`` and fitness ``(B,)`` of every swarm, stopped ones included."""
        g = np.argmin(self.pf, axis=1)
        rows = np.arange(self.idx.size)
        best_x, best_f = np.empty((len(self.results), self.x.shape[1])), np.empty(len(self.results))
        best_x[self.idx], best_f[self.idx] = self.p[rows, :, g], self.pf[rows, g]
        for b, res in enumerate(self.results):
            if res is not None:
                best_x[b], best_f[b] = res.x, res.fun
        return best_x, best_f

    def finish(self, done: NDArray[np.bool_], it: int, message: str | None = None, success: bool = True) -> None:
        """Record the results of the ``done`` rows (live ones) and mark them stopped."""
        n = self.x.shape[2]
        g = np.argmin(self.pf, axis=1)
        for k in np.flatnonzero(done):
            b = self.idx[k]
            reached = self.cfg.stop_fitness is not None and self.pf[k, g[k]] <= self.cfg.stop_fitness
            msg = message or ("reached the stop threshold" if reached else
                              f"converged: improvement below ftol over {self.cfg.patience} iterations")
            self.results[b] = SwarmResult(x=self.p[k, :, g[k]].copy(), fun=float(self.pf[k, g[k]]), nit=it,
                                          nfev=n * (it + 1), success=success, message=msg,
                                          history=self.history[:it + 1, b].copy())
        self.live = self.live & ~done
        self.n_live = int(self.live.sum())


def _evaluate(fun, view: NDArray[np.float64], which: NDArray[np.intp]) -> NDArray[np.float64]:
    """``fun`` on the swarm, seen as ``(b, n, dims)`` (a read-only view of the swarm's memory), shape (b, n)."""
    f = fun(view, which)
    if type(f) is not np.ndarray or f.dtype != np.float64:
        f = np.asarray(f, dtype=float)
    if f.shape != view.shape[:2]:
        want = f"({view.shape[1]},)" if view.shape[0] == 1 else str(view.shape[:2])
        raise param_error("minimize", "fun", f"a function returning shape {want}",
                          f.shape[1:] if view.shape[0] == 1 else f.shape)
    return f


def _read_only_view(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """The swarm ``x`` (b, dims, n) as ``fun`` sees it: ``(b, n, dims)``, read-only."""
    view = x.transpose(0, 2, 1)
    view.flags.writeable = False
    return view


def _neighbourhood_best(best_f: NDArray[np.float64], cfg: SwarmConfig) -> NDArray[np.intp]:
    """Index of the best personal best in each particle's neighbourhood, shape (B, n)."""
    n_prob, n = best_f.shape
    if cfg.topology == "global":
        return np.repeat(np.argmin(best_f, axis=1)[:, None], n, axis=1)
    offsets = np.arange(-cfg.neighbours, cfg.neighbours + 1)
    idx = (np.arange(n)[None, :] + offsets[:, None]) % n          # (2k+1, n)
    choice = np.argmin(best_f[:, idx], axis=1)                     # (B, n)
    return idx[choice, np.arange(n)[None, :]]
