#!/usr/bin/env python3
"""OpenCV side of the KLT comparison (a test peer, never a runtime dependency).

Reads a synthetic clip written by frugal-runtime (frame_NNNN.pgm, boxes.csv) and the
Rust tracker's starting corners (rust_points.csv: start,x,y), and for every segment
[start, start + length]:

* runs cv2.goodFeaturesToTrack in the same region the Rust tracker searches
  (the ground-truth box shrunk by the same margin), same max count / quality / distance;
* chains cv2.calcOpticalFlowPyrLK frame to frame from the *Rust* corners (no
  forward-backward filtering), so point positions can be compared one to one;
* runs the same tracker pipeline as the Rust Tracker with OpenCV primitives
  (own corners, LK forward + backward, FB error <= max_fb, median-flow box update)
  and times it per frame (LK forward + backward + box update), single-threaded, in
  wall-clock and in thread CPU time.
  OpenCV 5's Python binding no longer accepts pre-built pyramids in
  calcOpticalFlowPyrLK, so each of the two calls builds its pyramids itself.

Writes one JSON object to stdout.
"""
import argparse
import csv
import json
import os
import sys
import time

import cv2
import numpy as np


def read_pgm(path):
    with open(path, "rb") as f:
        data = f.read()
    parts = data.split(maxsplit=4)
    if parts[0] != b"P5":
        sys.exit(f"{path}: not a binary PGM")
    w, h, maxval = int(parts[1]), int(parts[2]), int(parts[3])
    if maxval != 255:
        sys.exit(f"{path}: only 8-bit PGM supported")
    pix = parts[4]
    return np.frombuffer(pix[: w * h], dtype=np.uint8).reshape(h, w)


def median_flow(old, new, box):
    """Similarity (scale s, translation t) by medians, applied to box (x1, y1, x2, y2)."""
    n = len(old)
    d0 = np.linalg.norm(old[:, None, :] - old[None, :, :], axis=2)
    d1 = np.linalg.norm(new[:, None, :] - new[None, :, :], axis=2)
    per_point = []
    for i in range(n):
        mask = (np.arange(n) != i) & (d0[i] >= 1.0)
        if mask.any():
            r = d1[i][mask] / d0[i][mask]
            per_point.append(np.sort(r)[len(r) // 2])
    s = float(np.sort(per_point)[len(per_point) // 2]) if per_point else 1.0
    tx = np.sort(new[:, 0] - s * old[:, 0])[n // 2]
    ty = np.sort(new[:, 1] - s * old[:, 1])[n // 2]
    x1, y1, x2, y2 = box
    return [s * x1 + tx, s * y1 + ty, s * x2 + tx, s * y2 + ty]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("clip")
    ap.add_argument("--length", type=int, default=10)
    ap.add_argument("--win", type=int, default=15)
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument("--iters", type=int, default=20)
    ap.add_argument("--eps", type=float, default=0.01)
    ap.add_argument("--max-points", type=int, default=64)
    ap.add_argument("--quality", type=float, default=0.01)
    ap.add_argument("--min-distance", type=float, default=4.0)
    ap.add_argument("--margin", type=float, default=0.1)
    ap.add_argument("--max-fb", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=3, help="timing repetitions (best is kept)")
    a = ap.parse_args()

    cv2.setNumThreads(1)
    names = sorted(n for n in os.listdir(a.clip) if n.startswith("frame_") and n.endswith(".pgm"))
    frames = [read_pgm(os.path.join(a.clip, n)) for n in names]
    with open(os.path.join(a.clip, "boxes.csv")) as f:
        boxes = [[float(r["x1"]), float(r["y1"]), float(r["x2"]), float(r["y2"])] for r in csv.DictReader(f)]
    starts = {}
    with open(os.path.join(a.clip, "rust_points.csv")) as f:
        for r in csv.DictReader(f):
            starts.setdefault(int(r["start"]), []).append([float(r["x"]), float(r["y"])])

    win = (a.win, a.win)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, a.iters, a.eps)
    lk = dict(winSize=win, maxLevel=a.levels - 1, criteria=crit)
    segments = []
    for start in sorted(starts):
        end = min(start + a.length, len(frames) - 1)
        x1, y1, x2, y2 = boxes[start]
        mx, my = (x2 - x1) * a.margin, (y2 - y1) * a.margin
        mask = np.zeros_like(frames[start])
        mask[int(np.ceil(y1 + my)): int(np.ceil(y2 - my)), int(np.ceil(x1 + mx)): int(np.ceil(x2 - mx))] = 255
        corners = cv2.goodFeaturesToTrack(frames[start], a.max_points, a.quality, a.min_distance, mask=mask, blockSize=3)
        corners = np.zeros((0, 2), np.float32) if corners is None else corners.reshape(-1, 2)

        # Chain LK from the Rust corners, no filtering.
        pts = np.array(starts[start], np.float32).reshape(-1, 1, 2)
        alive = np.ones(len(pts), bool)
        given = []
        for f in range(start + 1, end + 1):
            nxt, st, _ = cv2.calcOpticalFlowPyrLK(frames[f - 1], frames[f], pts, None, **lk)
            alive &= st.reshape(-1) == 1
            pts = nxt
            given.append([[float(p[0]), float(p[1]), bool(ok)] for p, ok in zip(pts.reshape(-1, 2), alive)])

        # Full pipeline with OpenCV primitives, timed per frame.
        best = None
        for _ in range(a.repeat):
            box = list(boxes[start])
            p = corners.reshape(-1, 1, 2).copy()
            out_boxes, times, cpu_times = [], [], []
            prev_img = frames[start]
            lost = False
            for f in range(start + 1, end + 1):
                t0, c0 = time.perf_counter(), time.thread_time()
                next_img = frames[f]
                if not lost and len(p) >= 4:
                    q, st, _ = cv2.calcOpticalFlowPyrLK(prev_img, next_img, p, None, **lk)
                    back, st2, _ = cv2.calcOpticalFlowPyrLK(next_img, prev_img, q, None, **lk)
                    fb = np.linalg.norm((back - p).reshape(-1, 2), axis=1)
                    keep = (st.reshape(-1) == 1) & (st2.reshape(-1) == 1) & (fb <= a.max_fb)
                    if keep.sum() >= 4:
                        box = median_flow(p.reshape(-1, 2)[keep], q.reshape(-1, 2)[keep], box)
                        p = q[keep]
                    else:
                        lost = True
                times.append(time.perf_counter() - t0)
                cpu_times.append(time.thread_time() - c0)
                out_boxes.append(None if lost else [float(v) for v in box])
                prev_img = next_img
            ms = 1000.0 * float(np.mean(times)) if times else 0.0
            cpu_ms = 1000.0 * float(np.mean(cpu_times)) if cpu_times else 0.0
            if best is None or ms < best[1]:
                best = (out_boxes, ms, cpu_ms)
        segments.append(dict(
            start=start,
            corners=corners.tolist(),
            given_tracks=given,
            boxes=best[0],
            ms_per_frame=best[1],
            cpu_ms_per_frame=best[2],
        ))
    json.dump(dict(opencv=cv2.__version__, segments=segments), sys.stdout)


if __name__ == "__main__":
    main()
