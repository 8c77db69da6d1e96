"""pymunk world of a house and the differential-drive robot in it.

The state advances by `advance(world, v, w, duration, dt)`: a function of the world and the command only,
so the Simulator class stays a thin stateful wrapper. The robot is a dynamic disc whose velocity is set
at every substep from the (v, w) command in its own frame (a perfect velocity controller); pymunk's
contact solver then removes the part of the motion that would enter an obstacle, so the robot stops
against a wall it drives straight into and slides along one it meets at an angle. Friction is zero so
contacts never spin it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pymunk

from vtr.sim2d.config import Pose
from vtr.sim2d.house import House

# pymunk's default slop (0.1) is in world units, i.e. 10 cm here: far too much overlap for metres.
COLLISION_SLOP = 5e-4
# Fraction of an overlap left after one second; pymunk's default (0.0018) corrects only ~6% per 10 ms substep,
# which let a robot pushing into a wall sink ~6 mm; this corrects about half per 20 ms substep (~1 mm).
COLLISION_BIAS = 1e-16
ROBOT_MASS = 10.0  # kg; only matters against the (immovable) static obstacles
ROBOT, OBSTACLE = 1, 2  # pymunk collision types


@dataclass
class World:
    """One pymunk space with the house's static obstacles and the robot body."""

    space: pymunk.Space
    robot: pymunk.Body
    robot_shape: pymunk.Circle
    command: tuple[float, float] = (0.0, 0.0)  # (v, w) applied by the robot's velocity_func
    touched: bool = False  # set by the contact callback whenever the robot touches an obstacle


def build_world(house: House, pose: Pose, robot_radius: float) -> World:
    """A fresh space (never reuse one across resets: pymunk caches contact impulses)."""
    space = pymunk.Space()
    space.gravity = (0.0, 0.0)
    space.collision_slop = COLLISION_SLOP
    space.collision_bias = COLLISION_BIAS
    space.iterations = 10
    static = space.static_body
    shapes: list[pymunk.Shape] = []
    for box in house.wall_boxes:
        shapes.append(pymunk.Poly(static, [tuple(p) for p in box]))
    for f in house.furniture:
        if f.shape == "circle":
            shapes.append(pymunk.Circle(static, f.radius, offset=f.center))
        else:
            shapes.append(pymunk.Poly(static, [tuple(p) for p in f.vertices]))
    for s in shapes:
        s.friction = 0.0
        s.elasticity = 0.0
        s.collision_type = OBSTACLE
    space.add(*shapes)

    moment = pymunk.moment_for_circle(ROBOT_MASS, 0.0, robot_radius)
    body = pymunk.Body(ROBOT_MASS, moment)
    body.position = (pose.x, pose.y)
    body.angle = pose.yaw
    shape = pymunk.Circle(body, robot_radius)
    shape.friction = 0.0
    shape.elasticity = 0.0
    shape.collision_type = ROBOT
    space.add(body, shape)
    world = World(space, body, shape)

    def contact(arbiter: pymunk.Arbiter, space: pymunk.Space, data: object) -> None:
        world.touched = True

    # A callback only runs while a contact exists, so a free drive costs nothing (unlike polling arbiters).
    space.on_collision(ROBOT, OBSTACLE, pre_solve=contact)

    def drive(b: pymunk.Body, gravity: pymunk.Vec2d, damping: float, dt: float) -> None:
        v, w = world.command
        b.velocity = (v * math.cos(b.angle), v * math.sin(b.angle))
        b.angular_velocity = w

    body.velocity_func = drive
    return world


def advance(world: World, v: float, w: float, duration: float, dt: float) -> bool:
    """Drive with body-frame velocities (v, w) for `duration` seconds of simulated time.

    Runs ceil(duration / dt) equal substeps. Returns whether the robot touched an obstacle during any substep.
    Chipmunk integrates positions at the start of a step with the velocity its solver corrected at the end
    of the previous one, so the command is applied in the body's velocity_func (before the solver) rather
    than by overwriting the velocity between steps, which would discard the contact correction and let the
    robot sink into walls. Only the first substep moves with the raw command.
    """
    if duration <= 0:
        return False
    n = max(1, math.ceil(duration / dt - 1e-9))
    h = duration / n
    body = world.robot
    space = world.space
    world.command = (v, w)
    yaw = body.angle
    body.velocity = (v * math.cos(yaw), v * math.sin(yaw))
    body.angular_velocity = w
    world.touched = False
    for _ in range(n):
        space.step(h)
    body.velocity = (0.0, 0.0)
    body.angular_velocity = 0.0
    return world.touched


def pose_of(world: World) -> Pose:
    """Ground-truth pose; yaw wrapped to [-pi, pi) (the body's own angle keeps counting turns)."""
    x, y = world.robot.position
    yaw = (float(world.robot.angle) + math.pi) % (2.0 * math.pi) - math.pi
    return Pose(float(x), float(y), yaw)
