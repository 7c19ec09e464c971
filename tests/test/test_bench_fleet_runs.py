"""bench_fleet's choice of Stage speedup per fleet size (--speedup) and its resumable log folder (--logs): which
runs it makes, which it keeps, and what it refuses. No run starts here: `run` is reached only for kept results,
and the launch is replaced where a new run would start."""
import json
import subprocess

import pytest

from test_bench_metrics import load_bench_fleet


@pytest.fixture(scope="module")
def bf():
    return load_bench_fleet()


def parse(bf, *argv):
    return bf.make_parser().parse_args(list(argv))


def test_ten_robots_run_at_half_speed_and_the_rest_at_real_time_by_default(bf):
    args = parse(bf)
    assert [bf.speedup_of(args, n) for n in (2, 5, 9, 10)] == [1.0, 1.0, 1.0, 0.5]
    assert bf.launch_command(args, 10, True, 1, 11311)[-3] == "speedup:=0.5"
    assert bf.launch_command(args, 5, True, 1, 11311)[-3] == "speedup:=1"


def test_a_bare_factor_counts_for_every_n_not_named(bf):
    args = parse(bf, "--speedup", "2", "10:0.25")
    assert [bf.speedup_of(args, n) for n in (2, 10)] == [2.0, 0.25]
    assert [bf.speedup_of(parse(bf, "--speedup", "2"), n) for n in (2, 10)] == [2.0, 2.0]
    assert bf.speedup_of(parse(bf, "--speedup", "5:3"), 2) == 1.0        # nothing for N = 2: real time


def test_settings_of_runs_made_before_per_n_speedups_read_as_one_factor(bf):
    import argparse
    assert bf.speedup_of(argparse.Namespace(speedup=0.5), 2) == 0.5


@pytest.mark.parametrize("item", ["0", "-1", "fast", "10:", ":1", "0:1", "a:1", "10:0", "inf", "nan", "1:2:3"])
def test_a_speedup_that_is_not_a_factor_above_zero_is_refused(bf, item, capsys):
    with pytest.raises(SystemExit):
        parse(bf, "--speedup", item)
    assert "--speedup" in capsys.readouterr().err


def test_the_smallest_factor_and_n_are_accepted(bf):
    assert bf.speedup_item("1e-9") == (None, 1e-9)
    assert bf.speedup_item("1:0.5") == (1, 0.5)


def test_naming_an_n_twice_is_refused(bf, monkeypatch, capsys):
    monkeypatch.setattr(bf.subprocess, "Popen", refuse_launch)
    with pytest.raises(SystemExit):
        run_main(bf, monkeypatch, ["--speedup", "10:0.5", "10:1"])
    assert "names an N" in capsys.readouterr().err


def test_below_real_time_a_run_may_take_longer_in_proportion(bf):
    args = parse(bf)
    assert bf.time_limit(args, 5) == 1200
    assert bf.time_limit(args, 10) == 2400
    assert bf.time_limit(parse(bf, "--speedup", "2"), 10) == 1200     # faster than real time: no shorter
    assert bf.time_limit(parse(bf, "--time-limit", "99"), 10) == 99


def result(bf, args, n, t=40.0):
    return {"time_to_goal": {"robot_0": t}, "time_mean": t, "bench_settings": bf.run_settings(args, n)}


def write(path, content):
    with open(str(path), "w") as f:
        json.dump(content, f)


def test_a_kept_result_with_the_same_settings_is_not_run_again(bf, tmp_path, monkeypatch):
    args = parse(bf, "--layout", "deadend", "--robots", "10")
    args.layout = "deadend"
    write(tmp_path / "deadend_n10_s1_on.json", result(bf, args, 10))
    monkeypatch.setattr(bf.subprocess, "Popen", lambda *a, **k: pytest.fail("a kept result was run again"))
    assert bf.run(10, True, 1, args, str(tmp_path))["time_mean"] == 40.0


class LaunchStarted(Exception):
    pass


def refuse_launch(*_args, **_kwargs):
    raise LaunchStarted()


@pytest.mark.parametrize("kept", [
    None,                                          # nothing kept
    "not json",                                    # a run stopped while writing
    "[]",                                          # not a result
    json.dumps({"time_mean": 1.0}),                # its settings not recorded
    json.dumps({"time_mean": 1.0, "bench_settings": {"speedup": 1.0}}),     # made at another speedup
])
def test_a_missing_or_unreadable_result_is_run(bf, tmp_path, monkeypatch, kept):
    args = parse(bf, "--layout", "deadend", "--robots", "10")
    args.layout = "deadend"
    if kept is not None:
        (tmp_path / "deadend_n10_s1_on.json").write_text(kept)
    monkeypatch.setattr(bf.subprocess, "Popen", refuse_launch)
    with pytest.raises(LaunchStarted):
        bf.run(10, True, 1, args, str(tmp_path))


