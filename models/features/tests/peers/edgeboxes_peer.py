"""OpenCV contrib's EdgeBoxes (cv2.ximgproc) on edge maps written by frugal-features.

Usage: edgeboxes_peer.py DIR N WIDTH HEIGHT ALPHA BETA MIN_BOX_AREA MAX_ASPECT MAX_BOXES
Reads DIR/e_<i>.f32 (edge strength) and DIR/o_<i>.f32 (edge normal orientation in
[0, pi), the structured-edge convention), writes DIR/b_<i>.i32 (x, y, w, h rows) and
prints "seconds <mean box-search time per frame>".
"""
import sys
import time

import cv2
import numpy as np


def main():
    d, n, w, h, alpha, beta, area, ar, maxb = sys.argv[1:10]
    n, w, h, maxb = int(n), int(w), int(h), int(maxb)
    cv2.setNumThreads(1)
    eb = cv2.ximgproc.createEdgeBoxes(alpha=float(alpha), beta=float(beta),
                                      minBoxArea=float(area), maxAspectRatio=float(ar),
                                      maxBoxes=maxb)
    total = 0.0
    for i in range(n):
        e = np.fromfile(f"{d}/e_{i}.f32", dtype="<f4").reshape(h, w)
        o = np.fromfile(f"{d}/o_{i}.f32", dtype="<f4").reshape(h, w)
        t = time.perf_counter()
        res = eb.getBoundingBoxes(e, o)
        total += time.perf_counter() - t
        boxes = res[0] if isinstance(res, tuple) else res
        np.asarray(boxes, dtype="<i4").reshape(-1, 4).tofile(f"{d}/b_{i}.i32")
    print("seconds", total / max(n, 1))


if __name__ == "__main__":
    main()
