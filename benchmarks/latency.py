"""`vtr bench latency`: CPU cost of one control step, stage by stage and backend by backend.

What it measures (p50 / p99 over many steps after a warm-up, all in one run so the numbers compare):
  * the runtime's stages at ``--threads``: frame decode (the wire protocol's decode of a real encoded
    frame), preprocess, inference, image error, and the whole control step (encoded frame in -> encoded
    command out, the simulator excluded); the ZeroMQ round trip to a local simulator separately;
  * the same model on onnxruntime fp32, onnxruntime int8, torch eager and OpenCV cv2.dnn at 1 thread and
    at all cores, each with its GFLOP per step and achieved GFLOP/s next to this machine's float32
    matrix-multiply rate measured in the same run;
  * the peak resident memory of a runtime-only process (torch and OpenCV blocked from importing).

It is a benchmark, not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vtr.benchmarks.timing import time_call, time_interleaved
from vtr.runtime.atomic import write_text_atomic

REPO_ROOT = Path(__file__).resolve().parent.parent

#: Targets from issue 5, as ratios (name -> (description, comparison, threshold)).
TARGETS = {
    "ort_fp32_vs_torch_eager": ("torch eager p50 / onnxruntime fp32 p50", ">=", 3.0),
    "int8_vs_fp32": ("onnxruntime fp32 p50 / int8 p50", ">=", 2.5),
    "step_overhead": ("whole step p50 / inference p50 - 1", "<=", 0.15),
    "fp32_vs_matmul": ("fp32 achieved GFLOP/s / matmul GFLOP/s", ">=", 0.60),
}


@dataclass
class LatencyConfig:
    """Settings of one latency benchmark run."""

    model: Path  # fp32 VelocityNet ONNX (inputs `current`, `subgoal`; output `velocities`)
    int8_model: Path | None = None  # int8 twin; None -> `<model stem>-int8.onnx` beside the model, if present
    checkpoint: Path | None = (
        None  # torch checkpoint for the eager backend; None -> rebuild from the ONNX weights
    )
    threads: int = 1  # intra-op threads for the runtime stage breakdown
    thread_counts: tuple[int, ...] = (1, 0)  # backend sweep; 0 means all cores
    steps: int = 200  # timed iterations per measurement
    warmup: int = 20  # untimed iterations before each measurement
    backends: tuple[str, ...] = ("ort_fp32", "ort_int8", "torch_eager", "cv2_dnn")
    matmul_size: int = 512  # n of the n x n x n float32 matmul used as the hardware reference
    zmq: bool = True  # time the ZeroMQ round trip to a local simulator server
    memory: bool = True  # measure peak RSS of a runtime-only subprocess
    sim_steps: int = 500  # simulator throughput steps (`vtr bench sim`) in the same summary; 0 = skip
    json_path: Path | None = None  # where to write every number (atomic write)

    def __post_init__(self) -> None:
        self.model = Path(self.model)
        if not self.model.is_file():
            raise ValueError(f"model file not found: {self.model}")
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
        unknown = set(self.backends) - {"ort_fp32", "ort_int8", "torch_eager", "cv2_dnn"}
        if unknown:
            raise ValueError(f"unknown backends: {sorted(unknown)}")
        if self.matmul_size < 16:
            raise ValueError(f"matmul_size must be >= 16, got {self.matmul_size}")
        if self.int8_model is None:
            sibling = self.model.with_name(self.model.stem + "-int8" + self.model.suffix)
            self.int8_model = sibling if sibling.is_file() else None
        elif not Path(self.int8_model).is_file():
            raise ValueError(f"int8 model file not found: {self.int8_model}")


def all_cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


# ---------------------------------------------------------------- inputs


def sample_frames(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Two nearby camera frames: from the simulator when it is installed, else smooth synthetic images."""
    try:
        from vtr.sim2d import CameraConfig, Pose, SimConfig, Simulator

        sim = Simulator(SimConfig(camera=CameraConfig(width=width, height=height), noise=0.0))
        sim.reset(seed=0)
        start = sim.pose
        a = sim.reset(pose=Pose(start.x, start.y, start.yaw), seed=0)
        b = sim.step(0.2, 0.3, 0.3)
        return np.ascontiguousarray(a), np.ascontiguousarray(b)
    except Exception:  # simulator missing or not ready yet: the timings do not depend on content
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
        a = np.stack([xx / width, yy / height, 0.5 + 0.5 * np.sin(xx / 9.0)], axis=-1)
        b = np.roll(a, 3, axis=1)
        return (a * 255).astype(np.uint8), (b * 255).astype(np.uint8)


