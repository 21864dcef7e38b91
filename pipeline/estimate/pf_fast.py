"""Fused numba kernels for the constant-velocity bootstrap particle filter (the speed path).

One **particle step** (issue 17 acceptance, ``benchmarks/pf.py``): predict by the seed-001 CV
model with white acceleration ``σ_a`` per axis (``p += vT + aT²/2, v += aT``), weight by one
2-D Gaussian position measurement ``N(z; p, σ_z² I)``, normalise (log-sum-exp), take the
weighted mean and resample systematically. :func:`cv_bootstrap_run` does ``T`` such steps over
structure-of-arrays particles without leaving compiled code.

Randomness is counter based, so a run depends on its ``seed`` only, never on the thread count
or scheduling: the particles are cut into fixed blocks of :data:`BLOCK`; block ``b`` of step
``k`` draws from a splitmix64 stream keyed by ``(seed, k, b)`` (Steele, Lea & Flood 2014) and
turns its 32-bit halves into normals by the 128-layer ziggurat (Marsaglia & Tsang 2000: a
table look-up and one compare for ~99 % of the draws, no transcendental); the systematic offset
``u`` of step ``k`` comes from the key ``(seed, k, −1)``. Blocks run in parallel (``prange``)
over numba's thread pool (``numba.set_num_threads``).

This is the same filter as :class:`pipeline.estimate.pf.ParticleFilter` with
:class:`~pipeline.estimate.models.PfConstantVelocity`, a
:class:`~pipeline.estimate.pf.GaussianPositionLikelihood` and ``every_step=True`` (tested
against the Kalman filter the same way), without the generic machinery (modes, NaN steps,
re-initialisation): a NaN measurement here is simply a predict-only step.
"""

from __future__ import annotations

import numbers

import numpy as np
from numba import njit, prange
from numpy.typing import ArrayLike, NDArray

from .models import turn_coefficients_one

F64 = NDArray[np.float64]

#: particles per random-number block (the unit of parallel work)
BLOCK = 4096

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
# the generator's uint64 constants as globals (numba freezes them) rather than np.uint64(...) calls:
# each call is one more function for numba to type at every place _normal/_unit are inlined,
# which made up a good part of the particle kernels' cold compile
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_LO32 = np.uint64(0xFFFFFFFF)
_U1, _U11, _U27, _U30, _U31, _U32, _U127 = (np.uint64(v) for v in (1, 11, 27, 30, 31, 32, 127))


def _ziggurat_tables() -> tuple[F64, F64, F64]:
    """Marsaglia & Tsang (2000) RNOR tables: ``kn`` (int thresholds), ``wn``, ``fn``."""
    m1 = 2147483648.0
    dn = tn = 3.442619855899
    vn = 9.91256303526217e-3
    kn, wn, fn = np.zeros(128), np.zeros(128), np.zeros(128)
    q = vn / np.exp(-0.5 * dn * dn)
    kn[0], kn[1] = (dn / q) * m1, 0.0
    wn[0], wn[127] = q / m1, dn / m1
    fn[0], fn[127] = 1.0, np.exp(-0.5 * dn * dn)
    for i in range(126, 0, -1):
        dn = np.sqrt(-2.0 * np.log(vn / dn + np.exp(-0.5 * dn * dn)))
        kn[i + 1] = (dn / tn) * m1
        tn = dn
        fn[i] = np.exp(-0.5 * dn * dn)
        wn[i] = dn / m1
    return kn, wn, fn


_KN, _WN, _FN = _ziggurat_tables()
_ZR = 3.442619855899


@njit(cache=True, inline="always")
def _mix(z):
    z = (z ^ (z >> _U30)) * _M1
    z = (z ^ (z >> _U27)) * _M2
    return z ^ (z >> _U31)


