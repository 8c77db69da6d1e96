#!/usr/bin/env python3
"""A simulated differential-drive robot in a small two-room apartment, served over the vtr-sim protocol.

Written from docs/PROTOCOL.md alone (version 1, lockstep). The robot (radius 0.2 m) carries a 128x128
rgb8 camera (90 deg horizontal field of view, 0.3 m above the floor, looking ahead) rendered by a
vectorised ray caster: textured walls (bricks, wallpaper, tiles, paint with skirting boards, posters),
box furniture, a plank / tile floor and a ceiling. Time only advances inside `step`; a collision stops
the robot at contact and is reported with `collided: true`. Run it, then check it:
    python examples/apartment_robot_server.py --bind tcp://127.0.0.1:5555 [--noise 0.05]
    vtr check-robot tcp://127.0.0.1:5555
--noise X: imperfect motors. Per reset (seeded by the reset's `seed`, 0 when absent) a speed scale and a
turn-rate scale 1 + X*N(0,1) and a curvature drift 0.5*X*N(0,1) rad/m; per step a proportional jitter
1 + X*N(0,1) and an additive jitter 0.1*limit*X*N(0,1) on each non-zero command component.
"""

import argparse
import json
import math
import secrets

import numpy as np
import zmq

# Apartment geometry (metres; world frame x east, y north, yaw counter-clockwise from +x). Walls 2.5 m.
#   Living room  x 0..5, y 0..4   wooden plank floor. Walls: south bricks, west striped wallpaper,
#                                 north cream paint with a landscape poster (x 1.2..2.2),
#                                 east green paint with skirting board.
#   Kitchen      x 5..8, y 0..3   tiled floor. Walls: south tiled up to 1.4 m, east blue wallpaper,
#                                 north yellow paint with a target poster (x 6.0..6.8).
#   Doorway      open gap in the wall x = 5 for y 1.5..2.5 (1 m wide, full height).
#   Furniture (solid boxes, drawn full height from the floor):
#     sofa            x 0.6..2.4,   y 3.1..3.9,  0.8 m high
#     bookshelf       x 0.05..0.4,  y 0.6..1.8,  1.8 m high
#     coffee table    centre (2.0, 2.2), 1.0 m x 0.6 m, rotated 0.5 rad, 0.45 m high
#                     (inside x 1.42..2.58, y 1.72..2.68)
#     kitchen counter x 7.35..7.95, y 0.05..2.2, 0.9 m high
#   Default start pose (1.0, 1.0, yaw 0): facing east, 3.8 m of free floor ahead.
W = H = 128
FOV_DEG, CAM_H, WALL_H, RADIUS = 90.0, 0.3, 2.5, 0.2
V_MAX, W_MAX, MAX_DUR, DT = 0.5, 1.0, 10.0, 0.02
FOC = (W / 2) / math.tan(math.radians(FOV_DEG) / 2)
ROOMS = [(0.0, 0.0, 5.0, 4.0), (5.0, 0.0, 8.0, 3.0)]
START = (1.0, 1.0, 0.0)
MAX_MSG, MAX_HDR = 4 * 1024 * 1024, 65536
COMMANDS = ("hello", "reset", "observe", "step", "stop")
# walls: (ax, ay, bx, by, texture, base colour); the room is on the left of a -> b
WALLS = [(0, 0, 5, 0, "bricks", (150, 70, 50)), (5, 0, 5, 1.5, "paint", (110, 150, 110))]
WALLS += [(5, 2.5, 5, 4, "paint", (110, 150, 110)), (5, 4, 0, 4, "poster1", (215, 200, 165))]
WALLS += [(0, 4, 0, 0, "stripes1", (190, 170, 120)), (5, 0, 8, 0, "tiles", (225, 215, 190))]
WALLS += [(8, 0, 8, 3, "stripes2", (120, 140, 190)), (8, 3, 5, 3, "poster2", (225, 205, 110))]
WALLS += [(5, 3, 5, 2.5, "paint", (225, 205, 110)), (5, 1.5, 5, 0, "paint", (225, 205, 110))]
# furniture: (texture, (centre x, centre y, length, depth, yaw), height)
FURNITURE = [("sofa", (1.5, 3.5, 1.8, 0.8, 0.0), 0.8), ("shelf", (0.225, 1.2, 0.35, 1.2, 0.0), 1.8)]
FURNITURE += [("table", (2.0, 2.2, 1.0, 0.6, 0.5), 0.45), ("counter", (7.65, 1.125, 0.6, 2.15, 0.0), 0.9)]
STRIPES = {  # wallpaper: stripe edges (m, one period) and colours
    "stripes1": ([0.05, 0.17, 0.2, 0.45, 0.5, 0.62], [(190, 170, 120), (120, 40, 50), (235, 225, 200)] * 2),
    "stripes2": ([0.03, 0.06, 0.25, 0.28], [(120, 140, 190), (240,) * 3, (40, 60, 120), (240,) * 3]),
}
BOOKS = np.array([(160, 30, 30), (30, 90, 150), (220, 180, 40), (40, 120, 60), (230, 230, 220), (90, 40, 99)])
HEAD = {"proto": "vtr-sim", "version": 1}
SQUARE = ((-1, -1), (1, -1), (1, 1), (-1, 1))
WA, WB = np.array([w[:2] for w in WALLS], float), np.array([w[2:4] for w in WALLS], float)
W_TEX, W_BASE = [w[4] for w in WALLS], np.array([w[5] for w in WALLS], float)
BOXES = []  # corners of each piece of furniture, counter-clockwise
for _, (cx, cy, lx, ly, yaw), _ in FURNITURE:
    c, s = math.cos(yaw) / 2, math.sin(yaw) / 2
    BOXES.append(np.array([(cx + c * a * lx - s * b * ly, cy + s * a * lx + c * b * ly) for a, b in SQUARE]))