def _model_io(path: Path) -> tuple[int, int, int]:
    import onnxruntime as ort

    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    shape = sess.get_inputs()[0].shape  # (B, 3, H, W)
    h, w = (int(d) if isinstance(d, int) else 128 for d in shape[2:4])
    out = sess.get_outputs()[0].shape
    n = int(out[2]) if len(out) == 3 and isinstance(out[2], int) else 2
    return h, w, n


def ort_session(path: Path, threads: int) -> Any:
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])


# ---------------------------------------------------------------- hardware reference


def matmul_rate_ort(n: int, threads: int, steps: int = 20) -> float:
    """Median GFLOP/s of an n x n x n float32 MatMul in onnxruntime (the engine that runs the model)."""
    import onnx
    import onnxruntime as ort
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(0)
    b = numpy_helper.from_array(rng.standard_normal((n, n)).astype(np.float32), "B")
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["A", "B"], ["C"])],
        "matmul",
        [helper.make_tensor_value_info("A", TensorProto.FLOAT, [n, n])],
        [helper.make_tensor_value_info("C", TensorProto.FLOAT, [n, n])],
        [b],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    sess = ort.InferenceSession(model.SerializeToString(), opts, providers=["CPUExecutionProvider"])
    a = rng.standard_normal((n, n)).astype(np.float32)
    t = time_call(lambda: sess.run(None, {"A": a}), steps, 3)
    del onnx
    return 2.0 * n**3 / (t["p50_ms"] / 1e3) / 1e9


_NUMPY_MATMUL = """
import json, sys, time
import numpy as np
n, steps = int(sys.argv[1]), int(sys.argv[2])
rng = np.random.default_rng(0)
a = rng.standard_normal((n, n)).astype(np.float32)
b = rng.standard_normal((n, n)).astype(np.float32)
for _ in range(3):
    a @ b
times = []
for _ in range(steps):
    t0 = time.perf_counter()
    a @ b
    times.append(time.perf_counter() - t0)
print(json.dumps({"gflops": 2.0 * n**3 / float(np.median(times)) / 1e9}))
"""


def matmul_rate_numpy(n: int, threads: int, steps: int = 20) -> float | None:
    """Median GFLOP/s of numpy's float32 matmul in a subprocess whose BLAS is pinned to `threads` threads."""
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS"):
        env[var] = str(threads)
    try:
        out = subprocess.run(
            [sys.executable, "-c", _NUMPY_MATMUL, str(n), str(steps)],
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )
        return float(json.loads(out.stdout.strip().splitlines()[-1])["gflops"])
    except (subprocess.SubprocessError, ValueError, KeyError, IndexError):
        return None


# ---------------------------------------------------------------- backends


