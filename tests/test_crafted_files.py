"""Crafted and broken files given to the commands that read them (issue 21): `vtr eval --run` (MCAP runs and
the taught route), `vtr collect --bag` and `vtr teach --bag` (ROS 1/2 bags), `vtr train` (datasets), `vtr
export` (checkpoints), `vtr bench latency` (ONNX).

Each case runs the real command line (``vtr.cli.main``) in a child forked from one warm process (imports paid
once), and must end with the expected exit code and one line on stderr naming the file (and the topic and
message index where one message is at fault), never a traceback; a damaged file that still reads gives a
warning line and a result. Memory: the child's peak RSS above what it started with stays under 4x the file's
size or the documented fixed cap (runtime.bag_caps: 64 MiB a chunk), where the bombs here took 630 MB before.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from crafted_files import (
    STORE,
    T0,
    channel,
    compressed_image,
    image_bomb_chunk,
    mcap,
    message,
    png_bomb,
    raw_bag,
    schema,
    twist,
    zip_bomb,
)
from numpy.lib import format as npy_format

from vtr.runtime.bag_caps import MAX_CHUNK_BYTES
from vtr.runtime.mcap_log import McapRunWriter
from vtr.runtime.route import Route

ROOT = Path(__file__).resolve().parents[1]
BAG_TOPICS = {"/camera/image": "sensor_msgs/msg/Image", "/cmd_vel": "geometry_msgs/msg/Twist"}
#: The child's peak RSS may rise by 4x the file's size or by this much (the per-chunk cap), whichever is more.
FIXED_CAP = MAX_CHUNK_BYTES

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


def _run_steps(path: Path, steps: int = 9, side: int = 8, extra: list[str] | None = None) -> Path:
    with McapRunWriter(path) as writer:
        for k in range(steps):
            image = np.full((side, side, 3), k, np.uint8)
            writer.record(
                {
                    "stamp": 0.1 * k,
                    "image": image,
                    "subgoal_image": image,
                    "v": 0.25,
                    "w": 0.0,
                    "pose": (0.025 * k, 0.0, 0.0),
                    "error": 5.0,
                    "subgoal": k // 2,
                }
            )
        for text in extra or []:
            writer._write("/vtr/step", writer._last_ns + 1, STORE.types["std_msgs/msg/String"](data=text))
        writer.record_summary({"status": "finished", "subgoals_reached": 5, "steps": steps})
    return path


def _pose_of_another_type(path: Path) -> Path:
    string = STORE.types["std_msgs/msg/String"](data="x")
    raw = bytes(STORE.serialize_cdr(string, "std_msgs/msg/String"))
    folder = raw_bag(path.with_suffix(""), {"/vtr/pose": "std_msgs/msg/String"}, [("/vtr/pose", T0, raw)])
    shutil.move(folder / f"{folder.name}.mcap", path)
    shutil.rmtree(folder)
    return path


def _cut(source: Path, path: Path, keep: float) -> Path:
    data = source.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    return path


def _corrupt_middle(source: Path, path: Path) -> Path:
    data = bytearray(source.read_bytes())
    mid = len(data) // 2
    data[mid - 2048 : mid + 2048] = np.random.default_rng(4).integers(0, 256, 4096, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))
    return path


def _bag_with(path: Path, bad: str) -> Path:
    """A 10-frame bag whose frame or command 2..4 is bad: a cut image, random bytes, a non-UTF-8 encoding."""
    messages = []
    for k in range(10):
        t = T0 + k * 10**8
        image = STORE.types["sensor_msgs/msg/Image"](
            header=STORE.types["std_msgs/msg/Header"](
                stamp=STORE.types["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9),
                frame_id="c",
            ),
            height=4,
            width=4,
            encoding="rgb8",
            is_bigendian=0,
            step=12,
            data=np.zeros(48, np.uint8),
        )
        raw_image = bytes(STORE.serialize_cdr(image, "sensor_msgs/msg/Image"))
        raw_cmd = twist()
        if bad == "cut image" and k == 3:
            raw_image = raw_image[: len(raw_image) // 2]
        if bad == "random twist" and k == 4:
            raw_cmd = np.random.default_rng(k).integers(0, 256, 16, dtype=np.uint8).tobytes()
        if bad == "encoding" and k == 2:
            raw_image = raw_image.replace(b"rgb8", b"\xff\xfe\x80\x81")
        messages += [("/camera/image", t, raw_image), ("/cmd_vel", t, raw_cmd)]
    return raw_bag(path, BAG_TOPICS, messages)


def _npy_header(shape: tuple[int, ...], dtype: str) -> bytes:
    out = io.BytesIO()
    npy_format.write_array_header_1_0(out, {"descr": dtype, "fortran_order": False, "shape": shape})
    return out.getvalue()


def _checkpoint_bomb(path: Path, small: Path) -> Path:
    """A torch checkpoint whose tensor's storage is a 100 MB member deflated to a few KB."""
    import zipfile

    torch.save({"kind": "velocitynet", "w": torch.zeros(4)}, small)
    with zipfile.ZipFile(small) as z:
        members = {i.filename: z.read(i) for i in z.infolist()}
    name = next(n for n in members if n.endswith("data/0"))
    members[name] = (b"", 100 * 2**20)
    return zip_bomb(path, members)