FA = np.vstack(BOXES)
FB = np.vstack([np.roll(b, -1, axis=0) for b in BOXES])
ALL_A, ALL_E = np.vstack([WA, FA]), np.vstack([WB, FB]) - np.vstack([WA, FA])
COLS = (np.arange(W) + 0.5 - W / 2) / FOC  # lateral offset of each column's ray (forward = 1)
AR = np.arange(W)
ROWS = (H / 2 - np.arange(H) - 0.5) / FOC  # elevation slope of each row (> 0 above the horizon)


def free(x, y):
    """True when a disc of RADIUS at (x, y) lies in the apartment and touches no wall or furniture."""
    if not any(x0 <= x <= x1 and y0 <= y <= y1 for x0, y0, x1, y1 in ROOMS):
        return False
    d = np.array([x, y]) - ALL_A
    t = np.clip((d * ALL_E).sum(1) / (ALL_E**2).sum(1), 0.0, 1.0)
    if np.min(np.hypot(*(d - t[:, None] * ALL_E).T)) < RADIUS:
        return False
    for b in BOXES:  # centre inside a box (only reachable by a reset)
        e, q = np.roll(b, -1, axis=0) - b, np.array([x, y]) - b
        if np.all(e[:, 0] * q[:, 1] - e[:, 1] * q[:, 0] >= 0):
            return False
    return True


def hsh(a, b=0):
    h = (np.asarray(a, np.int64) * 374761393 + np.asarray(b, np.int64) * 668265263) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    return ((h ^ (h >> 16)) & 0xFFFF) / 65535.0


def pick(cond, a, b):
    return np.where(cond[:, None], np.asarray(a, float), np.asarray(b, float))


def paint(u, z, base):
    return pick(z < 0.12, base * 0.45, base * (0.92 + 0.08 * z / WALL_H)[:, None])