def _backend_runner(
    name: str, cfg: LatencyConfig, threads: int, x: np.ndarray, y: np.ndarray
) -> Callable[[], Any]:
    """A zero-argument callable running one inference of the model on the given backend."""
    from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL

    if name in ("ort_fp32", "ort_int8"):
        path = cfg.model if name == "ort_fp32" else cfg.int8_model
        if path is None:
            raise FileNotFoundError(
                "no int8 model (pass --int8-model or put <model>-int8.onnx beside the model)"
            )
        sess = ort_session(Path(path), threads)
        feeds = {INPUT_CURRENT: x, INPUT_SUBGOAL: y}
        return lambda: sess.run(None, feeds)
    if name == "torch_eager":
        import torch

        torch.set_num_threads(threads)
        module = _torch_module(cfg)
        tx, ty = torch.from_numpy(x), torch.from_numpy(y)

        def run_torch() -> Any:
            with torch.inference_mode():
                return module(tx, ty)

        return run_torch
    if name == "cv2_dnn":
        import cv2

        cv2.setNumThreads(threads)
        net = cv2.dnn.readNetFromONNX(str(cfg.model))

        def run_cv2() -> Any:
            net.setInput(x, INPUT_CURRENT)
            net.setInput(y, INPUT_SUBGOAL)
            return net.forward()

        return run_cv2
    raise ValueError(f"unknown backend {name!r}")


def _torch_module(cfg: LatencyConfig) -> Callable[[Any, Any], Any]:
    """VelocityNet as a torch eager callable: from a checkpoint if given, else rebuilt from the ONNX weights."""
    if cfg.checkpoint is not None:
        from vtr.training.train import load_model

        kind, net, _ = load_model(cfg.checkpoint)
        if kind != "velocitynet":
            raise ValueError(f"{cfg.checkpoint} holds a {kind}, not a velocitynet")
        return lambda a, b: net(a, b)
    from vtr.benchmarks.onnx_tools import OnnxTorchModule
    from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL

    graph = OnnxTorchModule(cfg.model)
    return lambda a, b: graph(**{INPUT_CURRENT: a, INPUT_SUBGOAL: b})


def bench_backends(cfg: LatencyConfig, x: np.ndarray, y: np.ndarray, gflop: float) -> dict[str, Any]:
    """Every backend at every thread count, plus the matmul reference at the same thread counts."""
    results: dict[str, Any] = {"threads": {}}
    for t in cfg.thread_counts:
        threads = t or all_cores()
        entry: dict[str, Any] = {"matmul": {}, "backends": {}}
        ort_rate = matmul_rate_ort(cfg.matmul_size, threads)
        np_rate = matmul_rate_numpy(cfg.matmul_size, threads)
        entry["matmul"] = {
            "n": cfg.matmul_size,
            "ort_gflops": ort_rate,
            "numpy_gflops": np_rate,
            "best_gflops": max(r for r in (ort_rate, np_rate) if r is not None),
        }
        runners: dict[str, Callable[[], Any]] = {}
        for name in cfg.backends:
            try:
                runners[name] = _backend_runner(name, cfg, threads, x, y)
                runners[name]()
            except Exception as err:  # a backend that cannot load this model is reported, not fatal
                runners.pop(name, None)
                entry["backends"][name] = {"skipped": f"{type(err).__name__}: {err}"}
        timings = time_interleaved(runners, cfg.steps, cfg.warmup)
        for name, timing in timings.items():
            achieved = gflop / (timing["p50_ms"] / 1e3)
            entry["backends"][name] = {
                **timing,
                "gflop_per_step": gflop,
                "achieved_gflops": achieved,
                "fraction_of_matmul": achieved / entry["matmul"]["best_gflops"],
            }
        results["threads"][str(threads)] = entry
    return results


# ---------------------------------------------------------------- runtime stages


def bench_stages(cfg: LatencyConfig, current: np.ndarray, subgoal: np.ndarray) -> dict[str, Any]:
    """The runtime's own stages at cfg.threads, and the whole step: the real ``Repeater.step``."""
    from vtr.benchmarks.step_bench import BenchStep
    from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL
    from vtr.runtime.preprocess import image_error, to_nchw

    step = BenchStep(cfg.model, cfg.threads, current, subgoal)
    robot, policy = step.robot, step.policy
    feeds = {INPUT_CURRENT: to_nchw(current), INPUT_SUBGOAL: to_nchw(subgoal)}

    stages = time_interleaved(
        {
            "frame_decode": robot.decode,
            "preprocess": lambda: to_nchw(current),
            "inference": lambda: policy.infer(feeds),
            "image_error": lambda: image_error(current, subgoal),
            "command_encode": lambda: robot.encode_command(0.1, -0.2),
            "whole_step": step,
        },
        cfg.steps,
        cfg.warmup,
    )
    return {"threads": cfg.threads, "codec": "vtr.runtime.protocol", "step": step.name, "stages": stages}


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


