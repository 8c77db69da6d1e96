"""Sensor conditions: the robot's camera gives what a real sensor gives (sim2d.sensor), at teach and at repeat
alike (the same lens and sensor; the noise, flicker and blur differ frame by frame). Each is a ``SensorConfig``
the simulator applies to every frame, registered as a condition of the condition suite
(``vtr eval --suite conditions --conditions sensor_blur ...``).

The levels are those of the project's target (issue 20): motion blur of a 1/25 s exposure, noise of 6 levels
(a small sensor in a dim room), the exposure flickering by +-15% with slow drifts of gain and white balance,
JPEG at quality 30, barrel distortion k1 = -0.2; and all of them at once.
"""

from __future__ import annotations

from vtr.sim2d.sensor import SensorConfig

SENSORS: dict[str, SensorConfig] = {
    "sensor_blur": SensorConfig(exposure_s=0.04),
    "sensor_noise": SensorConfig(noise=6.0),
    "sensor_flicker": SensorConfig(flicker=0.15, gain_drift=0.1, white_balance_drift=0.05),
    "sensor_jpeg_30": SensorConfig(jpeg_quality=30),
    "sensor_k1_-0.2": SensorConfig(k1=-0.2),
    "sensor_all": SensorConfig(
        exposure_s=0.04,
        noise=6.0,
        flicker=0.15,
        gain_drift=0.1,
        white_balance_drift=0.05,
        jpeg_quality=30,
        k1=-0.2,
    ),
}
