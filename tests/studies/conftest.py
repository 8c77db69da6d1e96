"""A tiny stand-in model and a route saved by ``step_bench_ab --write``, shared by the step studies' tests."""

from __future__ import annotations

import pytest

from studies import step_bench_ab
from vtr.benchmarks.standin import make_standin_velocitynet
from vtr.runtime.model_meta import ModelMeta

TINY = ModelMeta(image_height=32, image_width=32, horizon=2)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, str]:
    folder = tmp_path_factory.mktemp("m")
    model = str(make_standin_velocitynet(folder / "tiny.onnx", meta=TINY, widths=(4, 8)))
    route = str(folder / "route.npz")
    step_bench_ab.write_route(route, model)
    return model, route
