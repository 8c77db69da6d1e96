"""Top-down picture of the house with the robot and its field of view, beside its camera image (cv2)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from vtr.runtime.atomic import write_bytes_atomic
from vtr.sim2d.config import Pose
from vtr.sim2d.simulator import Simulator


def top_down(sim: Simulator, px_per_m: float = 60.0) -> np.ndarray:
    """(H, W, 3) uint8 RGB plan view: mosaic floor, walls, furniture, rooms, robot and its view."""
    import cv2

    house = sim.house
    x0, y0, x1, y1 = house.bounds
    margin = 0.3
    w = int(math.ceil((x1 - x0 + 2 * margin) * px_per_m))
    h = int(math.ceil((y1 - y0 + 2 * margin) * px_per_m))

    def to_px(pts: np.ndarray) -> np.ndarray:
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        u = (pts[:, 0] - x0 + margin) * px_per_m
        v = h - (pts[:, 1] - y0 + margin) * px_per_m  # image rows grow downwards, y grows upwards
        return np.round(np.stack([u, v], axis=1) * 16).astype(np.int32)  # 4 fractional bits for cv2

    img = np.full((h, w, 3), 255, np.uint8)
    # The floor mosaic, faded so that the geometry stands out.
    ox, oy = house.floor_origin
    ext = house.floor_extent
    floor = cv2.resize(
        house.floor_image, (int(ext * px_per_m), int(ext * px_per_m)), interpolation=cv2.INTER_AREA
    )
    floor = np.flipud(floor)
    fu = int(round((ox - x0 + margin) * px_per_m))
    fv = int(round(h - (oy - y0 + margin + ext) * px_per_m))
    src = floor[max(0, -fv) : max(0, -fv) + h, max(0, -fu) : max(0, -fu) + w]
    img[max(0, fv) : max(0, fv) + src.shape[0], max(0, fu) : max(0, fu) + src.shape[1]] = src[
        : h - max(0, fv), : w - max(0, fu)
    ]
    img = (0.45 * img + 0.55 * 255).astype(np.uint8)

    shift = {"shift": 4, "lineType": cv2.LINE_AA}
    pose = sim.pose
    rc = sim.camera.raycast(pose.x, pose.y, pose.yaw)
    depth = rc["depth"].min(axis=0)
    hits = np.stack([pose.x + depth * rc["dx"], pose.y + depth * rc["dy"]], axis=1)
    view = np.concatenate([[[pose.x, pose.y]], hits])
    overlay = img.copy()
    cv2.fillPoly(overlay, [to_px(view)], (255, 230, 120), **shift)
    img = cv2.addWeighted(overlay, 0.5, img, 0.5, 0)

    for box in house.wall_boxes:
        cv2.fillPoly(img, [to_px(box)], (70, 70, 80), **shift)
    for f in house.furniture:
        color = house.texture_images[house.texture_names.index(f.texture)].reshape(-1, 3).mean(axis=0)
        color = tuple(int(c) for c in color)
        if f.shape == "circle":
            c = to_px([f.center])[0]
            cv2.circle(img, tuple(int(v) for v in c), int(f.radius * px_per_m * 16), color, -1, **shift)
            cv2.circle(img, tuple(int(v) for v in c), int(f.radius * px_per_m * 16), (30, 30, 30), 1, **shift)
        else:
            cv2.fillPoly(img, [to_px(f.vertices)], color, **shift)
            cv2.polylines(img, [to_px(f.vertices)], True, (30, 30, 30), 1, **shift)
    for room in house.rooms:
        c = to_px([room.polygon.mean(axis=0)])[0] / 16
        cv2.putText(
            img,
            room.name,
            (int(c[0]) - 25, int(c[1])),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.5,
            (20, 20, 20),
            1,
            cv2.LINE_AA,
        )
    for p in (pose,):
        c = to_px([[p.x, p.y]])[0]
        r = int(sim.cfg.robot_radius * px_per_m * 16)
        cv2.circle(img, tuple(int(v) for v in c), r, (220, 40, 40), -1, **shift)
        tip = to_px(
            [
                [
                    p.x + 1.6 * sim.cfg.robot_radius * math.cos(p.yaw),
                    p.y + 1.6 * sim.cfg.robot_radius * math.sin(p.yaw),
                ]
            ]
        )[0]
        cv2.line(img, tuple(int(v) for v in c), tuple(int(v) for v in tip), (20, 20, 20), 2, **shift)
    return img


def snapshot_image(sim: Simulator, px_per_m: float = 60.0) -> np.ndarray:
    """The plan view and the camera image side by side, the camera image upscaled to the plan's height."""
    import cv2

    plan = top_down(sim, px_per_m)
    cam = sim.observe()
    size = plan.shape[0] - 40
    cam_big = cv2.resize(cam, (size * cam.shape[1] // cam.shape[0], size), interpolation=cv2.INTER_NEAREST)
    panel = np.full((plan.shape[0], cam_big.shape[1] + 40, 3), 255, np.uint8)
    panel[20 : 20 + cam_big.shape[0], 20 : 20 + cam_big.shape[1]] = cam_big
    p = sim.pose
    text = f"camera {cam.shape[1]}x{cam.shape[0]}  pose x={p.x:.2f} y={p.y:.2f} yaw={math.degrees(p.yaw):.0f} deg"
    cv2.putText(panel, text, (20, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    return np.concatenate([plan, panel], axis=1)


def write_png(path: str | os.PathLike[str], rgb: np.ndarray) -> Path:
    """Write an RGB image as PNG atomically (temporary file in the same folder, then os.replace)."""
    import cv2

    path = Path(path)
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:
        raise OSError(f"could not encode PNG for {path}")
    write_bytes_atomic(path, buf.tobytes())
    return path


def snapshot(sim: Simulator, out: str | os.PathLike[str], pose: Pose | None = None) -> Path:
    """Reset to `pose` (if given), write the snapshot PNG and return its path."""
    if pose is not None:
        sim.reset(pose)
    return write_png(out, snapshot_image(sim))