_RSS_SCRIPT = """
import json, resource, sys
for blocked in ("torch", "cv2", "pymunk", "matplotlib"):
    sys.modules[blocked] = None
sys.path.insert(0, sys.argv[1])


def hwm_mb():
    # VmHWM belongs to this process's own address space; ru_maxrss also carries the parent's high-water
    # mark across fork + exec on Linux, so it would report the benchmark process, not this one.
    try:
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


from vtr.benchmarks.step_bench import BenchStep
import numpy as np
model, steps, h, w = sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
before = hwm_mb()
rng = np.random.default_rng(0)
subgoal = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
current = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
step = BenchStep(model, 1, current, subgoal)
for _ in range(steps):
    step()
heavy = sorted(m for m in ("torch", "cv2", "pymunk", "matplotlib", "onnx") if sys.modules.get(m) is not None)
print(json.dumps({"peak_rss_mb": hwm_mb(), "rss_after_imports_mb": before, "steps": steps,
                  "ru_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                  "heavy_modules_loaded": heavy, "step": step.name}))
"""


def bench_memory(cfg: LatencyConfig) -> dict[str, Any]:
    """Peak RSS of a process that imports only the runtime (+ onnxruntime) and runs control steps."""
    h, w, _ = _model_io(cfg.model)
    try:
        out = subprocess.run(
            [
                sys.executable,
                "-c",
                _RSS_SCRIPT,
                str(REPO_ROOT),
                str(cfg.model.resolve()),
                str(cfg.steps),
                str(h),
                str(w),
            ],
            capture_output=True,
            text=True,
            timeout=300,
            check=True,
            cwd=str(REPO_ROOT),
        )
        return json.loads(out.stdout.strip().splitlines()[-1])
    except subprocess.CalledProcessError as err:
        return {"skipped": f"runtime-only process failed: {err.stderr.strip().splitlines()[-1:]}"}
    except (subprocess.SubprocessError, ValueError, IndexError) as err:
        return {"skipped": f"{type(err).__name__}: {err}"}


# ---------------------------------------------------------------- summary


def ratios(result: dict[str, Any]) -> dict[str, Any]:
    """The issue's target ratios from a result dict (None where an input is missing)."""
    one = result["backends"]["threads"].get("1") or next(iter(result["backends"]["threads"].values()))
    b = one["backends"]

    def p50(name: str) -> float | None:
        return b.get(name, {}).get("p50_ms")

    out: dict[str, Any] = {}
    fp32, torch_eager, int8 = p50("ort_fp32"), p50("torch_eager"), p50("ort_int8")
    out["ort_fp32_vs_torch_eager"] = torch_eager / fp32 if fp32 and torch_eager else None
    out["int8_vs_fp32"] = fp32 / int8 if fp32 and int8 else None
    st = result["stages"]["stages"]
    out["step_overhead"] = st["whole_step"]["p50_ms"] / st["inference"]["p50_ms"] - 1.0
    out["fp32_vs_matmul"] = b.get("ort_fp32", {}).get("fraction_of_matmul")
    verdict = {}
    for key, (_, op, threshold) in TARGETS.items():
        value = out[key]
        verdict[key] = None if value is None else (value >= threshold if op == ">=" else value <= threshold)
    out["meets_target"] = verdict
    return out