def test_a_new_result_is_saved_with_its_settings(bf, tmp_path, monkeypatch):
    args = parse(bf, "--layout", "corridors", "--robots", "10")
    args.layout = "corridors"

    class Launch:
        pid = 0

        def poll(self):
            return 0

    def bench(command, **_kwargs):
        write(command[command.index("--out") + 1], {"time_mean": 33.0, "time_to_goal": {"robot_0": 33.0}})
    monkeypatch.setattr(bf.subprocess, "Popen", lambda *a, **k: Launch())
    monkeypatch.setattr(bf.subprocess, "run", bench)
    got = bf.run(10, False, 2, args, str(tmp_path))
    with open(str(tmp_path / "corridors_n10_s2_off.json")) as f:
        saved = json.load(f)
    assert got == saved and saved["bench_settings"]["speedup"] == 0.5 and saved["time_mean"] == 33.0


def run_main(bf, monkeypatch, argv):
    """bench_fleet's main on argv; a run it would start raises LaunchStarted unless the test set its own Popen."""
    if bf.subprocess.Popen is subprocess.Popen:
        monkeypatch.setattr(bf.subprocess, "Popen", refuse_launch)
    monkeypatch.setattr("sys.argv", ["bench_fleet"] + argv)
    return bf.main()


def test_results_made_with_other_settings_are_refused_before_anything_runs(bf, tmp_path, monkeypatch, capsys):
    made = parse(bf, "--speedup", "1")
    write(tmp_path / "deadend_n10_s1_on.json", result(bf, made, 10))
    monkeypatch.setattr(bf.subprocess, "Popen", lambda *a, **k: pytest.fail("a run started"))
    with pytest.raises(SystemExit):
        run_main(bf, monkeypatch, ["--layout", "deadend", "--robots", "10", "--logs", str(tmp_path)])
    err = capsys.readouterr().err
    assert "deadend_n10_s1_on.json: made with speedup 1.0, this bench asks 0.5" in err, err


def test_results_without_their_settings_are_refused(bf, tmp_path, monkeypatch, capsys):
    write(tmp_path / "deadend_n2_s3_off.json", {"time_mean": 1.0, "time_to_goal": {}})
    monkeypatch.setattr(bf.subprocess, "Popen", lambda *a, **k: pytest.fail("a run started"))
    with pytest.raises(SystemExit):
        run_main(bf, monkeypatch, ["--layout", "deadend", "--robots", "2", "--logs", str(tmp_path)])
    assert "deadend_n2_s3_off.json: made without its settings recorded" in capsys.readouterr().err


def test_a_complete_folder_reports_without_running_anything(bf, tmp_path, monkeypatch, capsys):
    args = parse(bf, "--layout", "deadend", "--robots", "2", "--seed", "1", "2")
    args.layout = "deadend"
    for seed in (1, 2):
        for sharing, t in ((True, 30.0), (False, 60.0)):
            r = dict(result(bf, args, 2, t), recoveries=0, stuck=0, entered_blocked_corridor=0, reached=2,
                     time_p95=t, distance_m=1.0, dispatch=[{"robot": "robot_0"}, {"robot": "robot_1"}],
                     broker_bytes_per_robot_per_min=1.0, payload_bytes_bridges=1, latency_ms_p50=1.0,
                     latency_ms_p99=1.0, latency_ms=[1.0], obstacles=1, obstacles_robots=0, obstacles_walls=0)
            write(tmp_path / ("deadend_n2_s%d_%s.json" % (seed, "on" if sharing else "off")), r)
    monkeypatch.setattr(bf.subprocess, "Popen", lambda *a, **k: pytest.fail("a run started"))
    table = tmp_path / "fleet.md"
    rc = run_main(bf, monkeypatch, ["--layout", "deadend", "--robots", "2", "--seed", "1", "2", "--logs",
                                    str(tmp_path), "--table", str(table)])
    assert rc == 0
    assert "| 2 | 1 2 | 30.0 ± 0.0 | 60.0 ± 0.0 | 0.50 |" in table.read_text()
    assert capsys.readouterr().out.count("kept from an earlier run") == 4


def test_a_logs_path_that_cannot_be_a_folder_is_refused(bf, tmp_path, monkeypatch, capsys):
    (tmp_path / "file").write_text("")
    with pytest.raises(SystemExit):
        run_main(bf, monkeypatch, ["--robots", "2", "--logs", str(tmp_path / "file" / "sub")])
    assert "--logs" in capsys.readouterr().err
