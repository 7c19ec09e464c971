"""bench_flood's and bench_bridge's latency lines: the sample count is printed, says why below 30, and a delivery that
never read lethal counts as late (infinitely) in the p99, not left out."""
import importlib.machinery
import importlib.util
import math
import os

SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "bench_flood")
PER_ROBOT = dict(bridge_rate_limited=0, bridge_queue_full=0, handler_quota=0, handler_rate=0, held=1, applied=1,
                 handled=1, layer_cpu=0.1, handler_cpu=0.1, bridge_cpu=0.1)


def load():
    loader = importlib.machinery.SourceFileLoader("bench_flood", SCRIPT)
    spec = importlib.util.spec_from_loader("bench_flood", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def report(bench, latencies, lost):
    lines = []
    bench.log = lines.append
    run = dict(load="1.0", flood_sent=0.1, drain=1.0, samples=len(latencies) + lost, latencies=latencies, lost=lost,
               robots={r: dict(PER_ROBOT) for r in bench.ROBOTS})
    missed = bench.report_flood([run])
    return {line.split()[0]: line for line in lines if line.strip()}, missed


def test_samples_stated_and_why_below_30():
    bench = load()
    rows, _ = report(bench, [0.1] * 30, 0)
    assert rows["good_latency_samples_n"].split()[1] == "30" and "< 30" not in rows["good_latency_samples_n"]
    rows, _ = report(bench, [0.1] * 29, 0)
    assert "run 1: n = 29 < 30: the flood drained so fast" in rows["good_latency_samples_n"]


def test_a_lost_delivery_is_late_in_the_p99():
    bench = load()
    rows, missed = report(bench, [0.1] * 98, 2)
    assert math.isinf(float(rows["good_latency_p99_ms"].split()[1]))
    assert "good_latency_p99" in missed
    rows, missed = report(bench, [0.1] * 100, 0)
    assert float(rows["good_latency_p99_ms"].split()[1]) == 100.0 and not missed


def test_the_bridge_bench_states_n_and_why_below_30():
    loader = importlib.machinery.SourceFileLoader("bench_bridge", SCRIPT.replace("bench_flood", "bench_bridge"))
    spec = importlib.util.spec_from_loader("bench_bridge", loader)
    bench = importlib.util.module_from_spec(spec)
    loader.exec_module(bench)
    assert bench.samples_note(30, 30) == "n = 30 updates"
    assert bench.samples_note(29, 29) == "n = 29 < 30: --rate x --seconds sends only 29 updates"