def wall_texture(name, u, z, base):
    """Colours (N, 3) of wall points at u metres along the wall and z metres above the floor."""
    if name == "bricks":
        row = np.floor(z / 0.08)
        uu = u + 0.13 * (row % 2)
        col = np.floor(uu / 0.26)
        mortar = (uu / 0.26 - col < 0.05) | (z / 0.08 - row < 0.14)
        return pick(mortar, (195, 190, 180), base * (0.75 + 0.45 * hsh(col, row))[:, None])
    if name in STRIPES:
        edges, pal = STRIPES[name]
        k = np.searchsorted(edges, (u % edges[-1]), side="right") % len(pal)
        c = np.asarray(pal, float)[k] * (0.9 + 0.1 * np.cos(z * 40))[:, None] ** 2
        return pick(z < 0.1, (90, 60, 40), pick(z > 2.35, base, c))
    if name == "tiles":
        iu, iz = np.floor(u / 0.15), np.floor(z / 0.15)
        grout = (u / 0.15 - iu < 0.06) | (z / 0.15 - iz < 0.06)
        t = pick((iu + iz) % 2 == 0, (240, 240, 235), (200, 225, 235))
        t = pick(hsh(iu, iz) > 0.85, (70, 130, 170), t)
        return pick(z > 1.4, paint(u, z, base), pick(grout, (150, 150, 145), t))
    if name not in ("poster1", "poster2"):
        return paint(u, z, base)
    u0, z0, pw, ph = (2.8, 0.8, 1.0, 0.75) if name == "poster1" else (1.2, 0.9, 0.8, 0.8)
    pu, pz = (u - u0) / pw, (z - z0) / ph
    if name == "poster1":  # a landscape: sky, sun, hills, lake
        c = np.stack([120 + 60 * pz, 160 + 50 * pz, 235 + 0 * pz], 1)
        c = pick((pu - 0.72) ** 2 + (pz - 0.75) ** 2 < 0.012, (250, 215, 60), c)
        c = pick(pz < 0.6 - 0.9 * np.abs(pu - 0.35), (70, 120, 60), c)
        c = pick(pz < 0.45 - 0.7 * np.abs(pu - 0.8), (40, 90, 50), c)
        c = pick(pz < 0.18, (40, 80, 160), c)
    else:  # a target of red, white and blue rings
        band = (np.floor(np.hypot(pu - 0.5, (pz - 0.5) * 0.8) * 14) % 3).astype(int)
        c = np.array([(200, 40, 40), (245, 245, 240), (30, 60, 150)], float)[band]
    inside = (pu >= 0) & (pu <= 1) & (pz >= 0) & (pz <= 1)
    frame = (pu < 0.05) | (pu > 0.95) | (pz < 0.05) | (pz > 0.95)
    return pick(inside, pick(frame, (30, 30, 30), c), paint(u, z, base))


def box_texture(name, u, z, length):
    """Colours (N, 3) of furniture points (u along the face of the given length, z above the floor)."""
    if name == "shelf":  # wooden frame, shelves every 0.45 m, books of random height and colour
        lvl, zz, book = np.floor(z / 0.45), z % 0.45, np.floor(u / 0.045)
        books = zz - 0.03 < 0.22 + 0.17 * hsh(book, lvl)
        c = pick(books, BOOKS[(hsh(lvl, book) * 5.99).astype(int)], (55, 38, 25))
        return pick((zz < 0.03) | (u < 0.03) | (u > length - 0.03), (125, 85, 50), c)
    if name == "sofa":  # red fabric, seat seam, cushions, armrests
        c = np.array([150.0, 40, 45]) * (0.9 + 0.1 * hsh(np.floor(u * 60), np.floor(z * 60)))[:, None]
        seam = (np.abs(z - 0.44) < 0.02) | ((length > 1) & (np.abs((u / length * 3 + 0.5) % 1 - 0.5) < 0.012))
        return pick(seam | (z < 0.05), (80, 20, 25), pick((u < 0.18) | (u > length - 0.18), (125, 32, 38), c))
    if name == "table":  # wooden top, legs at the corners, dark underneath
        wood = np.array([150.0, 100, 60]) * (0.9 + 0.1 * np.sin(u * 45 + 3 * z))[:, None]
        return pick(z > 0.38, (105, 70, 40), pick((u < 0.06) | (u > length - 0.06), wood, (35, 28, 22)))
    door = u / 0.5 % 1  # kitchen counter: white cabinet doors with handles, dark worktop and kickboard
    c = pick((door < 0.02) | (np.abs(z - 0.45) < 0.008), (120, 120, 120), (235, 235, 228))
    c = pick((np.abs(door - 0.5) < 0.08) & (np.abs(z - 0.72) < 0.015), (60, 60, 60), c)
    return pick(z > 0.86, (60, 60, 66), pick(z < 0.08, (40, 40, 40), c))


def ray_hits(p, r, a, b):
    """Distances t (forward units) and segment parameters s of rays p + t r against segments a -> b."""
    e, ap = b - a, a - p
    den = r[:, None, 0] * e[None, :, 1] - r[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ap[:, 0] * e[:, 1] - ap[:, 1] * e[:, 0])[None, :] / den
        s = (ap[None, :, 0] * r[:, None, 1] - ap[None, :, 1] * r[:, None, 0]) / den
    return np.where((t > 1e-6) & (s >= 0) & (s <= 1), t, np.inf), s


