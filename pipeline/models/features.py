"""Observation features for the maneuver HMMs (seed 000 §4, corrections §13.6).

Every feature set maps a ``state`` table (``schema.STATE`` columns on a uniform grid) to a
matrix of raw features ``x_t``; sets marked ``differenced`` then use the increments

.. math:: O_t = \\frac{(x_{t+1} - x_t) - x_{\\min}}{x_{\\max} - x_{\\min}}     \\qquad (3.7)

where ``x_min``/``x_max`` are the per-feature extrema of the (differenced) training data,
frozen at training time (:class:`MinMaxNormaliser`, stored with the model) and applied
unchanged to test and online data, whose values may therefore leave ``[0, 1]`` (§13.6).

Feature sets (``FEATURE_SETS``):

``state9``
    Thesis-faithful: NED position, velocity and acceleration (9-D), differenced at 5 Hz.
    Differencing makes the features position-invariant; they are *not* heading-invariant.
``state9h``
    ``state9`` with the horizontal components rotated into the run's initial heading frame
    (``yaw_rad`` of its first sample, known online), so runs flown on different headings share
    one model; GMR outputs are rotated back to NED.
``state9box``
    ``state9`` with every NED triple rotated into the aerobatic box frame,
    :math:`x_{box} = R_z(\\psi_{box})\\,x_{NED}` (:func:`heading_rotation`, ``box_heading_rad``:
    the flight's box rotation, ``params.box_rotation_rad`` of a FlightCoach log, carried into the
    ``state`` metadata by preprocessing), differenced like ``state9``. Flights flown in boxes of
    different headings share one model; GMR outputs are rotated back to NED,
    :math:`a_{NED} = R_z(\\psi_{box})^T a_{box}`.
``box``
    Velocity and acceleration in the aerobatic box frame (NED rotated about down by the box
    heading ``box_heading_rad``), the gravity direction in the body frame (attitude without
    heading) and body rates; not differenced (12-D).
``aero``
    Fully heading-invariant: speed, down velocity, body-frame acceleration, gravity direction
    in the body frame, body rates (11-D); not differenced. Preferred for aerobatic logs whose
    maneuvers are flown in either direction along the box.

Sampling: the thesis classifies at 5 Hz (``dt = 0.2 s``). :func:`decimate` takes every
``k``-th row of a faster uniform grid starting at ``phase``; the ``k`` phases of one
recording are near-independent replicas used for the leave-one-phase-out one-class threshold.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..frames.rotations import quat_rotate_inverse

F64 = NDArray[np.float64]

_NED = ("n", "e", "d")
POS = tuple(f"pos_{a}_m" for a in _NED)
VEL = tuple(f"vel_{a}_mps" for a in _NED)
ACC = tuple(f"acc_{a}_mps2" for a in _NED)
QUAT = tuple(f"q_{c}" for c in "wxyz")
RATES = ("p_radps", "q_radps", "r_radps")


@dataclass(frozen=True)
class FeatureSet:
    """Declaration of one feature set.

    Parameters
    ----------
    name : str
    names : tuple of str
        Feature names (``d_`` prefix when differenced), in column order.
    differenced : bool
        Whether observations are increments ``x_{t+1} - x_t`` (one fewer than samples).
    needs : tuple of str
        ``state`` columns required.
    """

    name: str
    names: tuple[str, ...]
    differenced: bool
    needs: tuple[str, ...]


FEATURE_SETS: dict[str, FeatureSet] = {
    "state9": FeatureSet("state9", tuple(f"d_{c}" for c in (*POS, *VEL, *ACC)), True,
                         (*POS, *VEL, *ACC)),
    "state9h": FeatureSet("state9h", tuple(f"d_{c}_h" for c in (*POS, *VEL, *ACC)), True,
                          (*POS, *VEL, *ACC, "yaw_rad")),
    "state9box": FeatureSet("state9box", tuple(f"d_{c}_box" for c in (*POS, *VEL, *ACC)), True,
                            (*POS, *VEL, *ACC)),
    "box": FeatureSet(
        "box",
        ("vel_x_box_mps", "vel_y_box_mps", "vel_z_box_mps", "acc_x_box_mps2", "acc_y_box_mps2",
         "acc_z_box_mps2", "g_x_body", "g_y_body", "g_z_body", *RATES),
        False, (*VEL, *ACC, *QUAT, *RATES)),
    "aero": FeatureSet(
        "aero",
        ("speed_mps", "vel_d_mps", "acc_x_body_mps2", "acc_y_body_mps2", "acc_z_body_mps2",
         "g_x_body", "g_y_body", "g_z_body", *RATES),
        False, (*VEL, *ACC, *QUAT, *RATES)),
}

#: indices (into ``state9`` observations) of the GMR input (position increments) and outputs
#: (velocity increments, acceleration increments), seed 000 (3.28)
STATE9_POS = (0, 1, 2)
STATE9_VEL = (3, 4, 5)
STATE9_ACC = (6, 7, 8)


#: differenced NED-triple sets whose GMR outputs are NED after a rotation about down
#: (``state9h``: the run's initial heading; ``state9box``: the box heading)
GMR_FEATURE_SETS = ("state9", "state9h", "state9box")


def heading_rotation(psi_rad: float) -> F64:
    r"""NED -> heading-frame rotation about down by ``psi_rad``.

    .. math:: R_z(\psi) = \begin{pmatrix} \cos\psi & \sin\psi & 0 \\ -\sin\psi & \cos\psi & 0
              \\ 0 & 0 & 1 \end{pmatrix}, \qquad x_{frame} = R_z(\psi)\,x_{NED}

    so the frame's x axis points along heading ``psi`` from north; ``R_z(\psi)^T`` rotates back.
    """
    c, s = np.cos(float(psi_rad)), np.sin(float(psi_rad))
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def rotate_triples(x: F64, rot: F64) -> F64:
    """Apply ``rot`` (3×3) to every consecutive NED triple of the columns of ``x`` (n, 3k)."""
    x = np.asarray(x, dtype=np.float64)
    n, m = x.shape
    if m % 3:
        raise ValueError(f"rotate_triples: {m} columns are not whole triples")
    return (x.reshape(n, m // 3, 3) @ np.asarray(rot).T).reshape(n, m)


def get_feature_set(name: str) -> FeatureSet:
    """The :class:`FeatureSet` keyed ``name`` in :data:`FEATURE_SETS` (``ValueError`` listing the
    known names otherwise)."""
    try:
        return FEATURE_SETS[name]
    except KeyError:
        raise ValueError(f"unknown feature set {name!r}; known: {', '.join(FEATURE_SETS)}") from None


def raw_features(state: pd.DataFrame, feature_set: str = "state9", *,
                 box_heading_rad: float = 0.0) -> F64:
    """Raw (not yet differenced or normalised) features of one uniformly sampled state table.

    Parameters
    ----------
    state : DataFrame
        ``schema.STATE`` columns (at least ``FeatureSet.needs``), one run, time-ordered.
    feature_set : str
        Key of :data:`FEATURE_SETS`.
    box_heading_rad : float
        Heading of the aerobatic box x axis from north (``box`` and ``state9box`` sets), rad.

    Returns
    -------
    ndarray, shape (n_samples, n_raw)
    """
    fs = get_feature_set(feature_set)
    missing = [c for c in fs.needs if c not in state.columns]
    if missing:
        raise ValueError(f"feature set {feature_set!r} needs state column(s) {missing}")
    if fs.name == "state9":
        return state[list(fs.needs)].to_numpy(dtype=np.float64)
    if fs.name == "state9box":
        x = state[list(fs.needs)].to_numpy(dtype=np.float64)
        return rotate_triples(x, heading_rotation(box_heading_rad))
    if fs.name == "state9h":
        x = state[list(fs.needs[:9])].to_numpy(dtype=np.float64).copy()
        yaw0 = float(state["yaw_rad"].iloc[0]) if len(state) else 0.0
        c, s = np.cos(yaw0), np.sin(yaw0)
        for i in (0, 3, 6):                                   # NED -> initial-heading frame
            n, e = x[:, i].copy(), x[:, i + 1].copy()
            x[:, i], x[:, i + 1] = c * n + s * e, -s * n + c * e
        return x
    v = state[list(VEL)].to_numpy(dtype=np.float64)
    a = state[list(ACC)].to_numpy(dtype=np.float64)
    q = state[list(QUAT)].to_numpy(dtype=np.float64)
    w = state[list(RATES)].to_numpy(dtype=np.float64)
    # gravity direction in body axes = attitude with the heading removed
    g_body = quat_rotate_inverse(q, np.array([0.0, 0.0, 1.0]))
    if fs.name == "box":
        c, s = np.cos(box_heading_rad), np.sin(box_heading_rad)
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # NED -> box
        return np.hstack([v @ rot.T, a @ rot.T, g_body, w])
    speed = np.linalg.norm(v, axis=1, keepdims=True)
    a_body = quat_rotate_inverse(q, a)
    return np.hstack([speed, v[:, 2:3], a_body, g_body, w])


def observations(raw: F64, differenced: bool) -> F64:
    """``x_{t+1} - x_t`` when ``differenced`` (n-1 rows), else ``raw`` itself."""
    raw = np.asarray(raw, dtype=np.float64)
    return np.diff(raw, axis=0) if differenced else raw


@dataclass(frozen=True)
class MinMaxNormaliser:
    """Per-feature min-max normalisation frozen at training (seed 000 (3.7), §13.6).

    Parameters
    ----------
    x_min, x_max : ndarray, shape (n_features,)
        Extrema of the training observations; a constant feature gets span 1.
    """

    x_min: F64
    x_max: F64

    @classmethod
    def fit(cls, X: F64) -> "MinMaxNormaliser":
        """Per-feature extrema of the training observations ``X`` (n_samples, n_features),
        rows with a non-finite value ignored (seed 000 (3.7)); ``ValueError`` for an empty or
        non-2-D ``X``."""
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or not len(X):
            raise ValueError("cannot fit a normaliser on an empty observation set")
        finite = np.isfinite(X).all(axis=1)
        return cls(np.min(X[finite], axis=0), np.max(X[finite], axis=0))

    @property
    def span(self) -> F64:
        s = self.x_max - self.x_min
        return np.where(s > 0, s, 1.0)

    def transform(self, X: F64) -> F64:
        """:math:`(x - x_{min}) / (x_{max} - x_{min})`."""
        return (np.asarray(X, dtype=np.float64) - self.x_min) / self.span

    def inverse(self, Xn: F64, idx=None) -> F64:
        """:math:`x_n (x_{max} - x_{min}) + x_{min}` (§13.3), optionally for feature ``idx``."""
        sl = slice(None) if idx is None else list(idx)
        return np.asarray(Xn, dtype=np.float64) * self.span[sl] + self.x_min[sl]

    def to_dict(self) -> dict:
        """``{"x_min": [...], "x_max": [...]}`` as JSON lists (the model's ``meta.json``)."""
        return {"x_min": self.x_min.tolist(), "x_max": self.x_max.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "MinMaxNormaliser":
        """Inverse of :meth:`to_dict`."""
        return cls(np.asarray(d["x_min"], dtype=np.float64), np.asarray(d["x_max"], dtype=np.float64))


def sample_period_s(t_ns) -> float:
    """Median sample period of a time column, s."""
    t = np.asarray(t_ns, dtype=np.int64)
    if len(t) < 2:
        return float("nan")
    return float(np.median(np.diff(t))) * 1e-9


def decimation_factor(t_ns, rate_hz: float) -> int:
    """Integer ``k`` with ``k / source_rate ≈ 1 / rate_hz`` (1 if the source is not faster).

    Raises
    ------
    ValueError
        When the source rate is not within 5 % of an integer multiple of ``rate_hz``; resample
        onto such a grid in preprocessing first.
    """
    dt = sample_period_s(t_ns)
    if not np.isfinite(dt) or dt <= 0:
        return 1
    ratio = 1.0 / (dt * rate_hz)
    k = int(round(ratio))
    if k < 1 or ratio < 0.95:
        raise ValueError(f"source rate {1 / dt:.2f} Hz is slower than the model rate {rate_hz} Hz")
    if abs(ratio - k) > 0.05 * k:
        raise ValueError(f"source rate {1 / dt:.2f} Hz is not an integer multiple of {rate_hz} Hz")
    return k


def decimate(state: pd.DataFrame, rate_hz: float, phase: int = 0) -> pd.DataFrame:
    """Every ``k``-th row from ``phase`` (``k`` from :func:`decimation_factor`)."""
    k = decimation_factor(state["t_ns"].to_numpy(), rate_hz)
    if not 0 <= phase < k:
        raise ValueError(f"phase {phase} outside 0..{k - 1}")
    return state.iloc[phase::k].reset_index(drop=True)


def run_sequences(df: pd.DataFrame, *, run_col: str = "run_id") -> list[tuple[object, pd.DataFrame]]:
    """Split a bulk table into ``(run_id, run table)`` in first-appearance order, each sorted by
    ``t_ns``; a table without ``run_col`` is one run."""
    if run_col not in df.columns:
        return [(0, df.sort_values("t_ns", kind="stable").reset_index(drop=True))]
    out = []
    for rid, g in df.groupby(run_col, sort=False):
        out.append((rid, g.sort_values("t_ns", kind="stable").reset_index(drop=True)))
    return out
