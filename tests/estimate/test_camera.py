"""Seed-001 camera: pinhole closed forms, the 4x4 chain, frames and the multi-observer likelihood."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.estimate.camera import (CAMERA_TO_GIMBAL, OBS_FIELDS, CameraLikelihood, PinholeCamera,
                                      camera_loglik, camera_loglik_per_observer, camera_to_world, enu_to_ned,
                                      ground_intersection, homogeneous, invert_pose, look_at_angles,
                                      ned_to_enu, observers_from_streams, pack_detections, quat_to_rot,
                                      ray_intersection, rot_zyx, yaw_enu_to_ned)
from pipeline.estimate.pf import ParticleFilter
from pipeline.estimate.models import PfConstantVelocity

CAM = PinholeCamera(800.0, 1280, 960)


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_enu_converts_to_ned_as_n_equals_y_e_equals_x_d_equals_minus_z():
    p = np.array([[1.15, 0.96, 40.0], [-30.0, 10.0, 0.0]])
    assert np.allclose(enu_to_ned(p), [[0.96, 1.15, -40.0], [10.0, -30.0, 0.0]])
    assert np.allclose(ned_to_enu(enu_to_ned(p)), p)
    # "40° north of east" in ENU is a NED bearing atan2(E, N) of 50°
    assert np.isclose(np.degrees(yaw_enu_to_ned(np.radians(40.0))), 50.0)


def test_zyx_rotation_equals_the_hand_built_product():
    y, p, r = 0.3, -0.4, 0.2
    assert np.allclose(rot_zyx(y, p, r), _rz(y) @ _ry(p) @ _rx(r))
    q = np.array([np.cos(0.35), 0, 0, np.sin(0.35)])          # 0.7 rad about D
    assert np.allclose(quat_to_rot(q), _rz(0.7))


def test_the_chain_composes_translations_and_rotations_in_the_printed_order():
    pos, RU = np.array([5.0, -3.0, -40.0]), _rz(0.5) @ _ry(0.1) @ _rx(-0.05)
    off, gy, gp = np.array([0.2, 0.0, 0.1]), 0.7, -0.6
    T = camera_to_world(pos, RU, gy, gp, off)
    RC = _rz(gy) @ _ry(gp) @ CAMERA_TO_GIMBAL
    hand = homogeneous(None, pos) @ homogeneous(RU) @ homogeneous(None, off) @ homogeneous(RC)
    assert np.allclose(T, hand)
    assert np.allclose(T[:3, :3], RU @ RC) and np.allclose(T[:3, 3], pos + RU @ off)
    assert np.allclose(invert_pose(T) @ T, np.eye(4)) and np.allclose(invert_pose(T), np.linalg.inv(T))


def test_a_point_on_the_optical_axis_projects_to_the_principal_point():
    pos, RU = np.array([0.0, 0.0, -40.0]), rot_zyx(0.3, 0.0, 0.0)
    target = np.array([60.0, 25.0, 0.0])
    gy, gp = look_at_angles(pos, RU, target)
    T = camera_to_world(pos, RU, gy, gp)
    assert np.allclose(CAM.project(target[None], T[None])[0, 0], CAM.principal)
    # and any point on the axis, at any depth
    axis = pos + np.outer([1.0, 7.0, 30.0], T[:3, 2])
    assert np.allclose(CAM.project(axis, T[None])[0], np.broadcast_to(CAM.principal, (3, 2)))


def test_a_camera_looking_down_maps_north_to_up_in_the_image_and_east_to_the_right():
    T = camera_to_world([0.0, 0.0, -10.0], np.eye(3), 0.0, -np.pi / 2)
    uv = CAM.project(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -20.0]]), T[None])[0]
    cu, cv = CAM.principal
    assert np.allclose(uv[0], [cu, cv - 80.0])       # f * 1 m / 10 m
    assert np.allclose(uv[1], [cu + 80.0, cv])
    assert np.all(np.isnan(uv[2]))                    # behind the camera


def test_projection_is_vectorised_over_particles_and_observers():
    rng = np.random.default_rng(0)
    P = rng.normal(0, 20, (7, 3)) * [1, 1, 0]
    Ts = np.stack([camera_to_world([x, y, -40.0], rot_zyx(h, 0, 0), *look_at_angles([x, y, -40.0], rot_zyx(h, 0, 0), [0, 0, 0.0]))
                   for x, y, h in ((50, 0, 0.1), (-30, 60, 1.0))])
    uv = CAM.project(P, Ts)
    assert uv.shape == (2, 7, 2)
    for o in range(2):
        for i in range(7):
            pc = np.linalg.inv(Ts[o]) @ np.r_[P[i], 1.0]
            assert np.allclose(uv[o, i], [640 + 800 * pc[0] / pc[2], 480 + 800 * pc[1] / pc[2]])


def test_rays_back_project_through_the_detection_and_meet_the_ground_at_the_target():
    target = np.array([30.0, -20.0, 0.0])
    origins, dirs = [], []
    for pos in ([0.0, 0.0, -40.0], [60.0, 10.0, -50.0], [10.0, -70.0, -30.0]):
        RU = rot_zyx(0.2, 0, 0)
        T = camera_to_world(pos, RU, *look_at_angles(pos, RU, target + [3.0, 2.0, 0.0]))
        uv = CAM.project(target[None], T[None])[0, 0]
        o, d = CAM.ray(uv, T)
        assert np.allclose(ground_intersection(o, d), target)
        origins.append(o)
        dirs.append(d)
    assert np.allclose(ray_intersection(origins, dirs), target)


def _scene(rng, n_obs=3, target=(20.0, 10.0, 0.0), sigma=5.0):
    target = np.asarray(target)
    Ts = []
    for k in range(n_obs):
        pos = np.array([80 * np.cos(2 * k), 80 * np.sin(2 * k), -40.0 - 10 * k])
        RU = rot_zyx(k, 0, 0)
        Ts.append(camera_to_world(pos, RU, *look_at_angles(pos, RU, target)))
    Ts = np.stack(Ts)
    uv = CAM.project(target[None], Ts)[:, 0] + sigma * rng.standard_normal((n_obs, 2))
    return Ts, uv


def test_the_likelihood_is_the_sum_of_the_per_observer_log_likelihoods():
    rng = np.random.default_rng(1)
    Ts, uv = _scene(rng, 4)
    sig = np.array([5.0, 6.0, 7.0, 8.0])
    row = pack_detections(uv, sig, Ts)
    x = np.zeros((200, 8))
    x[:, :2] = [20.0, 10.0] + rng.normal(0, 5, (200, 2))
    x[:, 7] = rng.normal(0, 1, 200)
    total = camera_loglik(x, row, CAM, d_index=7)
    per = camera_loglik_per_observer(x, row, CAM, d_index=7)
    assert np.allclose(total, per.sum(axis=0))
    # each term is the closed-form bivariate normal log-density of the pixel residual
    uv0 = CAM.project(np.column_stack([x[:, 0], x[:, 1], x[:, 7]]), Ts)
    r = (uv0 - uv[:, None, :]) / sig[:, None, None]
    assert np.allclose(per, -0.5 * (r ** 2).sum(-1) - np.log(2 * np.pi * sig[:, None] ** 2))
    # an observer without a detection drops out of the product
    uv[2] = np.nan
    row2 = pack_detections(uv, sig, Ts)
    assert np.allclose(camera_loglik(x, row2, CAM, d_index=7), np.delete(per, 2, axis=0).sum(axis=0))


def test_the_weighting_skips_leading_observers_without_detections_and_gives_zero_without_any():
    # the kernel's first detecting observer writes the output (no fill pass): an undetected first
    # observer, a particle behind a camera and a step without detections must all still be right
    rng = np.random.default_rng(5)
    Ts, uv = _scene(rng, 4)
    x = np.zeros((300, 7))
    x[:, :2] = [20.0, 10.0] + rng.normal(0, 5, (300, 2))
    per = camera_loglik_per_observer(x, pack_detections(uv, 6.0, Ts), CAM)
    uv[0] = uv[1] = np.nan
    for par in (False, True):
        got = camera_loglik(x, pack_detections(uv, 6.0, Ts), CAM, parallel=par)
        assert np.allclose(got, per[2:].sum(axis=0))
        none = camera_loglik(x, pack_detections(np.full((4, 2), np.nan), 6.0, Ts), CAM, parallel=par)
        assert np.array_equal(none, np.zeros(300))
    # ground points 1 km behind observer 2 (against its optical axis) are behind its camera: −∞
    xb = np.vstack([x, np.zeros((3, 7))])
    axis = Ts[2][:2, 2] / np.linalg.norm(Ts[2][:2, 2])
    xb[-3:, 0:2] = Ts[2][:2, 3] - np.array([[1000.0], [1100.0], [1200.0]]) * axis
    ll = camera_loglik(xb, pack_detections(uv, 6.0, Ts), CAM)
    assert np.all(np.isneginf(ll[-3:])) and np.all(np.isfinite(ll[:-3]))


def test_the_parallel_weighting_equals_the_serial_one():
    rng = np.random.default_rng(2)
    Ts, uv = _scene(rng, 16)
    row = pack_detections(uv, 5.0, Ts)
    x = np.zeros((1000, 7))
    x[:, :2] = rng.normal(0, 10, (1000, 2))
    a = camera_loglik(x, row, CAM, parallel=False)
    b = camera_loglik(x, row, CAM, parallel=True)
    assert np.allclose(a, b) and np.allclose(a, camera_loglik_per_observer(x, row, CAM).sum(axis=0))


def test_no_detection_at_all_is_a_predict_only_step():
    rng = np.random.default_rng(3)
    Ts, uv = _scene(rng, 3)
    row = pack_detections(np.full((3, 2), np.nan), 5.0, Ts)
    assert row.shape == (3 * OBS_FIELDS,) and np.all(np.isnan(row))
    lik = CameraLikelihood(CAM)
    pf = ParticleFilter([PfConstantVelocity(0.3)], None, lik, n_particles=100, rng=4)
    pf.init(mean=[20, 10, 1, 0, 0, 0, 0], cov=np.diag([25, 25, 1, 1, 0, 0, 0]))
    w0 = pf.weights.copy()
    s = pf.step(0.025, row)
    assert s.predict_only and not s.resampled and np.allclose(pf.weights, w0)
    s = pf.step(0.025, pack_detections(uv, 5.0, Ts))
    assert not s.predict_only and np.isfinite(s.loglik)


def test_the_filter_reinitialises_at_the_rays_ground_fix_when_every_weight_is_zero():
    rng = np.random.default_rng(5)
    Ts, uv = _scene(rng, 3, sigma=0.0)
    lik = CameraLikelihood(CAM, reinit_sigma_m=1.0)
    assert np.allclose(lik.ground_fix(pack_detections(uv, 5.0, Ts)), [20.0, 10.0, 0.0])
    # particles on a plane far above every camera are behind them all and weigh zero
    lik_above = CameraLikelihood(CAM, ground_d=-500.0, reinit_sigma_m=1.0)
    pf = ParticleFilter([PfConstantVelocity(0.3)], None, lik_above, n_particles=200, rng=6, reinit=lik.reinit)
    pf.init(mean=[20, 10, 0, 0, 0, 0, 0], cov=np.diag([1, 1, 0, 0, 0, 0, 0]))
    s = pf.step(0.0, pack_detections(uv, 5.0, Ts))
    assert s.reinit and pf.n_reinit == 1
    assert np.allclose(pf.x[:, :2].mean(axis=0), [20.0, 10.0], atol=0.3)


def test_the_collapse_test_reads_the_best_particles_pixel_residual_in_sigmas():
    rng = np.random.default_rng(7)
    Ts, uv = _scene(rng, 3, sigma=0.0)
    row = pack_detections(uv, 5.0, Ts)
    lik = CameraLikelihood(CAM, collapse_sigma=5.0)
    x = np.zeros((4, 7))
    x[:, :2] = [20.0, 10.0]                      # the target: residual 0
    assert not lik.collapsed(lik(x, row), row)
    x[:, :2] = [220.0, -190.0]                   # every particle 280 m off: far beyond 5 sigma
    assert lik.collapsed(lik(x, row), row)
    # the test's scale: it trips exactly where the best particle's RMS residual crosses the threshold
    x[:, :2] = [23.0, 11.0]
    ll = lik(x[:1], row)
    const = 3 * (-2 * np.log(5.0) - np.log(2 * np.pi))
    rho = np.sqrt(-2 * (ll[0] - const) / 6)
    assert np.isfinite(rho) and rho > 0
    assert CameraLikelihood(CAM, collapse_sigma=0.999 * rho).collapsed(ll, row)
    assert not CameraLikelihood(CAM, collapse_sigma=1.001 * rho).collapsed(ll, row)
    assert not CameraLikelihood(CAM).collapsed(ll, row)           # off by default in the class
    assert not lik.collapsed(ll, pack_detections(np.full((3, 2), np.nan), 5.0, Ts))


def test_the_filter_reinitialises_from_the_rays_when_the_best_particle_has_lost_the_target():
    rng = np.random.default_rng(8)
    Ts, uv = _scene(rng, 3, sigma=0.0)
    row = pack_detections(uv, 5.0, Ts)
    for collapse, expect in ((5.0, True), (None, False)):
        lik = CameraLikelihood(CAM, reinit_sigma_m=1.0, collapse_sigma=collapse)
        pf = ParticleFilter([PfConstantVelocity(0.3)], None, lik, n_particles=200, rng=9)
        # a cloud 60 m from the target: in front of every camera, so some weight is left
        pf.init(mean=[80, 10, 0, 0, 0, 0, 0], cov=np.diag([1, 1, 0, 0, 0, 0, 0]))
        s = pf.step(0.0, row)
        assert s.reinit is expect and pf.n_collapse == int(expect) and pf.n_reinit == int(expect)
        if expect:
            assert np.allclose(pf.x[:, :2].mean(axis=0), [20.0, 10.0], atol=0.3)


def test_the_window_fires_where_the_residual_sum_crosses_the_chi_square_quantile_and_then_empties():
    from scipy.stats import chi2

    from pipeline.estimate.camera import CollapseWindow

    w = CollapseWindow(4, 1e-3)
    lim = chi2.isf(1e-3, 4 * 6)                          # four steps of three detections, 6 dof each
    for _ in range(3):
        assert not w.push(lim / 4 * 1.01, 6)              # the window is not full yet
    assert w.push(lim / 4 * 1.01, 6) and w.fired == 1     # full and just above the quantile
    for _ in range(4):
        assert not w.push(lim / 4 * 0.99, 6)              # emptied on firing; refilled, just below
    assert not w.push(lim / 4 * 0.99, 6)                  # the oldest step leaves as one enters
    # the degrees of freedom follow the detections: one camera for a step lowers the quantile
    w2 = CollapseWindow(2, 1e-3)
    assert not w2.push(0.0, 2) and w2.push(chi2.isf(1e-3, 4) * 1.01, 2)
    with pytest.raises(ValueError, match="steps >= 1 and 0 < alpha < 1"):
        CollapseWindow(0, 1e-3)
    # a re-initialisation, whichever test called it, empties the window: those were the old cloud's
    rng = np.random.default_rng(3)
    Ts, uv = _scene(rng, 3, sigma=0.0)
    lik = CameraLikelihood(CAM, window=CollapseWindow(4, 1e-3))
    lik.window.push(1.0, 6)
    assert len(lik.window) == 1
    lik.reinit(np.zeros((10, 7)), pack_detections(uv, 5.0, Ts), rng)
    assert len(lik.window) == 0


def test_a_cloud_a_fraction_of_a_sigma_off_trips_the_window_though_no_single_step_can():
    from pipeline.estimate.camera import CollapseWindow

    rng = np.random.default_rng(21)
    sigma = 40.0                                        # px: wide, like the seed-001 bearing noise
    Ts, uv = _scene(rng, 3, sigma=0.0)                  # noise-free projections of the target
    x_true = np.array([[20.0, 10.0, 0, 0, 0, 0, 0]])
    x_off = np.array([[26.0, 10.0, 0, 0, 0, 0, 0]])     # the cloud 6 m north of the target
    bias = np.abs(CAM.project(x_off[:, [0, 1, 2]] * [1, 1, 0], Ts)[:, 0] - uv) / sigma
    assert 0.2 < np.sqrt(np.mean(bias ** 2)) < 1.0      # well under a sigma per image coordinate
    step_only = CameraLikelihood(CAM, collapse_sigma=5.0)
    fired = {}
    for name, x in (("true", x_true), ("off", x_off)):
        lik = CameraLikelihood(CAM, collapse_sigma=5.0, window=CollapseWindow(40, 1e-6))
        fired[name] = 0
        for _ in range(400):
            row = pack_detections(uv + sigma * rng.standard_normal(uv.shape), sigma, Ts)
            ll = lik(x, row)
            assert not step_only.collapsed(ll, row)      # the per-step test never trips
            fired[name] += lik.collapsed(ll, row)
    assert fired["true"] == 0 and fired["off"] >= 3


def test_a_camera_det_observer_without_a_pose_fails_naming_it():
    det = pd.DataFrame({"t_ns": [0, 0], "instance": [1, 2], "u_px": [640.0, 600.0], "v_px": [480.0, 500.0],
                        "sigma_px": [5.0, 5.0], "gimbal_yaw_rad": [0.0, 0.1], "gimbal_pitch_rad": [-0.5, -0.6]})
    lp = pd.DataFrame({"t_ns": [0, 10**9], "instance": [1, 1], "pos_n_m": [0.0, 1.0], "pos_e_m": [0.0, 0.0],
                       "pos_d_m": [-40.0, -40.0]})
    att = pd.DataFrame({"t_ns": [0, 10**9, 0], "instance": [1, 1, 2], "q_w": [1.0, 1.0, 1.0], "q_x": [0.0] * 3,
                        "q_y": [0.0] * 3, "q_z": [0.0] * 3})
    with pytest.raises(ValueError, match="observer instance 2 has no pose.*local_position"):
        observers_from_streams(det, lp, att)
    T = observers_from_streams(det.iloc[:1], lp, att)
    assert np.allclose(T[0], camera_to_world([0, 0, -40.0], np.eye(3), 0.0, -0.5))


def test_fixes_drawn_from_one_detection_are_its_ray_ground_intersections_with_the_pixel_noise_spread():
    from pipeline.estimate.camera import sample_fixes

    rng = np.random.default_rng(7)
    Ts, uv = _scene(rng, 1, sigma=0.0)
    row = pack_detections(uv, 1e-9, Ts)
    # no noise: every draw is the target itself
    assert np.allclose(sample_fixes(row, CAM, 50, rng), [20.0, 10.0, 0.0], atol=1e-5)
    # σ = 4 px: the draws' covariance is J diag(σ²) Jᵀ, J the pixel → ground-point Jacobian
    # taken here by finite differences of the hand-built ray-plane intersection
    sig = 4.0

    def ground(u, v):
        o, d = CAM.ray(np.array([u, v]), Ts[0])
        return (o + (0.0 - o[2]) / d[2] * d)[:2]

    h = 1e-3
    J = np.column_stack([(ground(uv[0, 0] + h, uv[0, 1]) - ground(uv[0, 0] - h, uv[0, 1])) / (2 * h),
                         (ground(uv[0, 0], uv[0, 1] + h) - ground(uv[0, 0], uv[0, 1] - h)) / (2 * h)])
    p = sample_fixes(pack_detections(uv, sig, Ts), CAM, 20000, rng)
    assert np.all(np.isfinite(p)) and np.allclose(p[:, 2], 0.0)
    C = np.cov(p[:, :2].T)
    assert np.allclose(C, sig ** 2 * J @ J.T, rtol=0.1, atol=0.02)
    assert np.allclose(p[:, :2].mean(axis=0), [20.0, 10.0], atol=0.05)


def test_fixes_from_several_detections_are_least_squares_ray_intersections_in_front_of_every_camera():
    from pipeline.estimate.camera import sample_fixes

    rng = np.random.default_rng(8)
    Ts, uv = _scene(rng, 3, sigma=0.0)
    row = pack_detections(uv, 1e-9, Ts)
    assert np.allclose(sample_fixes(row, CAM, 10, rng, on_ground=False), [20.0, 10.0, 0.0], atol=1e-5)
    # a grazing camera with a huge pixel error: rays above the horizon are redrawn, never used
    pos = np.array([200.0, 0.0, -30.0])
    T = camera_to_world(pos, np.eye(3), *look_at_angles(pos, np.eye(3), np.zeros(3)))[None]
    u0 = CAM.project(np.zeros((1, 3)), T)[:, 0]
    p = sample_fixes(pack_detections(u0, 250.0, T), CAM, 3000, rng)
    ok = np.all(np.isfinite(p), axis=1)
    assert ok.mean() > 0.99
    ahead = np.einsum("ij,j->i", p[ok] - pos, T[0, :3, 2])
    assert np.all(ahead > 0)
    # the draws follow an independent Monte Carlo of the same rays built by hand (R_wc d_c with
    # d_c = [(u − c_u)/f, (v − c_v)/f, 1], kept where they point down and meet the ground)
    e = 250.0 * rng.standard_normal((200000, 2))
    dc = np.column_stack([(u0[0, 0] + e[:, 0] - 640.0) / 800.0, (u0[0, 1] + e[:, 1] - 480.0) / 800.0,
                          np.ones(len(e))])
    dw = dc @ T[0, :3, :3].T
    down = dw[:, 2] > 0
    hand = pos[:2] + (30.0 / dw[down, 2])[:, None] * dw[down, :2]
    dist = np.hypot(*(p[ok, :2] - pos[:2]).T)
    dist_hand = np.hypot(*(hand - pos[:2]).T)
    for q in (0.25, 0.5, 0.75):
        assert np.isclose(np.quantile(dist, q), np.quantile(dist_hand, q), rtol=0.08)


def test_an_observers_attitude_is_interpolated_through_a_stored_quaternion_sign_flip():
    # yaw 170 deg and 190 deg, the second stored with q_w >= 0 (as -q): half way the camera looks
    # south (yaw 180 deg); interpolated component by component it looked north (0 deg)
    def q_yaw(deg):
        return np.array([np.cos(np.radians(deg) / 2), 0.0, 0.0, np.sin(np.radians(deg) / 2)])

    qa, qb = q_yaw(170.0), -q_yaw(190.0)
    assert qb[0] > 0
    lp = pd.DataFrame({"t_ns": [0, 100], "instance": [0, 0], "pos_n_m": [0.0, 0.0], "pos_e_m": [0.0, 0.0],
                       "pos_d_m": [-40.0, -40.0]})
    att = pd.DataFrame({"t_ns": [0, 100], "instance": [0, 0], **{f"q_{c}": [qa[j], qb[j]] for j, c in enumerate("wxyz")}})
    det = pd.DataFrame({"t_ns": [50], "instance": [0], "gimbal_yaw_rad": [0.0], "gimbal_pitch_rad": [0.0]})
    T = observers_from_streams(det, lp, att)
    ref = camera_to_world([0, 0, -40.0], quat_to_rot(q_yaw(180.0)), 0.0, 0.0)
    np.testing.assert_allclose(T[0], ref, atol=1e-12)