def lambert(e, r):
    n = np.stack([e[..., 1], -e[..., 0]], -1) / np.linalg.norm(e, axis=-1, keepdims=True)
    return 0.65 + 0.35 * np.abs((n * r).sum(-1)) / np.linalg.norm(r, axis=-1)


def render(x, y, yaw):
    """The camera image (H, W, 3) uint8 seen from the robot pose."""
    p, c, s = np.array([x, y]), math.cos(yaw), math.sin(yaw)
    r = np.array([c, s])[None, :] + COLS[:, None] * np.array([s, -c])[None, :]
    fog = lambda d: np.clip(1.15 / (1 + 0.13 * d), 0.3, 1.0)  # noqa: E731
    img = np.empty((H, W, 3))
    lo, hi = ROWS < 0, ROWS > 0
    d = CAM_H / -ROWS[lo][:, None]  # floor: distance of each pixel's ground point
    fx, fy = x + d * r[None, :, 0], y + d * r[None, :, 1]
    row = np.floor(fy / 0.16)
    xo = fx + 1.3 * hsh(row)
    col = np.floor(xo / 1.3)
    grain = (0.8 + 0.3 * hsh(row, col)) * (0.94 + 0.06 * np.sin(xo * 23 + 9 * hsh(col, row)))
    wood = np.array([165.0, 112, 68]) * grain[..., None]
    wood[(fy / 0.16 - row < 0.07) | (xo / 1.3 - col < 0.012)] = (85, 58, 36)
    ix, iy = np.floor(fx / 0.3), np.floor(fy / 0.3)
    tile = np.where(((ix + iy) % 2 == 0)[..., None], (215, 208, 190), (150, 140, 128)).astype(float)
    tile[(fx / 0.3 - ix < 0.04) | (fy / 0.3 - iy < 0.04)] = (105, 105, 100)
    img[lo] = np.where((fx < 5)[..., None], wood, tile) * fog(d)[..., None]
    d = (WALL_H - CAM_H) / ROWS[hi][:, None] + 0 * COLS[None, :]
    img[hi] = np.array([238.0, 236, 230]) * fog(d)[..., None]
    # walls: only the side facing the camera's room is drawn
    t, sw = ray_hits(p, r, WA, WB)
    e = WB - WA
    t[:, (e[:, 0] * (y - WA[:, 1]) - e[:, 1] * (x - WA[:, 0])) <= 0] = np.inf
    k = np.argmin(t, axis=1)
    tw = t[AR, k]
    u = np.broadcast_to(sw[AR, k] * np.linalg.norm(e[k], axis=1), (H, W))
    z = CAM_H + ROWS[:, None] * tw[None, :]
    shade = fog(tw) * lambert(e[k], r)
    for i, name in enumerate(W_TEX):
        m = (k == i)[None, :] & (z >= 0) & (z <= WALL_H)
        if m.any():
            img[m] = wall_texture(name, u[m], z[m], W_BASE[i]) * np.broadcast_to(shade, (H, W))[m][:, None]
    depth = np.broadcast_to(tw, (H, W)).copy()  # furniture: z-buffered per pixel
    tf, sf = ray_hits(p, r, FA, FB)
    ef = FB - FA
    for j, (name, _, h) in enumerate(FURNITURE):
        f = 4 * j + np.argmin(tf[:, 4 * j : 4 * j + 4], axis=1)
        tj = tf[AR, f]
        z = CAM_H + ROWS[:, None] * tj[None, :]
        m = (z >= 0) & (z <= h) & (tj[None, :] < depth)
        if m.any():
            flen = np.broadcast_to(np.linalg.norm(ef[f], axis=1), (H, W))[m]
            uf = np.broadcast_to(sf[AR, f], (H, W))[m] * flen
            sh = np.broadcast_to(fog(tj) * lambert(ef[f], r), (H, W))[m]
            img[m] = box_texture(name, uf, z[m], flen) * sh[:, None]
            depth[m] = np.broadcast_to(tj, (H, W))[m]
    return np.clip(img, 0, 255).astype(np.uint8)


def arc(x, y, th, v, w, h):
    if abs(w) < 1e-9:
        return x + v * h * math.cos(th), y + v * h * math.sin(th), th
    a = th + w * h
    return x + v / w * (math.sin(a) - math.sin(th)), y - v / w * (math.cos(a) - math.cos(th)), a


