"""One repeat run for the evaluation: the runtime's Repeater (closed loop) or the taught commands replayed
blind (open loop), on an in-process simulator; the true poses are kept for scoring only."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from vtr.evaluation import metrics
from vtr.runtime.contracts import Policy
from vtr.runtime.controller import Action

if TYPE_CHECKING:
    from vtr.evaluation.harness import EvalConfig
    from vtr.runtime.controller import ControllerConfig
    from vtr.runtime.follower import RouteController
    from vtr.runtime.route import Route
    from vtr.runtime.route_script import RouteScript
    from vtr.sim2d.local_robot import LocalRobot


@dataclass
class RunLog:
    """What one repeat run did: poses for scoring, commands, and how far it got."""

    poses: list[tuple[float, float, float]] = field(default_factory=list)
    commands: list[tuple[float, float]] = field(default_factory=list)
    switch_poses: dict[int, tuple[float, float, float]] = field(
        default_factory=dict
    )  # subgoal -> pose at switch
    subgoals_reached: int = 0
    steps: int = 0
    sim_time: float = 0.0
    collisions: int = 0
    outcome: str = ""
    detail: str = ""  # how the repeat ended, in words (Summary.detail)
    policy_ms: list[float] = field(default_factory=list)
    #: each commanded step's compute (the Repeater's judgement, policy and limits; the link apart), ms
    compute_ms: list[float] = field(default_factory=list)
    e_m: float | None = None
    waited_steps: int = 0  # zero steps held while something was in the way (Summary.waited_steps)


class PoseOracle:
    """Diagnostic upper bound, not a visual method: steers to the subgoal's taught pose using true poses.

    It runs inside the same Repeater and controller as VelocityNet, so the subgoal switching (e_m on
    images) is identical; its errors are the floor that switching rule leaves, and VelocityNet's distance
    above it is what the network costs. ``bind`` hands it the robot (true poses) and the controller (the
    subgoal index it steers to).
    """

    def __init__(
        self, v_max: float, w_max: float, horizon: int, dt: float, image_shape: tuple[int, int]
    ) -> None:
        self.v_max, self.w_max, self.horizon, self.dt = v_max, w_max, horizon, dt
        self.image_shape = image_shape
        self.position_tolerance = 0.01  # m: closer than this, only the heading is corrected
        self.robot: LocalRobot | None = None
        self.controller: RouteController | None = None
        self.route: Route | None = None

    def bind(self, robot: LocalRobot, controller: RouteController, route: Route) -> None:
        self.robot, self.controller, self.route = robot, controller, route

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        assert self.robot is not None and self.controller is not None
        index = min(self.controller.index, len(self.route) - 1)
        gx, gy, gyaw = self.route.poses[index]
        x, y, yaw = self.robot.last.pose
        c, s = math.cos(yaw), math.sin(yaw)
        ex, ey = c * (gx - x) + s * (gy - y), -s * (gx - x) + c * (gy - y)  # goal in the robot frame
        eyaw = float(metrics.wrap_angle(gyaw - yaw))
        rho, alpha = math.hypot(ex, ey), math.atan2(ey, ex)
        # a differential drive cannot slide sideways: turn toward the goal point (backing up when it lies
        # behind), drive, and once there turn to the goal's heading; each gap closed in about two steps
        # where the controller allows no translation (a taught turn in place), only turn
        if rho > self.position_tolerance and not self.controller.holds_turn(index):
            backwards = abs(alpha) > math.pi / 2
            heading = float(metrics.wrap_angle(alpha - math.pi)) if backwards else alpha
            v = (-1.0 if backwards else 1.0) * rho * max(math.cos(heading), 0.0) / (2 * self.dt)
            w = heading / (2 * self.dt)
        else:
            v, w = 0.0, eyaw / (2 * self.dt)
        v, w = float(np.clip(v, -self.v_max, self.v_max)), float(np.clip(w, -self.w_max, self.w_max))
        return np.tile(np.array([[v], [w]], dtype=np.float32), (1, self.horizon))


def repeat_closed_loop(
    robot: LocalRobot,
    policy: Policy,
    route: Route,
    start: tuple[float, float, float],
    cfg: EvalConfig,
    seed: int,
    controller_cfg: ControllerConfig | None = None,
) -> RunLog:
    """The runtime's Repeater (Algorithm 1 + controller) on images; poses are kept for scoring only.

    ``controller_cfg`` (a ControllerConfig) overrides the one ``cfg`` implies (the condition suite's)."""
    from vtr.runtime.controller import ControllerConfig
    from vtr.runtime.follower import controller_for_route
    from vtr.runtime.repeater import RepeatConfig, Repeater, StepRecord

    log = RunLog()
    first = robot.reset(pose=start, seed=seed)
    log.poses.append(first.pose)
    ccfg = controller_cfg
    if ccfg is None:  # the harness's: the default, or the paper's rule at its fixed --e-m
        ccfg = (
            ControllerConfig()
            if cfg.e_m is None
            else ControllerConfig(switching="rules", e_m_mode="fixed", e_m=cfg.e_m)
        )
    rcfg = RepeatConfig(controller=ccfg, dt=cfg.dt, max_steps=int(cfg.max_steps_factor * len(route) + 50))
    controller = controller_for_route(route, ccfg)
    if isinstance(policy, PoseOracle):
        policy.bind(robot, controller, route)

    def on_step(record: StepRecord) -> None:
        # the subgoals reached on this image were reached at the pose it was taken from
        for event in record.events:
            if event.action is Action.ADVANCE:
                log.switch_poses.setdefault(event.index - 1, record.pose)
        if record.commanded:
            log.commands.append((record.v, record.w))
            log.policy_ms.append(record.latency_ms["policy"])
            log.compute_ms.append(record.latency_ms["compute"])
            log.poses.append(robot.last.pose)
            log.collisions += int(robot.last.collided)

    summary = Repeater(robot, policy, route, controller, config=rcfg, on_step=on_step).run()
    if summary.completed:
        for k in range(len(route)):
            log.switch_poses.setdefault(k, log.poses[-1])
    log.subgoals_reached = summary.subgoals_reached
    log.steps = summary.steps
    log.outcome = summary.status.value
    log.detail = summary.detail
    log.e_m = summary.e_m
    log.sim_time = float(summary.sim_time_s)
    log.waited_steps = summary.waited_steps
    return log


def repeat_open_loop(
    robot: LocalRobot, script: RouteScript, start: tuple[float, float, float], seed: int, dt: float
) -> RunLog:
    """Replay the taught commands blind (the script's segments, step by step as taught): no correction."""
    log = RunLog()
    obs = robot.reset(pose=start, seed=seed)
    log.poses.append(obs.pose)
    t0 = obs.stamp
    for segment in script.segments:
        for _ in range(max(1, round(segment.duration / dt))):
            obs = robot.step(segment.v, segment.w, dt)
            robot.stop()
            log.steps += 1
            log.collisions += int(obs.collided)
            log.poses.append(obs.pose)
            log.commands.append((segment.v, segment.w))
    log.outcome = "replayed"
    log.sim_time = float(obs.stamp - t0)
    return log
