#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Render globes drawn at random from a seed, run process_bag on each, and tabulate the SLAM's figures.

usage: globe_sweep.py --seeds 101 102 ... --out DIR [--bin DIR] [--run NAME=ARGS ...] [--ideal | --realistic]
                      [--keep-bags] [--frames-scale F]

Each seed draws one globe scene (numpy's default_rng(seed), nothing else):
  radius 120-250 mm; the orbit 350-650 mm from the globe's centre and 250-400 mm from its surface (the SLAM rig's
  stereo overlap needs that much); latitude -30..30 deg; axial tilt 0..30 deg; spin 0.1-0.3 rad/s; frames for
  1.05 turns at 10 Hz; a constant gyro bias of -1.5..1.5 mrad/s on each axis. Everything else is
  config/datasets/globe.yaml's. The calibration in the bag is exact unless --realistic (the chessboard model of
  globe.yaml), --ideal gives no realism at all.
For every scene, `make_dataset globe-images` renders DIR/SEED/globe.bag, then every --run (default: 'gyro' =
--gyro --set estimate_gyro_bias=true and 'nogyro' = nothing: process_bag's defaults otherwise) writes
DIR/SEED/NAME/. The figures (SE(3) ATE of the trajectory.tum process_bag wrote and of the filter's, the sphere
radius against the truth, the final bias against the truth in stated standard deviations) go to DIR/sweep.yaml and
a Markdown table on stdout. A scene already rendered or processed is not redone (delete its directory to redo).
"""
import argparse
import math
import os
import subprocess
import sys
import time

import numpy as np
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))


def draw_scene(seed):
    rng = np.random.default_rng(seed)
    radius = rng.uniform(120.0, 250.0)
    distance = rng.uniform(max(350.0, radius + 250.0), min(650.0, radius + 400.0))
    rate = rng.uniform(0.1, 0.3)
    return {
        "radius_mm": round(float(radius), 1),
        "distance_mm": round(float(distance), 1),
        "latitude_deg": round(float(rng.uniform(-30.0, 30.0)), 1),
        "tilt_deg": round(float(rng.uniform(0.0, 30.0)), 1),
        "rate_rad_s": round(float(rate), 4),
        "frames": int(math.ceil(1.05 * 2.0 * math.pi / rate * 10.0)),
        "bias_rad_s": [round(float(b), 5) for b in rng.uniform(-1.5e-3, 1.5e-3, 3)],
    }


def write_config(path, scene, realistic, frames_scale):
    globe = {k: scene[k] for k in ("radius_mm", "distance_mm", "latitude_deg", "tilt_deg", "rate_rad_s")}
    globe["frames"] = max(20, int(round(scene["frames"] * frames_scale)))
    cfg = {"globe": globe, "gyro": {"bias_rad_s": scene["bias_rad_s"]}}
    if not realistic:
        cfg["images"] = {"calibration_error": {"enabled": False}}
    with open(path, "w") as f:
        yaml.safe_dump(cfg, f, default_flow_style=None, sort_keys=False)


def run(cmd, log):
    t0 = time.time()
    with open(log, "w") as f:
        rc = subprocess.call(cmd, stdout=f, stderr=subprocess.STDOUT)
    if rc != 0:
        sys.stderr.write("globe_sweep: %s exited %d (log: %s)\n" % (" ".join(cmd), rc, log))
    return rc, time.time() - t0


def figures(out_dir, scene):
    path = os.path.join(out_dir, "summary.yaml")
    if not os.path.exists(path):
        return {"error": "no summary.yaml in " + out_dir}
    with open(path) as f:
        s = yaml.safe_load(f)
    row = {"ate_se3_mm": s.get("ate_se3", {}).get("rmse_mm"), "filter_ate_se3_mm": s.get("filter_ate_se3_rmse_mm"),
           "trajectory": s.get("trajectory", "filter"), "frames": s.get("frames")}
    fit = s.get("sphere_fit")
    if isinstance(fit, dict):
        row["radius_mm"] = fit["radius_mm"]
        row["radius_error_percent"] = 100.0 * (fit["radius_mm"] - scene["radius_mm"]) / scene["radius_mm"]
    # the truth is a constant bias: the smoother's mean over the recording (the filter's last estimate without it)
    bias = s.get("smoother_mean_gyro_bias") or s.get("final_gyro_bias")
    if isinstance(bias, dict):
        est, std = np.array(bias["rad_s"]), np.array(bias["std_rad_s"])
        err = est - np.array(scene["bias_rad_s"])
        row["bias_error_mrad_s"] = [round(float(1e3 * e), 4) for e in err]
        row["bias_std_mrad_s"] = [round(float(1e3 * e), 4) for e in std]
        row["bias_error_in_std"] = [round(float(e / d), 2) if d > 0 else None for e, d in zip(err, std)]
    for key in ("smoother_seconds", "slam_ms_per_frame", "front_end_ms_per_frame"):
        if key in s:
            row[key] = s[key]
    return row


def fmt(v, spec):
    return "—" if v is None else format(v, spec)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--bin", default=os.path.join(HERE, "..", "build", "devel", "lib", "skin3d"),
                    help="where make_dataset and process_bag are (default: the build tree's)")
    ap.add_argument("--run", action="append", default=[],
                    help="NAME=process_bag arguments (repeatable; default gyro and nogyro)")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--realistic", action="store_true", help="the bag's calibration is off as a real one is")
    mode.add_argument("--ideal", action="store_true", help="make_dataset --ideal: no realism, exact calibration")
    ap.add_argument("--keep-bags", action="store_true", help="keep the rendered bags (default: deleted when done)")
    ap.add_argument("--frames-scale", type=float, default=1.0, help="render this share of the frames (quick looks)")
    a = ap.parse_args()
    runs = a.run or ["gyro=--gyro --set estimate_gyro_bias=true", "nogyro="]
    runs = [(r.split("=", 1)[0], r.split("=", 1)[1].split()) for r in runs]
    for tool in ("make_dataset", "process_bag"):
        if not os.access(os.path.join(a.bin, tool), os.X_OK):
            sys.exit("globe_sweep: no %s in %s (build it, or give --bin)" % (tool, a.bin))
    os.makedirs(a.out, exist_ok=True)
    table = []
    for seed in a.seeds:
        scene = draw_scene(seed)
        sd = os.path.join(a.out, str(seed))
        os.makedirs(sd, exist_ok=True)
        bag = os.path.join(sd, "globe.bag")
        pending = [(n, args) for n, args in runs if not os.path.exists(os.path.join(sd, n, "summary.yaml"))]
        if pending and not os.path.exists(bag):
            write_config(os.path.join(sd, "globe.yaml"), scene, a.realistic, a.frames_scale)
            cmd = [os.path.join(a.bin, "make_dataset"), "globe-images", "--config", os.path.join(sd, "globe.yaml"),
                   "--seed", str(seed), "--out", bag] + (["--ideal"] if a.ideal else [])
            print("globe_sweep: seed %d: rendering %s" % (seed, scene), flush=True)
            rc, sec = run(cmd, os.path.join(sd, "make_dataset.log"))
            if rc != 0:
                table.append({"seed": seed, "scene": scene, "error": "render failed"})
                continue
        for name, args in pending:
            cmd = [os.path.join(a.bin, "process_bag"), "--bag", bag, "--out", os.path.join(sd, name), "--quiet"] + args
            print("globe_sweep: seed %d: %s: %s" % (seed, name, " ".join(args)), flush=True)
            rc, sec = run(cmd, os.path.join(sd, name + ".log"))
        for name, _ in runs:
            row = {"seed": seed, "run": name, "scene": scene}
            row.update(figures(os.path.join(sd, name), scene))
            table.append(row)
        if not a.keep_bags and os.path.exists(bag):
            os.remove(bag)
    with open(os.path.join(a.out, "sweep.yaml"), "w") as f:
        yaml.safe_dump({"date": time.strftime("%Y-%m-%d"), "machine": os.uname().nodename,
                        "calibration": "realistic" if a.realistic else ("ideal" if a.ideal else "exact"),
                        "runs": {n: " ".join(args) for n, args in runs}, "results": table}, f, sort_keys=False)
    print("| seed | r / d mm | lat ° | rate rad/s | run | ATE mm (filter) | radius % | bias error / std |")
    print("|---|---|---|---|---|---|---|---|")
    for row in table:
        sc = row["scene"]
        if "error" in row:
            print("| %d | | | | %s | %s | | |" % (row["seed"], row.get("run", ""), row["error"]))
            continue
        z = row.get("bias_error_in_std")
        print("| %d | %.0f / %.0f | %+.0f | %.3f | %s | %s (%s) | %s | %s |" % (
            row["seed"], sc["radius_mm"], sc["distance_mm"], sc["latitude_deg"], sc["rate_rad_s"], row["run"],
            fmt(row.get("ate_se3_mm"), ".3f"), fmt(row.get("filter_ate_se3_mm"), ".2f"),
            fmt(row.get("radius_error_percent"), "+.3f"), "—" if not z else ", ".join("%+.1f" % v for v in z)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