class Robot:
    """The simulated robot: pose, lockstep clock and imperfect motors."""

    def reset(self, pose, seed):
        (self.x, self.y, self.yaw), self.clock = pose, 0.0
        self.rng = np.random.default_rng(seed)
        g = self.rng.standard_normal(3)
        self.k_v, self.k_w, self.drift = 1 + self.noise * g[0], 1 + self.noise * g[1], 0.5 * self.noise * g[2]

    def step(self, v, w, duration):
        n, g = self.noise, self.rng.standard_normal(4)
        ve = v * self.k_v * (1 + n * g[0]) + (0.1 * V_MAX * n * g[1] if v else 0.0)
        we = w * self.k_w * (1 + n * g[2]) + (0.1 * W_MAX * n * g[3] if w else 0.0) + self.drift * ve
        left, collided = duration, False
        while left > 1e-12 and not collided:
            h, left = min(DT, left), left - DT
            nxt = arc(self.x, self.y, self.yaw, ve, we, h)
            if not free(nxt[0], nxt[1]):  # find the contact point by bisection and stop there
                a, b = 0.0, 1.0
                for _ in range(12):
                    mid = (a + b) / 2
                    a, b = (mid, b) if free(*arc(self.x, self.y, self.yaw, ve, we, mid * h)[:2]) else (a, mid)
                nxt, collided = arc(self.x, self.y, self.yaw, ve, we, a * h), True
            self.x, self.y, self.yaw = nxt
        self.yaw = (self.yaw + math.pi) % (2 * math.pi) - math.pi
        self.clock += duration  # the clock runs the whole duration, even when the robot was stopped
        return collided


class Refused(Exception):
    """A request that breaks the contract, answered with an error reply; args: (message, code)."""


def need(ok, message, code="bad_request"):
    if not ok:
        raise Refused(message, code)


def check_values(o, depth=1):
    """The header rules on every value: nesting, integer and number ranges, UTF-8 strings."""
    if isinstance(o, (dict, list)):
        need(depth <= 16, "JSON nesting deeper than 16 levels")
        for v in o.values() if isinstance(o, dict) else o:
            check_values(v, depth + 1)
    elif isinstance(o, str):
        need(not any(0xD800 <= ord(ch) <= 0xDFFF for ch in o), "a string is not valid UTF-8")
    elif type(o) is int:
        need(abs(o) <= 2**53, f"integer {o} is out of range (|n| <= 2^53)")
    elif isinstance(o, float):
        need(math.isfinite(o) and abs(o) <= 1e15, f"number {o} is out of range (finite, |x| <= 1e15)")


def number(hdr, key):
    need(type(hdr.get(key)) in (int, float), f"'{key}' must be a number, got {hdr.get(key)!r}")
    return float(hdr[key])


