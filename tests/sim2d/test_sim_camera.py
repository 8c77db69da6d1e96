"""Camera sanity: shapes, poses, brightness, supersampling, determinism of the renderer itself."""

from __future__ import annotations

import numpy as np
import pytest

from vtr.sim2d import CameraConfig, Pose, SimConfig, Simulator
from vtr.sim2d.camera import Camera
from vtr.sim2d.house import load_house


@pytest.fixture(scope="module")
def house():
    return load_house("house")


def test_image_shape_dtype_and_content(house):
    cam = Camera(house, CameraConfig())
    img = cam.render(2.8, 3.0, 0.0)
    assert img.shape == (128, 128, 3) and img.dtype == np.uint8 and img.flags.c_contiguous
    assert img.std() > 20  # textured, not flat
    wide = Camera(house, CameraConfig(width=96, height=64, fov_deg=120)).render(2.8, 3.0, 0.0)
    assert wide.shape == (64, 96, 3)


def test_poses_give_different_images_and_the_same_pose_the_same_image(house):
    cam = Camera(house, CameraConfig(width=64, height=64))
    a = cam.render(2.8, 3.0, 0.0).astype(int)
    assert np.array_equal(a, cam.render(2.8, 3.0, 0.0))
    forward = cam.render(3.0, 3.0, 0.0).astype(int)
    turned = cam.render(2.8, 3.0, 0.1).astype(int)
    assert np.mean(np.abs(forward - a)) > 3  # moving 20 cm forward changes the view
    assert np.mean(np.abs(turned - a)) > 3  # so does turning 6 degrees
    # Different rooms look different.
    kitchen = cam.render(8.0, 1.2, 1.57).astype(int)
    assert np.mean(np.abs(kitchen - a)) > 20


def test_brightness_scales_the_image(house):
    base = Camera(house, CameraConfig(width=64, height=64)).render(2.8, 3.0, 0.5).astype(float)
    dark = (
        Camera(house, CameraConfig(width=64, height=64, brightness=0.5)).render(2.8, 3.0, 0.5).astype(float)
    )
    bright = Camera(house, CameraConfig(width=64, height=64, brightness=1.5)).render(2.8, 3.0, 0.5)
    assert np.abs(dark - 0.5 * base).max() <= 1.5  # exact up to rounding
    assert bright.mean() > base.mean() * 1.2 and bright.max() == 255  # brighter, saturating at 255


def test_supersampling_renders_the_same_scene_smoother(house):
    plain = Camera(house, CameraConfig(width=64, height=64)).render(2.8, 3.0, 0.5).astype(float)
    smooth = (
        Camera(house, CameraConfig(width=64, height=64, supersample=2)).render(2.8, 3.0, 0.5).astype(float)
    )
    assert smooth.shape == plain.shape
    assert np.mean(np.abs(smooth - plain)) < 15  # same scene
    # Averaging 2x2 samples removes pixel-to-pixel jitter: smaller horizontal gradients.
    assert np.abs(np.diff(smooth, axis=1)).mean() < np.abs(np.diff(plain, axis=1)).mean()


def test_simulator_images_come_from_the_camera(house):
    sim = Simulator(SimConfig(camera=CameraConfig(width=64, height=64)))
    img = sim.reset(Pose(2.8, 3.0, 0.0))
    assert np.array_equal(img, Camera(house, CameraConfig(width=64, height=64)).render(2.8, 3.0, 0.0))
    assert np.array_equal(sim.observe(), img)
