"""`vtr bench link` smoke runs with tiny budgets: the harness measures what it says (the full runs are in
the issue's closing note, not here)."""

from __future__ import annotations

from vtr.benchmarks import link_faults, link_trials


def test_client_and_loop_fuzz_count_faults_and_find_no_desync_or_motion_after_a_bad_frame():
    client = link_faults.client_fuzz(n=20, seed=1)
    assert client["fuzzed_replies"] == 20 and client["clean_exchanges"] > 0
    assert client["desyncs"] == 0 and client["client_tracebacks"] == 0
    loop = link_faults.loop_fuzz(n=20, seed=1)
    assert loop["fuzzed_replies"] == 20 and sum(loop["next_request_after_a_bad_reply"].values()) > 0
    assert loop["nonzero_commands_after_a_bad_frame"] == 0 and loop["loop_tracebacks"] == 0


def test_silent_and_restart_trials_measure_from_the_robot_side():
    silent = link_trials.silent(trials=2, seed=1)
    assert len(silent["step_to_zero_s_all"]) == 2 and 0.1 < silent["step_to_zero_s_p100"] < 0.5
    assert silent["run_endings"] == ["link_lost"]
    restart = link_trials.restart(trials=2, seed=1)
    assert restart["ended_saying_restarted"] == 2 and restart["steps_executed_by_rebooted_robot"] == 0
