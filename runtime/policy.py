"""VelocityNet on onnxruntime: checked once at load, then (current, subgoal) frames -> (2, N) velocities.

The stages are separate methods (``preprocess``, ``infer``, ``postprocess``) so a latency benchmark can
time each; ``predict`` runs all three and leaves their durations in ``last_timing_ms``. Images come as
:class:`~vtr.runtime.frame.Frame` (a plain array is converted once, at this edge): the current frame's input
tensor is scaled from its planar levels (shared with the matcher), and a subgoal's tensor is kept on its frame.
"""

from __future__ import annotations

import os
import time
from typing import TYPE_CHECKING, Any

import numpy as np
import onnxruntime as ort

from vtr.runtime.frame import Frame, as_frame
from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL, OUTPUT_VELOCITIES, ModelMeta
from vtr.runtime.paths import require_file
from vtr.runtime.preprocess import PREPROCESSINGS, clip_ufunc, input_into

if TYPE_CHECKING:
    from vtr.runtime.route import Route

#: A VelocityNet is a few MB; a file past this is refused before onnxruntime reads it.
MAX_MODEL_BYTES = 256 * 1024 * 1024


class ModelMismatchError(ValueError):
    """The ONNX model (or a route used with it) does not match what the runtime expects."""


def _dim_ok(dim: Any, expected: int) -> bool:
    """A symbolic/None dimension accepts anything; a fixed one must equal ``expected``."""
    return not isinstance(dim, int) or dim == expected