def format_report(result: dict[str, Any]) -> str:
    lines = [f"model: {result['model']}  ({result['gflop']:.3f} GFLOP per step, 1 MAC = 2 FLOP)"]
    lines.append(f"machine: {result['machine']['cores']} cores, {result['machine']['processor']}")
    st = result["stages"]
    lines += ["", f"runtime stages at {st['threads']} thread(s)  [codec: {st['codec']}; step: {st['step']}]"]
    lines.append(f"  {'stage':<16}{'p50 ms':>10}{'p99 ms':>10}")
    for name, t in st["stages"].items():
        lines.append(f"  {name:<16}{t['p50_ms']:>10.3f}{t['p99_ms']:>10.3f}")
    z = result["zmq"]
    if "skipped" in z:
        lines.append(f"  {'zmq_round_trip':<16}   skipped: {z['skipped']}")
    else:
        for name, t in z["calls"].items():
            label = "zmq " + name if name != "render_in_process" else "(sim render)"
            lines.append(f"  {label:<16}{t['p50_ms']:>10.3f}{t['p99_ms']:>10.3f}")
        lines.append(f"  {'zmq transport':<16}{z['transport_p50_ms']:>10.3f}  (observe round trip - render)")
    for threads, entry in result["backends"]["threads"].items():
        mm = entry["matmul"]
        np_rate = "n/a" if mm["numpy_gflops"] is None else f"{mm['numpy_gflops']:.1f}"
        lines += [
            "",
            f"backends at {threads} thread(s); float32 matmul {mm['n']}^3: onnxruntime {mm['ort_gflops']:.1f}, "
            f"numpy {np_rate} GFLOP/s",
            f"  {'backend':<12}{'p50 ms':>10}{'p99 ms':>10}{'GFLOP/s':>10}{'of matmul':>11}",
        ]
        for name, b in entry["backends"].items():
            if "skipped" in b:
                lines.append(f"  {name:<12}   skipped: {b['skipped'][:90]}")
            else:
                lines.append(
                    f"  {name:<12}{b['p50_ms']:>10.3f}{b['p99_ms']:>10.3f}{b['achieved_gflops']:>10.2f}"
                    f"{b['fraction_of_matmul']:>10.0%}"
                )
    mem = result["memory"]
    lines.append("")
    if "skipped" in mem:
        lines.append(f"runtime-only process peak RSS: skipped ({mem['skipped']})")
    elif mem:
        lines.append(
            f"runtime-only process peak RSS: {mem['peak_rss_mb']:.1f} MB over {mem['steps']} steps "
            f"(heavy modules loaded: {', '.join(mem['heavy_modules_loaded']) or 'none'})"
        )
    sim = result.get("sim", {})
    if "skipped" in sim:
        lines.append(f"simulator throughput: skipped ({sim['skipped']})")
    elif sim:
        lines.append(
            f"simulator throughput (`vtr bench sim`): {sim['steps_per_s']:.0f} steps/s "
            f"(render {sim['render_ms_median']:.2f} ms, physics {sim['physics_ms_median']:.2f} ms median)"
        )
    r = result["ratios"]
    lines += ["", "targets (issue 5), at 1 thread:"]
    for key, (desc, op, threshold) in TARGETS.items():
        value, ok = r[key], r["meets_target"][key]
        shown = "n/a" if value is None else (f"{value:+.1%}" if key == "step_overhead" else f"{value:.2f}")
        mark = "n/a" if ok is None else ("MET" if ok else "missed")
        lines.append(f"  {desc:<42} {shown:>8}  target {op} {threshold:g}  {mark}")
    return "\n".join(lines)


