#!/usr/bin/python3
"""The simulator against the NumPy baseline, in one session on one machine (docs/performance.md).

Runs bench/numpy_baseline.py's simulation (NumPy, one core) and simulator_bench's
BM_SimulatorTable3/1 (odomcov's best SIMD kernel, one thread) and BM_SimulatorTarget/AVX2 when
the CPU has it, on the same [Kleeman95] Table III config, and prints both rates and their ratio
with the machine's load:
    compare_numpy.py BUILD_DIR [--repeats N]
`cmake --build build --target bench` runs it last.
"""
import argparse
import json
import os
import subprocess
import sys

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
        rates[name] = max(rates.get(name, 0.0), b["steps/s"])
    return rates


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("build", help="the build folder (with bench/simulator_bench)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    load = os.getloadavg()[0]
    dl, dr = numpy_baseline.encoder_increments()
    numpy_rate = numpy_baseline.best_rate(8192, args.repeats, dl, dr)
    rates = simulator_rates(os.path.join(args.build, "bench", "simulator_bench"), args.repeats)
    load = max(load, os.getloadavg()[0])
    print(f"Table III, one core, best of {args.repeats} (load average {load:.2f} on "
          f"{os.cpu_count()} cores):")
    print(f"  NumPy baseline           {numpy_rate / 1e6:8.1f} M steps/s")
    for name, rate in rates.items():
        print(f"  odomcov {name:17s}{rate / 1e6:8.1f} M steps/s  = {rate / numpy_rate:5.1f}x NumPy")


if __name__ == "__main__":
    main()
