"""Crafted and broken files given to the commands that read them (issue 21): `vtr eval --run` (MCAP runs and
the taught route), `vtr collect --bag` and `vtr teach --bag` (ROS 2 bags; ROS 1 and sqlite3 ones are fuzzed in
tests/training/test_bag_fuzz.py), `vtr train` (datasets), `vtr export` (checkpoints), `vtr bench latency` (ONNX).

Each case runs the real command line (``vtr.cli.main``) in a child forked from one warm process (imports paid
once, two children at a time), and must end with the expected exit code and one line on stderr naming the file
(and the topic and message index where one message is at fault), never a traceback, leaving no output behind; a
damaged file that still reads gives warning lines naming it and a result. Memory: the child's peak RSS above
what it started with stays under 4x the file's size or the documented fixed cap (runtime.bag_caps: 64 MiB a
chunk); the bombs here peaked at 324-1,494 MB before the caps.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from crafted_files import (
    BAG_TOPICS,
    T0,
    bag_with,
    channel,
    checkpoint_bomb,
    compressed_image,
    corrupt_middle,
    cut,
    image_bomb_chunk,
    mcap,
    message,
    npy_header,
    png_bomb,
    pose_of_another_type,
    raw_bag,
    run_steps,
    schema,
    twist,
    zip_bomb,
)

from vtr.runtime.bag_caps import MAX_CHUNK_BYTES
from vtr.runtime.route import Route

ROOT = Path(__file__).resolve().parents[1]
#: The child's peak RSS may rise by 4x the file's size or by this much (the per-chunk cap), whichever is more.
FIXED_CAP = MAX_CHUNK_BYTES
BAG = ["--image-topic", "/camera/image", "--cmd-topic", "/cmd_vel", "--out", "{out}"]
ARGV = {
    "eval": ["eval", "--run", "{f}", "--taught", "{d}/route.npz"],
    "eval taught": ["eval", "--run", "{d}/good.mcap", "--taught", "{f}"],
    "collect": ["collect", "--bag", "{f}", *BAG],
    "teach": ["teach", "--bag", "{f}", *BAG],
    "train": ["train", "viewnet", "--preset", "tiny", "--data", "{f}", "--out", "{out}"],
    "export": ["export", "--checkpoint", "{f}", "--out", "{out}"],
    "bench": ["bench", "latency", "--model", "{f}"],
}


class Case(NamedTuple):
    argv: str  # a key of ARGV
    code: int  # the exit code
    words: tuple[str, ...]  # what the stderr lines hold
    make: Callable[[Path], Path]  # writes the crafted file into the folder, returns its path


def put(name: str, data: bytes) -> Callable[[Path], Path]:
    def make(d: Path) -> Path:
        (d / name).write_bytes(data)
        return d / name

    return make


def shared(d: Path) -> None:
    """Files several cases start from: a route, runs of 1, 2 and 3 chunks, a checkpoint, odd folders."""
    poses = [(0.05 * k, 0.0, 0.0) for k in range(13)]
    Route(images=np.zeros((13, 8, 8, 3), np.uint8), poses=poses, commands=np.zeros((13, 2))).save(
        d / "route.npz"
    )
    run_steps(d / "good.mcap")
    run_steps(d / "long.mcap", steps=25, side=96)  # two chunks: 1 MiB, 0.3 MiB
    run_steps(d / "longer.mcap", steps=40, side=96)  # three: the middle of the file lies in the second
    for name in ("folder", "yaml_bag", "shards"):
        (d / name).mkdir()
    (d / "yaml_bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: [1, 2\n")
    index = {"format": "vtr-shards", "format_version": 1, "shards": [5]}
    (d / "shards" / "index.json").write_text(json.dumps(index))


IMAGE = schema(1, "sensor_msgs/msg/Image") + channel(1, 1, "/vtr/camera/image")
TWIST = schema(2, "geometry_msgs/msg/Twist") + channel(2, 2, "/cmd_vel")
BAG_IMAGE = schema(1, "sensor_msgs/msg/Image") + channel(1, 1, "/camera/image")
PNG_TOPICS = {"/camera/image": "sensor_msgs/msg/CompressedImage", "/cmd_vel": BAG_TOPICS["/cmd_vel"]}
BIG_NPY = (npy_header((10**6, 8, 8, 3), "|u1"), 192 * 10**6)  # 192 MB of images in a 0.2 MB file


def png_bag(d: Path) -> Path:
    png = png_bomb(10000)
    return raw_bag(
        d / "png_bag",
        PNG_TOPICS,
        [("/camera/image", T0, compressed_image(png, T0)), ("/cmd_vel", T0, twist())],
    )


CASES = {
    "eval: empty": Case("eval", 2, ("empty",), put("empty.mcap", b"")),
    "eval: garbage": Case("eval", 2, ("not an MCAP",), put("garbage.mcap", bytes(range(256)) * 4)),
    "eval: cut in its only chunk": Case(
        "eval", 2, ("no poses", "damaged", "cut off"), lambda d: cut(d / "good.mcap", d / "half.mcap", 0.5)
    ),
    "eval: cut in its last chunk": Case(
        "eval", 0, ("warning", "damaged", "cut off"), lambda d: cut(d / "long.mcap", d / "cut.mcap", 0.8)
    ),
    "eval: 4 KiB corrupted in the middle": Case(
        "eval",
        0,
        ("warning", "damaged", "checksum"),
        lambda d: corrupt_middle(d / "longer.mcap", d / "mid.mcap"),
    ),
    "eval: step [1,2,3]": Case(
        "eval", 2, ("/vtr/step message 9", "list"), lambda d: run_steps(d / "list.mcap", extra=["[1,2,3]"])
    ),
    "eval: summary 5": Case(
        "eval",
        2,
        ("/vtr/step message 9", "summary is a JSON int"),
        lambda d: run_steps(d / "s5.mcap", extra=['{"summary": 5}']),
    ),
    "eval: subgoals_reached Infinity": Case(
        "eval",
        2,
        ("/vtr/step message 9", "subgoals_reached is inf"),
        lambda d: run_steps(d / "inf.mcap", extra=['{"summary": {"subgoals_reached": Infinity}}']),
    ),
    "eval: pose of another type": Case(
        "eval", 2, ("/vtr/pose carries std_msgs/msg/String",), lambda d: pose_of_another_type(d / "pose.mcap")
    ),
    "eval: zstd bomb (declared)": Case(
        "eval", 2, ("declares 286.1 MiB", "cap"), put("bomb.mcap", mcap(IMAGE, image_bomb_chunk(10000, 1)))
    ),
    "eval: zstd bomb (lying)": Case(
        "eval",
        2,
        ("expands past the 4096 bytes it declares",),
        put("liar.mcap", mcap(IMAGE, image_bomb_chunk(10000, 1, declared=4096))),
    ),
    "eval: the repeat's --log": Case(
        "eval", 2, ("JSON", "--log"), put("run.jsonl", b'{"step": 0, "v": 0.1}\n' * 5)
    ),
    "eval: a PNG": Case("eval", 2, ("a PNG image",), put("picture.png", png_bomb(100))),
    "eval: a folder": Case("eval", 2, ("cannot read it as a bag",), lambda d: d / "folder"),
    "eval: route zip bomb": Case(
        "eval taught", 2, ("refusing",), lambda d: zip_bomb(d / "bomb_route.npz", {"images.npy": BIG_NPY})
    ),
    "collect: cut image": Case(
        "collect",
        2,
        ("/camera/image message 3 does not decode",),
        lambda d: bag_with(d / "cut_bag", "cut image"),
    ),
    "teach: cut image": Case(
        "teach", 2, ("/camera/image message 3 does not decode",), lambda d: d / "cut_bag"
    ),
    "collect: random bytes as a Twist": Case(
        "collect",
        2,
        ("/cmd_vel message 4 does not decode",),
        lambda d: bag_with(d / "rnd_bag", "random twist"),
    ),
    "teach: random bytes as a Twist": Case(
        "teach", 2, ("/cmd_vel message 4 does not decode",), lambda d: d / "rnd_bag"
    ),
    "collect: non-UTF-8 encoding": Case(
        "collect",
        2,
        ("/camera/image message 2 does not decode",),
        lambda d: bag_with(d / "enc_bag", "encoding"),
    ),
    "teach: non-UTF-8 encoding": Case(
        "teach", 2, ("/camera/image message 2 does not decode",), lambda d: d / "enc_bag"
    ),
    "teach: PNG decompression bomb": Case(
        "teach", 2, ("/camera/image message 0", "10000x10000", "4096x4096 cap"), png_bag
    ),
    "collect: honest 10000x10000 image": Case(
        "collect",
        2,
        ("declares 286.1 MiB",),
        put("big.mcap", mcap(BAG_IMAGE, TWIST, message(2, T0, twist()), image_bomb_chunk(10000, 1))),
    ),
    "collect: garbage ROS 1 bag": Case(
        "collect",
        2,
        ("garbage.bag", "cannot read it as a bag"),
        put("garbage.bag", b"#ROSBAG V2.0\n" + bytes(500)),
    ),
    "collect: garbage metadata.yaml": Case(
        "collect", 2, ("cannot read it as a bag",), lambda d: d / "yaml_bag"
    ),
    "train: dataset zip bomb": Case(
        "train", 2, ("refus",), lambda d: zip_bomb(d / "bomb_data.npz", {"images.npy": BIG_NPY})
    ),
    "train: sharded index with a bad entry": Case("train", 2, ("index.json",), lambda d: d / "shards"),
    "export: checkpoint zip bomb": Case(
        "export", 2, ("refusing",), lambda d: checkpoint_bomb(d / "bomb.pt", d / "small.pt")
    ),
    "export: cut checkpoint": Case(
        "export", 2, ("not a torch checkpoint",), lambda d: cut(d / "small.pt", d / "cut.pt", 0.5)
    ),
    "bench latency: cut model": Case(
        "bench", 2, ("cut.onnx",), lambda d: cut(ROOT / "models" / "velocitynet.onnx", d / "cut.onnx", 0.5)
    ),
}

RUNNER = """
import json, os, resource, sys, traceback
import bz2, cv2, lz4.frame, torch  # noqa: F401  (imports paid once, before the children fork)
import rosbags.highlevel, rosbags.rosbag1, rosbags.rosbag2, rosbags.typesys  # noqa: F401
import vtr.cli, vtr.evaluation.harness, vtr.evaluation.recorded_runs, vtr.export.cli  # noqa: F401
import vtr.pipeline, vtr.teach_cmd, vtr.training.collect, vtr.training.bag_teach  # noqa: F401
import vtr.runtime.bag_reader, vtr.runtime.mcap_read, vtr.benchmarks.cli  # noqa: F401
rosbags.typesys.get_typestore(rosbags.typesys.Stores.ROS2_HUMBLE)  # built once (0.6 s), then cached