@njit(cache=True, inline="always")
def _unit(state):
    """Advance a splitmix64 state; (new state, uniform in (0, 1))."""
    state += _GOLDEN
    return state, ((_mix(state) >> _U11) + _U1) * (1.0 / 9007199254740993.0)


@njit(cache=True)
def _zig_slow(state, hz, iz, kn, wn, fn):
    """The ziggurat's tail/wedge branch (≈1 % of the draws)."""
    while True:
        x = hz * wn[iz]
        if iz == 0:
            while True:
                state, u = _unit(state)
                x = -np.log(u) / _ZR
                state, u = _unit(state)
                y = -np.log(u)
                if y + y >= x * x:
                    break
            return state, (_ZR + x) if hz > 0 else (-_ZR - x)
        state, u = _unit(state)
        if fn[iz] + u * (fn[iz - 1] - fn[iz]) < np.exp(-0.5 * x * x):
            return state, x
        state += _GOLDEN
        r = _mix(state)
        hz = np.int64(r & _LO32) - 2147483648
        iz = np.int64((r >> _U32) & _U127)
        if abs(hz) < kn[iz]:
            return state, hz * wn[iz]


@njit(cache=True, inline="always")
def _normal(state, kn, wn, fn):
    state += _GOLDEN
    r = _mix(state)
    hz = np.int64(r & _LO32) - 2147483648
    iz = np.int64((r >> _U32) & _U127)
    if abs(hz) < kn[iz]:
        return state, hz * wn[iz]
    return _zig_slow(state, hz, iz, kn, wn, fn)


def standard_normals(n: int, seed: int) -> F64:
    """``n`` standard normals from the kernels' generator (stream ``(seed, 0, 0)``), for tests."""
    return _normals(int(n), int(seed), _KN, _WN, _FN)


@njit(cache=True)
def _normals(n, seed, kn, wn, fn):
    out = np.empty(n)
    state = _key(seed, 0, 0)
    for i in range(n):
        state, out[i] = _normal(state, kn, wn, fn)
    return out


@njit(cache=True)
def _key(seed, k, b):
    return _mix(_mix(np.uint64(seed) + _GOLDEN * np.uint64(k + 1)) + _GOLDEN * np.uint64(b + 2))


@njit(cache=True)
def _uniform(seed, k, b):
    return (_mix(_key(seed, k, b)) >> _U11) * (1.0 / 9007199254740992.0)


@njit(cache=True, parallel=True)
def _predict_weigh(pn, pe, vn, ve, ll, blkmax, zn, ze, dt, sa, inv2s2, seed, k, has_z, kn, wn, fn):
    n = pn.shape[0]
    nb = blkmax.shape[0]
    h = 0.5 * dt * dt
    for b in prange(nb):
        state = _key(seed, k, b)
        lo = b * BLOCK
        hi = min(n, lo + BLOCK)
        m = -np.inf
        for i in range(lo, hi):
            state, an = _normal(state, kn, wn, fn)
            state, ae = _normal(state, kn, wn, fn)
            an *= sa
            ae *= sa
            pn[i] += dt * vn[i] + h * an
            pe[i] += dt * ve[i] + h * ae
            vn[i] += dt * an
            ve[i] += dt * ae
            if has_z:
                dn = zn - pn[i]
                de = ze - pe[i]
                v = -(dn * dn + de * de) * inv2s2
                ll[i] = v
                if v > m:
                    m = v
        blkmax[b] = m


@njit(cache=True, parallel=True)
def _block_sums(w, pn, pe, vn, ve, blksum, blkmom):
    n = w.shape[0]
    nb = blksum.shape[0]
    for b in prange(nb):
        lo = b * BLOCK
        hi = min(n, lo + BLOCK)
        s = 0.0
        m0 = 0.0
        m1 = 0.0
        m2 = 0.0
        m3 = 0.0
        for i in range(lo, hi):
            wi = w[i]
            s += wi
            m0 += wi * pn[i]
            m1 += wi * pe[i]
            m2 += wi * vn[i]
            m3 += wi * ve[i]
        blksum[b] = s
        blkmom[b, 0] = m0
        blkmom[b, 1] = m1
        blkmom[b, 2] = m2
        blkmom[b, 3] = m3


