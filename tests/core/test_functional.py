"""Functional joint centres (mocap_core.fit.functional): a made-up pelvis, thigh and shank with known hip and knee
centres and skin noise; too little motion refused with a message."""
from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocap_core.fit.functional import NoCentre, centre_of_rotation, cluster_poses, functional_centres, in_frame
from mocap_core.skeleton import INDEX

HIP = np.array([0.09, -0.03, -0.08])      # in the pelvis's frame
KNEE = np.array([0.0, 0.0, -0.42])        # from the hip, in the thigh's frame
PELVIS_MARKERS = np.array([[0.12, 0.05, 0.0], [-0.12, 0.05, 0.0], [0.08, -0.12, 0.02], [-0.08, -0.12, 0.02]])
THIGH_MARKERS = np.array([[0.06, 0.0, -0.2], [0.07, 0.03, -0.38], [-0.03, 0.05, -0.4]])   # from the hip
SHANK_MARKERS = np.array([[0.05, 0.02, -0.15], [0.06, -0.01, -0.38]])                    # from the knee


def walk(frames: int = 600, reach: float = 1.0, noise_m: float = 0.001, seed: int = 0):
    """Markers of a pelvis wandering about, a thigh turning at the hip in all three ways and a shank bending at the
    knee about the thigh's x axis (``reach`` scales the joints' range); and the true hip and knee centres."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 6 * np.pi, frames)
    Rp = Rotation.from_rotvec(np.stack([0.2 * np.sin(t / 3), 0.3 * np.sin(t / 5), 0.5 * np.sin(t / 7)], 1)).as_matrix()
    tp = np.stack([0.5 * np.sin(t / 4), 0.3 * np.cos(t / 6), 0.9 + 0.05 * np.sin(t)], 1)
    turn = reach * np.stack([0.6 * np.sin(t), 0.3 * np.sin(1.3 * t), 0.25 * np.sin(0.7 * t)], 1)
    Rt = Rp @ Rotation.from_rotvec(turn).as_matrix()
    Rs = Rt @ Rotation.from_rotvec(np.outer(reach * (0.8 + 0.7 * np.sin(1.7 * t)), [1.0, 0, 0])).as_matrix()
    hip = np.einsum("fab,b->fa", Rp, HIP) + tp
    knee = np.einsum("fab,b->fa", Rt, KNEE) + hip

    def seen(R, origin, local):
        return np.einsum("fab,kb->fka", R, local) + origin[:, None] + rng.normal(0, noise_m, (frames, len(local), 3))
    return seen(Rp, tp, PELVIS_MARKERS), seen(Rt, hip, THIGH_MARKERS), seen(Rs, knee, SHANK_MARKERS), hip, knee


def world(R, t, place):
    return np.einsum("fab,b->fa", R, place) + t


def test_hip_and_knee_centres_come_back_within_2_mm():
    pelvis, thigh, shank, hip, knee = walk()
    R, t = cluster_poses(pelvis)
    found = centre_of_rotation(in_frame(R, t, thigh), what="hip_l")
    hip_found = world(R, t, found.place)
    assert np.linalg.norm(hip_found - hip, axis=1).mean() < 0.002
    assert found.axis is None and (found.uncertainty_m < 0.02).all()
    # the thigh's pose from its markers and the hip centre just found; the knee on its hinge axis nearest the hip
    Rt, tt = cluster_poses(np.concatenate([hip_found[:, None], thigh], axis=1))
    near = in_frame(Rt, tt, hip_found[:, None])[:, 0].mean(axis=0)
    bend = centre_of_rotation(in_frame(Rt, tt, shank), hinge=True, near=near, what="knee_l")
    assert np.linalg.norm(world(Rt, tt, bend.place) - knee, axis=1).mean() < 0.002


def test_a_segment_pose_follows_its_markers_through_gaps():
    pelvis, *_ = walk(noise_m=0.0)
    holed = pelvis.copy()
    holed[100:200, 0] = np.nan          # one of four markers lost: three still give the pose
    holed[300:310, :2] = np.nan         # two lost: no pose
    R, t = cluster_poses(holed)
    full_R, full_t = cluster_poses(pelvis)
    assert np.isnan(R[300:310]).all()
    ok = np.isfinite(R).all(axis=(1, 2))
    assert ok.sum() == len(pelvis) - 10
    assert np.abs(R[ok] - full_R[ok]).max() < 1e-6 and np.abs(t[ok] - full_t[ok]).max() < 1e-6


def test_too_little_motion_is_refused_saying_how_much_it_moved():
    pelvis, thigh, *_ = walk(frames=600, reach=0.05, noise_m=0.003)
    R, t = cluster_poses(pelvis)
    why = centre_of_rotation(in_frame(R, t, thigh), what="hip_l").why_not("hip_l")
    assert re.match(r"hip_l: the child segment's markers moved [0-9/]+ mm rms .* it could be [0-9]+ mm off .* "
                    r"range-of-motion trial", why), why
    with pytest.raises(NoCentre, match="no marker of the child segment"):
        centre_of_rotation(np.full((100, 2, 3), np.nan), what="hip_l")


def test_a_hinge_is_not_taken_for_a_ball_joint():
    """Shank markers bent about one axis only: as a ball joint the centre is not trusted (it could be anywhere along
    the axis), as a hinge it is found."""
    _, thigh, shank, hip, knee = walk()
    Rt, tt = cluster_poses(np.concatenate([hip[:, None], thigh], axis=1))
    local = in_frame(Rt, tt, shank)
    assert centre_of_rotation(local, what="knee_l").why_not("knee_l")
    bend = centre_of_rotation(local, hinge=True, what="knee_l")
    assert bend.axis is not None and not bend.why_not("knee_l")


def test_a_calibration_finds_the_centres_it_can_and_says_why_not_the_others():
    """functional_centres over a made-up pelvis, thigh and shank: the hip and knee found, the elbow (no markers on
    the arm) refused with the reason."""
    pelvis, thigh, shank, hip, knee = walk()
    markers = np.concatenate([pelvis, thigh, shank], axis=1)
    bones = np.array([INDEX["pelvis"]] * 4 + [INDEX["hip_l"]] * 3 + [INDEX["knee_l"]] * 2)
    found = {f.joint: f for f in functional_centres(markers, bones, INDEX)}
    assert np.linalg.norm(found["hip_l"].positions - hip, axis=1).mean() < 0.002 and not found["hip_l"].why
    assert np.linalg.norm(found["knee_l"].positions - knee, axis=1).mean() < 0.002 and not found["knee_l"].why
    assert found["elbow_l"].positions is None and "carries 0 marker(s)" in found["elbow_l"].why
    assert found["hip_r"].positions is None
