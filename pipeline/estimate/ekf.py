"""The 9-state constant-acceleration EKF in NED (seed 000 §3), vectorised across runs.

Prediction (eq. 2.16, with the §13.2 fix ``P⁻ = A P Aᵀ + Q``):

.. math::

    x^-_{k+1} = A x^+_k \\;(+\\,B u_k),\\qquad P^-_{k+1} = A P^+_k A^T + Q

Update (§3, "Update"), with ``H = ∂h/∂x`` at ``x⁻`` and the innovation ``y = z − h(x⁻)``
(or the measurement model's ``residual(z, h)`` where it has one, e.g. the wrapped bearing of :class:`~pipeline.estimate.models.BearingMeasurement`):

.. math::

    S = H P^- H^T + R,\\quad K = P^- H^T S^{-1},\\quad x^+ = x^- + K y,

    P^+ = (I - KH) P^- (I - KH)^T + K R K^T \\quad\\text{(Joseph form, the default)},

    P^+ = (I - KH) P^- \\quad\\text{(standard form, eq. of §3; symmetrised)}

and the normalised innovation squared ``NIS = yᵀ S⁻¹ y``.

Every array may carry a leading run axis: means ``(n_runs, 9)``, covariances
``(n_runs, 9, 9)``; :func:`run_filter` loops over time only. An update takes 0..M stacked
measurements per step (``(..., M, n_z)``, M = 0: predict only); a measurement row with a
non-finite entry (NaN, or ±inf as the bearing bank and IMM treat it) is missing for that run
(its H row, residual and gain column are zero, exactly as if it were left out; it counts as 0
in ``dof``), so radar gaps and ragged measurement counts stay vectorised. A Joseph update with
one measurement a run and diagonal ``R`` (the radar, a bearing) runs compiled
(:func:`_joseph_update_kernel`, the same algebra, equal to the numpy one to ~1e-13 relative);
everything else runs the numpy algebra, which is also the fallback without numba.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scipy.linalg.lapack import dpotrf as _dpotrf
from scipy.linalg.lapack import dpotri as _dpotri

from .base import GaussianState, MeasurementModel, TransitionModel, check_times
from .models import HAVE_NUMBA, kernel_input, lazy_njit

F64 = NDArray[np.float64]


def _T(a: F64) -> F64:
    return np.swapaxes(a, -1, -2)


def _c(a: F64) -> F64:
    # numpy's stacked matmul takes its fast (BLAS) path only on contiguous operands: a
    # transposed view costs several times the copy
    return np.ascontiguousarray(a)


#: above this innovation size :func:`_spd_inverse` calls LAPACK: the scalar-plane loops cost
#: O(n³) numpy calls whatever the batch, which only pays for small n (the radar's 4, two stacked)
_PLANES_MAX_N = 8


def _spd_inverse(S: F64, y: F64) -> tuple[F64, F64, F64]:
    """``(S⁻¹, yᵀS⁻¹y, log|S|)`` of stacked symmetric positive definite ``S`` (..., n, n),
    ``S = L Lᵀ``, and residuals ``y`` (..., n), with ``yᵀS⁻¹y = |L⁻¹y|²`` and
    ``log|S| = 2 Σ log L_ii``.

    Cholesky–Banachiewicz and the triangular inverse by forward substitution, both on scalar
    planes vectorised over the stack (``L⁻¹[i, j] = −Σ_{j≤k<i} L[i, k] L⁻¹[k, j] / L[i, i]``),
    then ``S⁻¹[i, j] = Σ_{k≥max(i,j)} L⁻¹[k, i] L⁻¹[k, j]`` (``L⁻ᵀ L⁻¹``, one triangle mirrored)
    and ``L⁻¹y`` on the same planes (no stacked 4×4 products, no transposed copies): several
    times faster than LAPACK (``np.linalg.cholesky``/``solve``/
    ``inv``), which is called once per matrix, on many small systems (n = 4 for the radar). An
    SPD matrix needs no pivoting.

    Raises
    ------
    numpy.linalg.LinAlgError
        Where a matrix is not positive definite.
    """
    n = S.shape[-1]
    if n > _PLANES_MAX_N:
        # many stacked measurements (the trajectory learner's M demos × 13): one LAPACK call
        # per matrix beats n³/2 numpy calls on scalar planes
        if S.ndim == 2 or S.shape[0] == 1 and S.ndim == 3:
            # a single matrix: LAPACK's potrf/potri straight (numpy's stacked wrappers cost
            # several times the factorisation at this size)
            c, info = _dpotrf(S.reshape(n, n), lower=1, clean=1)
            if info != 0:
                raise np.linalg.LinAlgError("Matrix is not positive definite")
            d = np.diagonal(c)
            if not np.all(d > 0):
                raise np.linalg.LinAlgError("Matrix is not positive definite")
            inv, info = _dpotri(c, lower=1)
            # potri fills the lower triangle; the upper one is potrf's cleaned zeros
            Si = inv + inv.T
            Si.flat[::n + 1] *= 0.5
            yv = y.reshape(n)
            return (Si.reshape(S.shape), np.reshape(yv @ Si @ yv, y.shape[:-1]),
                    np.reshape(2.0 * np.log(d).sum(), y.shape[:-1]))
        L = np.linalg.cholesky(S)  # raises LinAlgError where S is not positive definite
        d = np.diagonal(L, axis1=-2, axis2=-1)
        if not np.all(d > 0):  # NaN fails too
            raise np.linalg.LinAlgError("Matrix is not positive definite")
        Li = np.linalg.inv(L)
        ly = np.matmul(Li, y[..., None])[..., 0]
        return _T(Li) @ Li, np.einsum("...i,...i->...", ly, ly), 2.0 * np.log(d).sum(axis=-1)
    if HAVE_NUMBA and S.ndim >= 3 and S.size >= _KERNEL_FROM * n * n:
        # many small systems (stacked or correlated measurements, the standard form over many
        # runs): the same arithmetic, one compiled pass per matrix instead of ~n³/2 numpy calls
        # over the planes (measured when the 1000-run, 325-step radar EKF still came here,
        # before _joseph_update_kernel: 0.512 -> 0.493 s CPU, median of 6)
        Si, nis, d, bad = _spd_inverse_kernel(kernel_input(S.reshape(-1, n, n)),
                                              kernel_input(np.broadcast_to(y, S.shape[:-1]).reshape(-1, n)))
        if bad:
            raise np.linalg.LinAlgError("Matrix is not positive definite")
        return Si.reshape(S.shape), nis.reshape(S.shape[:-2]), _logdet(d).reshape(S.shape[:-2])
    # planes are lists of (...)-shaped arrays (views of S and y, new arrays for the rest): no
    # moved-axis copies, and no stores into a planes array (each would be one more copy)
    L: list[list] = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            acc = S[..., i, j]
            if j:
                acc = acc - L[i][0] * L[j][0]
                for k in range(1, j):
                    acc -= L[i][k] * L[j][k]
            if i == j:
                if not acc.min() > 0:  # NaN fails too
                    raise np.linalg.LinAlgError("Matrix is not positive definite")
                L[i][i] = np.sqrt(acc)
            else:
                L[i][j] = acc / L[j][j]
    Li: list[list] = [[None] * n for _ in range(n)]
    for i in range(n):
        Li[i][i] = 1.0 / L[i][i]
        for j in range(i):
            acc = L[i][j] * Li[j][j]
            for k in range(j + 1, i):
                acc += L[i][k] * Li[k][j]
            acc *= -Li[i][i]
            Li[i][j] = acc
    Si = np.empty(S.shape)
    for i in range(n):
        for j in range(i + 1):
            acc = Li[i][i] * Li[i][j]  # the first term, k = max(i, j) = i
            for k in range(i + 1, n):
                acc += Li[k][i] * Li[k][j]
            Si[..., i, j] = acc
            if j != i:
                Si[..., j, i] = acc
    nis = None
    for i in range(n):
        ly = Li[i][0] * y[..., 0]
        for k in range(1, i + 1):
            ly += Li[i][k] * y[..., k]
        ly *= ly
        nis = ly if nis is None else nis + ly
    logdet = np.log(L[0][0])
    for i in range(1, n):
        logdet = logdet + np.log(L[i][i])
    return Si, nis, 2.0 * logdet


#: from this many stacked systems on, :func:`_spd_inverse` runs :func:`_spd_inverse_kernel`
_KERNEL_FROM = 64


def _logdet(diag: F64) -> F64:
    """``log|S| = 2 Σ_i log L_ii`` from a kernel's Cholesky diagonals ``diag`` (N, n): numpy's
    log, summed in the order the scalar planes of :func:`_spd_inverse` take (numba's libm log
    may differ in the last bit)."""
    logdet = np.log(diag[:, 0])
    for i in range(1, diag.shape[1]):
        logdet = logdet + np.log(diag[:, i])
    return 2.0 * logdet


def _spd_inverse_kernel(S, y):  # pragma: no cover - compiled by numba
    """:func:`_spd_inverse`'s scalar-plane algorithm, matrix by matrix over (N, n, n): the same
    operations in the same order (Cholesky–Banachiewicz, ``L⁻¹`` by forward substitution,
    ``S⁻¹ = L⁻ᵀ L⁻¹``, ``|L⁻¹y|²``). Returns ``(Si, nis, diag, bad)``: ``diag`` (N, n) the
    ``L_ii`` (the caller takes ``2 Σ log L_ii``), ``bad`` True when a matrix is not positive
    definite (a NaN included)."""
    N, n = S.shape[0], S.shape[1]
    Si = np.empty((N, n, n))
    nis = np.empty(N)
    diag = np.empty((N, n))
    L = np.zeros((n, n))
    Li = np.zeros((n, n))
    for r in range(N):
        for i in range(n):
            for j in range(i + 1):
                acc = S[r, i, j]
                for k in range(j):
                    acc -= L[i, k] * L[j, k]
                if i == j:
                    if not acc > 0:
                        return Si, nis, diag, True
                    L[i, i] = np.sqrt(acc)
                    diag[r, i] = L[i, i]
                else:
                    L[i, j] = acc / L[j, j]
        for i in range(n):
            Li[i, i] = 1.0 / L[i, i]
            for j in range(i):
                acc = L[i, j] * Li[j, j]
                for k in range(j + 1, i):
                    acc += L[i, k] * Li[k, j]
                Li[i, j] = acc * -Li[i, i]
        for i in range(n):
            for j in range(i + 1):
                acc = Li[i, i] * Li[i, j]
                for k in range(i + 1, n):
                    acc += Li[k, i] * Li[k, j]
                Si[r, i, j] = acc
                Si[r, j, i] = acc
        q = 0.0
        for i in range(n):
            ly = Li[i, 0] * y[r, 0]
            for k in range(1, i + 1):
                ly += Li[i, k] * y[r, k]
            q += ly * ly
        nis[r] = q
    return Si, nis, diag, False


_spd_inverse_kernel = lazy_njit(_spd_inverse_kernel)


#: runs a block of :func:`_joseph_update_kernel` holds in its scalar planes: the compiled
#: loops run across a block's runs, and a loop's setup (numba cannot tell LLVM that the planes
#: do not overlap, so every loop checks at run time) is paid once per block row, not per run;
#: 64 measured best (1000-run radar EKF: 16 → 0.31 s, 32 → 0.29, 64 → 0.285, 128 → 0.38,
#: whose planes no longer fit the L2 cache)
_LANES = 64
#: whether :meth:`ExtendedKalmanFilter.update_stats` runs :func:`_joseph_update_kernel` where it
#: applies (the tests switch it off to hold the kernel equal to the numpy algebra)
_JOSEPH_KERNEL = HAVE_NUMBA


def _joseph_update_kernel(x, P, H, y, r, xo, Po, nis, diag):  # pragma: no cover - numba
    """One Joseph-form update of N filters, one measurement of m scalars each with diagonal
    noise ``r``: :meth:`ExtendedKalmanFilter.update_stats`'s algebra (module docstring) in
    compiled loops.

    .. math::

        S = H P^- H^T + \\operatorname{diag} r = L L^T,\\quad K = P^- H^T S^{-1},\\quad
        x^+ = x^- + K y,\\quad P^+ = (I - KH) P^- (I - KH)^T + K \\operatorname{diag}(r) K^T

    The runs go through in blocks of :data:`_LANES`, each held as scalar planes ``(i, j, run)``
    so that every innermost loop runs across the block's runs (vectorised), as the numpy path's
    stacked products do, without their temporaries and transposed copies. Two structural
    savings, both exact: a column of ``H`` that is zero for the whole block (the radar's three
    accelerations) is left out of every sum it would add only zeros to, and ``I − KH`` is the
    identity there; ``P⁺`` is computed on one triangle and mirrored (the numpy product is
    symmetric to round-off). ``S⁻¹`` and ``yᵀS⁻¹y = |L⁻¹y|²`` as :func:`_spd_inverse_kernel`.

    Writes ``xo`` (N, n), ``Po`` (N, n, n), ``nis`` (N,) and ``diag`` (N, m) (the ``L_ii``;
    the caller takes ``log|S| = 2 Σ log L_ii``). Returns the first run whose ``S`` is not
    positive definite (a NaN included), or −1.
    """
    N, n = x.shape
    m = y.shape[1]
    W = min(_LANES, N)
    Pl = np.empty((n, n, W))
    Hl = np.empty((m, n, W))
    yl = np.empty((m, W))
    PHT = np.empty((n, m, W))
    L = np.empty((m, m, W))
    Li = np.empty((m, m, W))
    Si = np.empty((m, m, W))
    K = np.empty((n, m, W))
    A = np.empty((n, n, W))
    T1 = np.empty((n, n, W))
    acc = np.empty(W)
    q = np.empty(W)
    cols = np.empty(n, dtype=np.int64)
    free = np.empty(n, dtype=np.bool_)
    bad = -1
    for r0 in range(0, N, W):
        nb = min(W, N - r0)
        # gather run by run (contiguous reads; the planes are small enough for L1/L2)
        for b in range(nb):
            for i in range(n):
                for j in range(n):
                    Pl[i, j, b] = P[r0 + b, i, j]
            for a in range(m):
                yl[a, b] = y[r0 + b, a]
                for j in range(n):
                    Hl[a, j, b] = H[r0 + b, a, j]
        # the columns of H with a nonzero entry in this block
        nc = 0
        for j in range(n):
            used = False
            for a in range(m):
                for b in range(nb):
                    if Hl[a, j, b] != 0.0:
                        used = True
            free[j] = not used
            if used:
                cols[nc] = j
                nc += 1
        # P Hᵀ
        for i in range(n):
            for a in range(m):
                for b in range(nb):
                    PHT[i, a, b] = 0.0
                for c in range(nc):
                    k = cols[c]
                    for b in range(nb):
                        PHT[i, a, b] += Pl[i, k, b] * Hl[a, k, b]
        # S = H P Hᵀ + diag r and its Cholesky factor L (Cholesky–Banachiewicz), row by row
        for a in range(m):
            for e in range(a + 1):
                for b in range(nb):
                    acc[b] = 0.0
                for c in range(nc):
                    k = cols[c]
                    for b in range(nb):
                        acc[b] += Hl[a, k, b] * PHT[k, e, b]
                if a == e:
                    ra = r[a]
                    for b in range(nb):
                        acc[b] += ra
                for k in range(e):
                    for b in range(nb):
                        acc[b] -= L[a, k, b] * L[e, k, b]
                if a == e:
                    for b in range(nb):
                        L[a, a, b] = np.sqrt(acc[b])  # NaN where not positive: flagged below
                else:
                    for b in range(nb):
                        L[a, e, b] = acc[b] / L[e, e, b]
        for a in range(m):
            for b in range(nb):
                if not L[a, a, b] > 0.0 and bad < 0:
                    bad = r0 + b
        # L⁻¹ by forward substitution, S⁻¹ = L⁻ᵀ L⁻¹, nis = |L⁻¹ y|²
        for a in range(m):
            for b in range(nb):
                Li[a, a, b] = 1.0 / L[a, a, b]
            for e in range(a):
                for b in range(nb):
                    acc[b] = L[a, e, b] * Li[e, e, b]
                for k in range(e + 1, a):
                    for b in range(nb):
                        acc[b] += L[a, k, b] * Li[k, e, b]
                for b in range(nb):
                    Li[a, e, b] = acc[b] * -Li[a, a, b]
        for a in range(m):
            for e in range(a + 1):
                for b in range(nb):
                    acc[b] = Li[a, a, b] * Li[a, e, b]
                for k in range(a + 1, m):
                    for b in range(nb):
                        acc[b] += Li[k, a, b] * Li[k, e, b]
                for b in range(nb):
                    Si[a, e, b] = acc[b]
                    Si[e, a, b] = acc[b]
        for b in range(nb):
            q[b] = 0.0
        for a in range(m):
            for b in range(nb):
                acc[b] = 0.0
            for k in range(a + 1):
                for b in range(nb):
                    acc[b] += Li[a, k, b] * yl[k, b]
            for b in range(nb):
                q[b] += acc[b] * acc[b]
        for b in range(nb):
            nis[r0 + b] = q[b]
            for a in range(m):
                diag[r0 + b, a] = L[a, a, b]
        # K = P Hᵀ S⁻¹, x⁺ = x⁻ + K y
        for i in range(n):
            for a in range(m):
                for b in range(nb):
                    acc[b] = 0.0
                for e in range(m):
                    for b in range(nb):
                        acc[b] += PHT[i, e, b] * Si[e, a, b]
                for b in range(nb):
                    K[i, a, b] = acc[b]
            for b in range(nb):
                acc[b] = 0.0
            for a in range(m):
                for b in range(nb):
                    acc[b] += K[i, a, b] * yl[a, b]
            for b in range(nb):
                xo[r0 + b, i] = x[r0 + b, i] + acc[b]
        # A = I − K H on the used columns (the identity's column elsewhere)
        for i in range(n):
            for c in range(nc):
                k = cols[c]
                for b in range(nb):
                    acc[b] = 0.0
                for a in range(m):
                    for b in range(nb):
                        acc[b] += K[i, a, b] * Hl[a, k, b]
                d = 1.0 if k == i else 0.0
                for b in range(nb):
                    A[i, k, b] = d - acc[b]
        # T1 = A P⁻; a free column k of A is e_k, so its one term is 1·P⁻[k, j] at k = i. The
        # terms are summed in k order whichever columns are free, so a run's result does not
        # depend on the runs beside it in its block (the left-out terms are exact zeros)
        for i in range(n):
            for j in range(n):
                for b in range(nb):
                    T1[i, j, b] = 0.0
                for k in range(n):
                    if free[k]:
                        if k == i:
                            for b in range(nb):
                                T1[i, j, b] += Pl[i, j, b]
                    else:
                        for b in range(nb):
                            T1[i, j, b] += A[i, k, b] * Pl[k, j, b]
        # P⁺ = T1 Aᵀ + K diag(r) Kᵀ on the lower triangle, into the planes P⁻ no longer needs
        for i in range(n):
            for j in range(i + 1):
                for b in range(nb):
                    acc[b] = 0.0
                for k in range(n):
                    if free[k]:
                        if k == j:
                            for b in range(nb):
                                acc[b] += T1[i, j, b]
                    else:
                        for b in range(nb):
                            acc[b] += T1[i, k, b] * A[j, k, b]
                for a in range(m):
                    ra = r[a]
                    for b in range(nb):
                        acc[b] += K[i, a, b] * ra * K[j, a, b]
                for b in range(nb):
                    Pl[i, j, b] = acc[b]
                    Pl[j, i, b] = acc[b]
        for b in range(nb):
            for i in range(n):
                for j in range(n):
                    Po[r0 + b, i, j] = Pl[i, j, b]
    return bad


_joseph_update_kernel = lazy_njit(_joseph_update_kernel, error_model="numpy")


@dataclass(frozen=True)
class UpdateStats:
    """Innovation statistics of one update.

    Attributes
    ----------
    nis : ndarray, shape (...)
        ``yᵀ S⁻¹ y`` (0 where nothing was measured).
    dof : ndarray of int, shape (...)
        Number of measured scalars (the NIS's χ² degrees of freedom).
    logdet : ndarray, shape (...), optional
        ``log|S|`` over the measured rows (0 where nothing was measured), so the step's
        log-likelihood (prediction-error decomposition) is
        ``−½ (nis + logdet + dof·log 2π)``.
    """

    nis: F64
    dof: NDArray[np.int64]
    logdet: F64 | None = None


@dataclass(frozen=True)
class ExtendedKalmanFilter:
    """EKF over a transition and a measurement model (see the module docstring).

    Parameters
    ----------
    transition : TransitionModel
        ``matrix(dt)``, ``noise(dt)`` (e.g. :class:`~pipeline.estimate.base.ConstantAcceleration`).
    measurement : MeasurementModel
        ``h``, ``jacobian``, ``R`` (e.g. :class:`~pipeline.estimate.models.RadarModel`).
    joseph : bool
        Joseph-form covariance update (True) or the standard form ``(I − KH)P``.
    """

    transition: TransitionModel
    measurement: MeasurementModel
    joseph: bool = True

    def predict(self, prior: GaussianState, t_ns: int, F: ArrayLike | None = None,
                Q: ArrayLike | None = None, bu: ArrayLike | None = None,
                fx: ArrayLike | None = None) -> GaussianState:
        """Predict ``prior`` to ``t_ns``.

        Parameters
        ----------
        prior : GaussianState
            Mean ``(..., n_x)``, covariance ``(..., n_x, n_x)``.
        t_ns : int
            Target time (ns); ``dt = (t_ns − prior.t_ns)·1e-9`` s.
        F, Q : ndarray, optional
            Override the transition's ``matrix(dt)`` / ``noise(dt)``; shape ``(n_x, n_x)`` or
            per run ``(..., n_x, n_x)`` (the EKF+HMM's ``A_H``, ``Q₂``).
        bu : ndarray, optional
            Deterministic input ``B u``, shape ``(..., n_x)`` (the EKF+HMM's ``B[â; ĵ]``).
        fx : ndarray, optional
            The predicted mean ``f(x)`` of a nonlinear transition, shape ``(..., n_x)``, which
            replaces ``F x`` (``F`` is then its Jacobian, ``P⁻ = F P Fᵀ + Q``; the bearing-only
            bank and IMM, seed 002).
        """
        dt = (int(t_ns) - prior.t_ns) * 1e-9
        F = self.transition.matrix(dt) if F is None else np.asarray(F, dtype=np.float64)
        Q = self.transition.noise(dt) if Q is None else np.asarray(Q, dtype=np.float64)
        if fx is not None:
            mean = np.asarray(fx, dtype=np.float64)
        else:
            mean = prior.mean @ F.T if F.ndim == 2 else np.matmul(F, prior.mean[..., None])[..., 0]
        if bu is not None:
            mean = mean + bu
        P = prior.cov
        if F.ndim == 2:
            # a shared F: P Fᵀ for every run is one (runs·n)×n by n×n product (a single BLAS
            # call, where a stacked product calls BLAS once per run), then F (P Fᵀ)
            cov = F @ (_c(P).reshape(-1, P.shape[-1]) @ F.T).reshape(P.shape)
        else:
            cov = F @ P @ _c(_T(F))
        cov += Q
        return GaussianState(mean, cov, t_ns)

    def update(self, pred: GaussianState, z: ArrayLike) -> GaussianState:
        """Update ``pred`` with the measurement(s) ``z``; see :meth:`update_stats`."""
        return self.update_stats(pred, z)[0]

    def update_stats(self, pred: GaussianState, z: ArrayLike,
                     out: F64 | None = None) -> tuple[GaussianState, UpdateStats]:
        """Update ``pred`` with 0..M stacked measurements and return the innovation statistics.

        Parameters
        ----------
        pred : GaussianState
            Predicted state, batch shape ``b`` (``()`` for one run).
        z : array_like, shape ``b + (n_z,)`` or ``b + (M, n_z)``
            One measurement per run, or M stacked ones (independent, each with noise ``R``);
            M = 0 returns ``pred``. Rows with a NaN or ±inf are missing measurements for that
            run (an inf would otherwise poison the state for the rest of a run).
            ``h(x⁻)`` and ``H`` come from the measurement model's ``h_and_jacobian`` where it
            has one (one pass, e.g. :meth:`~pipeline.estimate.models.RadarModel.h_and_jacobian`),
            else from its ``h`` and ``jacobian``.
        out : ndarray, shape ``b + (n_x, n_x)``, optional
            Written with the posterior covariance, which is then a view of it (a caller that
            keeps every step, like :func:`run_filter`, saves a copy of each).
        """
        R = np.asarray(self.measurement.R, dtype=np.float64)
        n_z = R.shape[0]
        b = pred.batch_shape
        z = np.asarray(z, dtype=np.float64)
        if z.shape == b + (n_z,):
            z = z[..., None, :]
        if z.ndim != len(b) + 2 or z.shape[:len(b)] != b or z.shape[-1] != n_z:
            raise ValueError(f"update: measurement shape {z.shape} does not fit the state batch {b} "
                             f"with {n_z} components (expected {b + (n_z,)} or {b + ('M', n_z)})")
        M = z.shape[-2]
        if M * n_z > _PLANES_MAX_N and int(np.prod(b)) == 1 and not np.isfinite(z).all():
            # one run with many stacked rows, some missing (the trajectory learner's 0..M demo
            # samples per hidden step): leaving the missing rows out is exactly the zero-gain
            # treatment below, on a smaller innovation covariance
            keep = np.isfinite(z.reshape(M, n_z)).all(axis=-1)
            z = z[..., keep, :]
            M = int(keep.sum())
        if M == 0:
            if out is not None:
                np.copyto(out, pred.cov)
                pred = GaussianState(pred.mean, out, pred.t_ns)
            return pred, UpdateStats(np.zeros(b), np.zeros(b, dtype=np.int64), np.zeros(b))
        x, P = pred.mean, pred.cov
        n_x = x.shape[-1]
        hj = getattr(self.measurement, "h_and_jacobian", None)  # optional: both in one pass
        hx, Hj = hj(x) if hj is not None else (self.measurement.h(x), self.measurement.jacobian(x))
        hx = hx[..., None, :]
        Hj = np.asarray(Hj)[..., None, :, :]  # (..., 1, n_z, n_x)
        # one flat test for the common case (everything measured); per row only when needed
        full = bool(np.isfinite(z).all())
        valid = None if full and M == 1 else np.isfinite(z).all(axis=-1)  # (..., M)
        # optional hook: a model with angular components wraps its innovation
        # (BearingMeasurement.residual); the default is the plain difference
        res = getattr(self.measurement, "residual", None)
        d = res(z, hx) if res is not None else z - hx
        if full and M == 1:
            y, H = d[..., 0, :], Hj[..., 0, :, :]
        else:
            y = np.where(valid[..., None], d, 0.0).reshape(b + (M * n_z,))
            H = np.broadcast_to(np.where(valid[..., None, None], Hj, 0.0), b + (M, n_z, n_x)).reshape(b + (M * n_z, n_x))
        dof = np.full(b, M * n_z, dtype=np.int64) if valid is None else valid.sum(axis=-1) * n_z
        if (_JOSEPH_KERNEL and self.joseph and M == 1 and R.ndim == 2
                and not np.any(R - np.diag(np.diagonal(R)))):
            # the common case (one measurement a run, diagonal noise: the radar Monte Carlo,
            # the IMM's bearings) in one compiled pass; the same algebra. A missing run has
            # H = 0, y = 0 (above): zero gain, its state unchanged, exactly as below
            mean, cov, nis, logdet = self._joseph_compiled(x, P, H, y, np.diagonal(R), out, pred.t_ns)
            if not full:
                v = valid[..., 0]
                nis, logdet = np.where(v, nis, 0.0), np.where(v, logdet, 0.0)
                # the kernel mirrors one triangle; an unmeasured run keeps P⁻ as it was
                np.copyto(cov, P, where=~v[..., None, None])
            fold = getattr(self.measurement, "fold", None)
            if fold is not None:
                mean, cov = fold(mean, cov)
            return GaussianState(mean, cov, pred.t_ns), UpdateStats(nis, dof, logdet)
        if M > 1:
            # block-diagonal R (np.kron costs more than the update at this size)
            Rs = np.zeros((M * n_z, M * n_z))
            for m in range(M):
                Rs[m * n_z:(m + 1) * n_z, m * n_z:(m + 1) * n_z] = R
        else:
            Rs = R
        if not full:
            # a missing row: H row 0, residual 0, noise 1 -> zero gain column, no contribution
            miss = np.repeat(~valid, n_z, axis=-1)
            Rs = np.where(miss[..., None] | miss[..., None, :], 0.0, Rs)
            Rs = Rs + miss[..., None] * np.eye(M * n_z)
        H = _c(H)
        PHT = P @ _c(_T(H))
        S = H @ PHT + Rs
        try:
            # nis = yᵀS⁻¹y = |L⁻¹y|²; a missing row's unit diagonal adds 0 to log|S|
            Si, nis, logdet = _spd_inverse(S, y)
        except np.linalg.LinAlgError:
            raise ValueError(f"update at t_ns={pred.t_ns}: the innovation covariance H P Hᵀ + R is not "
                             "positive definite (a non-finite or degenerate state/covariance)") from None
        K = PHT @ Si  # P Hᵀ S⁻¹, as filterpy
        mean = x + np.matmul(K, y[..., None])[..., 0]
        if self.joseph:
            # the product form keeps P symmetric positive definite under round-off (an expanded
            # form loses it with the radar's 45 µrad against metres of position variance)
            IKH = K @ H
            np.subtract(np.eye(n_x), IKH, out=IKH)
            cov = np.matmul(IKH @ P, _c(_T(IKH)), out=out)
            KT = _c(_T(K))
            if Rs.ndim == 2 and not np.any(Rs - np.diag(np.diagonal(Rs))):
                # diagonal R: K R = K·diag(R), as one flat product (a (..., 4)-shaped broadcast
                # runs numpy's inner loop over 4 elements at a time)
                r = np.tile(np.diagonal(Rs), K.shape[-2])
                cov += (K.reshape(K.shape[:-2] + r.shape) * r).reshape(K.shape) @ KT
            else:
                cov += K @ Rs @ KT
        else:
            A = P - K @ _c(_T(PHT))  # (I − KH)P = P − K (HP)
            cov = np.add(A, _T(A), out=out)
            cov *= 0.5
        # optional hook: a model that cannot tell a state from its mirror image picks the
        # physical one (RadarModel.fold: the target above the radar's horizontal plane)
        fold = getattr(self.measurement, "fold", None)
        if fold is not None:
            mean, cov = fold(mean, cov)
        return GaussianState(mean, cov, pred.t_ns), UpdateStats(nis, dof, logdet)


    @staticmethod
    def _joseph_compiled(x: F64, P: F64, H: F64, y: F64, r: F64, out: F64 | None,
                         t_ns: int) -> tuple[F64, F64, F64, F64]:
        """:func:`_joseph_update_kernel` over the flattened batch: ``(mean, cov, nis, logdet)``
        shaped as the batch; ``cov`` is ``out`` where that is C-contiguous."""
        n_x, n_z = x.shape[-1], y.shape[-1]
        b = x.shape[:-1]
        N = int(np.prod(b))
        # inputs read-only (kernel_input), outputs writable: one compiled specialisation
        xf = kernel_input(np.reshape(x, (N, n_x)))
        Pf = kernel_input(np.broadcast_to(P, b + (n_x, n_x)).reshape(N, n_x, n_x))
        Hf = kernel_input(np.broadcast_to(H, b + (n_z, n_x)).reshape(N, n_z, n_x))
        yf = kernel_input(np.reshape(y, (N, n_z)))
        direct = out is not None and out.flags.c_contiguous
        cov = out if direct else np.empty(b + (n_x, n_x))
        mean, nis, diag = np.empty((N, n_x)), np.empty(N), np.empty((N, n_z))
        bad = -1 if N == 0 else _joseph_update_kernel(xf, Pf, Hf, yf, kernel_input(np.asarray(r, dtype=np.float64)),
                                                      mean, cov.reshape(N, n_x, n_x), nis, diag)
        if bad >= 0:
            raise ValueError(f"update at t_ns={t_ns}: the innovation covariance H P Hᵀ + R is not "
                             "positive definite (a non-finite or degenerate state/covariance)")
        if out is not None and not direct:
            np.copyto(out, cov)
            cov = out
        return mean.reshape(b + (n_x,)), cov, nis.reshape(b), _logdet(diag).reshape(b)


@dataclass(frozen=True)
class FilterTrack:
    """A filter run over runs × time (arrays ordered runs, time, state).

    Attributes
    ----------
    t_ns : ndarray of int64, shape (T,)
    mean, cov : ndarray, shapes (R, T, n_x), (R, T, n_x, n_x) or None
        Filtered (posterior) estimates.
    pred_mean, pred_cov : ndarray or None
        Predicted (prior) estimates at each step (step 0: the initial state); kept for the
        RTS smoother (``store="all"``).
    F : ndarray, shape (T, n_x, n_x), (R, T, n_x, n_x) or None
        ``F[k]`` maps step k−1 to step k (``F[0] = I``); per run (the Jacobians at each run's
        posterior) for a nonlinear transition.
    nis : ndarray, shape (R, T)
    dof : ndarray of int, shape (R, T)
        Measured scalars per step (0: predict only, a radar gap).
    logdet : ndarray, shape (R, T) or None
        ``log|S|`` of each update (0 where nothing was measured); with ``nis`` and ``dof`` the
        prediction-error decomposition of the log-likelihood, see :meth:`loglik`.
    """

    t_ns: NDArray[np.int64]
    mean: F64
    cov: F64 | None
    nis: F64
    dof: NDArray[np.int64]
    pred_mean: F64 | None = None
    pred_cov: F64 | None = None
    F: F64 | None = None
    logdet: F64 | None = None

    def loglik(self) -> F64:
        """Per-run log-likelihood ``log p(z_0..z_{T−1})``, shape (R,), by the prediction-error
        decomposition ``Σ_k −½ (yᵀS⁻¹y + log|S| + n_k log 2π)`` (exact for a linear model; the
        usual EKF approximation otherwise)."""
        if self.logdet is None:
            raise ValueError("FilterTrack.loglik: the track holds no log|S| (built without it)")
        return -0.5 * (self.nis + self.logdet + self.dof * np.log(2.0 * np.pi)).sum(axis=1)

    @property
    def n_predict_only(self) -> NDArray[np.int64]:
        """Predict-only steps per run (no valid measurement)."""
        return (self.dof == 0).sum(axis=1)


def run_filter(ekf: ExtendedKalmanFilter, prior: GaussianState, t_ns: ArrayLike, z: ArrayLike,
               store: str = "all", bu: ArrayLike | None = None) -> FilterTrack:
    """Run ``ekf`` over a measurement sequence, vectorised across runs (a loop over time only).

    Parameters
    ----------
    ekf : ExtendedKalmanFilter
    prior : GaussianState
        Initial estimate, batch ``(R,)`` (one row per run) or unbatched (one run, R = 1), at
        ``prior.t_ns`` ≤ ``t_ns[0]``; when that equals ``t_ns[0]`` the first step is an update
        only. Its mean and covariance must be finite.
    t_ns : array_like of int, shape (T,)
        Step times (ns), shared by every run: non-decreasing (equal stamps update again at the
        same instant, without a predict); floats must hold whole nanoseconds
        (:func:`~pipeline.estimate.base.check_times`).
    z : array_like, shape (T, R, n_z) or (T, R, M, n_z)
        Measurements per step and run (rows with a NaN or ±inf: missing, ``dof`` 0 for that
        run; M = 0: predict only).
    store : {"all", "filtered", "mean"}
        What to keep: everything the RTS smoother needs, posterior mean and covariance, or the
        posterior mean only (the covariance arrays of a large Monte Carlo are big).
    bu : array_like, shape (T, n_x) or (T, R, n_x), optional
        Deterministic input added to the prediction into step k (``x⁻_k = F x⁺_{k−1} + bu[k]``;
        ``bu[0]`` is used only when step 0 is predicted): the trajectory learner's bias ``β``.

    Raises
    ------
    ValueError
        Bad ``store``, ``bu`` or measurement shapes; a decreasing or fractional ``t_ns`` or a
        prior after ``t_ns[0]`` (naming the first bad row); a non-finite prior.

    Returns
    -------
    FilterTrack
        With a nonlinear transition (one with ``f`` and ``jacobian``,
        :class:`~pipeline.estimate.base.NonlinearTransitionModel`) the prediction is
        ``x⁻_k = f(x⁺_{k−1}) + bu[k]``, ``P⁻_k = F_k P⁺_{k−1} F_kᵀ + Q`` with ``F_k`` the Jacobian at
        ``x⁺_{k−1}``, and ``F`` holds each run's ``F_k`` (``(R, T, n_x, n_x)``: the extended RTS
        smoother's).

    Notes
    -----
    Each step is a prediction (two stacked 9×9 products over the runs, ~650 KB temporaries at
    1000 runs) and an update, which in the common case (one measurement a run, diagonal ``R``,
    Joseph form) is one pass of :func:`_joseph_update_kernel` (1000-run radar Monte Carlo,
    325 steps: 0.44–0.45 s CPU with the numpy algebra, 0.34 s with the kernel). Two process
    settings matter as much: single-threaded BLAS, and a glibc heap that keeps freed blocks
    (``mallopt`` M_TRIM/M_MMAP_THRESHOLD; otherwise every temporary is page-faulted in afresh,
    ~2× slower on a VM). ``benchmarks/ekf.py`` sets both.
    """
    if store not in ("all", "filtered", "mean"):
        raise ValueError(f"run_filter: store must be 'all', 'filtered' or 'mean', not {store!r}")
    t_ns = check_times(t_ns, "run_filter", prior.t_ns)
    if prior.mean.ndim == 1:
        prior = GaussianState(prior.mean[None], prior.cov[None], prior.t_ns)
    bad = ~(np.isfinite(prior.mean).all(axis=-1) & np.isfinite(prior.cov).all(axis=(-1, -2)))
    if bad.any():
        raise ValueError(f"run_filter: the prior mean or covariance is not finite (run {int(np.argmax(bad))}, "
                         f"{int(bad.sum())} run(s))")
    z = np.asarray(z, dtype=np.float64)
    R_, n_x, T = prior.mean.shape[0], prior.n_x, len(t_ns)
    if z.shape[0] != T or z.shape[1] != R_:
        raise ValueError(f"run_filter: measurements shaped {z.shape}, expected ({T}, {R_}, ...)")
    # filled time-major (one contiguous block per step) and handed out as runs × time views:
    # writing run-major would touch R scattered rows every step
    mean = np.empty((T, R_, n_x))
    cov = np.empty((T, R_, n_x, n_x)) if store != "mean" else None
    pm = np.empty((T, R_, n_x)) if store == "all" else None
    pc = np.empty((T, R_, n_x, n_x)) if store == "all" else None
    nonlinear = callable(getattr(ekf.transition, "f", None)) and callable(getattr(ekf.transition, "jacobian", None))
    # a model that gives f and its Jacobian from one evaluation (``linearise``) saves a call a step
    lin = getattr(ekf.transition, "linearise", None) if nonlinear else None
    if nonlinear and not callable(lin):
        def lin(x, dt):
            return ekf.transition.f(x, dt), ekf.transition.jacobian(x, dt)
    Fs = (np.empty((T, R_, n_x, n_x)) if nonlinear else np.empty((T, n_x, n_x))) if store == "all" else None
    nis = np.empty((T, R_))
    dof = np.empty((T, R_), dtype=np.int64)
    logdet = np.empty((T, R_))
    if bu is not None:
        bu = np.asarray(bu, dtype=np.float64)
        if bu.shape not in ((T, n_x), (T, R_, n_x)):
            raise ValueError(f"run_filter: bu shaped {bu.shape}, expected ({T}, {n_x}) or ({T}, {R_}, {n_x})")
    state = prior
    eye = np.eye(n_x)
    models: dict[int, tuple[F64, F64]] = {}  # step (ns) -> (F, Q): regular steps build them once
    for k in range(T):
        if int(t_ns[k]) != state.t_ns:
            step = int(t_ns[k]) - state.t_ns
            if nonlinear:
                dt = step * 1e-9
                fx, F = lin(state.mean, dt)
                state = ekf.predict(state, int(t_ns[k]), F=F, Q=ekf.transition.noise(dt),
                                    bu=None if bu is None else bu[k], fx=fx)
            else:
                if step not in models:
                    models[step] = (ekf.transition.matrix(step * 1e-9), ekf.transition.noise(step * 1e-9))
                F, Q = models[step]
                state = ekf.predict(state, int(t_ns[k]), F=F, Q=Q, bu=None if bu is None else bu[k])
        else:
            F = eye
        if store == "all":
            pm[k], pc[k], Fs[k] = state.mean, state.cov, F
        # the posterior covariance is written straight into its slot (no copy per step)
        state, st = ekf.update_stats(state, z[k], out=None if cov is None else cov[k])
        mean[k] = state.mean
        nis[k], dof[k], logdet[k] = st.nis, st.dof, st.logdet

    def rt(a):
        return None if a is None else np.swapaxes(a, 0, 1)

    return FilterTrack(t_ns, rt(mean), rt(cov), rt(nis), rt(dof), rt(pm), rt(pc), rt(Fs) if nonlinear else Fs,
                       rt(logdet))
