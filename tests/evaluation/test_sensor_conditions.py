"""The sensor conditions are conditions of the suite, each a sensor the repeat's simulator applies."""

from __future__ import annotations

import numpy as np

from vtr.evaluation.condition_run import CONDITIONS
from vtr.evaluation.sensor_conditions import SENSORS
from vtr.sim2d import SimConfig, Simulator


def test_every_sensor_is_a_condition_and_changes_the_frames():
    assert {
        "sensor_blur",
        "sensor_noise",
        "sensor_flicker",
        "sensor_jpeg_30",
        "sensor_k1_-0.2",
        "sensor_all",
    } <= set(SENSORS)
    clean = Simulator(SimConfig())
    clean.reset(seed=0)
    ideal = clean.step(0.3, 0.6, 0.1).astype(float)
    for name, sensor in SENSORS.items():
        assert CONDITIONS[name].sensor == name and CONDITIONS[name].light is None
        sim = Simulator(SimConfig(sensor=sensor))
        sim.reset(seed=0)
        frames = [sim.step(0.3, 0.6, 0.1).astype(float) for _ in range(3)]
        assert np.abs(frames[0] - ideal).mean() > 0.5, name  # the sensor changed what the camera gives


def test_the_target_levels():
    assert SENSORS["sensor_jpeg_30"].jpeg_quality == 30 and SENSORS["sensor_k1_-0.2"].k1 == -0.2
    assert SENSORS["sensor_all"].active