def child(name, argv, err):
    fd = os.open(err, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(fd, 2)
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
    start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    try:
        code = vtr.cli.main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:
        traceback.print_exc()
        code = 99
    sys.stderr.flush()
    with open(err + ".kb", "w") as f:
        f.write(str(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - start))
    os._exit(code)


cases, out = json.loads(sys.argv[1]), sys.argv[2]
running, codes = {}, {}
for name, argv in cases.items():
    pid = os.fork()
    if pid == 0:
        child(name, argv, os.path.join(out, name + ".err"))
    running[pid] = name
    while len(running) >= 2 or (running and len(codes) + len(running) == len(cases)):  # two at a time (CI)
        pid, status = os.wait()
        codes[running.pop(pid)] = os.waitstatus_to_exitcode(status)
results = {}
for name, code in codes.items():
    err = os.path.join(out, name + ".err")
    kb = int(open(err + ".kb").read()) if os.path.exists(err + ".kb") else -1
    results[name] = {"code": code, "err": open(err).read(), "kb": kb}
print(json.dumps(results))
"""


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    d = tmp_path_factory.mktemp("crafted")
    shared(d)
    argvs, paths = {}, {}
    for i, (name, case) in enumerate(CASES.items()):  # in order: a later case may use an earlier one's file
        paths[name] = case.make(d)
        subs = {"{f}": str(paths[name]), "{out}": str(d / f"out{i}"), "{d}": str(d)}
        argvs[f"case{i}"] = [_sub(a, subs) for a in ARGV[case.argv]]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run(
        [sys.executable, "-c", RUNNER, json.dumps(argvs), str(d)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    raw = json.loads(proc.stdout.splitlines()[-1])
    return {
        name: {**raw[f"case{i}"], "path": paths[name], "out": d / f"out{i}"} for i, name in enumerate(CASES)
    }


def _sub(arg: str, subs: dict[str, str]) -> str:
    for key, value in subs.items():
        arg = arg.replace(key, value)
    return arg


@pytest.mark.parametrize("name", list(CASES))
def test_a_crafted_file_is_one_line_exit_2_and_bounded_memory(name: str, results: dict[str, dict]) -> None:
    r, case = results[name], CASES[name]
    err, path = r["err"], r["path"]
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert r["code"] == case.code, err
    if r["code"] == 2:
        assert len(lines) == 1 and path.name in lines[0], err
        assert not r["out"].exists(), f"{name} left {r['out']} behind"
    else:  # damaged but partly readable: read, with a warning naming the file
        assert lines and all("warning" in line and path.name in line for line in lines), err
    text = " ".join(lines)
    assert all(word in text for word in case.words), err
    size = path.stat().st_size if path.is_file() else sum(p.stat().st_size for p in path.iterdir())
    assert r["kb"] * 1024 <= max(4 * size, FIXED_CAP), (
        f"{name}: peak RSS grew {r['kb']} KB for a {size}-byte file"
    )