def run(cfg: LatencyConfig) -> dict[str, Any]:
    """Run every measurement and return one JSON-ready dict (also written to cfg.json_path)."""
    import platform

    from vtr.benchmarks.onnx_tools import count_flops

    h, w, _ = _model_io(cfg.model)
    current, subgoal = sample_frames(h, w)
    from vtr.runtime.preprocess import to_nchw

    x, y = to_nchw(current), to_nchw(subgoal)
    flops = count_flops(cfg.model)
    result: dict[str, Any] = {
        "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()},
        "model": str(cfg.model),
        "int8_model": None if cfg.int8_model is None else str(cfg.int8_model),
        "gflop": flops["gflop"],
        "flops": flops,
        "machine": {"cores": all_cores(), "processor": platform.processor() or platform.machine()},
        "stages": bench_stages(cfg, current, subgoal),
        "zmq": bench_zmq(cfg) if cfg.zmq else {"skipped": "disabled"},
        "backends": bench_backends(cfg, x, y, flops["gflop"]),
        "memory": bench_memory(cfg) if cfg.memory else {"skipped": "disabled"},
        "sim": bench_sim(cfg, (h, w)) if cfg.sim_steps else {"skipped": "disabled"},
    }
    result["ratios"] = ratios(result)
    if cfg.json_path is not None:
        write_json(cfg.json_path, result)
    return result


def write_json(path: Path, data: Any) -> None:
    write_text_atomic(path, json.dumps(data, indent=2, default=_json_default) + "\n")


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--model", type=Path, default=Path("models/velocitynet.onnx"), help="fp32 VelocityNet ONNX"
    )
    parser.add_argument(
        "--int8-model", type=Path, default=None, help="int8 twin (default: <model>-int8.onnx)"
    )
    parser.add_argument(
        "--checkpoint", type=Path, default=None, help="torch checkpoint for the eager backend"
    )
    parser.add_argument("--threads", type=int, default=1, help="threads for the runtime stage breakdown")
    parser.add_argument(
        "--thread-counts",
        default="1,all",
        help="comma-separated thread counts for the backend sweep ('all' = cores)",
    )
    parser.add_argument("--steps", type=int, default=200, help="timed iterations per measurement")
    parser.add_argument("--warmup", type=int, default=20, help="untimed iterations before each measurement")
    parser.add_argument("--backends", default="ort_fp32,ort_int8,torch_eager,cv2_dnn", help="comma-separated")
    parser.add_argument("--matmul-size", type=int, default=512, help="n of the reference n^3 float32 matmul")
    parser.add_argument("--no-zmq", action="store_true", help="skip the ZeroMQ round trip")
    parser.add_argument("--no-memory", action="store_true", help="skip the runtime-only peak RSS subprocess")
    parser.add_argument("--sim-steps", type=int, default=500, help="simulator throughput steps (0 = skip)")
    parser.add_argument("--json", type=Path, default=None, help="write every number here")
    parser.add_argument(
        "--standin", action="store_true", help="write a random-weight stand-in VelocityNet to --model first"
    )


def config_from_args(args: argparse.Namespace) -> LatencyConfig:
    counts = tuple(0 if t.strip() == "all" else int(t) for t in args.thread_counts.split(",") if t.strip())
    if args.standin:
        from vtr.benchmarks.onnx_tools import make_standin_velocitynet

        args.model.parent.mkdir(parents=True, exist_ok=True)
        make_standin_velocitynet(args.model)
    return LatencyConfig(
        model=args.model,
        int8_model=args.int8_model,
        checkpoint=args.checkpoint,
        threads=args.threads,
        thread_counts=counts,
        steps=args.steps,
        warmup=args.warmup,
        backends=tuple(b.strip() for b in args.backends.split(",") if b.strip()),
        matmul_size=args.matmul_size,
        zmq=not args.no_zmq,
        memory=not args.no_memory,
        sim_steps=args.sim_steps,
        json_path=args.json,
    )


def run_cli(args: argparse.Namespace) -> int:
    try:
        cfg = config_from_args(args)
    except ValueError as err:
        print(f"vtr bench latency: {err}", file=sys.stderr)
        return 2
    result = run(cfg)
    print(format_report(result))
    if cfg.json_path is not None:
        print(f"\nwrote {cfg.json_path}")
    return 0
