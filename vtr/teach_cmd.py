"""`vtr teach`: the robot's teach (runtime/teach.py) and, on a desktop, a route from a drive recorded in a ROS
bag (`--bag`, training/bag_teach.py). Reading bags needs rosbags and, for compressed images, OpenCV, so it stays
off the robot board: `vtr-robot teach` is the live-robot teach alone."""

from __future__ import annotations

import argparse
import sys

from vtr.runtime import teach
from vtr.runtime.cliargs import config_from_args
from vtr.runtime.teach import TeachConfig
from vtr.training import bag_teach


def add_arguments(parser: argparse.ArgumentParser) -> None:
    teach.add_arguments(parser)
    bag_teach.add_arguments(parser)


def run_cli(args: argparse.Namespace) -> int:
    if not args.bag:
        return teach.run_cli(args)
    if args.drive or args.follow or args.route:
        print(
            "vtr teach: --bag makes a route from a recorded drive; leave out --route, --drive and --follow",
            file=sys.stderr,
        )
        return 2
    try:
        teach_cfg = config_from_args(TeachConfig, args)
    except ValueError as exc:
        print(f"vtr teach: {exc}", file=sys.stderr)
        return 2
    return bag_teach.run_cli(args, teach_cfg)
