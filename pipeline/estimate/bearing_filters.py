"""The bearing-only estimators as the study and the replay run them (issue 16): config →
:mod:`pipeline.estimate.bank` settings, and the CPPV bank, MPC bank and CV/CT IMM
(:mod:`pipeline.estimate.imm`) over one bearing history, in CPPV coordinates.

``estimate.bearing_only.bank`` picks a :data:`pipeline.estimate.bank.PRESETS` entry and the open
choices (``q_form``, ``mpc_p0``, ``grid``); ``gate`` the NIS gate. Every setting used goes into
the output metadata (:meth:`BankSettings.metadata`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .bank import GATE_CHI2_1_099, BankSettings, omega_grid, range_grid, run_bank, settings_for, theta_grid

F64 = NDArray[np.float64]


def bank_settings(cfg: Mapping[str, Any] | None, *, preset: str | None = None, coords: str | None = None,
                  grid: tuple[int, int, int] | None = None, **fields: Any) -> BankSettings:
    """A :class:`BankSettings` from the ``estimate.bearing_only`` section.

    ``preset`` (default ``bank.preset``), then ``bank.grid``/``grid`` (N_r, N_ω, N_θ),
    ``coords``, ``q_form`` (→ ``q_faithful``), ``mpc_p0`` and the ``gate`` section; ``fields``
    override any :class:`BankSettings` field last."""
    cfg = dict(cfg or {})
    b = dict(cfg.get("bank") or {})
    g = dict(cfg.get("gate") or {})
    s = settings_for(preset or b.get("preset", "cppv_25_1_6"))
    kw: dict[str, Any] = {"q_faithful": b.get("q_form", "corrected") == "faithful",
                          "mpc_p0": b.get("mpc_p0", "faithful"),
                          "gate": bool(g.get("enabled", False)), "gate_chi2": float(g.get("chi2", GATE_CHI2_1_099))}
    grid = grid or b.get("grid")
    if grid is not None:
        kw.update(n_r=int(grid[0]), n_omega=int(grid[1]), n_theta=int(grid[2]))
        kw["name"] = f"{coords or s.coords}_{grid[0]}_{grid[1]}_{grid[2]}"
    if coords is not None and coords != s.coords:
        kw["coords"] = coords
        kw.setdefault("name", f"{coords}_{s.n_r}_{s.n_omega}_{s.n_theta}")
    kw.update(fields)
    return s.replace(**kw)


def bank_grid(s: BankSettings) -> F64:
    """(N, 3) initial (range, course, turn rate) of each filter, in the bank's enumeration
    ``i = j + N_r (k + N_ω l)`` (range fastest, then ω, then θ)."""
    r, _ = range_grid(s.n_r, s.r_min_m, s.r_max_m)
    w, _ = omega_grid(s)
    th, _ = theta_grid(s)
    L, K, J = np.meshgrid(th, w, r, indexing="ij")      # θ slowest, range fastest
    return np.column_stack([J.ravel(), L.ravel(), K.ravel()])


def replay_tracks(t_s: F64, bearing: F64, ownship_vel: F64, sigma_rad: float, cfg: Mapping[str, Any], *,
                  preset: str | None = None, mpc_preset: str = "mpc_15_5_2") -> dict[str, Any]:
    """The replay's three estimators over one bearing history: ``{bank_cppv, bank_mpc, imm}``
    → :class:`~pipeline.estimate.bearing_run.BearingTrack` (``imm`` only when
    :mod:`pipeline.estimate.imm` is available)."""
    from .bearing_run import BearingTrack

    out: dict[str, Any] = {}
    for name, coords in (("bank_cppv", "cppv"), ("bank_mpc", "mpc")):
        # the MPC model's process noise is its preset's q_mpc·I₅ alone (MpcModel.noise): the
        # CPPV preset's speed noise would not reach it, so none is passed to claim otherwise
        s = bank_settings(cfg, preset=preset if coords == "cppv" else mpc_preset)
        tr = run_bank(s, t_s, bearing, sigma_rad, ownship_vel, store_cov=True, store_weights=True)
        div = np.zeros(len(t_s), np.int64)
        steps = tr.diverged_step[0]
        for k in steps[steps >= 0]:
            div[k:] += 1
        out[name] = BearingTrack(mean=tr.cppv_mean[0], cov=tr.cppv_cov[0], nis=tr.nis[0], mode_p=None,
                                 weights=tr.weights[0], grid=bank_grid(s), n_diverged=div,
                                 meta={"bank": tr.metadata})
    imm = imm_track(t_s, bearing, ownship_vel, sigma_rad, cfg, preset=preset)
    if imm is not None:
        out["imm"] = imm
    return out


def imm_transition(cfg: Mapping[str, Any] | None, *, mix_rate_hz: float | None = None,
                   delta: float | None = None) -> tuple[Any, dict[str, Any]]:
    """The IMM's ``transition`` for :func:`pipeline.estimate.imm.run_imm` from ``imm``:
    a full ``transmat`` if configured, else ``(T_d, δ)``; and the settings for the metadata."""
    im = dict((cfg or {}).get("imm") or {})
    td = float(mix_rate_hz if mix_rate_hz is not None else im.get("mix_rate_hz", 20.0))
    d = float(delta if delta is not None else im.get("delta", 1e-4))
    if im.get("transmat") is not None and mix_rate_hz is None and delta is None:
        return np.asarray(im["transmat"], dtype=np.float64), {"transmat": im["transmat"], "mix_rate_hz": td}
    return (td, d), {"mix_rate_hz": td, "delta": d}


def imm_modes(s: BankSettings, bearing: F64, sigma_rad: float, ownship_vel: F64, cfg: Mapping[str, Any] | None, *,
              cv_prior: tuple[F64, F64] | None = None) -> list[Any]:
    """The two IMM modes ``[cv, ct]`` (digest §6): the CT bank of settings ``s`` and the CV
    EKF from the bank's combined moments without ω (§4.2), or from ``cv_prior`` (mean (R, 4),
    cov (R, 4, 4); the truth in CV-first scenarios, D5). ``ownship_vel`` (R, T, 2)."""
    from .bank import CvModel, first_bearing
    from .imm import bank_mode, cv_mode_from, ekf_mode

    im = dict((cfg or {}).get("imm") or {})
    z = np.atleast_2d(bearing)
    vo = np.asarray(ownship_vel, dtype=np.float64).reshape(z.shape + (2,))
    ct = bank_mode(s, first_bearing(z), sigma_rad, vo[:, 0], name="ct")
    cvm = CvModel(sigma_v2=float(im.get("q_cv", 1e-3)), sigma_theta_dot2=float(im.get("q_cv_course", 1e-6)))
    cv = cv_mode_from(ct, cvm, name="cv") if cv_prior is None else ekf_mode("cv", cvm, *cv_prior)
    return [cv, ct]


def imm_track(t_s, bearing, ownship_vel, sigma_rad, cfg, *, preset=None):
    """The CV/CT IMM over one history (``imm`` settings; the CT mode is the CPPV bank of
    ``preset``) as a :class:`~pipeline.estimate.bearing_run.BearingTrack`."""
    from .bearing_run import BearingTrack
    from .imm import run_imm

    s = bank_settings(cfg, preset=preset)
    trans, tmeta = imm_transition(cfg)
    mu0 = list((cfg.get("imm") or {}).get("mu0", [0.5, 0.5]))
    modes = imm_modes(s, bearing, sigma_rad, ownship_vel[None], cfg)
    tr = run_imm(modes, trans, t_s, bearing, sigma_rad, ownship_vel, mu0=mu0, store_cov=True, store_weights=True)
    div = np.zeros(len(t_s), np.int64)
    w = tr.weights[1][0] if tr.weights is not None else None
    return BearingTrack(mean=tr.mean[0], cov=tr.cov[0], nis=tr.nis[0], mode_p=tr.mode_p[0], weights=w,
                        grid=bank_grid(s), n_diverged=div + int(tr.diverged[1][0].sum()),
                        meta={"bank": s.metadata(), "imm": {**tr.metadata, **tmeta, "mu0": mu0,
                                                            "modes": list(tr.mode_names)}})