class OnnxPolicy:
    """One onnxruntime session, created once. ``threads`` sets intra-op threads (default 1, a small board)."""

    def __init__(
        self, path: str | os.PathLike[str], threads: int = 1, max_bytes: int = MAX_MODEL_BYTES
    ) -> None:
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        self.path = require_file(path, "model file")
        size = os.path.getsize(self.path)
        if size > max_bytes:
            raise ModelMismatchError(
                f"{self.path}: {size / 2**20:.0f} MiB is larger than the {max_bytes / 2**20:.0f} MiB a model may be"
            )
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        try:
            self.session = ort.InferenceSession(self.path, options, providers=["CPUExecutionProvider"])
        except Exception as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ModelMismatchError(
                f"onnxruntime cannot load {self.path!r} ({first[:160]}); pass a VelocityNet ONNX from `vtr export`"
            ) from exc
        try:
            self.meta = ModelMeta.from_props(dict(self.session.get_modelmeta().custom_metadata_map))
        except ValueError as exc:
            raise ModelMismatchError(f"{self.path}: {exc}") from exc
        self._check_signature()
        #: Outputs with NaN/inf that were replaced by a zero command.
        self.nonfinite_count = 0
        #: Durations of the last predict() stages, in milliseconds.
        self.last_timing_ms: dict[str, float] = {}
        # the current image's tensor, rewritten every step, and as (1, 3, H, W): one object, bound once
        self._current_buf = np.empty((3, self.meta.image_height, self.meta.image_width), np.float32)
        self._current_feed = self._current_buf[None]
        # The session reads its inputs from, and writes its output to, arrays bound by address
        # (IOBinding): ~5 us a run less than session.run, which wraps every input and output anew. An
        # input array is bound again only when another array object comes (a new subgoal). predict's
        # own buffers and the feeds a caller passes to infer() have a binding each, so that a caller
        # alternating the two (the latency benchmark) does not rebind on every call.
        self._raw = np.empty((1, 2, self.meta.horizon), np.float32)
        self._own, self._given = self._new_binding(), self._new_binding()
        self._high = np.array([[self.meta.v_max], [self.meta.w_max]], dtype=np.float32)
        self._low = -self._high

    def _check_signature(self) -> None:
        meta = self.meta
        if meta.preprocessing not in PREPROCESSINGS:
            raise ModelMismatchError(
                f"{self.path}: model expects preprocessing {meta.preprocessing!r}, this runtime does "
                f"{', '.join(PREPROCESSINGS)}"
            )
        inputs = {i.name: i for i in self.session.get_inputs()}
        if set(inputs) != {INPUT_CURRENT, INPUT_SUBGOAL}:
            raise ModelMismatchError(
                f"{self.path}: inputs are {sorted(inputs)}, expected {[INPUT_CURRENT, INPUT_SUBGOAL]}"
            )
        expected_in = (1, 3, meta.image_height, meta.image_width)
        for name, arg in inputs.items():
            if arg.type != "tensor(float)":
                raise ModelMismatchError(f"{self.path}: input {name!r} is {arg.type}, expected tensor(float)")
            shape = list(arg.shape)
            if len(shape) != 4 or not all(
                _dim_ok(d, e) for d, e in zip(shape[1:], expected_in[1:], strict=True)
            ):
                raise ModelMismatchError(
                    f"{self.path}: input {name!r} has shape {shape}, expected (B, 3, {meta.image_height}, "
                    f"{meta.image_width}) as its metadata says"
                )
        outputs = {o.name: o for o in self.session.get_outputs()}
        if OUTPUT_VELOCITIES not in outputs:
            raise ModelMismatchError(
                f"{self.path}: outputs are {sorted(outputs)}, expected {OUTPUT_VELOCITIES!r}"
            )
        out = outputs[OUTPUT_VELOCITIES]
        shape = list(out.shape)
        if len(shape) != 3 or not (_dim_ok(shape[1], 2) and _dim_ok(shape[2], meta.horizon)):
            raise ModelMismatchError(
                f"{self.path}: output {OUTPUT_VELOCITIES!r} has shape {shape}, expected (B, 2, {meta.horizon})"
            )

    @property
    def image_shape(self) -> tuple[int, int]:
        """(H, W) the model takes."""
        return (self.meta.image_height, self.meta.image_width)

    def check_route(self, route: Route) -> None:
        """Refuse a route whose images are not at the model's resolution."""
        shape = tuple(route.images.shape[1:3])
        if shape != self.image_shape:
            raise ModelMismatchError(
                f"route images are {shape[0]}x{shape[1]} but the model takes "
                f"{self.image_shape[0]}x{self.image_shape[1]}; teach it with `vtr teach --model MODEL`, which maps the "
                "camera's frames to the model's input"
            )

    # ------------------------------------------------------------------ stages
    def preprocess(self, current: Frame | np.ndarray, subgoal: Frame | np.ndarray) -> dict[str, np.ndarray]:
        """Current and subgoal frames (or uint8 (H, W, 3) arrays, converted once here) -> the session's feeds
        (float32 (1, 3, H, W) each). The current image's tensor is one buffer, rewritten by the next call;
        the subgoal's is made once per subgoal frame and kept on it."""
        current, subgoal = as_frame(current, self.image_shape), as_frame(subgoal, self.image_shape)
        input_into(current.levels, self._current_buf, self.meta.preprocessing)  # _current_feed's values
        return {
            INPUT_CURRENT: self._current_feed,
            INPUT_SUBGOAL: subgoal.derived(self._input_key, self._input),
        }

    @property
    def _input_key(self) -> tuple[str, str]:
        return ("network_input", self.meta.preprocessing)

    def _input(self, frame: Frame) -> np.ndarray:
        """A frame's (1, 3, H, W) network input, read-only (kept on a subgoal's frame)."""
        tensor = input_into(frame.levels, np.empty(frame.levels.shape, np.float32), self.meta.preprocessing)
        tensor.flags.writeable = False
        return tensor

    def _new_binding(self) -> tuple[Any, dict[str, np.ndarray]]:
        binding = self.session.io_binding()
        binding.bind_output(
            OUTPUT_VELOCITIES, "cpu", 0, np.float32, list(self._raw.shape), self._raw.ctypes.data
        )
        return binding, {}

    def infer(self, feeds: dict[str, np.ndarray]) -> np.ndarray:
        """Run the network on float32 (1, 3, H, W) feeds; returns the raw (2, N) output of the first batch
        item, in a buffer the next call rewrites. The feeds are read where they lie (bound by address, an
        array bound again only when another object comes), so their values may change in place between
        calls; a feed that is not a C-ordered float32 array is copied into one first, and a batch of more
        than one goes through ``session.run``."""
        return self._run(self._given, feeds)

    def _run(self, bindings: tuple[Any, dict[str, np.ndarray]], feeds: dict[str, np.ndarray]) -> np.ndarray:
        binding, bound = bindings
        for name, array in feeds.items():
            if bound.get(name) is not array:
                if array.ndim != 4 or array.shape[0] != 1:  # the output is bound for one batch item
                    (out,) = self.session.run([OUTPUT_VELOCITIES], feeds)
                    return np.asarray(out)[0]
                if array.dtype != np.float32 or not array.flags.c_contiguous:
                    array = np.ascontiguousarray(array, dtype=np.float32)
                binding.bind_cpu_input(name, array)
                bound[name] = array
        self.session.run_with_iobinding(binding)
        return self._raw[0]

    def postprocess(self, raw: np.ndarray) -> np.ndarray:
        """Non-finite -> zero command (counted); finite values clipped to the model's v/w limits."""
        raw = np.asarray(raw, dtype=np.float32).reshape(2, self.meta.horizon)
        if not np.isfinite(raw).all():
            self.nonfinite_count += 1
            return np.zeros((2, self.meta.horizon), dtype=np.float32)
        return clip_ufunc(raw, self._low, self._high)

    def predict(self, current: Frame | np.ndarray, subgoal: Frame | np.ndarray) -> np.ndarray:
        """Current and subgoal frames (or (H, W, 3) uint8 arrays) -> (2, N): row 0 v (m/s), row 1 w (rad/s)."""
        t0 = time.perf_counter()
        return self._infer_timed(t0, self.preprocess(current, subgoal))

    def _infer_timed(self, t0: float, feeds: dict[str, np.ndarray]) -> np.ndarray:
        """Inference and postprocess on ready ``feeds``; the stages since ``t0`` go to ``last_timing_ms``."""
        t1 = time.perf_counter()
        raw = self._run(self._own, feeds)
        t2 = time.perf_counter()
        out = self.postprocess(raw)
        self.last_timing_ms = {"preprocess": (t1 - t0) * 1e3, "inference": (t2 - t1) * 1e3}
        return out