class Server(Robot):
    """The protocol side: validates requests, drives the robot, builds replies."""

    def __init__(self, noise):
        self.noise, self.session = noise, secrets.token_hex(6)
        self.reset(START, 0)

    def reply(self, cmd, seq, **fields):
        return dict(HEAD, cmd=cmd, seq=seq, ok=True, session=self.session, stamp=self.clock, **fields)

    def image(self, cmd, seq, collided=False):
        pose = {"x": self.x, "y": self.y, "yaw": self.yaw}
        hdr = self.reply(cmd, seq, encoding="rgb8", height=H, width=W, pose=pose, collided=collided)
        return [json.dumps(hdr).encode(), render(self.x, self.y, self.yaw).tobytes()]

    def handle(self, frames):
        cmd = seq = None
        try:
            need(sum(len(f) for f in frames) <= MAX_MSG, f"message larger than {MAX_MSG} bytes")
            need(len(frames[0]) <= MAX_HDR, f"header larger than {MAX_HDR} bytes")
            try:
                hdr = json.loads(frames[0].decode("utf-8"), parse_constant=float)  # NaN: refused below
            except (UnicodeDecodeError, ValueError, RecursionError) as exc:
                raise Refused(f"malformed JSON header: {exc}", "bad_request") from None
            need(isinstance(hdr, dict), "the header must be a JSON object")
            cmd = hdr.get("cmd") if hdr.get("cmd") in COMMANDS else None  # an unknown cmd is echoed as null
            seq = hdr.get("seq") if type(hdr.get("seq")) is int and 0 <= hdr["seq"] <= 2**53 else None
            check_values(hdr)
            need(len(frames) == 1, f"a request is one frame, got {len(frames)}")
            need(hdr.get("proto") == "vtr-sim", f"proto must be 'vtr-sim', got {hdr.get('proto')!r}")
            version = hdr.get("version")
            need(type(version) is int and version == 1, f"version {version!r} unsupported: I speak 1")
            need(cmd is not None, f"unknown cmd {hdr.get('cmd')!r}: expected one of {', '.join(COMMANDS)}")
            need(seq is not None, f"seq must be an integer >= 0, got {hdr.get('seq')!r}")
            if "stamp" in hdr:
                number(hdr, "stamp")
            sess = hdr.get("session")
            need(sess is None or (isinstance(sess, str) and 0 < len(sess) <= 64), "session: 1 to 64 chars")
            mine = sess is None or sess == self.session or cmd not in ("reset", "step")
            need(mine, f"session {sess!r} is not this server's {self.session!r}", "session_mismatch")
            return self.dispatch(cmd, seq, hdr)
        except Exception as exc:  # Refused: the request's fault; anything else: the robot's. Keep serving.
            msg, code = exc.args if isinstance(exc, Refused) else (repr(exc), "robot_error")
            err = {**self.reply(cmd, seq), "ok": False, "error": msg, "code": code}
            return [json.dumps(err).encode()]

    def dispatch(self, cmd, seq, hdr):
        if cmd == "hello":
            camera = {"width": W, "height": H, "fov_deg": FOV_DEG, "height_m": CAM_H}
            limits = {"v_max": V_MAX, "w_max": W_MAX, "max_duration": MAX_DUR}
            info = {"noise": self.noise, "radius_m": RADIUS, "rooms": ROOMS, "start_pose": START}
            names = {"protocol_version": 1, "robot": "apartment-diffdrive", "map": "apartment"}
            clock = {"dt": DT, "mode": "lockstep", "cmd_vel_timeout": 0.0, "realtime_factor": 1.0}
            hdr = self.reply(cmd, seq, **names, camera=camera, limits=limits, **clock, info=info)
            return [json.dumps(hdr).encode()]
        if cmd == "observe":
            return self.image(cmd, seq)
        if cmd == "stop":  # lockstep: the robot never moves between steps
            return [json.dumps(self.reply(cmd, seq)).encode()]
        if cmd == "reset":
            pose, seed = hdr.get("pose"), 0 if hdr.get("seed") is None else hdr["seed"]
            need(type(seed) is int and seed >= 0, f"seed must be an integer >= 0, got {seed!r}")
            if pose is None:
                pose = START
            else:
                need(isinstance(pose, dict), "pose must be an object {x, y, yaw}")
                pose = (number(pose, "x"), number(pose, "y"), number(pose, "yaw"))
                need(free(pose[0], pose[1]), f"pose {pose[:2]} is not free (walls, furniture, radius)")
                pose = (pose[0], pose[1], (pose[2] + math.pi) % (2 * math.pi) - math.pi)
            self.reset(pose, seed)
            return self.image(cmd, seq)
        v, w, dur = number(hdr, "v"), number(hdr, "w"), number(hdr, "duration")
        need(abs(v) <= V_MAX, f"v={v} m/s is out of range: |v| must be <= v_max={V_MAX} m/s")
        need(abs(w) <= W_MAX, f"w={w} rad/s is out of range: |w| must be <= w_max={W_MAX} rad/s")
        need(0 < dur <= MAX_DUR, f"duration={dur} s is out of range: it must be in (0, {MAX_DUR}] s")
        return self.image(cmd, seq, collided=self.step(v, w, dur))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bind", default="tcp://127.0.0.1:5555", help="ZeroMQ endpoint to bind (REP socket)")
    ap.add_argument("--noise", type=float, default=0.0, help="motor noise level X (0: perfect motors)")
    args = ap.parse_args()
    server = Server(args.noise)
    sock = zmq.Context().socket(zmq.REP)
    sock.setsockopt(zmq.MAXMSGSIZE, MAX_MSG)  # a peer sending a larger frame is disconnected
    try:
        sock.bind(args.bind)
    except zmq.ZMQError as exc:  # a port in use, an address not of this machine: one line, exit 2
        ap.exit(2, f"apartment_robot_server.py: cannot bind --bind {args.bind}: {zmq.strerror(exc.errno)}\n")
    print(f"apartment robot: session {server.session} on {args.bind}, noise {args.noise}", flush=True)
    try:
        while True:
            sock.send_multipart(server.handle(sock.recv_multipart()))
    except KeyboardInterrupt:
        sock.close(linger=0)


if __name__ == "__main__":
    main()
