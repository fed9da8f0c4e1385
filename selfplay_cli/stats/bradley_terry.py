"""Bradley-Terry (Elo) ratings of a whole population from its games: maximum likelihood, or MAP under
BayesElo's prior of virtual draws; Hunter's (2004) existence condition handled explicitly; intervals
and ranks in :mod:`selfplay_cli.stats.intervals`.

The prior (BayesElo's)
----------------------
Rémi Coulom's BayesElo regularises the Bradley-Terry likelihood with *virtual draws*. Its source
(``CCondensedResults::AddPrior`` in ``CCondensedResults.cpp``; the default ``Prior(2.0)`` in
``CEloRatingCUI.cpp``, help text "prior [x] ... get[set] prior (= number of virtual draws)"; read in
github.com/ddugovic/BayesianElo, an import of http://remi-coulom.fr/Bayesian-Elo/) adds, for every player
``i`` and every opponent ``j`` of ``i``, ``prior * 0.25 * N_ij / N_i`` draws to each of the four
(colour, side) draw counters of the pair, i.e. ``(prior / 2) * N_ij / N_i`` virtual draws between ``i``
and ``j``, where ``N_ij`` is the number of real games between them and ``N_i`` all of ``i``'s games. Both
players of a pair do this, so the pair receives

    V_ij = (prior / 2) * N_ij * (1 / N_i + 1 / N_j)

virtual draws. Two players that only met each other get ``prior`` virtual draws between them; in general
every player spreads ``prior / 2`` draws over its opponents pro rata and receives a share of each opponent's.
:func:`prior_draws` computes ``V``; :data:`DEFAULT_PRIOR` is BayesElo's default, 2. A virtual draw counts as
half a point to each side, like a real draw here (BayesElo itself models draws with its own ``eloDraw``
parameter; with the half-point convention used here a draw is half a win and half a loss). Because the
virtual draws sit on the edges of the game graph, the posterior has a finite maximum (the MAP ratings)
for every player connected to the anchor by a chain of games, whatever the results: a perfect or zero
score gives a finite, data-and-prior-determined rating, not a bound. ``prior_games=0`` is the pure
maximum-likelihood fit, with Hunter's existence condition handled as :func:`fit_bradley_terry` describes.

Intervals and ranks are in :mod:`selfplay_cli.stats.intervals`.

numpy and the standard library only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .elo import NAT_TO_ELO

__all__ = ["BOUND_PRIOR_GAMES", "DEFAULT_PRIOR", "FLAG_DISCONNECTED", "FLAG_PERFECT", "FLAG_UNRATED", "FLAG_ZERO",
           "BTFit", "fit_bradley_terry", "pair_matrices", "prior_draws", "reachable"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

DEFAULT_PRIOR: float = 2.0
"""BayesElo's default prior (``Prior(2.0)`` in its ``CEloRatingCUI.cpp``): the number of virtual draws, see
:func:`prior_draws`. Two players that only met each other get 2 virtual draws between them."""

BOUND_PRIOR_GAMES: float = 1.0
"""Maximum likelihood only (``prior_games=0``): weight, in games, of the virtual draw that turns an infinite ML
rating into a finite, flagged bound."""

FLAG_PERFECT = "perfect"
FLAG_ZERO = "zero"
FLAG_DISCONNECTED = "disconnected"
FLAG_UNRATED = "unrated"



@dataclass
class BTFit:
    """Result of :func:`fit_bradley_terry`.

    Attributes:
        ratings: (n_players,) Elo ratings, always finite; ``ratings[anchor] == anchor_rating`` if the
            anchor played.
        flags: per player ``None`` (a true ML estimate) or one of ``"perfect"``, ``"zero"``,
            ``"disconnected"``, ``"unrated"`` (see :func:`fit_bradley_terry`).
        games, wins, draws, losses: per-player (weighted) counts; int64 unless non-integer weights
            were given, then float64.
        score: per-player mean points per game (0.5 for players without games).
        iterations: total Newton iterations over all sub-problems.
        converged: True if every Newton solve reached the tolerance.
        anchor, anchor_rating: the gauge used.
    """

    ratings: FloatArray
    flags: list[str | None]
    games: npt.NDArray[np.int64] | FloatArray
    wins: npt.NDArray[np.int64] | FloatArray
    draws: npt.NDArray[np.int64] | FloatArray
    losses: npt.NDArray[np.int64] | FloatArray
    score: FloatArray
    iterations: int
    converged: bool
    anchor: int = 0
    anchor_rating: float = 1000.0


def _sigmoid(x: FloatArray) -> FloatArray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _at(w: FloatArray, theta: FloatArray) -> tuple[float, FloatArray]:
    """The Bradley-Terry log-likelihood ``sum_ij W_ij log sigmoid(theta_i - theta_j)`` (points as wins) at ``theta``,
    and the win probabilities ``p_ij = sigmoid(theta_i - theta_j)`` there, from one ``exp(-|d|)`` (the Newton step
    needs both where the line search accepts a point; computed apart they took half the fit's time)."""
    d = theta[:, None] - theta[None, :]
    e = np.exp(-np.abs(d))
    ll = -float(np.sum(w * (np.log1p(e) + np.maximum(-d, 0.0))))
    one = 1.0 + e
    return ll, np.where(d >= 0.0, 1.0, e) / one


def _pcg(mat: FloatArray, rhs: FloatArray, rtol: float = 1e-12) -> FloatArray:
    """Solve ``mat x = rhs`` (symmetric positive (semi)definite) by Jacobi-preconditioned conjugate gradients.

    Used instead of a LAPACK factorisation because it needs only matrix-vector products: on small
    matrices a multi-threaded BLAS factorisation can be dominated by thread wake-up latency on a busy
    machine, while CG on a diagonally dominant graph Laplacian converges in a few dozen products.
    Stops when ``|r| <= rtol |rhs|`` or after ``4 * size + 50`` iterations.
    """
    diag = np.diag(mat).copy()
    inv_d = np.divide(1.0, diag, out=np.zeros_like(diag), where=diag > 0)
    x = np.zeros_like(rhs)
    r = rhs.copy()
    z = inv_d * r
    p = z.copy()
    rz = float(r @ z)
    stop = rtol * float(np.linalg.norm(rhs))
    for _ in range(4 * rhs.size + 50):
        if float(np.linalg.norm(r)) <= stop or rz <= 0.0:
            break
        q = mat @ p
        pq = float(p @ q)
        if pq <= 0.0:
            break
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        z = inv_d * r
        rz_new = float(r @ z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x


def _newton(w: FloatArray, n: FloatArray, theta: FloatArray, free: npt.NDArray[np.bool_],
            tol_nat: float, max_iter: int) -> tuple[FloatArray, int, bool]:
    """Maximise the BT log-likelihood over ``theta[free]`` (the other entries stay fixed).

    ``w[i, j]``: points i scored against j, ``n[i, j] = n[j, i]``: games between them (both may include
    virtual games). Gradient ``g_i = sum_j (w_ij - n_ij p_ij)`` with ``p_ij = sigmoid(theta_i - theta_j)``;
    the negative Hessian is the weighted graph Laplacian ``L_ii = sum_j c_ij``, ``L_ij = -c_ij``,
    ``c_ij = n_ij p_ij (1 - p_ij)``, restricted to the free rows/columns (positive definite when every
    free player is linked to a fixed one). Newton step ``L delta = g``, capped at 5 nats
    (~870 Elo) per player and backtracked until the (concave) log-likelihood does not decrease.
    Stops when the largest accepted step is below ``tol_nat``.
    """
    theta = theta.copy()
    idx = np.flatnonzero(free)
    if idx.size == 0:
        return theta, 0, True
    sub = np.ix_(idx, idx)
    ll0, p = _at(w, theta)  # (then each accepted point's: where the next step starts)
    for it in range(1, max_iter + 1):
        grad = np.sum(w - n * p, axis=1)[idx]
        c = n * p * (1.0 - p)
        lap = -c[sub]
        lap[np.diag_indices_from(lap)] += c[idx].sum(axis=1)
        step = _pcg(lap, grad)
        big = float(np.max(np.abs(step)))
        if big > 5.0:
            step *= 5.0 / big
        t = 1.0
        while True:
            trial = theta.copy()
            trial[idx] += t * step
            ll1, p1 = _at(w, trial)
            if ll1 >= ll0 - 1e-12 * (1.0 + abs(ll0)) or t < 1e-6:
                break
            t *= 0.5
        theta, ll0, p = trial, ll1, p1
        if t * float(np.max(np.abs(step))) < tol_nat:
            return theta, it, True
    return theta, max_iter, False


def reachable(adj: npt.NDArray[np.bool_], start: int) -> npt.NDArray[np.bool_]:
    """Players reachable from ``start`` along edges ``adj[i, j]`` (breadth-first, vectorised); with a symmetric
    ``adj`` this is ``start``'s connected component."""
    seen = np.zeros(adj.shape[0], dtype=bool)
    seen[start] = True
    frontier = seen.copy()
    while frontier.any():
        nxt = adj[frontier].any(axis=0) & ~seen
        seen |= nxt
        frontier = nxt
    return seen


def prior_draws(n: FloatArray, prior_games: float) -> FloatArray:
    """BayesElo's virtual draws on the game graph: ``V_ij = (prior / 2) * N_ij * (1 / N_i + 1 / N_j)``.

    ``n[i, j] = n[j, i]``: (weighted) games between i and j; ``N_i`` = row sums. Zero where no game was played,
    and all zero for ``prior_games == 0``. See the module docstring for the source of the definition.
    """
    if prior_games < 0:
        raise ValueError("prior_games must be non-negative")
    games = n.sum(axis=1)
    share = np.divide(n, games[:, None], out=np.zeros_like(n), where=games[:, None] > 0)
    return 0.5 * prior_games * (share + share.T)


def _fit_matrices(
    w: FloatArray, n: FloatArray, anchor: int, anchor_rating: float, prior_games: float,
    init: FloatArray | None, tol: float, max_iter: int,
) -> tuple[FloatArray, list[str | None], int, bool]:
    """Core of :func:`fit_bradley_terry` on the aggregated pair matrices (see its docstring): each connected
    component of the game graph fitted on its own (:func:`_fit_map_component` under a prior,
    :func:`_fit_ml_component` without), then placed on the anchor's scale."""
    n_players = w.shape[0]
    games = n.sum(axis=1)
    has_games = games > 0
    played = n > 0
    ratings = np.full(n_players, float(anchor_rating))
    flags: list[str | None] = [None if g else FLAG_UNRATED for g in has_games]
    tol_nat = tol / NAT_TO_ELO
    # Heuristic start: logit of each player's score with one virtual draw.
    points = w.sum(axis=1)
    heuristic = np.log((points + 0.5) / (games - points + 0.5))
    if init is None:
        start_theta = heuristic
    else:
        start_theta = np.where(np.isfinite(init), (init - anchor_rating) / NAT_TO_ELO, heuristic)
    iterations, converged = 0, True
    unassigned = has_games.copy()
    while unassigned.any():
        comp = reachable(played, int(np.flatnonzero(unassigned)[0]))
        unassigned &= ~comp
        members = np.flatnonzero(comp)
        with_anchor = bool(comp[anchor])
        root = anchor if with_anchor else int(members[np.argmax(games[members])])
        r = int(np.searchsorted(members, root))
        theta = start_theta[members] - start_theta[root]
        theta[r] = 0.0
        if not with_anchor:
            for i in members:
                flags[i] = FLAG_DISCONNECTED
        if prior_games > 0.0:
            theta, its, ok = _fit_map_component(w, n, members, r, theta, prior_games, tol_nat, max_iter)
        else:
            theta, its, ok = _fit_ml_component(w, n, members, root, r, theta, flags if with_anchor else None,
                                               tol_nat, max_iter)
        iterations, converged = iterations + its, converged and ok
        if with_anchor:
            ratings[members] = anchor_rating + (theta - theta[r]) * NAT_TO_ELO
        else:
            ratings[members] = anchor_rating + (theta - theta.mean()) * NAT_TO_ELO
    return ratings, flags, iterations, converged


def _fit_map_component(w: FloatArray, n: FloatArray, members: IntArray, r: int, theta: FloatArray,
                       prior_games: float, tol_nat: float, max_iter: int) -> tuple[FloatArray, int, bool]:
    """The MAP fit of one connected component (``members``, its root at position ``r`` held fixed): the virtual
    draws link every pair that met, so the posterior has a finite maximum on the whole component; only its offset
    to another component stays undetermined."""
    wc, nc = w[np.ix_(members, members)], n[np.ix_(members, members)]
    v = prior_draws(nc, prior_games)
    free = np.ones(members.size, dtype=bool)
    free[r] = False
    return _newton(wc + 0.5 * v, nc + v, theta, free, tol_nat, max_iter)


def _fit_ml_component(w: FloatArray, n: FloatArray, members: IntArray, root: int, r: int, theta: FloatArray,
                      flags: list[str | None] | None, tol_nat: float, max_iter: int) -> tuple[FloatArray, int, bool]:
    """The maximum-likelihood fit of one connected component (``members``; ``root``, at position ``r``, held
    fixed): its root's strongly connected component exactly, every other member a bound. ``flags`` (the anchor's
    component only; None for another component, whose members are all disconnected) gets each bounded member's
    flag."""
    games = n.sum(axis=1)
    scored = w > 0
    wc, nc = w[np.ix_(members, members)], n[np.ix_(members, members)]
    fwd = reachable(scored, root)  # players the root's group (transitively) scored against
    bwd = reachable(scored.T, root)  # players that (transitively) scored against the root
    main = fwd & bwd  # strongly connected component of the root: ML exists there (Hunter 2004)
    if flags is not None:
        for i in members:
            if main[i]:
                continue
            elif bwd[i] and not fwd[i]:  # scored against the anchor's group, never conceded to it
                flags[i] = FLAG_PERFECT
            elif fwd[i] and not bwd[i]:
                flags[i] = FLAG_ZERO
            else:
                flags[i] = FLAG_DISCONNECTED
    main_c = main[members]
    mi = np.flatnonzero(main_c)
    free_m = np.ones(mi.size, dtype=bool)
    free_m[int(np.flatnonzero(mi == r)[0])] = False
    sub = np.ix_(mi, mi)
    th_m, iterations, converged = _newton(wc[sub], nc[sub], theta[mi], free_m, tol_nat, max_iter)
    if main_c.all():
        theta[mi] = th_m
        return theta, iterations, converged
    # Bounds: BOUND_PRIOR_GAMES virtual draws for each player outside the root's strongly connected component,
    # spread over its opponents pro rata (symmetrised); main stays fixed.
    g = np.where(main_c, 0.0, BOUND_PRIOR_GAMES)
    v = (g / games[members])[:, None] * nc
    v = v + v.T
    # Start the bounded players from their heuristic, shifted like the main group moved.
    theta[~main_c] += float(np.mean(th_m - theta[mi]))
    theta[mi] = th_m
    theta, its, ok = _newton(wc + 0.5 * v, nc + v, theta, ~main_c, tol_nat, max_iter)
    return theta, iterations + its, converged and ok


def _validate_games(
    a: npt.ArrayLike, b: npt.ArrayLike, score_a: npt.ArrayLike, n_players: int, anchor: int,
    weights: npt.ArrayLike | None,
) -> tuple[IntArray, IntArray, FloatArray, FloatArray | None]:
    ai = np.asarray(a).astype(np.int64, copy=False).ravel()
    bi = np.asarray(b).astype(np.int64, copy=False).ravel()
    sc = np.asarray(score_a, dtype=np.float64).ravel()
    if not (ai.size == bi.size == sc.size):
        raise ValueError("a, b and score_a must have the same length")
    if n_players <= 0:
        raise ValueError("n_players must be positive")
    if not 0 <= anchor < n_players:
        raise ValueError(f"anchor {anchor} is not a player index in [0, {n_players})")
    if ai.size and (min(ai.min(), bi.min()) < 0 or max(ai.max(), bi.max()) >= n_players):
        raise ValueError("player indices must lie in [0, n_players)")
    if np.any(ai == bi):
        raise ValueError("a player cannot play against itself (a == b)")
    if not np.all((sc >= 0.0) & (sc <= 1.0)):
        raise ValueError("score_a must lie in [0, 1] (1 win, 0.5 draw, 0 loss)")
    wt = None
    if weights is not None:
        wt = np.asarray(weights, dtype=np.float64).ravel()
        if wt.size != ai.size or not np.all(np.isfinite(wt)) or np.any(wt < 0):
            raise ValueError("weights must be finite, non-negative and one per game")
    return ai, bi, sc, wt


def pair_matrices(a: npt.ArrayLike, b: npt.ArrayLike, score_a: npt.ArrayLike,
                  n_players: int) -> tuple[FloatArray, FloatArray]:
    """``(W, N)``: ``W[i, j]`` the points i scored against j, ``N[i, j] = N[j, i]`` the games between them, from games
    given as index arrays (``a`` scored ``score_a`` against ``b``)."""
    ai, bi = np.asarray(a, dtype=np.int64).ravel(), np.asarray(b, dtype=np.int64).ravel()
    return _pair_matrices(ai, bi, np.asarray(score_a, dtype=np.float64).ravel(), None, n_players)


def _pair_matrices(ai: IntArray, bi: IntArray, sc: FloatArray, wt: FloatArray | None,
                   n_players: int) -> tuple[FloatArray, FloatArray]:
    """Aggregate games: ``W[i, j]`` = points i scored against j, ``N[i, j] = N[j, i]`` = games i-j."""
    m = n_players * n_players
    code = ai * n_players + bi
    g = np.ones_like(sc) if wt is None else wt
    pts_a = np.bincount(code, weights=g * sc, minlength=m).reshape(n_players, n_players)
    pts_b = np.bincount(code, weights=g * (1.0 - sc), minlength=m).reshape(n_players, n_players)
    cnt = np.bincount(code, weights=g, minlength=m).reshape(n_players, n_players)
    return pts_a + pts_b.T, cnt + cnt.T


def fit_bradley_terry(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    score_a: npt.ArrayLike,
    n_players: int,
    anchor: int = 0,
    anchor_rating: float = 1000.0,
    weights: npt.ArrayLike | None = None,
    prior_games: float = 0.0,
    *,
    init: npt.ArrayLike | None = None,
    tol: float = 1e-6,
    max_iter: int = 100,
) -> BTFit:
    """Maximum-likelihood (``prior_games=0``) or MAP Bradley-Terry (Elo) ratings of a population from its games.

    (Long for its docstring, the model and what the fit does where a rating does not exist; the work is in
    :func:`_fit_matrices` and :func:`_player_counts`.)

    Model: game ``k`` between ``a[k]`` and ``b[k]`` gives A ``score_a[k]`` points (1 win, 1/2 draw,
    0 loss) and B ``1 - score_a[k]``, with ``P(a beats b) = E(r_a - r_b) = 1 / (1 + 10**(-(r_a - r_b)/400))``.
    Draws count as half a win for each side (the usual Elo / Chatbot-Arena convention), so with
    ``W_ij`` = (weighted) points i scored against j and ``N_ij = N_ji`` the (weighted) games between
    them, the log-likelihood is ``sum_{i,j} W_ij log E(r_i - r_j)`` and the ML ratings solve the score
    equations

        sum_j N_ij (W_ij / N_ij - E(r_i - r_j)) = 0     for every player i except the anchor,

    with ``r_anchor = anchor_rating`` fixing the additive gauge. The games are first aggregated into
    the n x n matrices ``W, N`` (one ``bincount``), then solved by Newton's method with the n x n
    Hessian (the likelihood is concave, so Newton with backtracking converges; typically 5-8
    iterations) to ``tol`` Elo (largest update). ``weights`` multiplies each game (bootstrap counts);
    ``init`` (Elo, n_players) warm-starts the solver.

    Existence (Hunter 2004): the ML ratings are finite iff the directed graph "i scored something
    against j" is strongly connected. This function therefore

    1. fits the strongly connected component of the anchor ("main") exactly, using the games within
       it (these are the exact ML ratings of those players: in the full likelihood all other players
       drift to +-infinity and their games against main contribute nothing);
    2. gives every other player in the anchor's connected component a finite *bound*: the ML rating
       with main held fixed after adding, for each such player i, ``BOUND_PRIOR_GAMES`` (= 1) virtual
       draw spread over i's opponents in proportion to the games played against them. For a single
       player with ``P`` points in ``n`` games against fixed opponents this is the rating at which its
       expected score against its actual schedule equals ``(P + 1/2) / (n + 1)``, e.g. 2/2 wins against
       one opponent gives ``E(d) = 5/6``, ``d = 400 log10 5 = +279.6``. These players are flagged

       * ``"perfect"``: the ML rating is +infinity: the player belongs to a group that scored 100 %
         against every opponent outside the group (most often: the player won every game);
       * ``"zero"``: the mirror image, ML rating -infinity (most often: a 0 % score);
       * ``"disconnected"``: neither (its group both beat and lost to groups the anchor cannot be
         compared with), so its offset to the anchor is undetermined;

    3. connected components that do not contain the anchor are fitted the same way around their own
       most active player, then shifted so that the component's mean rating is ``anchor_rating``; all
       their players are flagged ``"disconnected"`` (their ratings are not comparable to the anchor's);
    4. players without any (non-zero-weight) game get ``anchor_rating`` and the flag ``"unrated"``.

    ``prior_games > 0`` turns this into a MAP fit under BayesElo's prior: ``V = prior_draws(N, prior_games)``
    virtual draws are added to the games (module docstring) and each connected component is fitted in one
    piece, by the same Newton iteration. The MAP is finite for every player with games, so nobody is flagged
    ``"perfect"`` or ``"zero"``: those flags say that the *maximum-likelihood* rating is infinite, which is
    not the estimate reported under a prior. ``"disconnected"`` (a component without the anchor) and
    ``"unrated"`` keep their meaning. Ratings are always finite, never NaN.

    Args:
        a, b: int arrays of player indices (``0 <= a, b < n_players``, ``a != b``).
        score_a: A's points per game in [0, 1] (W/D/L counts treat > 1/2 as a win, < 1/2 a loss).
        n_players: population size.
        anchor, anchor_rating: the player whose rating is fixed, and its value.
        weights: optional non-negative weight per game.
        prior_games: BayesElo's prior, in virtual draws (:func:`prior_draws`; 0 = pure maximum likelihood;
            the ladder's default is :data:`DEFAULT_PRIOR`).
        init: optional warm start (Elo ratings, e.g. a previous fit's ``ratings``).
        tol: convergence tolerance on the ratings, in Elo.
        max_iter: Newton iteration cap per sub-problem.
    """
    ai, bi, sc, wt = _validate_games(a, b, score_a, n_players, anchor, weights)
    if prior_games < 0:
        raise ValueError("prior_games must be non-negative")
    w, nmat = _pair_matrices(ai, bi, sc, wt, n_players)
    init_arr = None if init is None else np.asarray(init, dtype=np.float64).ravel()
    if init_arr is not None and init_arr.size != n_players:
        raise ValueError("init must have one rating per player")
    ratings, flags, iterations, converged = _fit_matrices(
        w, nmat, anchor, float(anchor_rating), float(prior_games), init_arr, tol, max_iter
    )
    return BTFit(ratings=ratings, flags=flags, **_player_counts(ai, bi, sc, wt, n_players), iterations=iterations,
                 converged=converged, anchor=int(anchor), anchor_rating=float(anchor_rating))


def _player_counts(ai: IntArray, bi: IntArray, sc: FloatArray, wt: FloatArray | None,
                   n_players: int) -> dict[str, npt.NDArray[np.int64] | FloatArray]:
    """Per player: (weighted) games, wins, draws, losses (int64 unless a weight is not whole) and mean score."""
    g = np.ones_like(sc) if wt is None else wt
    win, draw, loss = g * (sc > 0.5), g * (sc == 0.5), g * (sc < 0.5)

    def per_player(x_a: FloatArray, x_b: FloatArray) -> FloatArray:
        return np.bincount(ai, x_a, minlength=n_players) + np.bincount(bi, x_b, minlength=n_players)

    games = per_player(g, g)
    wins, draws, losses = per_player(win, loss), per_player(draw, draw), per_player(loss, win)
    points = per_player(g * sc, g * (1.0 - sc))
    score = np.divide(points, games, out=np.full(n_players, 0.5), where=games > 0)
    integral = wt is None or bool(np.all(wt == np.round(wt)))
    conv = (lambda x: np.rint(x).astype(np.int64)) if integral else (lambda x: x)
    return {"games": conv(games), "wins": conv(wins), "draws": conv(draws), "losses": conv(losses), "score": score}
