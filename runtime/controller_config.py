"""The controller's settings (runtime.controller's docstring explains each rule)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from vtr.runtime.localiser import LocaliserConfig
from vtr.runtime.matching import MatchConfig
from vtr.runtime.thresholds import DEFAULT_BOUNDS, THRESHOLD_MODES

#: How the subgoal steered to is chosen: "localiser" (runtime.follower: from the route localiser's estimate,
#: the default) or "rules" (runtime.controller: the paper's threshold switching and the earlier rules on it).
SWITCHING = ("localiser", "rules")


@dataclass
class ControllerConfig:
    """Subgoal-switching settings (see the module docstring for each rule)."""

    #: "localiser" (default) or "rules" (the paper's Algorithm 1 and the earlier release's rules).
    switching: str = "localiser"
    #: localiser: the route localiser's settings.
    localiser: LocaliserConfig = field(default_factory=LocaliserConfig)
    #: localiser: steer to the first subgoal more than this many gaps ahead of the estimate (the paper's
    #: horizon: VelocityNet is trained to reach the view two control steps, one subgoal, ahead).
    lead: float = 0.5
    #: localiser: weight of the taught command at the estimated position in each command (feed-forward;
    #: VelocityNet's command is the rest).
    feed_forward: float = 0.5
    #: localiser: the same for the turn rate. 0: VelocityNet steers alone, so its heading and side corrections
    #: keep their full gain (dev routes, start 10 cm / 10 deg off: cross-track 41 -> 26 mm against 0.5).
    feed_forward_turn: float = 0.0
    #: localiser: where the floor tells the side offset ``dy`` (runtime.side_offset), turn toward the taught
    #: path so that the robot heads for the path point ``side_lookahead`` metres ahead (pure pursuit): add
    #: ``side_gain`` x atan(dy / side_lookahead) rad/s, at most ``side_turn.SIDE_TURN_MAX``. VelocityNet holds
    #: the heading its view asks for at about 3.6 rad/s per rad (a fit of its turn on dev traces: -3.6 psi - 2.0
    #: dy), so this moves the heading it holds to the pursuit heading, at any pace; 0: VelocityNet alone
    #: (ablation ``after_no_side``). The earlier law (40 rad/s per m per m/s of speed) closed a 10 cm / 10 deg
    #: start over 1.0-1.2 m on dev routes and slower still on slowly taught ones (issue 19, evaluation/README).
    side_gain: float = 3.6
    #: localiser: the pursuit's lookahead (m): a side offset closes over about this much travel (plus the
    #: turn), once the heading toward the path is within SIDE_TURN_MAX's reach.
    side_lookahead: float = 0.2
    #: localiser: FINISHED needs the estimate within this many gaps of the last subgoal.
    finish_span: float = 0.5
    #: localiser: stop as blocked when the camera sees the way ahead blocked (runtime.obstruction; routes
    #: with taught poses only). Off only for ablations (the condition suite's ``after_no_obstruction``).
    obstruction: bool = True

    #: Image comparison (runtime.matching): patch-normalised by default, raw for the paper.
    match: MatchConfig = field(default_factory=MatchConfig)
    #: "fixed" uses ``e_m``; "calibrated": one threshold from the route; "per_subgoal": one per subgoal from
    #: its incoming gap; "hybrid" (default): the route's, raised where both neighbouring gaps are wide (dev:
    #: the example room's fast turns, where a 2 degree miss scored above the route's threshold; ablation
    #: ``after_route_threshold``).
    e_m_mode: str = "hybrid"
    #: Fixed switch threshold in the matcher's units (the paper's 17 on 0..255 for raw).
    e_m: float = 17.0
    #: Quantile of the consecutive-subgoal distances used by "calibrated" (0.5 = median).
    calib_quantile: float = 0.5
    #: Fraction of that distance (of the incoming gap for "per_subgoal", of the smaller neighbouring gap for
    #: "hybrid") taken as the threshold.
    calib_fraction: float = 0.75
    #: Bounds on a derived threshold; None takes DEFAULT_BOUNDS for the matching method.
    e_m_min: float | None = None
    e_m_max: float | None = None
    #: Relative switch: ADVANCE when d(next) <= pass_ratio * d(current); 0 disables it (the default, and
    #: the paper's); 1.0 goes with "per_subgoal".
    pass_ratio: float = 0.0
    #: Commands without progress before the stall guard acts; 0 disables it (the paper has none).
    stall_steps: int = 10
    #: Progress means the error fell this much below its best at this subgoal (matcher units); None:
    #: 2% of the subgoal's threshold.
    stall_min_improvement: float | None = None
    #: How many subgoals ahead the stall guard, the lost test and localisation look.
    lookahead: int = 5
    #: The stall guard jumps to / accepts a subgoal only within jump_factor thresholds. 2.5 (was 2.0): a
    #: robot held 1-2 cm and 1-2 deg from the taught pose by the policy's dead zone scores 1.5-1.8
    #: thresholds in the unchanged room, and a moved table or a start offset adds the rest (dev routes).
    jump_factor: float = 2.5
    #: The policy idles (every command under ``idle_speed`` m/s and ``idle_turn`` rad/s) for this many
    #: commands in a row next to the subgoal: the stall guard acts at once instead of after ``stall_steps``
    #: (the flicker of a noisy error kept "improving" by noise while the robot stood 8 mm from the subgoal
    #: for 30 commands); 0 disables it.
    idle_steps: int = 3
    idle_speed: float = 0.01
    idle_turn: float = 0.02
    #: A plateau acceptance needs the view to have changed since the previous one (the robot moved).
    plateau_needs_motion: bool = True
    #: "Changed" means a distance of at least this fraction of the current subgoal's incoming gap.
    motion_fraction: float = 0.25
    #: Lost when the best nearby match exceeds lost_factor * the route's median gap (or the wider taught gap
    #: next to the subgoals there, where more: thresholds.lost_bounds) ...
    lost_factor: float = 2.0
    #: ... for this many consecutive commands; 0 disables the test.
    lost_steps: int = 5
    #: Stop the repeat when an observation reports a contact.
    stop_on_contact: bool = True
    #: Even out a left-to-right light gain toward the current subgoal before patch matching (runtime.light's
    #: ramp): a gain that varies inside a tile survives the tile's normalisation (one side of the view darker).
    #: Off by default: on the held-out routes it finished every one-side-darker run but cost moved-furniture
    #: runs (evaluation/README, "The light ramp before matching").
    match_ramp: bool = False
    #: Pick the starting subgoal by best match over the whole route (the paper starts at 0).
    localise: bool = False
    #: Localisation confidence floor: best-match error must be at most this; None means 3 * e_m.
    localise_max_error: float | None = None
    #: Where the taught robot turned in place (v = 0 into the subgoal), the repeat does not translate
    #: either: the policy's forward output there pushed the robot into the furniture it turned beside.
    hold_turns: bool = True
    #: Progress gate (runtime.progress_gate): switch past a subgoal only after commanding this fraction of
    #: the taught travel into it; 0 disables it (the paper's rule). Dev houses 910-924 (an earlier release):
    #: off / 0.5 / 0.7 / 1.0: mean error 15.0 / 11.4 / 10.6 / 8.8 mm at 1.59 / 1.86 / 2.01 / 2.56 control
    #: steps per taught step. With the zero bias and hybrid thresholds 0.3 (was 0.5): dev houses 9.3 -> 9.5
    #: mm at 1.66 -> 1.55x, dev routes under noise 1.53 -> 1.44x (evaluation/README.md).
    progress_gate: float = 0.3
    #: ... or after this many commands held back by the gate (a robot already at the subgoal).
    gate_patience: int = 3
    #: Blend the taught command into subgoal i into each command toward it with this weight (0: the policy
    #: alone; teach & repeat systems such as Bearnav replay the taught speeds and correct from vision).
    taught_prior: float = 0.0
    #: Subtract this fraction of the policy's command at the subgoal itself, policy(S, S), from every command
    #: toward S (computed once per subgoal when the route is loaded). A robot standing on the subgoal should
    #: be told to stand still; in a world unlike the training houses the network's "zero" drifts (0.1-0.2
    #: rad/s of turn on identical images in the example room) and the robot drives off the first subgoal.
    #: Dev: the example room's dev routes 15 -> 20 of 20 (with hybrid thresholds); dev houses and routes no
    #: worse (ablation ``after_no_zero_bias``).
    zero_bias: float = 1.0
    #: Keep moving between control steps instead of the paper's stop-and-go.
    continuous: bool = False
    #: Extra commands at a subgoal while the error still falls under the threshold (0: switch at once).
    settle_steps: int = 1

    @classmethod
    def paper(cls) -> ControllerConfig:
        """Algorithm 1 exactly: raw error, fixed e_m = 17, switch at once, nothing else."""
        return cls(
            switching="rules",
            match=MatchConfig.paper(),
            e_m_mode="fixed",
            e_m=17.0,
            pass_ratio=0.0,
            stall_steps=0,
            settle_steps=0,
            lost_steps=0,
            stop_on_contact=False,
            hold_turns=False,
            progress_gate=0.0,
            match_ramp=False,
            idle_steps=0,
            zero_bias=0.0,
        )

    @classmethod
    def before(cls) -> ControllerConfig:
        """The previous default: raw error, one calibrated e_m per route, settle 2, old plateau rule."""
        return cls(
            switching="rules",
            match=MatchConfig.paper(),
            e_m_mode="calibrated",
            pass_ratio=0.0,
            settle_steps=2,
            plateau_needs_motion=False,
            lost_steps=0,
            stop_on_contact=False,
            hold_turns=False,
            stall_min_improvement=0.25,
            jump_factor=2.0,
            progress_gate=0.0,
            match_ramp=False,
            idle_steps=0,
            zero_bias=0.0,
        )

    def __post_init__(self) -> None:
        if self.switching not in SWITCHING:
            raise ValueError(f"switching must be one of {SWITCHING}, got {self.switching!r}")
        for name, hi in (
            ("lead", 3.0),
            ("feed_forward", 1.0),
            ("feed_forward_turn", 1.0),
            ("finish_span", 2.0),
            ("side_gain", 100.0),
            ("side_lookahead", 2.0),
        ):
            if not 0 <= getattr(self, name) <= hi:
                raise ValueError(f"{name} must be in [0, {hi}], got {getattr(self, name)!r}")
        if not self.side_lookahead > 0:
            raise ValueError(f"side_lookahead must be > 0, got {self.side_lookahead!r}")
        if self.e_m_mode not in THRESHOLD_MODES:
            raise ValueError(f"e_m_mode must be one of {THRESHOLD_MODES}, got {self.e_m_mode!r}")
        positive = {
            "e_m": self.e_m,
            "calib_fraction": self.calib_fraction,
            "jump_factor": self.jump_factor,
            "lost_factor": self.lost_factor,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        if not 0.0 <= self.calib_quantile <= 1.0:
            raise ValueError(f"calib_quantile must be in [0, 1], got {self.calib_quantile}")
        lo, hi = self.bounds
        if not 0 < lo <= hi:
            raise ValueError(f"e_m_max={hi} must be >= e_m_min={lo} > 0")
        for name in ("stall_steps", "settle_steps", "lost_steps", "gate_patience", "idle_steps"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.stall_min_improvement is not None and not self.stall_min_improvement >= 0:
            raise ValueError(f"stall_min_improvement must be >= 0, got {self.stall_min_improvement}")
        for name in (
            "pass_ratio",
            "motion_fraction",
            "progress_gate",
            "idle_speed",
            "idle_turn",
            "taught_prior",
            "zero_bias",
        ):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("taught_prior", "zero_bias"):
            if getattr(self, name) > 1:
                raise ValueError(f"{name} is a weight in [0, 1], got {getattr(self, name)}")
        if self.lookahead < 1:
            raise ValueError(f"lookahead must be >= 1, got {self.lookahead}")
        if self.localise_max_error is not None and not self.localise_max_error > 0:
            raise ValueError(f"localise_max_error must be > 0, got {self.localise_max_error}")

    @property
    def bounds(self) -> tuple[float, float]:
        lo, hi = DEFAULT_BOUNDS[self.match.method]
        return (lo if self.e_m_min is None else self.e_m_min, hi if self.e_m_max is None else self.e_m_max)
