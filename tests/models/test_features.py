"""Feature sets: differencing/normalisation, decimation phases, heading invariance."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.frames.rotations import euler_to_quat, quat_multiply
from pipeline.models.features import (FEATURE_SETS, decimate, decimation_factor, heading_rotation,
                                      observations, raw_features, rotate_triples)


def random_state(rng, n=40):
    df = pd.DataFrame({"t_ns": np.arange(n, dtype=np.int64) * 40_000_000})
    for i, a in enumerate("ned"):
        df[f"pos_{a}_m"] = rng.normal(size=n).cumsum()
        df[f"vel_{a}_mps"] = rng.normal(size=n) * 10
        df[f"acc_{a}_mps2"] = rng.normal(size=n) * 3
    yaw = rng.uniform(-3, 3, n)
    q = euler_to_quat(rng.uniform(-3, 3, n), rng.uniform(-1.5, 1.5, n), yaw)
    df["yaw_rad"] = yaw
    for i, c in enumerate("wxyz"):
        df[f"q_{c}"] = q[:, i]
    for c in ("p_radps", "q_radps", "r_radps"):
        df[c] = rng.normal(size=n)
    return df


def rotate_world(df, psi):
    """The same flight seen with the world frame turned by ``psi`` about down."""
    c, s = np.cos(psi), np.sin(psi)
    out = df.copy()
    for k, u in (("pos", "m"), ("vel", "mps"), ("acc", "mps2")):
        n, e = df[f"{k}_n_{u}"], df[f"{k}_e_{u}"]
        out[f"{k}_n_{u}"], out[f"{k}_e_{u}"] = c * n - s * e, s * n + c * e
    qz = euler_to_quat(0.0, 0.0, psi)
    q = quat_multiply(np.broadcast_to(qz, (len(df), 4)), df[["q_w", "q_x", "q_y", "q_z"]].to_numpy())
    out[["q_w", "q_x", "q_y", "q_z"]] = q
    out["yaw_rad"] = df["yaw_rad"] + psi
    return out


@pytest.mark.parametrize("psi", [0.3, -2.0, np.pi])
def test_aero_and_box_features_are_heading_invariant(rng, psi):
    df = random_state(rng)
    rot = rotate_world(df, psi)
    np.testing.assert_allclose(raw_features(rot, "aero"), raw_features(df, "aero"), atol=1e-9)
    np.testing.assert_allclose(raw_features(rot, "box", box_heading_rad=0.4 + psi),
                               raw_features(df, "box", box_heading_rad=0.4), atol=1e-9)
    np.testing.assert_allclose(raw_features(rot, "state9h"), raw_features(df, "state9h"), atol=1e-9)
    # the thesis features are not: they change with the heading
    assert not np.allclose(raw_features(rot, "state9"), raw_features(df, "state9"))


def test_state9_observation_is_the_increment(rng):
    df = random_state(rng, 10)
    o = observations(raw_features(df, "state9"), FEATURE_SETS["state9"].differenced)
    assert o.shape == (9, 9)
    np.testing.assert_allclose(o[3, :3], df[["pos_n_m", "pos_e_m", "pos_d_m"]].to_numpy()[4]
                               - df[["pos_n_m", "pos_e_m", "pos_d_m"]].to_numpy()[3])


def test_decimation_phases(rng):
    df = random_state(rng, 23)                                        # 25 Hz
    assert decimation_factor(df["t_ns"], 5.0) == 5
    phases = [decimate(df, 5.0, k) for k in range(5)]
    assert [len(p) for p in phases] == [5, 5, 5, 4, 4]
    np.testing.assert_array_equal(phases[2]["t_ns"], df["t_ns"].to_numpy()[2::5])
    with pytest.raises(ValueError):
        decimate(df, 5.0, 5)
    with pytest.raises(ValueError, match="slower"):
        decimation_factor(df["t_ns"], 50.0)
    with pytest.raises(ValueError, match="unknown feature set"):
        raw_features(df, "state12")


@pytest.mark.parametrize("psi", [0.0, 0.7, -2.5, np.pi])
def test_the_heading_rotation_round_trips_and_turns_north_onto_the_box_axis(rng, psi):
    R = heading_rotation(psi)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(R), 1.0)
    # a unit vector along heading psi is the box frame's x axis; down stays down
    np.testing.assert_allclose(R @ [np.cos(psi), np.sin(psi), 0.0], [1.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(R @ [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], atol=1e-15)
    x = rng.normal(size=(7, 9))
    np.testing.assert_allclose(rotate_triples(rotate_triples(x, R), R.T), x, atol=1e-12)
    with pytest.raises(ValueError, match="triples"):
        rotate_triples(x[:, :8], R)


@pytest.mark.parametrize("psi", [0.3, -2.0, np.pi])
def test_state9box_is_invariant_to_the_box_heading_and_matches_the_box_set(rng, psi):
    df = random_state(rng)
    rot = rotate_world(df, psi)
    np.testing.assert_allclose(raw_features(rot, "state9box", box_heading_rad=0.4 + psi),
                               raw_features(df, "state9box", box_heading_rad=0.4), atol=1e-9)
    # box heading 0: the thesis features themselves
    np.testing.assert_array_equal(raw_features(df, "state9box"), raw_features(df, "state9"))
    # the same box frame as the `box` set (velocity and acceleration columns)
    x = raw_features(df, "state9box", box_heading_rad=0.4)
    b = raw_features(df, "box", box_heading_rad=0.4)
    np.testing.assert_allclose(x[:, 3:9], b[:, :6], atol=1e-12)
    # every triple rotated; the down components untouched
    np.testing.assert_array_equal(x[:, 2::3], raw_features(df, "state9")[:, 2::3])
    fs = FEATURE_SETS["state9box"]
    assert fs.differenced and len(fs.names) == 9 and "yaw_rad" not in fs.needs
    assert observations(x, fs.differenced).shape == (len(df) - 1, 9)
