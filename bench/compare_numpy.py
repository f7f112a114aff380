#!/usr/bin/python3
"""The simulator against the NumPy baseline, in one session on one machine (docs/performance.md).

Runs bench/numpy_baseline.py's simulation (NumPy, one core) and simulator_bench's
BM_SimulatorTable3/1 (odomcov's best SIMD kernel, one thread) and BM_SimulatorTarget/AVX2 when
the CPU has it, on the same [Kleeman95] Table III config, and prints both rates and their ratio
with the machine's load, by wall-clock and by CPU time (one thread on each side, so the CPU time
is the time a core spent; on a machine shared with other jobs the wall clock also counts the time
the process waited for a core):
    compare_numpy.py BUILD_DIR [--repeats N]
`cmake --build build --target bench` runs it last.
"""
import argparse
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy_baseline  # noqa: E402


def simulator_rates(binary, repeats):
    out = subprocess.run(
        [binary, "--benchmark_filter=BM_SimulatorTable3/1/|BM_SimulatorTarget/AVX2",
         "--benchmark_format=json", f"--benchmark_repetitions={repeats}",
         "--benchmark_report_aggregates_only=false"],
        check=True, capture_output=True, text=True).stdout
    rates = {}
    for b in json.loads(out)["benchmarks"]:
        if b.get("run_type") != "iteration":
            continue
        name = "AVX2 forced" if "Target/AVX2" in b["name"] else f"best ({b.get('label', '')})"
        # steps/s is per wall-clock second; the same steps per CPU second:
        cpu = b["steps/s"] * b["real_time"] / b["cpu_time"]
        wall, best_cpu = rates.get(name, (0.0, 0.0))
        rates[name] = (max(wall, b["steps/s"]), max(best_cpu, cpu))
    return rates


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("build", help="the build folder (with bench/simulator_bench)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    load = os.getloadavg()[0]
    dl, dr = numpy_baseline.encoder_increments()
    numpy_wall = numpy_baseline.best_rate(8192, args.repeats, dl, dr)
    numpy_cpu = numpy_baseline.best_rate(8192, args.repeats, dl, dr, time.process_time)
    rates = simulator_rates(os.path.join(args.build, "bench", "simulator_bench"), args.repeats)
    load = max(load, os.getloadavg()[0])
    print(f"Table III, one core, best of {args.repeats} (load average up to {load:.2f} on "
          f"{os.cpu_count()} cores), M steps/s:")
    print(f"  {'':26s}{'wall clock':>12s}{'CPU time':>12s}")
    print(f"  {'NumPy baseline':26s}{numpy_wall / 1e6:12.1f}{numpy_cpu / 1e6:12.1f}")
    for name, (wall, cpu) in rates.items():
        print(f"  {'odomcov ' + name:26s}{wall / 1e6:12.1f}{cpu / 1e6:12.1f}   "
              f"= {wall / numpy_wall:4.1f}x / {cpu / numpy_cpu:4.1f}x NumPy")


if __name__ == "__main__":
    main()