@njit(cache=True, parallel=True)
def _systematic_indices(w, blksum, total, u, idx):
    """Systematic resampling of unnormalised ``w`` into ``idx``: block ``b`` of positions starts
    its merge at the weight block its first position falls in (found from the block sums)."""
    n = w.shape[0]
    nb = blksum.shape[0]
    cum = np.empty(nb + 1)
    cum[0] = 0.0
    for b in range(nb):
        cum[b + 1] = cum[b] + blksum[b]
    step = total / n
    for b in prange(nb):
        lo = b * BLOCK
        hi = min(n, lo + BLOCK)
        p = (lo + u) * step
        jb = 0
        while jb < nb - 1 and cum[jb + 1] < p:
            jb += 1
        i = jb * BLOCK
        c = cum[jb] + w[i]
        for j in range(lo, hi):
            p = (j + u) * step
            while c < p and i < n - 1:
                i += 1
                c += w[i]
            idx[j] = i


def _positive(v, name: str, who: str) -> float:
    """``v`` as a float, or one ValueError unless it is a positive finite real number."""
    if not (isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)) and np.isfinite(v) and v > 0):
        raise ValueError(f"{who}: {name} must be a positive finite number, got {v!r}")
    return float(v)


def _check_measurements(z: ArrayLike, who: str) -> F64:
    """Measurements as a float array (T, 2) (NaN rows allowed: predict-only steps)."""
    Z = np.asarray(z, dtype=np.float64)
    if Z.ndim != 2 or Z.shape[1] != 2:
        raise ValueError(f"{who}: z must have shape (T, 2) (N, E positions), got {Z.shape}")
    return Z


def cv_bootstrap_run(x0: ArrayLike, z: ArrayLike, dt: float, sigma_a: float, sigma_z: float,
                     seed: int) -> tuple[F64, F64]:
    """``T`` CV bootstrap steps (predict, weigh, normalise, mean, systematic resampling).

    Parameters
    ----------
    x0 : array_like, shape (N, 4)
        Initial particles ``[N, E, v_N, v_E]`` (equal weights).
    z : array_like, shape (T, 2)
        Position measurements; a NaN row is a predict-only step (no weighting or resampling).
    dt, sigma_a, sigma_z : float
        Step (s), white-acceleration σ (m/s²) and measurement σ (m).
    seed : int

    Returns
    -------
    mean : (T, 4)
        Weighted means before resampling.
    x : (N, 4)
        The final particles.

    Raises
    ------
    ValueError
        ``x0`` not (N, 4) with N >= 1, ``z`` not (T, 2), or ``dt``, ``sigma_a`` or ``sigma_z`` not a
        positive finite number (checked before any kernel runs).
    """
    X0 = np.asarray(x0, dtype=np.float64)
    if X0.ndim != 2 or X0.shape[1] != 4 or X0.shape[0] < 1:
        raise ValueError(f"cv_bootstrap_run: x0 must have shape (N, 4) with N >= 1 particles, got {X0.shape}")
    Z = _check_measurements(z, "cv_bootstrap_run")
    dt, sigma_a, sigma_z = (_positive(v, name, "cv_bootstrap_run")
                            for v, name in ((dt, "dt"), (sigma_a, "sigma_a"), (sigma_z, "sigma_z")))
    X = np.ascontiguousarray(X0.T).copy()
    n = X.shape[1]
    nb = (n + BLOCK - 1) // BLOCK
    ll = np.empty(n)
    blkmax = np.empty(nb)
    blksum = np.empty(nb)
    blkmom = np.empty((nb, 4))
    Y = np.empty_like(X)
    idx = np.empty(n, dtype=np.int64)
    inv2s2 = 0.5 / (sigma_z * sigma_z)
    out = np.empty((len(Z), 4))
    for k in range(len(Z)):
        has_z = bool(np.all(np.isfinite(Z[k])))
        _predict_weigh(X[0], X[1], X[2], X[3], ll, blkmax, Z[k, 0] if has_z else 0.0,
                       Z[k, 1] if has_z else 0.0, dt, sigma_a, inv2s2, seed, k, has_z, _KN, _WN, _FN)
        if not has_z:
            out[k] = X.mean(axis=1)
            continue
        # numpy's exp is SIMD (AVX2/AVX-512); numba's is a scalar libm call, ~10× slower
        np.subtract(ll, blkmax.max(), out=ll)
        np.exp(ll, out=ll)
        _block_sums(ll, X[0], X[1], X[2], X[3], blksum, blkmom)
        total = blksum.sum()
        out[k] = blkmom.sum(axis=0) / total
        _systematic_indices(ll, blksum, total, _uniform(seed, k, -1), idx)
        np.take(X, idx, axis=1, out=Y)
        X, Y = Y, X
    return out, np.ascontiguousarray(X.T)


