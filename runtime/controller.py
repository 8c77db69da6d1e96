"""Subgoal switching as a pure state machine: an image in, a decision out. No I/O and no model inside.

The paper's Algorithm 1, exactly, when ``ControllerConfig(e_m_mode="fixed", e_m=17, stall_steps=0,
settle_steps=0, localise=False, continuous=False)`` (``ControllerConfig.paper()``)::

    while i < l:
        error = mean |I_t - I_i|                  (0..255, at the model's resolution)
        if error > e_m:  COMMAND                  the daemon runs VelocityNet(I_t, I_i), applies the first
                                                  (v, w) for dt = 0.1 s, then commands zero
        else:            ADVANCE                  i += 1, and the same image is judged against I_{i+1}
    FINISHED

Beyond the paper, each switchable in :class:`ControllerConfig`:

- **e_m calibrated from the route** (``e_m_mode="calibrated"``, the default). With d_k = mean |I_k -
  I_{k+1}| the image change between consecutive taught subgoals, ``e_m = clip(calib_fraction *
  quantile(d, calib_quantile), e_m_min, e_m_max)``. Rationale: a robot standing on subgoal k sees an error
  of about d_k to subgoal k+1; e_m must sit below it or subgoals are skipped without moving, and well
  above zero or the robot can never get close enough. Three quarters of the median spacing (the
  default) asks the robot to close at least a quarter of each gap. Measured with the shipped model on 5
  routes at noise 0.05: half the spacing stalled on 2 of them (1 degree of yaw already costs an error of
  about 10 on our textured walls), three quarters completed all 5 with position errors within 2 mm of it. ``e_m_mode="fixed"`` uses ``e_m`` (the paper's 17).
- **Stall guard** (``stall_steps`` > 0): if the error to the current subgoal has not dropped by
  ``stall_min_improvement`` below its best value for ``stall_steps`` consecutive commands, look at the
  next ``lookahead`` subgoals; JUMP to the best-matching one if its error is at most ``jump_factor * e_m``
  and lower than the current error; else, if the current error itself is at most ``jump_factor * e_m``,
  ADVANCE (the robot sits on a plateau next to the subgoal: a trained policy has a small dead zone near
  its goal, and the error is steep in yaw, so 1 degree short can sit just above e_m); else STALLED
  (terminal: the daemon stops the robot and says why).
- **Settling** (``settle_steps`` > 0, default 2): once the error is under e_m, keep steering to the same
  subgoal while the error still falls (by more than ``stall_min_improvement``), for at most
  ``settle_steps`` extra commands, then ADVANCE. The paper switches the moment the error crosses e_m, so
  the robot passes every subgoal on the near side of the threshold; settling lets it close the rest of the
  gap. Measured with the shipped model at noise 0.05: 0, 2 and 4 settle steps give translation mean errors
  of 12.0, 6.3 and 3.7 mm and translation + rotation 12.2, 4.7 and 3.1 mm, for 1, 1.8 and 2.5 times the
  control steps.
- **Start-anywhere localisation** (``localise=True``): on the first image, JUMP to the best-matching
  subgoal over the whole route if its error is at most ``localise_max_error`` (default ``3 * e_m``), else
  start at subgoal 0 as the paper does.
- **Continuous mode** (``continuous=True``): COMMAND decisions carry ``then_stop=False``, so the daemon
  does not send the zero command between steps and the robot keeps moving while the next command is
  computed (on a lockstep simulator no time passes between steps, so this changes only what is sent).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from vtr.runtime.preprocess import image_error


class Action(str, enum.Enum):
    COMMAND = "command"  # run the policy on (image, subgoal) and apply its first (v, w)
    ADVANCE = "advance"  # the subgoal was reached: move on to the next (same image, decide again)
    JUMP = "jump"  # stall guard or localisation moved the subgoal index (decide again)
    FINISHED = "finished"  # past the last subgoal
    STALLED = "stalled"  # stall guard found nothing close: stop


@dataclass(frozen=True)
class Decision:
    action: Action
    #: Subgoal index the decision is about (for COMMAND: the one to steer to; for ADVANCE/JUMP: the new one).
    index: int
    #: Mean abs pixel error (0..255) of the image to the subgoal it was judged against; NaN when finished.
    error: float
    #: COMMAND only: send a zero command after the control step (False in continuous mode).
    then_stop: bool = True
    note: str = ""


#: Decisions the controller takes without moving the robot: it acts on them itself and judges again.
SWITCHES = (Action.ADVANCE, Action.JUMP)


@dataclass(frozen=True)
class Verdict:
    """Everything the controller decided on one image (:meth:`Controller.judge`).

    ``decision`` is the one the repeat loop acts on: COMMAND, FINISHED or STALLED. ``events`` are the
    ADVANCE and JUMP decisions the controller took and acted on before it, in order (empty when the
    subgoal did not change); ``from_index`` is the subgoal index before this image was judged.
    """

    decision: Decision
    events: tuple[Decision, ...]
    from_index: int


@dataclass
class ControllerConfig:
    """Subgoal-switching settings (see the module docstring for each rule)."""

    #: "fixed" uses ``e_m``; "calibrated" derives e_m from the route's consecutive-subgoal errors.
    e_m_mode: str = "calibrated"
    #: Fixed switch threshold, mean abs pixel difference on 0..255 (the paper's 17).
    e_m: float = 17.0
    #: Quantile of the consecutive-subgoal errors used by calibration (0.5 = median).
    calib_quantile: float = 0.5
    #: Fraction of that quantile taken as e_m.
    calib_fraction: float = 0.75
    #: Lower bound on a calibrated e_m (below it sensor noise alone would stall the robot).
    e_m_min: float = 1.0
    #: Upper bound on a calibrated e_m.
    e_m_max: float = 64.0
    #: Commands without progress before the stall guard acts; 0 disables it (the paper has none).
    stall_steps: int = 10
    #: Progress means the error fell this much (0..255 scale) below its best at the current subgoal.
    stall_min_improvement: float = 0.25
    #: How many subgoals ahead the stall guard looks.
    lookahead: int = 5
    #: The stall guard jumps only to a subgoal whose error is at most jump_factor * e_m.
    jump_factor: float = 2.0
    #: Pick the starting subgoal by best match over the whole route (the paper starts at 0).
    localise: bool = False
    #: Localisation confidence floor: best-match error must be at most this; None means 3 * e_m.
    localise_max_error: float | None = None
    #: Keep moving between control steps instead of the paper's stop-and-go.
    continuous: bool = False
    #: Settling: once under e_m, keep steering to the same subgoal while the error still falls, for at
    #: most this many extra commands, then advance. 0 switches at once, as the paper does.
    settle_steps: int = 2

    @classmethod
    def paper(cls) -> ControllerConfig:
        """Algorithm 1 exactly: fixed e_m = 17, switch at once, no stall guard."""
        return cls(e_m_mode="fixed", e_m=17.0, stall_steps=0, settle_steps=0)

    def __post_init__(self) -> None:
        if self.e_m_mode not in ("fixed", "calibrated"):
            raise ValueError(f"e_m_mode must be 'fixed' or 'calibrated', got {self.e_m_mode!r}")
        positive = {
            "e_m": self.e_m,
            "calib_fraction": self.calib_fraction,
            "e_m_min": self.e_m_min,
            "jump_factor": self.jump_factor,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        if not 0.0 <= self.calib_quantile <= 1.0:
            raise ValueError(f"calib_quantile must be in [0, 1], got {self.calib_quantile}")
        if not self.e_m_max >= self.e_m_min:
            raise ValueError(f"e_m_max={self.e_m_max} must be >= e_m_min={self.e_m_min}")
        if self.stall_steps < 0:
            raise ValueError(f"stall_steps must be >= 0, got {self.stall_steps}")
        if self.settle_steps < 0:
            raise ValueError(f"settle_steps must be >= 0, got {self.settle_steps}")
        if self.stall_min_improvement < 0:
            raise ValueError(f"stall_min_improvement must be >= 0, got {self.stall_min_improvement}")
        if self.lookahead < 1:
            raise ValueError(f"lookahead must be >= 1, got {self.lookahead}")
        if self.localise_max_error is not None and not self.localise_max_error > 0:
            raise ValueError(f"localise_max_error must be > 0, got {self.localise_max_error}")


def consecutive_errors(images: np.ndarray) -> np.ndarray:
    """(L-1,) mean abs pixel errors between consecutive subgoals of (L, H, W, 3) uint8 images."""
    return np.array([image_error(images[k], images[k + 1]) for k in range(len(images) - 1)], dtype=np.float64)


def calibrate_e_m(images: np.ndarray, cfg: ControllerConfig) -> float:
    """e_m from the route itself (rule in the module docstring); the fixed e_m if the route has one image."""
    d = consecutive_errors(images)
    if d.size == 0:
        return cfg.e_m
    return float(np.clip(cfg.calib_fraction * np.quantile(d, cfg.calib_quantile), cfg.e_m_min, cfg.e_m_max))


class Controller:
    """Decide, image by image, whether to command, advance, jump, finish or give up."""

    def __init__(self, subgoals: np.ndarray, cfg: ControllerConfig | None = None) -> None:
        if (
            subgoals.dtype != np.uint8
            or subgoals.ndim != 4
            or subgoals.shape[0] < 1
            or subgoals.shape[-1] != 3
        ):
            raise ValueError(
                f"subgoals must be (L, H, W, 3) uint8 with L >= 1, got {subgoals.shape} {subgoals.dtype}"
            )
        self.cfg = cfg or ControllerConfig()
        self.subgoals = subgoals
        self.e_m = self.cfg.e_m if self.cfg.e_m_mode == "fixed" else calibrate_e_m(subgoals, self.cfg)
        self.index = 0
        self.stalled = False
        self.jumps = 0
        self.plateaus = 0  # subgoals accepted by the stall guard at error <= jump_factor * e_m
        self.localised_to: int | None = None
        self._localise_pending = self.cfg.localise
        self._best = math.inf
        self._no_progress = 0
        self._last_error = math.inf
        self._settled = 0

    def __len__(self) -> int:
        return int(self.subgoals.shape[0])

    @property
    def finished(self) -> bool:
        return self.index >= len(self)

    @property
    def subgoal(self) -> np.ndarray:
        """The current subgoal image (H, W, 3) uint8."""
        return self.subgoals[min(self.index, len(self) - 1)]

    def _set_index(self, index: int) -> None:
        self.index = index
        self._best = math.inf
        self._no_progress = 0
        self._last_error = math.inf
        self._settled = 0

    def decide(self, image: np.ndarray) -> Decision:
        """One step of the state machine for ``image`` ((H, W, 3) uint8 at the subgoals' resolution)."""
        if image.shape != self.subgoals.shape[1:]:
            raise ValueError(
                f"image shape {image.shape} differs from the subgoals' {self.subgoals.shape[1:]}"
            )
        if self.finished:
            return Decision(Action.FINISHED, self.index, math.nan)
        if self.stalled:
            return Decision(Action.STALLED, self.index, math.nan, note="stalled earlier")
        if self._localise_pending:
            self._localise_pending = False
            decision = self._localise(image)
            if decision is not None:
                return decision
        error = image_error(image, self.subgoals[self.index])
        improving = error < self._last_error - self.cfg.stall_min_improvement
        self._last_error = error
        if error <= self.e_m:
            if improving and self._settled < self.cfg.settle_steps:
                self._settled += 1
                return Decision(
                    Action.COMMAND, self.index, error, then_stop=not self.cfg.continuous, note="settling"
                )
            self._set_index(self.index + 1)
            return Decision(Action.ADVANCE, self.index, error)
        if self.cfg.stall_steps > 0:
            if error < self._best - self.cfg.stall_min_improvement:
                self._best = error
                self._no_progress = 0
            else:
                self._best = min(self._best, error)
                self._no_progress += 1
            if self._no_progress >= self.cfg.stall_steps:
                return self._unstall(image, error)
        return Decision(Action.COMMAND, self.index, error, then_stop=not self.cfg.continuous)

    def judge(self, image: np.ndarray) -> Verdict:
        """Decide on ``image`` until a decision needs the robot: subgoal switches (ADVANCE, JUMP) are
        applied here and reported as events, so the caller handles only COMMAND, FINISHED and STALLED."""
        from_index, events = self.index, []
        decision = self.decide(image)
        while decision.action in SWITCHES:
            events.append(decision)
            decision = self.decide(image)
        return Verdict(decision, tuple(events), from_index)

    def relocalise(self) -> None:
        """Search the whole route for the best-matching subgoal on the next image (after a robot restart)."""
        self._localise_pending = True

    def _localise(self, image: np.ndarray) -> Decision | None:
        errors = np.array([image_error(image, s) for s in self.subgoals])
        best = int(np.argmin(errors))
        floor = self.cfg.localise_max_error if self.cfg.localise_max_error is not None else 3.0 * self.e_m
        if errors[best] > floor:
            return None
        self.localised_to = best
        if best == self.index:
            return None
        self._set_index(best)
        return Decision(Action.JUMP, best, float(errors[best]), note=f"localised to subgoal {best}")

    def _unstall(self, image: np.ndarray, error: float) -> Decision:
        ahead = range(self.index + 1, min(self.index + 1 + self.cfg.lookahead, len(self)))
        candidates = [(image_error(image, self.subgoals[j]), j) for j in ahead]
        bound = self.cfg.jump_factor * self.e_m
        if candidates:
            best_error, best = min(candidates)
            if best_error <= bound and best_error < error:
                self.jumps += 1
                self._set_index(best)
                return Decision(Action.JUMP, best, best_error, note="stall guard")
        if error <= bound:
            # The policy has brought the robot as close as it can (its output has a small dead zone near
            # the goal): accept the subgoal rather than give up a route the robot is still on.
            self.plateaus += 1
            self._set_index(self.index + 1)
            return Decision(Action.ADVANCE, self.index, error, note="accepted on plateau")
        self.stalled = True
        return Decision(
            Action.STALLED,
            self.index,
            error,
            note=f"error {error:.1f} stopped falling for {self.cfg.stall_steps} steps and none of the next "
            f"{self.cfg.lookahead} subgoals is within {self.cfg.jump_factor} * e_m = {self.cfg.jump_factor * self.e_m:.1f}",
        )
