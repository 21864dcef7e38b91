"""Seed-003 ship tracks: straight, π-turn, weave and non-weave (straight–curve–straight).

Van de Kerkhof (2014) §3.1 builds its test tracks by switching a constant-velocity and an
augmented coordinated-turn model with **zero process noise** (digest 003 §6, §11 item 6). This
module does the same, exactly: each segment is a straight (ω = 0) or a turn at a constant rate
ω, integrated by :func:`pipeline.estimate.models.ct_transition` at the step T (1 s by default,
digest 003 A1).

Frames and signs (pinned by tests): NED with (x, y) = (N, E), course measured from North toward
East, **ω > 0 a right turn and ω < 0 a left turn** — the reverse of the thesis's printed
convention (its x = East, y = North frame makes ω > 0 a left turn). The thesis's start point
(200, 200) m and velocity (1, 1) m/s are symmetric in x/y and so the same in both frames.

The truth is deterministic; only the sensors draw noise, one realisation per seed, vectorised
over seeds (:func:`gps_measure`, :func:`radar_measure`).
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..estimate.models import Radar2DModel, ct_transition

F64 = NDArray[np.float64]

#: segment kinds: straight, left turn (ω < 0 in NED), right turn (ω > 0)
KINDS = ("S", "L", "R")
#: the thesis's start (N, E) (m) and velocity (v_N, v_E) (m/s), §3.1
THESIS_START_NE = (200.0, 200.0)
THESIS_VEL_NE = (1.0, 1.0)
#: the thesis's turn rate magnitude (rad/s), §3.1
THESIS_OMEGA = 0.1


@dataclass(frozen=True)
class Segment:
    """One piece of a track: ``kind`` ``S``/``L``/``R``, ``steps`` steps, turn-rate magnitude ``omega`` (rad/s)."""

    kind: str
    steps: int
    omega: float = THESIS_OMEGA

    @property
    def signed_omega(self) -> float:
        """ω in NED: 0 straight, −|ω| left, +|ω| right."""
        return {"S": 0.0, "L": -abs(self.omega), "R": abs(self.omega)}[self.kind]


@dataclass(frozen=True)
class ShipTrack:
    """A noise-free ship track.

    Attributes
    ----------
    name : str
        ``straight``, ``pi_turn``, ``weave``, ``non_weave`` or a derived name.
    dt : float
        Step T (s).
    state : ndarray, shape (T, 5)
        ``[N, E, v_N, v_E, ω]`` at each step (m, m/s, rad/s), step 0 the start.
    kind : ndarray of str, shape (T,)
        The segment kind driving the step into k (``S`` at k = 0).
    weave : ndarray of bool, shape (T,)
        Steps inside a weave (from the start of its first turn to the end of its last);
        all False for non-weave tracks.
    turn_end : ndarray of int
        Step index at which each turn ends (its last step), in order.
    """

    name: str
    dt: float
    state: F64
    kind: NDArray[np.str_]
    weave: NDArray[np.bool_]
    turn_end: NDArray[np.int64]

    @property
    def n_steps(self) -> int:
        return int(self.state.shape[0])

    @property
    def t_s(self) -> F64:
        return np.arange(self.n_steps) * self.dt

    def transformed(self, *, rotate_rad: float = 0.0, shift_ne: ArrayLike = (0.0, 0.0),
                    name: str | None = None) -> "ShipTrack":
        """The track rotated by ``rotate_rad`` about the origin (a right-handed N→E rotation,
        positive clockwise seen from above, so turn directions and ω are kept) then shifted."""
        c, s = np.cos(rotate_rad), np.sin(rotate_rad)
        Rm = np.array([[c, -s], [s, c]])
        st = self.state.copy()
        st[:, 0:2] = st[:, 0:2] @ Rm.T + np.asarray(shift_ne, dtype=np.float64)
        st[:, 2:4] = st[:, 2:4] @ Rm.T
        return ShipTrack(name or self.name, self.dt, st, self.kind, self.weave, self.turn_end)

    def moved_to_end_at(self, end_ne: ArrayLike, name: str | None = None) -> "ShipTrack":
        """The track translated so that its last position is ``end_ne`` (digest 003 §8 range sweep)."""
        return self.transformed(shift_ne=np.asarray(end_ne, dtype=np.float64) - self.state[-1, 0:2], name=name)


def build_track(segments: Sequence[Segment], *, start_ne: ArrayLike = THESIS_START_NE,
                vel_ne: ArrayLike = THESIS_VEL_NE, dt: float = 1.0, name: str = "track",
                weave: bool = False) -> ShipTrack:
    """Integrate ``segments`` exactly (zero process noise) from ``start_ne`` with ``vel_ne``.

    Each step of a segment applies :func:`~pipeline.estimate.models.ct_transition` with the
    segment's signed ω (0 for a straight: a constant-velocity step).

    Parameters
    ----------
    segments : sequence of Segment
    start_ne, vel_ne : (2,) array_like
        Start position (m) and velocity (m/s), (N, E).
    dt : float
        Step T (s).
    name : str
    weave : bool
        Mark the steps from the first turn's start to the last turn's end as weave.
    """
    if not segments or any(s.kind not in KINDS or s.steps < 1 for s in segments):
        raise ValueError(f"ship track {name}: segments need a kind in {KINDS} and steps >= 1")
    if not _positive_finite(dt):
        raise ValueError(f"ship track {name}: dt must be a positive finite step (s), got {dt!r}")
    x = np.array([*np.asarray(start_ne, float), *np.asarray(vel_ne, float), 0.0])
    states, kinds, turn_end = [x.copy()], ["S"], []
    for seg in segments:
        x[4] = seg.signed_omega
        for _ in range(seg.steps):
            x = ct_transition(x, dt)
            states.append(x.copy())
            kinds.append(seg.kind)
        if seg.kind != "S":
            turn_end.append(len(states) - 1)
    st = np.array(states)
    st[:, 4] = _omega_per_step(segments)  # ω of the segment driving each step (0 at k = 0)
    kind = np.array(kinds)
    w = np.zeros(len(kind), dtype=bool)
    if weave and turn_end:
        first = int(np.flatnonzero(kind != "S")[0])
        w[first:turn_end[-1] + 1] = True
    return ShipTrack(name, float(dt), st, kind, w, np.asarray(turn_end, dtype=np.int64))


def _real(v) -> bool:
    """A real number (not a bool or a string)."""
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def _positive_finite(v) -> bool:
    return _real(v) and bool(np.isfinite(v) and v > 0)


def _omega_per_step(segments: Sequence[Segment]) -> list[float]:
    out = [0.0]
    for seg in segments:
        out += [seg.signed_omega] * seg.steps
    return out


def straight_track(steps: int = 200, **kw) -> ShipTrack:
    """A straight track of ``steps`` steps (seed 003 track 1's shape)."""
    return build_track([Segment("S", steps)], name=kw.pop("name", "straight"), **kw)


def pi_turn_track(lead: int = 60, tail: int = 100, omega: float = THESIS_OMEGA, **kw) -> ShipTrack:
    """Straight – **left** turn of π – straight (digest 003 §4.2.3, A13); the turn takes
    ``round(π/ω)`` steps at ω = −|omega| (NED: left); ``omega`` must be non-zero and finite, and
    below 2π rad/s (a turn of at least one step)."""
    if not _positive_finite(abs(omega) if _real(omega) else None) or int(round(np.pi / abs(omega))) < 1:
        raise ValueError(f"pi_turn_track: omega must be a non-zero finite turn rate with round(π/|omega|) >= 1 "
                         f"steps (|omega| < 2π rad/s), got {omega!r}")
    n = int(round(np.pi / abs(omega)))
    return build_track([Segment("S", lead), Segment("L", n, abs(np.pi / n)), Segment("S", tail)],
                       name=kw.pop("name", "pi_turn"), **kw)


def non_weave_track(lead: int = 60, turn_steps: int = 15, tail: int = 100, omega: float = THESIS_OMEGA,
                    **kw) -> ShipTrack:
    """Straight – **right** curve – straight (digest 003 §6, Fig. 3.1b, A13)."""
    return build_track([Segment("S", lead), Segment("R", turn_steps, omega), Segment("S", tail)],
                       name=kw.pop("name", "non_weave"), **kw)


def weave_track(n_turns: int = 6, lead: int = 40, turn_steps: int = 12, straight_steps: int = 20,
                tail: int = 80, omega: float = THESIS_OMEGA, first: str = "L", **kw) -> ShipTrack:
    """A weave: ``n_turns`` alternating turns (starting with ``first``) of ``turn_steps`` steps at
    |ω| = ``omega``, separated by straights of ``straight_steps``, after a ``lead`` straight and
    before a ``tail`` straight (the CL → SL → CR → SR cycle of digest 003 §4)."""
    if first not in ("L", "R"):
        raise ValueError(f"weave_track: first must be 'L' or 'R', got {first!r}")
    segs = [Segment("S", lead)]
    k = first
    for i in range(n_turns):
        segs.append(Segment(k, turn_steps, omega))
        segs.append(Segment("S", straight_steps if i < n_turns - 1 else tail))
        k = "R" if k == "L" else "L"
    return build_track(segs, name=kw.pop("name", "weave"), weave=True, **kw)


def gps_measure(track: ShipTrack, n_seeds: int, rng: np.random.Generator, sigma_m: float = 1.0) -> F64:
    """GPS positions ``(n_seeds, T, 2)``: the track's (N, E) plus N(0, σ²) per axis (seed 003: 1 m);
    ``sigma_m`` must be finite and >= 0 (0: the exact positions)."""
    if not (_real(sigma_m) and np.isfinite(sigma_m) and sigma_m >= 0):
        raise ValueError(f"gps_measure: sigma_m must be a finite number >= 0, got {sigma_m!r}")
    return track.state[None, :, 0:2] + sigma_m * rng.standard_normal((n_seeds, track.n_steps, 2))


def radar_measure(track: ShipTrack, n_seeds: int, rng: np.random.Generator,
                  radar: Radar2DModel | None = None) -> F64:
    """2-D radar ``[r, b, d]`` ``(n_seeds, T, 3)`` of the track (seed 003 §5.1 noise by default)."""
    radar = radar or Radar2DModel()
    return radar.measure(np.broadcast_to(track.state, (n_seeds, *track.state.shape)), rng)