# --- the jump-Markov step (CV / CA / augmented-CT modes over PF_STATE) -------------------------

#: mode kinds of :func:`jm_run` (the models of ``estimate.models`` they reproduce)
KIND_CV, KIND_CA, KIND_CT = 0, 1, 2


#: the shared ω → 0-safe turn coefficients (models.turn_coefficients, scalar form), inlined
_turn_one = njit(cache=True, inline="always")(turn_coefficients_one)


@njit(cache=True, parallel=True)
def _jm_step(X, mode, F, kind, init, sig, sigw, ll, blkmax, zn, ze, dt, inv2s2, seed, k, has_z, kn, wn, fn):
    """One block ``b`` at a time: draw each particle's mode from its row of ``F = cumsum(Π(Δt))``
    (seed 001 (2.21)) and apply the entering mode's ``enter`` (CA: a along v; CT: ω ~ N(0, init))
    from the stream ``(seed, 2k, b)``; then propagate each particle by its mode and weigh it from
    the stream ``(seed, 2k + 1, b)``. Particles are independent, so doing both per block is the
    same as the mode draw for all particles first; one ``prange`` kernel rather than two spares
    numba one parallel lowering in a cold compile."""
    n = mode.shape[0]
    K = F.shape[0]
    nb = blkmax.shape[0]
    h = 0.5 * dt * dt
    d3 = dt * dt * dt / 6.0
    rdt = np.sqrt(dt)
    for b in prange(nb):
        lo = b * BLOCK
        hi = min(n, lo + BLOCK)
        # the mode draw
        state = _key(seed, 2 * k, b)
        for i in range(lo, hi):
            state, u = _unit(state)
            r = mode[i]
            if u <= F[r, r] and (r == 0 or u > F[r, r - 1]):
                continue  # stays (the common case): F[r, r−1] < u ≤ F[r, r]
            j = 0
            while j < K - 1 and u > F[r, j]:
                j += 1
            if j != r:
                mode[i] = j
                if kind[j] == KIND_CA:
                    state, a = _normal(state, kn, wn, fn)
                    a *= init[j]
                    sp = np.sqrt(X[2, i] * X[2, i] + X[3, i] * X[3, i])
                    if sp > 1e-9:
                        X[5, i] = a * X[2, i] / sp
                        X[6, i] = a * X[3, i] / sp
                    else:
                        X[5, i] = a
                        X[6, i] = 0.0
                elif kind[j] == KIND_CT:
                    state, a = _normal(state, kn, wn, fn)
                    X[4, i] = a * init[j]
        # propagate and weigh
        state = _key(seed, 2 * k + 1, b)
        m = -np.inf
        for i in range(lo, hi):
            r = mode[i]
            kd = kind[r]
            state, e1 = _normal(state, kn, wn, fn)
            state, e2 = _normal(state, kn, wn, fn)
            e1 *= sig[r]
            e2 *= sig[r]
            vn = X[2, i]
            ve = X[3, i]
            if kd == KIND_CV:
                X[0, i] += dt * vn + h * e1
                X[1, i] += dt * ve + h * e2
                X[2, i] = vn + dt * e1
                X[3, i] = ve + dt * e2
                X[4, i] = 0.0
                X[5, i] = 0.0
                X[6, i] = 0.0
            elif kd == KIND_CA:
                an = X[5, i]
                ae = X[6, i]
                X[0, i] += dt * vn + h * an + d3 * e1
                X[1, i] += dt * ve + h * ae + d3 * e2
                X[2, i] = vn + dt * an + h * e1
                X[3, i] = ve + dt * ae + h * e2
                X[5, i] = an + dt * e1
                X[6, i] = ae + dt * e2
                X[4, i] = 0.0
            else:
                # the shared ct_transition with models.turn_coefficients' ω→0-safe s, c;
                # cos ωT = 1 − ω c and sin ωT = ω s exactly: no second pair of trig calls
                w = X[4, i]
                s, c = _turn_one(w, dt)
                cw = 1.0 - w * c
                sw = w * s
                X[0, i] += s * vn - c * ve + h * e1
                X[1, i] += c * vn + s * ve + h * e2
                X[2, i] = cw * vn - sw * ve + dt * e1
                X[3, i] = sw * vn + cw * ve + dt * e2
                state, e3 = _normal(state, kn, wn, fn)
                X[4, i] += sigw[r] * rdt * e3
                X[5, i] = 0.0
                X[6, i] = 0.0
            if has_z:
                dn = zn - X[0, i]
                de = ze - X[1, i]
                v = -(dn * dn + de * de) * inv2s2
                ll[i] = v
                if v > m:
                    m = v
        blkmax[b] = m


