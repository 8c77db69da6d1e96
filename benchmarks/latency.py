"""`vtr bench latency`: CPU cost of one control step, stage by stage and backend by backend.

What it measures (p50 / p99 over many steps after a warm-up, all in one run so the numbers compare):
  * the runtime's stages at ``--threads``: frame decode (the wire protocol's decode of a real encoded
    frame), preprocess, inference, image error, and the whole control step (encoded frame in -> encoded
    command out, the simulator excluded); the ZeroMQ round trip to a local simulator separately;
  * of each whole step, its compute (the real ``Repeater.step``'s own stage times: the controller's judgement,
    the policy, the command's limits) apart from its link (the command's request and reply, the zero command),
    beside inference alone timed in the same loop: issue 19's budget is p99 step compute <= 1 ms at 1 thread;
    also the CPU time the thread spent judging and predicting, which a wait for a core on a busy machine does
    not inflate;
  * the same model on onnxruntime fp32, onnxruntime int8, torch eager and OpenCV cv2.dnn at 1 thread and
    at all cores, each with its GFLOP per step and achieved GFLOP/s next to this machine's float32
    matrix-multiply rate measured in the same run;
  * the peak resident memory of a runtime-only process (torch and OpenCV blocked from importing).

It is a benchmark, not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import functools
import json
import subprocess
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vtr.benchmarks.backends import bench_backends
from vtr.benchmarks.hardware import all_cores, child_env
from vtr.benchmarks.latency_report import END_VARIANT, STEP_VARIANTS, TAUGHT_VARIANT, format_report, ratios
from vtr.benchmarks.results import write_json
from vtr.benchmarks.timing import summarise, time_interleaved
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.status_line import Progress

BACKENDS = ("ort_fp32", "ort_int8", "torch_eager", "cv2_dnn")


@dataclass
class LatencyConfig:
    """Settings of one latency benchmark run."""

    model: Path | None = opt(None, "fp32 VelocityNet ONNX (default: the shipped models/velocitynet.onnx)")
    int8_model: Path | None = opt(
        None, "int8 twin (default: <model stem>-int8.onnx beside the model, if present)"
    )
    checkpoint: Path | None = opt(
        None, "VelocityNet checkpoint for torch eager (default: the model's layout)"
    )
    threads: int = opt(1, "intra-op threads for the runtime stages and the whole step")
    thread_counts: tuple[int, ...] = opt((1, 0), "thread counts of the backend sweep (0 = all cores)")
    steps: int = opt(200, "timed iterations per measurement")
    warmup: int = opt(20, "untimed iterations before each measurement")
    backends: tuple[str, ...] = opt(BACKENDS, "inference backends to time", choices=BACKENDS)
    matmul_size: int = opt(512, "n of the n x n x n float32 matmul used as the hardware reference")
    zmq: bool = opt(True, "time the ZeroMQ round trip to a local simulator server")
    memory: bool = opt(True, "measure the peak RSS of a runtime-only subprocess")
    sim_steps: int = opt(500, "simulator throughput steps (`vtr bench sim`) in the same run; 0 = skip")
    json_path: Path | None = opt(None, "write every number here", flag="--json")
    also_models: tuple[Path, ...] = opt(
        (),
        "more VelocityNet ONNX files whose whole step and inference are timed in the same run (e.g. "
        "a paper-sized network: the step overhead depends on the network)",
    )

    def __post_init__(self) -> None:
        from vtr.models import find_int8, find_model
        from vtr.runtime.policy import OnnxPolicy

        self.model = find_model(self.model)
        OnnxPolicy(self.model)  # a file that is not a VelocityNet ONNX: one line now, not a traceback later
        if self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads}")
        if not self.thread_counts or any(t < 0 for t in self.thread_counts):
            raise ValueError(
                f"thread_counts must be non-empty and >= 0 (0 = all cores), got {self.thread_counts}"
            )
        if self.steps < 2:
            raise ValueError(f"steps must be >= 2, got {self.steps}")
        if self.warmup < 0:
            raise ValueError(f"warmup must be >= 0, got {self.warmup}")
        if self.sim_steps < 0:
            raise ValueError(f"sim_steps must be >= 0, got {self.sim_steps}")
        unknown = set(self.backends) - set(BACKENDS)
        if unknown:
            raise ValueError(f"unknown backends: {sorted(unknown)}")
        if self.matmul_size < 16:
            raise ValueError(f"matmul_size must be >= 16, got {self.matmul_size}")
        self.int8_model = find_int8(self.model, self.int8_model)
        for other in self.also_models:
            OnnxPolicy(other)


def _model_io(path: Path) -> tuple[int, int, int]:
    import onnxruntime as ort

    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    shape = sess.get_inputs()[0].shape  # (B, 3, H, W)
    h, w = (int(d) if isinstance(d, int) else 128 for d in shape[2:4])
    out = sess.get_outputs()[0].shape
    n = int(out[2]) if len(out) == 3 and isinstance(out[2], int) else 2
    return h, w, n


def bench_stages(
    cfg: LatencyConfig, current: np.ndarray, route: np.ndarray, poses: np.ndarray | None = None
) -> dict[str, Any]:
    """The runtime's own stages at cfg.threads, and the whole step: the real ``Repeater.step``, with the
    raw error, with patch matching, without the zero command, and with light matching too; and, given the
    route's taught ``poses``, the light-matched step on the route with them (``whole_step_taught``: the
    obstruction detector and the side estimate at work, as on every forward step of a real route), and in its
    end zone (``whole_step_end``: the floor registered along the route too, as on a real route's last steps).

    The stages are timed round-robin in one loop. Each whole-step variant is timed in its own loop,
    round-robin with inference on its own policy (``pairs``; its ratio is judged against that inference):
    a daemon runs one onnxruntime session, not four taking turns in the cache."""
    from vtr.benchmarks.step_bench import BenchStep, sample_end_view
    from vtr.runtime.frame import Frame, as_frame
    from vtr.runtime.light import LightMatchedPolicy
    from vtr.runtime.matching import MatchConfig
    from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL
    from vtr.runtime.preprocess import image_error, to_nchw

    subgoal = route[0]
    variants = {
        "whole_step_raw": BenchStep(cfg.model, cfg.threads, current, route, match=MatchConfig.paper()),
        "whole_step": BenchStep(cfg.model, cfg.threads, current, route),
        "whole_step_continuous": BenchStep(cfg.model, cfg.threads, current, route, continuous=True),
        "whole_step_match_light": BenchStep(cfg.model, cfg.threads, current, route, match_light=True),
    }
    if poses is not None:
        variants[TAUGHT_VARIANT] = BenchStep(
            cfg.model, cfg.threads, current, route, match_light=True, poses=poses
        )
        end_view = sample_end_view(*route.shape[1:3], poses, route)
        variants[END_VARIANT] = BenchStep(
            cfg.model, cfg.threads, end_view, route, match_light=True, poses=poses, hold_at=len(route) - 1.5
        )
    step = variants["whole_step"]
    robot, policy = step.robot, step.policy
    feeds = {INPUT_CURRENT: to_nchw(current), INPUT_SUBGOAL: to_nchw(subgoal)}
    matcher = step.repeater.controller.matcher
    subgoal_features = matcher.features(subgoal)  # cached per subgoal by the controller
    light_policy = LightMatchedPolicy(policy)
    pixels, goal = as_frame(current).image, as_frame(subgoal)  # read-only pixels; the subgoal's frame, kept

    def fresh() -> Frame:
        """A new frame of the current image, as each step's is: the stages below each make its planar levels
        (~15 us at 128x128), which the whole step makes once for all of them."""
        return Frame.decoded(pixels)

    stages = time_interleaved(
        {
            "frame_decode": robot.decode,
            "preprocess": lambda: policy.preprocess(fresh(), goal),
            "inference": lambda: policy.infer(feeds),
            "image_error": lambda: image_error(current, subgoal),
            "matching": lambda: matcher.distance(matcher.features(fresh()), subgoal_features),
            "light_matching": lambda: light_policy.match(fresh(), goal),
            "command_encode": lambda: robot.encode_command(0.1, -0.2),
        },
        cfg.steps,
        cfg.warmup,
    )
    pairs, compute = {}, {}
    for name, bench in variants.items():
        pair = time_interleaved(
            {"inference": functools.partial(bench.policy.infer, feeds), "whole_step": bench},
            cfg.steps,
            cfg.warmup,
        )
        pairs[name] = pair
        stages[name] = pair["whole_step"]
        # the timed steps' own split (the Repeater's stage times): compute, and the link apart
        compute[name] = {
            "step_compute": summarise(np.array(bench.compute_ms[-cfg.steps :]) * 1e6),
            "link": summarise(np.array(bench.link_ms[-cfg.steps :]) * 1e6),
            "step_compute_cpu": summarise(np.array(bench.compute_cpu_ms[-cfg.steps :]) * 1e6),
            "inference": pair["inference"],
        }
    return {
        "threads": cfg.threads,
        "codec": "vtr.runtime.protocol",
        "step": step.name,
        "matching": {name: bench.matching for name, bench in variants.items()},
        "stages": stages,
        "pairs": pairs,
        "compute": compute,
    }


def step_overhead(cfg: LatencyConfig, model: Path) -> dict[str, Any]:
    """``bench_stages`` for another network, on a sample route at its image size, and its overheads."""
    from dataclasses import replace

    from vtr.benchmarks.flops import count_flops
    from vtr.benchmarks.step_bench import sample_route

    stages = bench_stages(replace(cfg, model=model, also_models=()), *sample_route(*_model_io(model)[:2]))
    pairs = stages["pairs"]
    overhead = {
        key: pairs[v]["whole_step"]["p50_ms"] / pairs[v]["inference"]["p50_ms"] - 1.0
        for key, v in STEP_VARIANTS.items()
    }
    return {"gflop": count_flops(model)["gflop"], "stages": stages, "step_overhead": overhead}


def bench_zmq(cfg: LatencyConfig) -> dict[str, Any]:
    from vtr.benchmarks.zmq_bench import zmq_round_trip

    try:
        return zmq_round_trip(cfg.steps, cfg.warmup, _model_io(cfg.model)[:2])
    except Exception as err:  # simulator server not installed or not reachable
        return {"skipped": f"{type(err).__name__}: {err}"}


def bench_sim(cfg: LatencyConfig, image_size: tuple[int, int]) -> dict[str, Any]:
    """`vtr bench sim` (the simulator's own benchmark) at the model's camera size."""
    try:
        from vtr.benchmarks.sim_throughput import SimBenchConfig
        from vtr.benchmarks.sim_throughput import run as run_sim

        h, w = image_size
        return run_sim(SimBenchConfig(steps=cfg.sim_steps, warmup=min(50, cfg.sim_steps), width=w, height=h))
    except Exception as err:  # simulator not installed
        return {"skipped": f"{type(err).__name__}: {err}"}


def bench_memory(cfg: LatencyConfig) -> dict[str, Any]:
    """Peak RSS of a process that imports only the runtime (+ onnxruntime) and runs control steps."""
    h, w, _ = _model_io(cfg.model)
    try:
        out = subprocess.run(
            [
                sys.executable,
                "-m",
                "vtr.benchmarks.memory_probe",
                str(cfg.model.resolve()),
                str(cfg.steps),
                str(h),
                str(w),
            ],
            capture_output=True,
            text=True,
            timeout=300,
            check=True,
            env=child_env(),
        )
        return json.loads(out.stdout.strip().splitlines()[-1])
    except subprocess.CalledProcessError as err:
        return {"skipped": f"runtime-only process failed: {err.stderr.strip().splitlines()[-1:]}"}
    except (subprocess.SubprocessError, ValueError, IndexError) as err:
        return {"skipped": f"{type(err).__name__}: {err}"}


def run(cfg: LatencyConfig) -> dict[str, Any]:
    """Run every measurement and return one JSON-ready dict (also written to cfg.json_path)."""
    import platform

    from vtr.benchmarks.flops import count_flops
    from vtr.benchmarks.step_bench import sample_taught
    from vtr.runtime.preprocess import to_nchw

    h, w, _ = _model_io(cfg.model)
    current, route, poses = sample_taught(h, w)
    x, y = to_nchw(current), to_nchw(route[0])
    flops = count_flops(cfg.model)
    progress = Progress("vtr bench latency", total=6, eta=False)  # one live line on stderr, a terminal only

    def measured(name: str, measure: Callable[[], Any]) -> Any:
        progress.start(name)
        out = measure()
        progress.advance(name)
        return out

    result: dict[str, Any] = {
        "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()},
        "model": str(cfg.model),
        "int8_model": None if cfg.int8_model is None else str(cfg.int8_model),
        "gflop": flops["gflop"],
        "flops": flops,
        "machine": {"cores": all_cores(), "processor": platform.processor() or platform.machine()},
        "stages": measured("stages", lambda: bench_stages(cfg, current, route, poses)),
        "zmq": measured("zmq", lambda: bench_zmq(cfg) if cfg.zmq else {"skipped": "disabled"}),
        "backends": measured("backends", lambda: bench_backends(cfg, x, y, flops["gflop"])),
        "memory": measured("memory", lambda: bench_memory(cfg) if cfg.memory else {"skipped": "disabled"}),
        "sim": measured("sim", lambda: bench_sim(cfg, (h, w)) if cfg.sim_steps else {"skipped": "disabled"}),
        "also_models": measured("also", lambda: {str(m): step_overhead(cfg, m) for m in cfg.also_models}),
    }
    progress.close()
    result["ratios"] = ratios(result)
    if cfg.json_path is not None:
        write_json(cfg.json_path, result)
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, LatencyConfig)
    parser.add_argument(
        "--standin", action="store_true", help="write a random-weight stand-in VelocityNet to --model first"
    )


def run_cli(args: argparse.Namespace) -> int:
    if args.standin:
        if args.model is None:
            raise ValueError("--standin needs --model: the file to write the stand-in to")
        from vtr.benchmarks.standin import make_standin_velocitynet

        args.model.parent.mkdir(parents=True, exist_ok=True)
        make_standin_velocitynet(args.model)
    cfg = config_from_args(LatencyConfig, args)  # a ValueError is one line, exit 2
    result = run(cfg)
    print(format_report(result))
    if cfg.json_path is not None:
        print(f"\nwrote {cfg.json_path}")
    return 0