def build(tmp: Path) -> dict[str, tuple[list[str], int, list[str], Path]]:
    """name -> (argv, exit code, words its one line must hold, the crafted file)."""
    route = tmp / "route.npz"
    Route(
        images=np.zeros((13, 8, 8, 3), np.uint8),
        poses=[(0.05 * k, 0.0, 0.0) for k in range(13)],
        commands=np.zeros((13, 2)),
    ).save(route)
    good = _run_steps(tmp / "good.mcap")
    long = _run_steps(tmp / "long.mcap", steps=25, side=96)  # two chunks (1 MiB, 0.3 MiB)
    longer = _run_steps(tmp / "longer.mcap", steps=40, side=96)  # three: the middle of the file is in the 2nd
    image_topic = schema(1, "sensor_msgs/msg/Image") + channel(1, 1, "/vtr/camera/image")
    bag_topics = schema(1, "sensor_msgs/msg/Image") + channel(1, 1, "/camera/image")
    bag_topics += schema(2, "geometry_msgs/msg/Twist") + channel(2, 2, "/cmd_vel")
    files: dict[str, Path] = {}

    def put(name: str, data: bytes) -> Path:
        files[name] = tmp / name
        files[name].write_bytes(data)
        return files[name]

    png = png_bomb(10000)
    e = ["eval", "--run", "{f}", "--taught", str(route)]
    c = [
        "collect",
        "--bag",
        "{f}",
        "--image-topic",
        "/camera/image",
        "--cmd-topic",
        "/cmd_vel",
        "--out",
        "{out}",
    ]
    t = [
        "teach",
        "--bag",
        "{f}",
        "--image-topic",
        "/camera/image",
        "--cmd-topic",
        "/cmd_vel",
        "--out",
        "{out}",
    ]
    cases = {
        "eval: empty": (e, 2, ["empty"], put("empty.mcap", b"")),
        "eval: garbage": (e, 2, ["not an MCAP"], put("garbage.mcap", bytes(range(256)) * 4)),
        "eval: cut in its only chunk": (
            e,
            2,
            ["no poses", "damaged", "cut off"],
            _cut(good, tmp / "half.mcap", 0.5),
        ),
        "eval: cut in its last chunk": (
            e,
            0,
            ["warning", "damaged", "cut off"],
            _cut(long, tmp / "cut.mcap", 0.8),
        ),
        "eval: 4 KiB corrupted in the middle": (
            e,
            0,
            ["warning", "damaged"],
            _corrupt_middle(longer, tmp / "mid.mcap"),
        ),
        "eval: step [1,2,3]": (
            e,
            2,
            ["/vtr/step message 9", "list"],
            _run_steps(tmp / "list.mcap", extra=["[1,2,3]"]),
        ),
        "eval: summary 5": (
            e,
            2,
            ["/vtr/step message 9", "summary is a JSON int"],
            _run_steps(tmp / "s5.mcap", extra=['{"summary": 5}']),
        ),
        "eval: subgoals_reached Infinity": (
            e,
            2,
            ["/vtr/step message 9", "subgoals_reached is inf"],
            _run_steps(tmp / "inf.mcap", extra=['{"summary": {"subgoals_reached": Infinity}}']),
        ),
        "eval: pose of another type": (
            e,
            2,
            ["/vtr/pose carries std_msgs/msg/String"],
            _pose_of_another_type(tmp / "pose.mcap"),
        ),
        "eval: zstd bomb (declared)": (
            e,
            2,
            ["declares 286.1 MiB", "cap"],
            put("bomb.mcap", mcap(image_topic, image_bomb_chunk(10000, 1))),
        ),
        "eval: zstd bomb (lying)": (
            e,
            2,
            ["expands past the 4096 bytes it declares"],
            put("liar.mcap", mcap(image_topic, image_bomb_chunk(10000, 1, declared=4096))),
        ),
        "eval: the repeat's --log": (
            e,
            2,
            ["JSON", "--log"],
            put("run.jsonl", b'{"step": 0, "v": 0.1}\n' * 5),
        ),
        "eval: a PNG": (e, 2, ["a PNG image"], put("picture.png", png)),
        "eval: a folder": (e, 2, ["cannot read it as a bag"], tmp / "folder"),
        "eval: route zip bomb": (
            ["eval", "--run", str(good), "--taught", "{f}"],
            2,
            ["refusing"],
            zip_bomb(
                tmp / "bomb_route.npz", {"images.npy": (_npy_header((10**6, 8, 8, 3), "|u1"), 192 * 10**6)}
            ),
        ),
        "collect: cut image": (
            c,
            2,
            ["/camera/image message 3 does not decode"],
            _bag_with(tmp / "cut_bag", "cut image"),
        ),
        "teach: cut image": (t, 2, ["/camera/image message 3 does not decode"], tmp / "cut_bag"),
        "collect: random bytes as a Twist": (
            c,
            2,
            ["/cmd_vel message 4 does not decode"],
            _bag_with(tmp / "rnd_bag", "random twist"),
        ),
        "teach: random bytes as a Twist": (t, 2, ["/cmd_vel message 4 does not decode"], tmp / "rnd_bag"),
        "collect: non-UTF-8 encoding": (
            c,
            2,
            ["/camera/image message 2 does not decode"],
            _bag_with(tmp / "enc_bag", "encoding"),
        ),
        "teach: non-UTF-8 encoding": (t, 2, ["/camera/image message 2 does not decode"], tmp / "enc_bag"),
        "teach: PNG decompression bomb": (
            t,
            2,
            ["/camera/image message 0", "10000x10000", "4096x4096 cap"],
            raw_bag(
                tmp / "png_bag",
                {"/camera/image": "sensor_msgs/msg/CompressedImage", "/cmd_vel": BAG_TOPICS["/cmd_vel"]},
                [("/camera/image", T0, compressed_image(png, T0)), ("/cmd_vel", T0, twist())],
            ),
        ),
        "collect: honest 10000x10000 image": (
            c,
            2,
            ["declares 286.1 MiB"],
            put("big.mcap", mcap(bag_topics, message(2, T0, twist()), image_bomb_chunk(10000, 1))),
        ),
        "collect: garbage ROS 1 bag": (
            c,
            2,
            ["garbage.bag", "cannot read it as a bag"],
            put("garbage.bag", b"#ROSBAG V2.0\n" + bytes(500)),
        ),
        "collect: garbage metadata.yaml": (c, 2, ["cannot read it as a bag"], tmp / "yaml_bag"),
        "train: dataset zip bomb": (
            ["train", "viewnet", "--preset", "tiny", "--data", "{f}", "--out", "{out}"],
            2,
            ["refus"],
            zip_bomb(
                tmp / "bomb_data.npz", {"images.npy": (_npy_header((10**6, 8, 8, 3), "|u1"), 192 * 10**6)}
            ),
        ),
        "train: sharded index with a bad entry": (
            ["train", "viewnet", "--preset", "tiny", "--data", "{f}", "--out", "{out}"],
            2,
            ["index.json"],
            tmp / "shards",
        ),
        "export: checkpoint zip bomb": (
            ["export", "--checkpoint", "{f}", "--out", "{out}"],
            2,
            ["refusing"],
            _checkpoint_bomb(tmp / "bomb.pt", tmp / "small.pt"),
        ),
        "export: cut checkpoint": (
            ["export", "--checkpoint", "{f}", "--out", "{out}"],
            2,
            ["not a torch checkpoint"],
            _cut(tmp / "small.pt", tmp / "cut.pt", 0.5),
        ),
        "bench latency: cut model": (
            ["bench", "latency", "--model", "{f}"],
            2,
            ["cut.onnx"],
            _cut(ROOT / "models" / "velocitynet.onnx", tmp / "cut.onnx", 0.5),
        ),
    }
    (tmp / "shards").mkdir()
    (tmp / "shards" / "index.json").write_text(
        json.dumps({"format": "vtr-shards", "format_version": 1, "shards": [5]})
    )
    (tmp / "folder").mkdir()
    (tmp / "yaml_bag").mkdir()
    (tmp / "yaml_bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: [1, 2\n")
    return cases


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    tmp = tmp_path_factory.mktemp("crafted")
    cases = build(tmp)
    argvs = {}
    for i, (argv, _, _, path) in enumerate(cases.values()):
        out = tmp / f"out{i}"
        argvs[f"case{i}"] = [a.replace("{f}", str(path)).replace("{out}", str(out)) for a in argv]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run(
        [sys.executable, "-c", RUNNER, json.dumps(argvs), str(tmp)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    raw = json.loads(proc.stdout.splitlines()[-1])
    return {
        name: {**raw[f"case{i}"], "path": path, "code_expected": code, "words": words, "out": tmp / f"out{i}"}
        for i, (name, (_, code, words, path)) in enumerate(cases.items())
    }


CASE_NAMES = [
    "eval: empty",
    "eval: garbage",
    "eval: cut in its only chunk",
    "eval: cut in its last chunk",
    "eval: 4 KiB corrupted in the middle",
    "eval: step [1,2,3]",
    "eval: summary 5",
    "eval: subgoals_reached Infinity",
    "eval: pose of another type",
    "eval: zstd bomb (declared)",
    "eval: zstd bomb (lying)",
    "eval: the repeat's --log",
    "eval: a PNG",
    "eval: a folder",
    "eval: route zip bomb",
    "collect: cut image",
    "teach: cut image",
    "collect: random bytes as a Twist",
    "teach: random bytes as a Twist",
    "collect: non-UTF-8 encoding",
    "teach: non-UTF-8 encoding",
    "teach: PNG decompression bomb",
    "collect: honest 10000x10000 image",
    "collect: garbage ROS 1 bag",
    "collect: garbage metadata.yaml",
    "train: dataset zip bomb",
    "train: sharded index with a bad entry",
    "export: checkpoint zip bomb",
    "export: cut checkpoint",
    "bench latency: cut model",
]


@pytest.mark.parametrize("name", CASE_NAMES)
def test_a_crafted_file_is_one_line_exit_2_and_bounded_memory(name: str, results: dict[str, dict]) -> None:
    r = results[name]
    err = r["err"]
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert r["code"] == r["code_expected"], err
    path = r["path"]
    if r["code"] == 2:
        assert len(lines) == 1, err
        assert path.name in lines[0] or str(path) in lines[0], err
        assert not r["out"].exists(), f"{name} left {r['out']} behind"
    else:  # damaged but partly readable: read, with a warning naming the file
        assert lines and all("warning" in line and path.name in line for line in lines), err
    text = " ".join(lines)
    assert all(word in text for word in r["words"]), err
    size = path.stat().st_size if path.is_file() else sum(p.stat().st_size for p in path.iterdir())
    assert r["kb"] * 1024 <= max(4 * size, FIXED_CAP), (
        f"{name}: peak RSS grew {r['kb']} KB for a {size}-byte file"
    )


def test_every_case_is_listed(results: dict[str, dict]) -> None:
    assert sorted(results) == sorted(CASE_NAMES)