@njit(cache=True, parallel=True)
def _jm_sums(w, X, mode, K, blksum, blkmom, blkmode):
    n = w.shape[0]
    nb = blksum.shape[0]
    d = X.shape[0]
    for b in prange(nb):
        lo = b * BLOCK
        hi = min(n, lo + BLOCK)
        s = 0.0
        for q in range(d):
            blkmom[b, q] = 0.0
        for q in range(K):
            blkmode[b, q] = 0.0
        for i in range(lo, hi):
            wi = w[i]
            s += wi
            for q in range(d):
                blkmom[b, q] += wi * X[q, i]
            blkmode[b, mode[i]] += wi
        blksum[b] = s


#: round-off tolerance of jm_run's Π: row sums within it of 1, no entry below −tolerance
PI_ROW_TOL = 1e-9


def _check_jm_modes(kinds, Pi_dt, sigma, sigma_omega, enter_sigma):
    """:func:`jm_run`'s mode settings as arrays, checked before any kernel indexes them: the kinds
    (K of them), a row-stochastic K×K ``Pi_dt`` and K non-negative finite σ per parameter."""
    kind = np.asarray(kinds)
    if kind.ndim != 1 or kind.size < 1:
        raise ValueError(f"jm_run: kinds must be a 1-D list of K >= 1 mode kinds, got shape {kind.shape}")
    known = (KIND_CV, KIND_CA, KIND_CT)
    bad = [k for k in kind.tolist() if k not in known]
    if bad:
        raise ValueError(f"jm_run: kinds must be KIND_CV ({KIND_CV}), KIND_CA ({KIND_CA}) or KIND_CT "
                         f"({KIND_CT}), got {bad[0]!r}")
    kind = kind.astype(np.int64)
    K = kind.size
    Pi = np.asarray(Pi_dt, dtype=np.float64)
    if Pi.shape != (K, K):
        raise ValueError(f"jm_run: Pi_dt must be {K}x{K} (K = len(kinds) = {K}), got shape {Pi.shape}")
    if not np.all(np.isfinite(Pi)):
        r = int(np.argmax(~np.isfinite(Pi).all(axis=1)))
        raise ValueError(f"jm_run: Pi_dt row {r} is not finite: {Pi[r].tolist()}")
    # negative only by round-off, as markov.check_stochastic allows (an entry of −1e-17 from a
    # matrix product): the kernel then never draws that mode, the same as an exact 0
    if np.any(Pi < -PI_ROW_TOL):
        r = int(np.argmax((Pi < -PI_ROW_TOL).any(axis=1)))
        raise ValueError(f"jm_run: Pi_dt row {r} has a negative probability: {Pi[r].tolist()}")
    off = np.abs(Pi.sum(axis=1) - 1.0)
    if np.any(off > PI_ROW_TOL):
        r = int(np.argmax(off > PI_ROW_TOL))
        raise ValueError(f"jm_run: Pi_dt row {r} sums to {Pi[r].sum():.12g}, not 1 (within {PI_ROW_TOL:g}): "
                         f"{Pi[r].tolist()}")
    out = []
    for name, v in (("sigma", sigma), ("sigma_omega", sigma_omega), ("enter_sigma", enter_sigma)):
        a = np.asarray(v, dtype=np.float64)
        if a.shape != (K,):
            raise ValueError(f"jm_run: {name} must have one entry per mode kind (K = len(kinds) = {K}), "
                             f"got shape {a.shape}")
        if not np.all(np.isfinite(a) & (a >= 0)):
            i = int(np.argmax(~(np.isfinite(a) & (a >= 0))))
            raise ValueError(f"jm_run: {name}[{i}] must be a finite number >= 0, got {a[i].item()!r}")
        out.append(a)
    return kind, Pi, *out


