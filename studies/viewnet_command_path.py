"""`python -m studies.viewnet_command_path --data DATASET` (from the checkout's root): does ViewNet, trained
from nothing, learn to use the command, or does it stay at copy-the-input?

The ViewNet loop of ``training.train`` (Adam, the same batches), instrumented: every ``--every`` steps, on
the first ``--val-batches`` held-out batches in eval mode, the L1 ratio to the copy-the-input baseline, the
mean |flow offset| and how much of it the command moves: mean |flow(I, c) - flow(I, 0)| in grid units
(0 when the decoder ignores the command). The variants change one thing at the start:
``--velocity-gain`` (ViewNetConfig.velocity_gain; 1 = before the fix), ``--head-init`` (the flow head's
default init times this, instead of zeros), ``--command-init`` (the stem's command weights times this).
Prints one JSON line per measurement.
"""

from __future__ import annotations

import argparse
import json
import time

import torch


def measure(args: argparse.Namespace) -> list[dict[str, float]]:
    from vtr.training.config import get_preset, override
    from vtr.training.dataset import load_dataset
    from vtr.training.distributed import Dist
    from vtr.training.losses import viewnet_loss
    from vtr.training.models import ViewNet
    from vtr.training.windows import Windows

    torch.set_num_threads(args.threads)
    preset = get_preset(args.preset)
    model_cfg = override(preset.viewnet, velocity_gain=args.velocity_gain)
    cfg = override(preset.train_viewnet, steps=args.steps, seed=args.seed, lr=args.lr)
    data = load_dataset(args.data, image_size=model_cfg.image_size)
    windows = Windows(data, 2, cfg, Dist())
    torch.manual_seed(cfg.seed)  # as train_viewnet: the initial weights come from the seed
    net = ViewNet(model_cfg)
    if args.head_init:
        net.flow.reset_parameters()
        with torch.no_grad():
            net.flow.weight.mul_(args.head_init)
            net.flow.bias.zero_()
    with torch.no_grad():
        net.stem[0].weight[-2:].mul_(args.command_init)  # the 2 input channels the command enters on
    optim = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    held_out = [windows.gather(s) for s in windows.val_batches(cfg.batch_size, args.val_batches)]
    batches = windows.train_batches(cfg.batch_size, cfg.seed, 0, Dist())
    rows, t0 = [], time.perf_counter()
    for step in range(1, cfg.steps + 1):
        frames, commands = windows.gather(next(batches))
        loss = viewnet_loss(net, frames, commands[:, 0])
        optim.zero_grad(set_to_none=True)
        loss.backward()
        optim.step()
        if step % args.every == 0 or step == cfg.steps:
            rows.append({"step": step, **_held_out(net, held_out), "elapsed_s": time.perf_counter() - t0})
            print(json.dumps({k: round(v, 6) for k, v in rows[-1].items()}), flush=True)
    return rows


@torch.no_grad()
def _held_out(net: torch.nn.Module, batches: list) -> dict[str, float]:
    net.eval()
    l1 = copy = moved = flow = 0.0
    for frames, commands in batches:
        image, c = frames[:, 0], commands[:, 0]
        l1 += float((net(image, c) - frames[:, 1]).abs().mean())
        copy += float((image - frames[:, 1]).abs().mean())
        offset = net.flow_offset(image, c)
        moved += float((offset - net.flow_offset(image, torch.zeros_like(c))).abs().mean())
        flow += float(offset.abs().mean())
    net.train()
    n = len(batches)
    return {"ratio_to_copy": l1 / copy, "flow": flow / n, "flow_from_command": moved / n}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m studies.viewnet_command_path", description=__doc__)
    p.add_argument("--data", required=True, help="dataset (`vtr collect`)")
    p.add_argument("--preset", default="default")
    p.add_argument("--steps", type=int, default=600)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--every", type=int, default=100, help="steps between measurements")
    p.add_argument("--val-batches", type=int, default=12)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--velocity-gain", type=float, default=1.0, help="1: before the fix; the presets use 10")
    p.add_argument(
        "--head-init", type=float, default=0.0, help="flow head: default init times this (0: zeros)"
    )
    p.add_argument("--command-init", type=float, default=1.0, help="the stem's command weights times this")
    return p


def main(argv: list[str] | None = None) -> int:
    measure(parser().parse_args(argv))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
