#!/usr/bin/python3
"""Runs the benchmarks: all of them, or those named.

Usage: run_bench.py [NAME ...]        (make bench, or make bench NAME=core)

Each benchmark prints its figures as it goes (ratios against a baseline measured in the
same run); the output is also kept in out/bench/NAME.txt. A target missed is printed as
NOT MET with its figure and listed in the summary, but fails nothing (these machines are
noisy); a benchmark that crashed or could not run exits non-zero, and then so does this
runner, after the others ran.
"""
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEVEL = os.path.join(ROOT, "catkin_ws", "devel")
OUT = os.path.join(ROOT, "out", "bench")

# name: (command, what it measures)
BENCHMARKS = {
    "core": ([os.path.join(DEVEL, "lib", "sharing_layer_cpp", "bench_core")],
             "sharing layer core: per-scan cost of monitoring vs raytrace + mark"),
    "plugin_cycle": ([sys.executable, os.path.join(ROOT, "scripts", "bench_plugin_flags")],
                     "costmap_2d plugin: whole update cycle and scan pass against upstream ObstacleLayer, wall and CPU "
                     "clock, at -O2 and -O3 (each against upstream built alike)"),
    "layer_updates": ([sys.executable, os.path.join(ROOT, "sharing_layer_cpp", "scripts", "bench_layer_updates")],
                      "what applying a shared obstacle costs the layer against the handler, as nodes, with 10, 1,000 "
                      "and 10,000 obstacles held"),
    "bindings": ([sys.executable, os.path.join(ROOT, "sharing_layer_cpp", "scripts", "bench_bindings")],
                 "pybind11 call overhead as a ratio of process_scan"),
    "handler": ([sys.executable, os.path.join(ROOT, "sharing_handler_py", "scripts", "bench_handler")],
                "SharingHandler: updates/s, latency, memory per obstacle"),
    "bridge": ([sys.executable, os.path.join(ROOT, "coaty_bridge", "scripts", "bench_bridge")],
               "Coaty bridge over mosquitto: events/s, latency, compact vs plain bytes"),
    "fleet_scale": ([sys.executable, os.path.join(ROOT, "coaty_bridge", "scripts", "bench_fleet_scale")],
                    "100 simulated robots on one mosquitto (latency to every robot that must apply an update, "
                    "CPU, memory, bytes by kind), then on bridged brokers (--brokers, --bridged-robots)"),
    "join": ([sys.executable, os.path.join(ROOT, "coaty_bridge", "scripts", "bench_join")],
             "a robot joining a running fleet of 40 (400 obstacles held by each): Resolves, bytes and time until "
             "it has every obstacle, creator answers vs everyone answers"),
    "flood": ([sys.executable, os.path.join(ROOT, "coaty_bridge", "scripts", "bench_flood")],
              "one login floods 5,000 valid new obstacles at 3 robots' bridge, handler and costmap nodes: p99 "
              "latency of another robot's obstacle into the costmaps, CPU per update of layer and handler, handler "
              "cost per update with 10,000 vs 10 held"),
    "sim": ([sys.executable, os.path.join(ROOT, "fleet_sim", "scripts", "bench_sim")],
            "simulator: real-time factor for 2 and 20 robots"),
    "nav": ([sys.executable, os.path.join(ROOT, "fleet_nav", "scripts", "bench_nav")],
            "navigation host: C++ A* and inflation vs a Python/SciPy baseline"),
    "replay": ([sys.executable, os.path.join(ROOT, "sharing_replay", "scripts", "bench_replay")],
               "offline bag replay: real-time factor on a 10-minute two-robot bag"),
    "lifecycle": ([sys.executable, os.path.join(ROOT, "tests", "scripts", "bench_lifecycle"),
                   "--table", os.path.join(OUT, "lifecycle.md")],
                  "shared obstacle lifecycle: followers sent 10 s .. 15 min after a block was found, and after it "
                  "was removed (two-corridor world, sharing on vs off)"),
    "fleet": ([sys.executable, os.path.join(ROOT, "tests", "scripts", "bench_fleet"), "--layout", "all",
               "--logs", os.path.join(OUT, "fleet_runs"),
               "--table", os.path.join(OUT, "fleet.md"), "--chart", os.path.join(OUT, "fleet.png")],
              "fleet benefit on upstream move_base and Stage: N = 2, 5, 10 robots in the facility, dead-end and "
              "two-corridor worlds, sharing on vs off, 3 seeds (tables and charts out/bench/fleet_<world>.md/png; "
              "runs kept in out/bench/fleet_runs: run again, only the missing ones run)"),
}


def script_of(command):
    """The benchmark's program: the script a Python command runs, else the binary itself (the arguments after it,
    such as fleet's --chart PATH, are not the program)."""
    return command[1] if command[0] == sys.executable and len(command) > 1 else command[0]


def run(name):
    command, what = BENCHMARKS[name]
    script = script_of(command)
    print("=== bench %s: %s" % (name, what), flush=True)
    if not os.path.exists(script):
        print("bench %s: %s does not exist (not built, or not written yet)" % (name, script), flush=True)
        return "missing"
    os.makedirs(OUT, exist_ok=True)
    log_path = os.path.join(OUT, name + ".txt")
    start = time.time()
    missed = []
    with open(log_path, "w") as log:
        proc = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                universal_newlines=True, bufsize=1)
        for line in proc.stdout:
            sys.stdout.write(line)
            log.write(line)
            if "NOT MET" in line and not line.startswith(("targets:", "targets_met:")):
                missed.append(line.strip())
        proc.wait()
    print("=== bench %s: exit %d after %.0f s (output in %s)"
          % (name, proc.returncode, time.time() - start, os.path.relpath(log_path, ROOT)), flush=True)
    if proc.returncode != 0:
        return "exit %d" % proc.returncode
    return "ok" if not missed else "ok, target missed: " + "; ".join(missed)


def main(argv):
    names = argv or list(BENCHMARKS)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        print("run_bench: unknown benchmark(s) %s; known: %s" % (", ".join(unknown), ", ".join(BENCHMARKS)))
        return 2
    results = [(name, run(name)) for name in names]
    print("\nsummary:")
    for name, result in results:
        print("  %-9s %s" % (name, result))
    return 0 if all(result.startswith("ok") for _, result in results) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
