#!/usr/bin/env python3
"""Writes the motion fixtures of `render-pose --motion` with numpy's own `.npz` writer, in the
layouts of the files people have (so the reader is checked against what numpy writes, not only
against the project's writer):

- `walk_amass.npz`: AMASS layout (z-up world), SMPL-H `poses` (120, 156) float64 at 60 fps, `trans`,
  `betas` (16,), `gender` as a numpy unicode scalar, `mocap_framerate` as a 0-d float64 array and
  `dmpls` (120, 8): a person walking 2 m along the world's -y with swinging legs and arms and a
  slight bob.
- `wave_people_snapshot.npz`: PeopleSnapshot / InstantAvatar layout (OpenCV camera frame, y down),
  float32: `global_orient` (40, 3), `body_pose` (40, 69), `transl` (40, 3), `betas` (1, 10): a person
  facing the camera 3 m away, waving the right arm.

Made by this project (no captured data); same licence as the repository. Run from anywhere:
    python3 data-fixtures/motion/make_motion_fixtures.py
"""
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def axis_angle_x(a):
    return np.array([a, 0.0, 0.0])


def walk_amass():
    n, fps = 120, 60.0
    t = np.arange(n) / fps
    phase = 2 * np.pi * 1.0 * t  # one stride cycle per second
    poses = np.zeros((n, 156))
    poses[:, 0:3] = axis_angle_x(np.pi / 2)  # SMPL's y-up rest turned z-up, facing -y
    # SMPL joint j has values 3j..3j+3: hips 1, 2; knees 4, 5; shoulders 16, 17; elbows 18, 19.
    poses[:, 3 * 1] = 0.45 * np.sin(phase)
    poses[:, 3 * 2] = -0.45 * np.sin(phase)
    poses[:, 3 * 4] = 0.6 * np.clip(np.sin(phase + 1.2), 0, None)
    poses[:, 3 * 5] = 0.6 * np.clip(-np.sin(phase + 1.2), 0, None)
    poses[:, 3 * 16 + 2] = -1.2  # arms down from the T-pose
    poses[:, 3 * 17 + 2] = 1.2
    poses[:, 3 * 16 + 1] = 0.35 * np.sin(phase)
    poses[:, 3 * 17 + 1] = 0.35 * np.sin(phase)
    poses[:, 3 * 18 + 1] = -0.3
    poses[:, 3 * 19 + 1] = 0.3
    poses[:, 66:] = 0.05  # finger joints (dropped by an SMPL reader)
    trans = np.stack([np.zeros(n), -1.0 * t, 0.92 + 0.02 * np.cos(2 * phase)], axis=1)
    np.savez_compressed(
        os.path.join(HERE, "walk_amass.npz"),
        poses=poses,
        trans=trans,
        betas=np.zeros(16),
        gender=np.array("neutral"),
        mocap_framerate=np.array(fps),
        dmpls=np.zeros((n, 8)),
    )


def wave_people_snapshot():
    n = 40
    phase = 2 * np.pi * np.arange(n) / 20.0
    global_orient = np.tile(axis_angle_x(np.pi), (n, 1))  # upright in y-down, facing the camera
    body_pose = np.zeros((n, 69))
    # body_pose holds joints 1..23: joint j at 3(j-1)..3(j-1)+3.
    body_pose[:, 3 * 15 + 2] = -1.2  # left arm down (joint 16)
    body_pose[:, 3 * 16 + 2] = 0.3 + 0.5 * np.sin(phase)  # right arm waving (joint 17)
    body_pose[:, 3 * 18 + 1] = 1.0 + 0.4 * np.sin(phase)  # right elbow (joint 19)
    transl = np.tile(np.array([0.0, 0.25, 3.0]), (n, 1))
    np.savez(
        os.path.join(HERE, "wave_people_snapshot.npz"),
        global_orient=global_orient.astype(np.float32),
        body_pose=body_pose.astype(np.float32),
        transl=transl.astype(np.float32),
        betas=np.zeros((1, 10), dtype=np.float32),
    )


if __name__ == "__main__":
    walk_amass()
    wave_people_snapshot()
