#!/usr/bin/env python3
"""bench/run's last step: bench/results.json from the figures the benchmarks recorded
(bench/results.h, one file per benchmark: bench/out/NAME.figures.json) and their Google
Benchmark timings (bench/out/NAME.json), with the ratios that need two timings of one run, and
the machine. Each figure names the benchmark it came from; a run of some benchmarks keeps the
other benchmarks' figures from the previous results.json.

usage: bench/collect.py OUT_DIR RESULTS.json SECONDS NAME...
"""
import json
import os
import platform
import subprocess
import sys

# Ratios of two Google Benchmark timings of the same run: name -> (numerator, denominator, peer).
DERIVED = {
    "render.measured.x_embree_primary_rays":
        ("scene.BM_Render640x480Measured/real_time", "scene.BM_EmbreePrimaryRays640x480/real_time",
         "Embree casting the same 640x480 primary rays at the scene's mesh (time of rouen's "
         "render / time of the rays alone)"),
    "render.predicted.x_embree_primary_rays":
        ("scene.BM_Render640x480Predicted/real_time", "scene.BM_EmbreePrimaryRays640x480/real_time",
         "as above, under lighting predicted for a new time"),
}
# Google Benchmark's own fields, not counters.
FIELDS = {"name", "family_index", "per_family_instance_index", "run_name", "run_type",
          "repetitions", "repetition_index", "threads", "iterations", "real_time", "cpu_time",
          "time_unit", "label", "aggregate_name", "aggregate_unit", "error_occurred",
          "error_message"}


def main():
    out_dir, results_path, seconds, names = sys.argv[1], sys.argv[2], int(sys.argv[3]), \
        sys.argv[4:]
    figures, benchmarks = {}, list(names)
    if os.path.exists(results_path):
        with open(results_path) as f:
            old = json.load(f)
        # The figures of benchmarks not run this time (figures naming no benchmark are dropped).
        for k, v in old.get("figures", {}).items():
            if v.get("bench") and v["bench"] not in names:
                figures[k] = v
        benchmarks += [b for b in old.get("benchmarks", []) if b not in names and any(
            v.get("bench") == b for v in figures.values())]
    timings = {}
    for n in names:
        recorded = os.path.join(out_dir, n + ".figures.json")
        if os.path.exists(recorded):
            with open(recorded) as f:
                for k, v in json.load(f).items():
                    v["bench"] = n
                    figures[k] = v
        out = os.path.join(out_dir, n + ".json")
        if not os.path.exists(out):
            continue
        with open(out) as f:
            run = json.load(f)
        for b in run.get("benchmarks", []):
            if b.get("error_occurred"):
                continue
            key = "%s.%s" % (n, b["name"])
            entry = {"value": b["real_time"], "cpu": b["cpu_time"], "unit": b["time_unit"],
                     "bench": n}
            counters = {k: v for k, v in b.items() if k not in FIELDS}
            if counters:
                entry["counters"] = counters
            if b.get("label"):
                entry["label"] = b["label"]
            timings[key] = entry
            figures["time." + key] = entry
    for name, (num, den, peer) in DERIVED.items():
        if num in timings and den in timings and timings[num]["unit"] == timings[den]["unit"]:
            figures[name] = {"value": timings[num]["value"] / timings[den]["value"],
                             "unit": "ratio", "peer": peer, "bench": timings[num]["bench"]}
    cpu = ""
    try:
        lines = subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines()
        cpu = next(l.split(":", 1)[1].strip() for l in lines if l.startswith("Model name"))
    except (OSError, StopIteration):
        pass
    doc = {"figures": dict(sorted(figures.items())),
           "machine": {"cpu": cpu, "cores": os.cpu_count(), "system": platform.platform()},
           "benchmarks": sorted(benchmarks), "seconds_of_this_run": seconds}
    with open(results_path + ".tmp", "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    os.replace(results_path + ".tmp", results_path)
    print("\nbench/run: %d figures in %s (%d s); ratios against a peer:" %
          (len(figures), results_path, seconds))
    for k, v in sorted(figures.items()):
        if "peer" in v:
            print("  %-48s %10.3g   vs %s" % (k, v["value"], v["peer"]))


if __name__ == "__main__":
    main()
