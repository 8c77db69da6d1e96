"""The MPC-vs-BC study's pieces: the imperfect-driving relabel, the intervals and the table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from studies import mpc_vs_bc as study
from studies.mpc_vs_bc_table import render, sign_test


def test_the_log_leads_the_wheels_by_the_lag_and_holds_the_under_steered_turn() -> None:
    commands = np.zeros((10, 2), np.float32)
    commands[:9, 0] = np.arange(9) * 0.01  # executed v after frames 0..8; frame 9 ends the episode
    commands[:9, 1] = 0.5
    episodes = np.zeros(10, np.int32)
    old = study.NOISE
    study.NOISE = (0.0, 0.0)
    try:
        logged, params = study.relabel(commands, episodes, np.random.default_rng(3))
    finally:
        study.NOISE = old
    lag, gain = params[0]
    assert lag in study.LAGS and study.GAIN[0] <= gain <= study.GAIN[1]
    k = int(lag)
    np.testing.assert_allclose(
        logged[: 9 - k, 0], commands[k:9, 0], atol=1e-6
    )  # logged at t = executed at t+lag
    np.testing.assert_allclose(logged[:9, 1], 0.5 / gain, atol=1e-5)  # the base turned by gain x the log
    assert np.all(logged[9] == 0)  # an episode's last frame has no command


def test_wilson_and_the_sign_test() -> None:
    lo, hi = study.wilson(16, 16)
    assert hi == 1.0 and 0.79 < lo < 0.81
    lo, hi = study.wilson(8, 16)
    assert 0.27 < lo < 0.29 and 0.71 < hi < 0.73
    assert sign_test(0, 0) == 1.0
    assert abs(sign_test(6, 0) - 2 / 64) < 1e-12


def test_the_table_counts_completions_and_pairs_mpc_with_bc(tmp_path: Path) -> None:
    (tmp_path / "eval").mkdir()

    def run(route: str, seed: int, ok: bool) -> dict:
        return {
            "route": route,
            "seed": seed,
            "ran": True,
            "completed": ok,
            "status": "finished",
            "position_error_m": 0.01,
            "steps_per_taught_step": 1.5,
        }

    mpc = {"runs": [run("a", 0, True), run("a", 1, True)]}
    bc = {"runs": [run("a", 0, True), run("a", 1, False)]}
    (tmp_path / "eval" / "clean_mpc_s0_s300.json").write_text(json.dumps(mpc))
    (tmp_path / "eval" / "clean_bc_s0_s300.json").write_text(json.dumps(bc))
    text = render(tmp_path, "cmd")
    assert "**2/2**" in text and "**1/2**" in text
    assert (
        "| clean_mpc_s0_s300 vs clean_bc_s0_s300 | 2 | 1 | 0 | 1.00 | 10.0 / 10.0 (MPC lower in 0 of 1) |"
        in text
    )


def test_the_seeds_table_pools_mpc_against_bc_paired_by_seed_route_and_noise(tmp_path: Path) -> None:
    from studies.mpc_vs_bc_table import render_seeds

    def doc(done: list[bool]) -> dict:
        runs = [
            {
                "ran": True,
                "completed": c,
                "status": "finished" if c else "lost",
                "position_error_m": 0.01,
                "steps_per_taught_step": 1.0,
                "route": f"r{i}",
                "seed": 0,
            }
            for i, c in enumerate(done)
        ]
        return {"runs": runs}

    ev, rd = tmp_path / "eval", tmp_path / "runs"
    ev.mkdir()
    outcomes = {
        "clean_mpc_s0": [True, True],
        "clean_bc_s0": [True, False],
        "clean_mpc_s1": [True, False],
        "clean_bc_s1": [False, False],
    }
    for label, done in outcomes.items():
        (ev / f"{label}.json").write_text(json.dumps(doc(done)))
        for stage in (f"{label}_a", label):
            (rd / stage).mkdir(parents=True)
            (rd / stage / "metrics.jsonl").write_text('{"step": 25}\n{"step": 50}\n')
    text = render_seeds(ev, rd)
    assert "| clean | MPC (w1 0.8, w2 0.3) | 0 | 50 + 50 |" in text
    # pooled over the two seeds: MPC 3 of 4, BC 1 of 4; MPC alone completed 2 paired runs, BC none
    assert "| clean | 3/4 | 1/4 | 4 | 2 | 0 | 0.50 |" in text