def jm_run(x0: ArrayLike, mode0: ArrayLike, z: ArrayLike, dt: float, Pi_dt: ArrayLike,
           kinds: ArrayLike, sigma: ArrayLike, sigma_omega: ArrayLike, enter_sigma: ArrayLike,
           sigma_z: float, seed: int) -> tuple[F64, F64, F64, NDArray[np.int64]]:
    """``T`` jump-Markov bootstrap steps over :data:`~pipeline.estimate.models.PF_STATE` particles.

    Mode ``k`` of kind ``kinds[k]`` reproduces (statistically, not draw for draw)
    :class:`~pipeline.estimate.models.PfConstantVelocity` (``KIND_CV``, ``sigma`` = σ_a),
    :class:`~pipeline.estimate.models.PfConstantAcceleration` (``KIND_CA``, ``sigma`` = σ_j,
    ``enter_sigma`` = acc_init_sigma) or
    :class:`~pipeline.estimate.models.PfAugmentedCoordinatedTurn` (``KIND_CT``, ``sigma`` = σ_a,
    ``sigma_omega``, ``enter_sigma`` = omega_init_sigma), all with ``zero_unused``; a step is
    mode draw from ``Pi_dt`` (+ enter), propagate, 2-D position likelihood, normalise, mean and
    mode fractions before resampling, systematic resampling (every step).

    Returns
    -------
    mean : (T, 7); mode_p : (T, K); x : (N, 7) final particles; mode : (N,) final modes

    Raises
    ------
    ValueError
        Before any kernel runs (they index ``sigma[r]``, ``Pi_dt[r]`` ... unchecked): ``x0`` not
        (N, 7); ``z`` not (T, 2); ``dt`` or ``sigma_z`` not positive and finite; a kind other than
        ``KIND_CV``/``KIND_CA``/``KIND_CT``; ``Pi_dt`` not K×K (K = ``len(kinds)``), not finite,
        negative or with a row sum off 1 by more than :data:`PI_ROW_TOL`; ``sigma``,
        ``sigma_omega`` or ``enter_sigma`` not K finite values >= 0; ``mode0`` not N integers in
        [0, K). The message names the row, entry or particle.
    """
    X0 = np.asarray(x0, dtype=np.float64)
    if X0.ndim != 2 or X0.shape[1] != 7 or X0.shape[0] < 1:
        raise ValueError(f"jm_run: particles must have shape (N, 7) with N >= 1, got {X0.shape}")
    Z = _check_measurements(z, "jm_run")
    dt = _positive(dt, "dt", "jm_run")
    sigma_z = _positive(sigma_z, "sigma_z", "jm_run")
    kind, Pi, sig, sigw, init = _check_jm_modes(kinds, Pi_dt, sigma, sigma_omega, enter_sigma)
    K = kind.size
    mode_in = np.asarray(mode0)
    if mode_in.shape != (X0.shape[0],):
        raise ValueError(f"jm_run: mode0 must have shape ({X0.shape[0]},) (one mode per particle), "
                         f"got {mode_in.shape}")
    if mode_in.dtype.kind not in "iu" and not (mode_in.dtype.kind == "f" and np.all(mode_in == np.round(mode_in))):
        raise ValueError(f"jm_run: mode0 must hold integer mode indices, got dtype {mode_in.dtype}")
    bad = ~((mode_in >= 0) & (mode_in < K))
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"jm_run: mode0 must lie in [0, {K}) (K = len(kinds)); particle {i} has mode "
                         f"{mode_in[i].item()!r} ({int(bad.sum())} particle(s) out of range)")
    X = np.ascontiguousarray(X0.T).copy()
    mode = np.asarray(mode_in, dtype=np.int64).copy()
    F = np.cumsum(Pi, axis=1)
    # a proper CDF per row: the last entry pinned to exactly 1. _check_jm_modes has refused any
    # row whose sum misses 1 by more than PI_ROW_TOL (1e-9), so this moves it by round-off only
    # (a retimed or printed Π), the sliver the kernel's search gives the last mode anyway; it
    # never rewrites a wrong matrix
    F[:, -1] = 1.0
    n = mode.size
    nb = (n + BLOCK - 1) // BLOCK
    ll = np.zeros(n)
    blkmax, blksum = np.empty(nb), np.empty(nb)
    blkmom, blkmode = np.empty((nb, 7)), np.empty((nb, K))
    Y = np.empty_like(X)
    idx = np.empty(n, dtype=np.int64)
    inv2s2 = 0.5 / (sigma_z * sigma_z)
    mode_y = np.empty_like(mode)
    mean = np.empty((len(Z), 7))
    mode_p = np.empty((len(Z), K))
    for k in range(len(Z)):
        has_z = bool(np.all(np.isfinite(Z[k])))
        _jm_step(X, mode, F, kind, init, sig, sigw, ll, blkmax,
                 Z[k, 0] if has_z else 0.0, Z[k, 1] if has_z else 0.0, dt, inv2s2,
                 seed, k, has_z, _KN, _WN, _FN)
        if not has_z:
            ll.fill(1.0)
            _jm_sums(ll, X, mode, K, blksum, blkmom, blkmode)
            mean[k], mode_p[k] = blkmom.sum(axis=0) / n, blkmode.sum(axis=0) / n
            continue
        np.subtract(ll, blkmax.max(), out=ll)
        np.exp(ll, out=ll)
        _jm_sums(ll, X, mode, K, blksum, blkmom, blkmode)
        total = blksum.sum()
        mean[k], mode_p[k] = blkmom.sum(axis=0) / total, blkmode.sum(axis=0) / total
        _systematic_indices(ll, blksum, total, _uniform(seed, k, -1), idx)
        np.take(X, idx, axis=1, out=Y)  # numpy's gather beats a numba loop here (~2x)
        np.take(mode, idx, out=mode_y)
        X, Y = Y, X
        mode, mode_y = mode_y, mode
    return mean, mode_p, np.ascontiguousarray(X.T), mode
