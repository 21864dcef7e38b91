"""Command profiles: the five seed-000 maneuvers M1–M5 and how profiles are composed.

Every maneuver is a **thrust + Euler-angle command series** (seed 000 §2) that
:mod:`pipeline.simulate.quadcopter` integrates through the §1 dynamics — there are no position
or velocity splines. A channel is a table of knots ``(t_i, c_i)``; between two knots the command
follows the quintic smoothstep

.. math:: c(t) = c_i + (c_{i+1} - c_i)\\,S(s),\\quad S(s) = 10 s^3 - 15 s^4 + 6 s^5,
          \\quad s = (t - t_i)/(t_{i+1} - t_i)

so every command has continuous first and second derivatives (the body rates the IMU sees are
smooth and the jerk is continuous) and is held constant outside its knot range. Angle knots
are degrees (roll φ, pitch θ, yaw ψ relative to the run's heading); thrust knots are
``U1/(m g)``. With ``vertical_thrust=True`` the thrust knots give the *vertical* component and
the command is ``U1/(mg) = c(t)/(cos φ cos θ)`` (an ideal altitude-rate loop), which keeps
vertical acceleration free of the cross-coupling of banked turns.

The maneuvers (25 s each, heading frame x forward, y right, z down; figures of seed 000 §2.2):

* **M1** climbs from 10 m to about 55 m while roll (±22°) and pitch (±14°) flip every 1–2 s:
  oscillatory acceleration with fast reversals, the largest jerk of the five.
* **M2** starts at 180 m from the low-dynamic command, eases its vertical thrust to a steady
  descent (0.675 g from 0.5 to 3 s) and keeps it — for 10 s only the height changes fast —
  then circles (bank 30°, yaw through 360°) while descending to about 55 m: the horizontal
  dynamics sit in the last 15 s.
* **M3** descends gently towards the target while weaving left–right (roll ±30°, pitch −4°):
  lateral acceleration dominates (≥ 2× forward and vertical).
* **M4** the least dynamic, mostly vertical: its transition takes the low-dynamic thrust down
  to M4's initial thrust, which is M2's descent thrust, so its z-acceleration for the first
  seconds has M2's shape and size (the M2/M4 confusion of seed 000 §3.4.2); it then levels
  off (thrust 1.06, 0.97, 1.0, 1.05, 0.97, 1.0) with small tilts (roll 4°, pitch −5 → −11°).
* **M5** (the "unknown"): climbs for 10 s, then descends, with large changes on every axis.

Start state and transitions (:func:`hmm_command`, :func:`maneuver_scenario`). Seed 000 §2.4
pads every Monte Carlo maneuver with low-dynamic flight, "created through a constant
commanded thrust and pitch angle", and describes how each maneuver reaches its first command:

* §2.4.1 (M1): "There is a transition period from 12 to 14.8 seconds from the low dynamic
  maneuver to the initial maneuver thrust, which prevents an immediate rapid increase in UAV
  acceleration when the maneuver starts."
* §2.4.2 (M2): "Maneuver 2 does not require a transition period before the start of the
  maneuver as the initial thrust matches the desired initial thrust of the maneuver."
* §2.4.3 (M3): "Before the maneuver, thrust begins to move towards the initial thrust of the
  maneuver."
* §2.4.4 (M4): "Before and after the maneuver, there are small transition periods in order to
  start at the correct initial thrust and transition back to small constant Euler angles and
  the initial thrust."

So every run of the HMM sets starts in that low-dynamic state — the :func:`low_dynamic`
command (pitch −5°, thrust holding height), at its equilibrium velocity — whatever the
maneuver, and all runs look alike at t = 0. M2's first command *is* the low-dynamic command,
so an M2 run is the bare 25 s maneuver. M1, M3, M4 (and M5, which the thesis does not
describe: it gets M1's transition) start ``lead_s`` = 3 s before their maneuver and blend
all four command channels from low-dynamic to the first command over [0, ``ramp_s`` = 2.8 s]
— the §2.4.1 window 12 → 14.8 s of the 15 s pad, i.e. the Monte Carlo ``ramp_in`` — so their
runs last 28 s, all labelled with the maneuver (the classifier sees the run from its first
sample, as it sees an M2 run). The change scenarios start the same way.

Limits |φ|,|θ| ≤ 50°, |v| ≤ 40 m/s and |a| ≤ 10 m/s² (vector norms, disturbance included)
are met by construction margins and asserted on 100-run samples in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .quadcopter import CommandSample

F64 = NDArray[np.float64]
DEG = np.pi / 180.0

#: maneuver labels in order
MANEUVERS: tuple[str, ...] = ("M1", "M2", "M3", "M4", "M5")
#: maneuver length (s), seed 000 §2
MANEUVER_S = 25.0
#: pitch of the low-dynamic flight (deg; the ``simulate.low_dynamic_pitch_deg`` default)
LOW_PITCH_DEG = -5.0
#: M2's descent thrust, vertical component in g: the steady value that brings M2 from 180 m to
#: 55 m (§2.2.2) with the descent held through the circle (0.6738 solves it; rounded)
M2_DESCENT_THRUST = 0.675
#: a maneuver's start in an HMM-set run (s) and its transition window [0, RAMP_S] (§2.4.1:
#: 12 → 14.8 s before the 15 s maneuver start)
LEAD_S = 3.0
RAMP_S = 2.8


def _smooth(s: F64) -> tuple[F64, F64]:
    """Quintic smoothstep S(s) and dS/ds on [0, 1] (clamped outside)."""
    s = np.clip(s, 0.0, 1.0)
    return s ** 3 * (10 - 15 * s + 6 * s * s), 30 * s * s * (1 - s) ** 2


def knots_eval(tk: F64, ck: F64, t: F64) -> tuple[F64, F64]:
    """Value and derivative of a knot channel at times ``t`` (held outside [t_0, t_last])."""
    tk = np.asarray(tk, float)
    ck = np.asarray(ck, float)
    t = np.asarray(t, float)
    if len(tk) == 1:
        return np.full(t.shape, ck[0]), np.zeros(t.shape)
    i = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, len(tk) - 2)
    span = tk[i + 1] - tk[i]
    s, ds = _smooth((t - tk[i]) / span)
    dc = ck[i + 1] - ck[i]
    return ck[i] + dc * s, dc * ds / span


class Command:
    """A command profile: ``sample(t)`` -> :class:`CommandSample` (yaw relative to heading)."""

    duration_s: float = MANEUVER_S

    def sample(self, t: F64) -> CommandSample:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass(frozen=True)
class KnotCommand(Command):
    """Four knot channels. ``thr``/``roll``/``pitch``/``yaw``: ``((t...), (value...))``; angles
    in degrees, thrust in U1/(mg) (vertical component when ``vertical_thrust``).
    ``transition_in``: whether a run blends into the first command from low-dynamic flight."""

    thr: tuple
    roll: tuple
    pitch: tuple
    yaw: tuple = ((0.0,), (0.0,))
    vertical_thrust: bool = False
    duration_s: float = MANEUVER_S
    start_alt_m: float = 10.0
    #: reaches its first command through a transition from low-dynamic flight (seed 000 §2.4;
    #: False for M2, whose first command is the low-dynamic one)
    transition_in: bool = True

    def sample(self, t: F64) -> CommandSample:
        t = np.asarray(t, float)
        e, de = np.empty(t.shape + (3,)), np.empty(t.shape + (3,))
        for j, ch in enumerate((self.roll, self.pitch, self.yaw)):
            v, d = knots_eval(ch[0], ch[1], t)
            e[..., j], de[..., j] = v * DEG, d * DEG
        thr, _ = knots_eval(self.thr[0], self.thr[1], t)
        if self.vertical_thrust:
            thr = thr / (np.cos(e[..., 0]) * np.cos(e[..., 1]))
        return CommandSample(thr, e, de)


@dataclass(frozen=True)
class ConstCommand(Command):
    """Constant thrust ratio and angles (deg): the seed-000 low-dynamic flight."""

    thr: float = 1.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0
    duration_s: float = 1.0

    def sample(self, t: F64) -> CommandSample:
        t = np.asarray(t, float)
        e = np.broadcast_to(np.array([self.roll_deg, self.pitch_deg, self.yaw_deg]) * DEG, t.shape + (3,))
        return CommandSample(np.full(t.shape, self.thr), e.copy(), np.zeros(t.shape + (3,)))


@dataclass(frozen=True)
class Shifted(Command):
    """``inner`` started at ``t0`` (held at its first command before, last after)."""

    inner: Command
    t0: float

    def sample(self, t: F64) -> CommandSample:
        tt = np.clip(np.asarray(t, float) - self.t0, 0.0, self.inner.duration_s)
        c = self.inner.sample(tt)
        inside = ((np.asarray(t) - self.t0 >= 0) & (np.asarray(t) - self.t0 <= self.inner.duration_s))
        return CommandSample(c.thr, c.euler, c.euler_rate * inside[..., None])


@dataclass(frozen=True)
class Blend(Command):
    """``(1−w) a + w b`` with ``w`` the smoothstep from ``t0`` to ``t0 + dur``.

    ``channels`` selects which of (thr, roll, pitch, yaw) are blended; the others stay ``a``'s.
    The product rule keeps the Euler-rate channels exact.
    """

    a: Command
    b: Command
    t0: float
    dur: float
    channels: tuple[bool, bool, bool, bool] = (True, True, True, True)
    duration_s: float = MANEUVER_S

    def sample(self, t: F64) -> CommandSample:
        t = np.asarray(t, float)
        ca, cb = self.a.sample(t), self.b.sample(t)
        w, dw = _smooth((t - self.t0) / self.dur)
        dw = dw / self.dur
        m = np.asarray(self.channels, float)
        wt = w * m[0]
        we, dwe = w[..., None] * m[1:], dw[..., None] * m[1:]
        thr = (1 - wt) * ca.thr + wt * cb.thr
        e = (1 - we) * ca.euler + we * cb.euler
        de = (1 - we) * ca.euler_rate + we * cb.euler_rate + dwe * (cb.euler - ca.euler)
        return CommandSample(thr, e, de)


def _k(*pairs: tuple[float, float]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    return tuple(p[0] for p in pairs), tuple(p[1] for p in pairs)


def _flips(t_start: float, t_end: float, period: float, amp: float, flip: float,
           phase: int = 1, taper: float = 1.0) -> tuple:
    """Square-ish wave: hold ±amp, reverse within ``flip`` seconds, zero at both ends."""
    pts = [(0.0, 0.0), (t_start, 0.0)]
    t, sgn = t_start + flip / 2, phase
    while t + period / 2 <= t_end:
        pts.append((t, sgn * amp))
        pts.append((t + period / 2 - flip / 2, sgn * amp))
        t += period / 2 + flip / 2
        sgn = -sgn
        amp *= taper
    last = pts[-1][0]
    pts.append((last + flip, 0.0))
    return _k(*pts)


def default_maneuvers() -> dict[str, KnotCommand]:
    """The five seed-000 maneuvers (see the module docstring)."""
    m1 = KnotCommand(
        thr=_k((0, 1.10), (23.0, 1.10), (25, 1.0)),
        roll=_flips(1.0, 24.0, 2.4, 22.0, 0.45),
        pitch=_flips(1.6, 24.0, 3.4, 14.0, 0.45, phase=-1),
        yaw=_k((0, 0.0)),
        vertical_thrust=True, start_alt_m=10.0,
    )
    # M2 (§2.2.2): the low-dynamic command first (§2.4.2: no transition), a steady descent for
    # 10 s ("only the vertical position ... is rapidly changing"), the circle in the last 15 s
    m2 = KnotCommand(
        thr=_k((0, 1.0), (0.5, 1.0), (3.0, M2_DESCENT_THRUST), (22.0, M2_DESCENT_THRUST), (25, 1.0)),
        roll=_k((0, 0.0), (10.0, 0.0), (12.0, 30.0), (22.0, 30.0), (24.5, 0.0)),
        pitch=_k((0, LOW_PITCH_DEG), (10.0, LOW_PITCH_DEG), (12.0, -18.0), (22.0, -18.0), (24.5, 0.0)),
        yaw=_k((0, 0.0), (10.0, 0.0), (11.0, 8.0), (23.5, 352.0), (25.0, 360.0)),
        vertical_thrust=True, start_alt_m=180.0, transition_in=False,
    )
    m3 = KnotCommand(
        thr=_k((0, 0.96), (23.0, 0.96), (25, 1.0)),
        roll=_flips(1.0, 24.0, 5.0, 30.0, 1.4),
        pitch=_k((0, -4.0), (23.0, -4.0), (25.0, 0.0)),
        yaw=_k((0, 0.0)),
        vertical_thrust=True, start_alt_m=60.0,
    )
    # M4 (§2.2.4): starts at M2's descent thrust (reached through its §2.4.4 transition, so the
    # first seconds' z-acceleration is M2's), levels off, small tilts, back to the low-dynamic
    # pitch and thrust at the end ("back to small constant Euler angles and the initial thrust")
    m4 = KnotCommand(
        thr=_k((0, M2_DESCENT_THRUST), (3.5, M2_DESCENT_THRUST), (6.0, 1.06), (7.5, 0.97), (11.0, 1.0),
               (13.0, 1.05), (16.0, 0.97), (19.0, 1.0)),
        roll=_k((0, 0.0), (9.0, 0.0), (12.0, 4.0), (17.0, 4.0), (20.0, 0.0)),
        pitch=_k((0, LOW_PITCH_DEG), (7.0, LOW_PITCH_DEG), (10.0, LOW_PITCH_DEG - 6.0),
                 (18.0, LOW_PITCH_DEG - 6.0), (21.0, LOW_PITCH_DEG)),
        yaw=_k((0, 0.0)),
        vertical_thrust=True, start_alt_m=70.0,
    )
    m5 = KnotCommand(
        thr=_k((0, 1.0), (1.5, 1.45), (4.0, 1.45), (5.5, 1.05), (7.0, 1.3), (9.0, 1.3), (11.0, 0.55),
               (14.0, 0.55), (15.5, 1.1), (17.0, 0.7), (20.0, 0.7), (22.0, 1.25), (24.0, 1.0)),
        roll=_k((0, 0.0), (2.0, -25.0), (5.0, -25.0), (7.0, 20.0), (10.0, 20.0), (12.5, -28.0),
                (15.0, -28.0), (17.0, 10.0), (20.0, 25.0), (23.0, 0.0)),
        pitch=_k((0, 0.0), (1.5, -20.0), (4.0, -20.0), (6.5, 15.0), (9.0, 15.0), (11.0, -25.0),
                 (14.0, -25.0), (16.5, 10.0), (19.0, -15.0), (22.0, -15.0), (24.5, 0.0)),
        yaw=_k((0, 0.0), (8.0, 0.0), (14.0, -60.0), (25.0, -60.0)),
        vertical_thrust=True, start_alt_m=40.0,
    )
    return {"M1": m1, "M2": m2, "M3": m3, "M4": m4, "M5": m5}


@dataclass(frozen=True)
class Phase:
    """A labelled time span of a scenario (s)."""

    t_start: float
    t_end: float
    label: str


@dataclass(frozen=True)
class Scenario:
    """A full command profile with its labelled phases, duration and start altitude."""

    name: str
    command: Command
    duration_s: float
    phases: tuple[Phase, ...]
    start_alt_m: float
    meta: dict = field(default_factory=dict, compare=False)

    def labels_at(self, t: F64) -> NDArray[np.object_]:
        out = np.full(np.shape(t), "", dtype=object)
        for ph in self.phases:
            out[(t >= ph.t_start) & (t < ph.t_end)] = ph.label
        if self.phases:
            out[np.asarray(t) >= self.phases[-1].t_end] = self.phases[-1].label
        return out


def hmm_command(man: KnotCommand, *, lead_s: float = LEAD_S, ramp_s: float = RAMP_S,
                pitch_deg: float = LOW_PITCH_DEG) -> tuple[Command, float]:
    """The command of one HMM-set run and the maneuver's start time in it.

    Seed 000 §2.4: the run starts in low-dynamic flight (:func:`low_dynamic`) and, unless the
    maneuver's first command already is that ("Maneuver 2 does not require a transition period
    before the start of the maneuver as the initial thrust matches the desired initial thrust
    of the maneuver", §2.4.2; ``man.transition_in`` False), blends all channels into the first
    command over [0, ``ramp_s``] ("a transition period from 12 to 14.8 seconds from the low
    dynamic maneuver to the initial maneuver thrust", §2.4.1) and starts the maneuver at
    ``lead_s``.

    Returns
    -------
    (Command, float)
        The command (``duration_s`` = lead + maneuver) and the maneuver's start (s).
    """
    if not man.transition_in or lead_s <= 0:
        return man, 0.0
    cmd = Blend(low_dynamic(pitch_deg), Shifted(man, lead_s), 0.0, ramp_s,
                duration_s=lead_s + man.duration_s)
    return cmd, lead_s


def maneuver_scenario(name: str, man: KnotCommand, *, lead_s: float = LEAD_S, ramp_s: float = RAMP_S,
                      pitch_deg: float = LOW_PITCH_DEG) -> Scenario:
    """One HMM-set run: low-dynamic start, the §2.4 transition (none for M2), the 25 s maneuver.

    The whole run carries the maneuver's label; ``meta`` records ``maneuver_start_s`` and the
    transition window ``transition_s`` (None without one).
    """
    cmd, t0 = hmm_command(man, lead_s=lead_s, ramp_s=ramp_s, pitch_deg=pitch_deg)
    dur = t0 + man.duration_s
    return Scenario(name, cmd, dur, (Phase(0.0, dur, name),), man.start_alt_m,
                    {"maneuver_start_s": t0, "transition_s": (0.0, ramp_s) if t0 > 0 else None})


def low_dynamic(pitch_deg: float = -5.0) -> ConstCommand:
    """Seed-000 low-dynamic flight: constant pitch and the thrust that holds altitude with it."""
    return ConstCommand(thr=1.0 / np.cos(pitch_deg * DEG), pitch_deg=pitch_deg, duration_s=1e9)


def padded_scenario(name: str, man: KnotCommand, *, pre_s: float = 15.0, post_s: float = 25.0,
                    ramp_in: tuple[float, float] = (12.0, 14.8), ramp_out: tuple[float, float] = (40.0, 50.0),
                    pitch_deg: float = -5.0) -> Scenario:
    """Seed-000 Monte Carlo trajectory: ``pre_s`` low-dynamic, the maneuver, ``post_s`` low-dynamic.

    Commands move from low-dynamic to the maneuver's first command over ``ramp_in`` (12→14.8 s
    for M1 in the thesis) and back over ``ramp_out`` (40→50 s; thrust, roll and pitch — yaw
    keeps the maneuver's final heading). Phases: ``low`` [0, pre), maneuver [pre, pre+25),
    ``low`` [pre+25, end).
    """
    low = low_dynamic(pitch_deg)
    t_end_man = pre_s + man.duration_s
    inner = Blend(low, Shifted(man, pre_s), ramp_in[0], ramp_in[1] - ramp_in[0])
    cmd = Blend(inner, low, ramp_out[0], ramp_out[1] - ramp_out[0], channels=(True, True, True, False))
    dur = t_end_man + post_s
    phases = (Phase(0.0, pre_s, "low"), Phase(pre_s, t_end_man, name), Phase(t_end_man, dur, "low"))
    return Scenario(f"mc_{name}", cmd, dur, phases, man.start_alt_m,
                    {"pre_s": pre_s, "post_s": post_s, "ramp_in": ramp_in, "ramp_out": ramp_out})


#: seed 000 Table 3.9
SWITCHES: dict[str, tuple[str, str]] = {"A": ("M1", "M2"), "B": ("M2", "M4"), "C": ("M3", "M1"), "D": ("M4", "M3")}


def switch_scenario(key: str, t_switch: float, mans: dict[str, KnotCommand], blend_s: float = 2.0, *,
                    lead_s: float = LEAD_S, ramp_s: float = RAMP_S,
                    pitch_deg: float = LOW_PITCH_DEG) -> Scenario:
    """Change scenario ``key`` (A–D): the first maneuver's HMM-set run (:func:`hmm_command`:
    low-dynamic start and its transition) until ``t_switch``, a ``blend_s`` command blend into
    the second maneuver, which then runs its full 25 s from ``t_switch``.

    ``t_switch`` counts from the start of the run, as the classifier sees it (for M1, M3, M4
    the first ``lead_s`` are the transition). The truth label changes at ``t_switch``; the
    blend is recorded in ``meta``. The start altitude is the first maneuver's;
    :func:`pipeline.simulate.scenarios.simulate_scenario` lifts a scenario whose nominal path
    would go below ``min_alt_m``.
    """
    a, b = SWITCHES[key]
    ma, mb = mans[a], mans[b]
    first, t0 = hmm_command(ma, lead_s=lead_s, ramp_s=ramp_s, pitch_deg=pitch_deg)
    cmd = Blend(first, Shifted(mb, t_switch), t_switch, blend_s)
    dur = t_switch + mb.duration_s
    phases = (Phase(0.0, t_switch, a), Phase(t_switch, dur, b))
    return Scenario(f"switch_{key}_{t_switch:g}s", cmd, dur, phases, ma.start_alt_m,
                    {"switch": key, "t_switch_s": t_switch, "blend_s": blend_s, "first": a, "second": b,
                     "first_maneuver_start_s": t0})


def _smooth2(s: F64) -> F64:
    """Second derivative d²S/ds² of the quintic smoothstep (zero outside [0, 1])."""
    inside = (s > 0) & (s < 1)
    s = np.clip(s, 0.0, 1.0)
    return np.where(inside, 60 * s - 180 * s * s + 120 * s ** 3, 0.0)


@dataclass(frozen=True)
class AltitudeCommand(Command):
    r"""Level-attitude thrust command that flies a smooth altitude schedule on the nominal model.

    The schedule ``h(t)`` is a knot channel (m, up); the thrust command is the inverse
    dynamics of the vertical axis, :math:`U_1/(mg) = 1 + (\ddot h + k_z \dot h)/g` with
    :math:`k_z = A_z/m`. The command (not the altitude) is what the simulator integrates, so the
    disturbance moves the flown altitude away from the schedule as in any other run.
    """

    alt: tuple
    k_z: float
    g: float
    duration_s: float = 60.0

    def sample(self, t: F64) -> CommandSample:
        t = np.asarray(t, float)
        tk, ck = np.asarray(self.alt[0], float), np.asarray(self.alt[1], float)
        _, hd = knots_eval(tk, ck, t)
        i = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, len(tk) - 2)
        span = tk[i + 1] - tk[i]
        hdd = (ck[i + 1] - ck[i]) * _smooth2((t - tk[i]) / span) / span ** 2
        thr = 1.0 + (hdd + self.k_z * hd) / self.g
        return CommandSample(thr, np.zeros(t.shape + (3,)), np.zeros(t.shape + (3,)))


def calibration_scenario(*, hover_alts_m: tuple[float, ...] = (2.0, 4.5), hover_s: float = 8.0,
                         climb_alt_m: float = 25.0, params=None) -> Scenario:
    """Barometer-calibration flight (seed 004 §6.3): 3 s on the ground, take-off to the first
    hover height, a hover at each ``hover_alts_m`` (all below the 6 m rangefinder limit, at
    different times), a climb-out to ``climb_alt_m`` and cruise there, a return to the first
    hover height for a last hover (so the baro offset is seen before and after the climb),
    landing and 3 s on the ground. Transitions take 4 s (+0.25 s per metre).
    Phases: ``ground``, ``hover``, ``climb``, ``cruise``, ``descent``, ``hover``, ``land``,
    ``ground``.
    """
    from .quadcopter import QuadParams

    p = params or QuadParams()
    pts = [(0.0, 0.0), (3.0, 0.0)]
    phases = [Phase(0.0, 3.0, "ground")]
    t = 3.0

    def move(to: float, label: str) -> None:
        nonlocal t
        dur = 4.0 + 0.25 * abs(to - pts[-1][1])
        phases.append(Phase(t, t + dur, label))
        t += dur
        pts.append((t, to))

    def hold(label: str, dur: float) -> None:
        nonlocal t
        phases.append(Phase(t, t + dur, label))
        t += dur
        pts.append((t, pts[-1][1]))

    move(hover_alts_m[0], "takeoff")
    hold("hover", hover_s)
    for h in hover_alts_m[1:]:
        move(h, "climb" if h > pts[-1][1] else "descent")
        hold("hover", hover_s)
    move(climb_alt_m, "climb")
    hold("cruise", hover_s)
    move(hover_alts_m[0], "descent")
    hold("hover", hover_s)
    move(0.0, "land")
    hold("ground", 3.0)
    cmd = AltitudeCommand(_k(*pts), float(p.k[2]), p.g_mps2, duration_s=t)
    return Scenario("calibration", cmd, t, tuple(phases), 0.0,
                    {"hover_alts_m": list(hover_alts_m), "climb_alt_m": climb_alt_m})
