"""Sensor realism (sim2d.sensor): each operation does what it says, deterministically per seed."""

from __future__ import annotations

import numpy as np
import pytest

from vtr.sim2d import SimConfig, Simulator
from vtr.sim2d.sensor import (
    Sensor,
    SensorConfig,
    add_noise,
    describe,
    jpeg,
    motion_blur,
    parse_sensor,
    radial_distortion,
)


def _stripes(h: int = 32, w: int = 48) -> np.ndarray:
    img = np.zeros((h, w, 3), np.uint8)
    img[:, ::4] = 255  # vertical lines every 4 px
    return img


def test_motion_blur_smears_along_the_motion_only():
    img = _stripes()
    turned = motion_blur(img, 4.0, 0.0).astype(float)
    assert turned[:, 8:40].std(axis=1).mean() < 0.5 * img[:, 8:40].astype(float).std(axis=1).mean()
    assert np.allclose(turned[0], turned[-1])  # a sideways slide: rows stay alike
    assert motion_blur(img, 0.01, 0.0) is img  # under a tenth of a pixel: untouched


def test_barrel_distortion_keeps_corners_and_magnifies_the_centre():
    img = np.zeros((65, 65, 3), np.uint8)
    img[32, :] = 255  # a horizontal line through the centre stays straight
    assert radial_distortion(img, -0.2)[32, 5:60].min() > 200
    img = np.zeros((65, 65, 3), np.uint8)
    img[:, 48] = 255  # a vertical line right of the centre bows outwards, most in its middle
    out = radial_distortion(img, -0.2)
    cols = [int(np.argmax(out[r, :, 0])) for r in (2, 32, 62)]
    assert cols[1] > cols[0] and cols[1] > cols[2] and cols[1] > 48  # the centre magnified: barrel
    corner = np.zeros((65, 65, 3), np.uint8)
    corner[0, 0] = 255
    assert radial_distortion(corner, -0.2)[0, 0, 0] == 255  # corners stay put


def test_noise_and_jpeg_change_the_image_by_their_amount():
    img = np.full((32, 32, 3), 128, np.uint8)
    noisy = add_noise(img, 6.0, np.random.default_rng(0)).astype(float)
    assert 5.0 < (noisy - 128).std() < 7.0
    grad = np.tile(np.linspace(0, 255, 64, dtype=np.uint8)[None, :, None], (64, 1, 3))
    grad[::8] = 0
    q30 = np.abs(jpeg(grad, 30).astype(float) - grad).mean()
    q95 = np.abs(jpeg(grad, 95).astype(float) - grad).mean()
    assert q30 > q95 > 0


def test_sensor_is_deterministic_per_seed_and_drifts_over_time():
    cfg = SensorConfig(
        exposure_s=0.04, noise=4.0, flicker=0.15, gain_drift=0.1, white_balance_drift=0.05, k1=-0.1
    )
    img = np.full((24, 24, 3), 120, np.uint8)
    runs = []
    for seed in (1, 1, 2):
        s = Sensor(cfg, focal_px=12.0, seed=seed)
        runs.append([s.apply(img, 0.3, 0.5, 0.1 * k) for k in range(20)])
    assert all(np.array_equal(a, b) for a, b in zip(runs[0], runs[1], strict=True))
    assert not np.array_equal(runs[0][5], runs[2][5])
    means = [float(f.mean()) for f in runs[0]]
    assert max(means) - min(means) > 5  # the exposure flickers and drifts


def test_simulator_applies_the_sensor_and_reset_reseeds_it():
    cfg = SimConfig(sensor=SensorConfig(noise=5.0, exposure_s=0.05))
    sim = Simulator(cfg)
    sim.reset(seed=3)
    a = sim.step(0.3, 0.8, 0.1)
    sim.reset(seed=3)
    assert np.array_equal(a, sim.step(0.3, 0.8, 0.1))
    clean = Simulator(SimConfig())
    clean.reset(seed=3)
    assert np.abs(a.astype(float) - clean.step(0.3, 0.8, 0.1)).mean() > 2
    assert sim.info()["sensor"] == "blur=0.05,noise=5"


def test_sensor_specs_parse_and_bad_ones_are_one_line():
    cfg = parse_sensor("blur=0.04, noise=6,jpeg=30,k1=-0.2")
    assert cfg == SensorConfig(exposure_s=0.04, noise=6.0, jpeg_quality=30, k1=-0.2)
    assert parse_sensor(describe(cfg)) == cfg
    for bad, match in [
        ("blur", "NAME=VALUE"),
        ("noise=abc", "not a number"),
        ("k1=-2", r"k1 must be"),
        ("jpeg=101", "0..100"),
    ]:
        with pytest.raises(ValueError, match=match) as err:
            parse_sensor(bad)
        assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="SimConfig.sensor"):
        SimConfig(sensor="noise=3")  # type: ignore[arg-type]
