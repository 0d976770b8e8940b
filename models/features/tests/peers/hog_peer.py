"""Reference HoG for frugal-features' parity test and speed comparison.

Usage:
  hog_peer.py features WINDOWS N SIZE CELL BLOCK BINS OUT
      skimage.feature.hog (L2-Hys, channel_axis=-1) of N SIZE×SIZE×3 uint8 windows
      read from WINDOWS (raw bytes), written to OUT as little-endian float64.
  hog_peer.py bench WINDOWS N SIZE CELL BLOCK BINS
      prints "skimage <seconds per window>" and "opencv <seconds per window>".
"""
import sys
import time

import numpy as np
from skimage.feature import hog


def windows(path, n, size):
    return np.fromfile(path, dtype=np.uint8).reshape(n, size, size, 3)


def sk(w, cell, block, bins):
    return hog(w, orientations=bins, pixels_per_cell=(cell, cell),
               cells_per_block=(block, block), block_norm="L2-Hys",
               feature_vector=True, channel_axis=-1)


def main():
    mode, path, n, size, cell, block, bins = sys.argv[1:8]
    n, size, cell, block, bins = map(int, (n, size, cell, block, bins))
    ws = windows(path, n, size)
    if mode == "features":
        out = np.stack([sk(w, cell, block, bins) for w in ws]).astype("<f8")
        out.tofile(sys.argv[8])
    elif mode == "bench":
        reps = max(1, 2000 // n)
        t = time.perf_counter()
        for _ in range(reps):
            for w in ws:
                sk(w, cell, block, bins)
        print("skimage", (time.perf_counter() - t) / (reps * n))
        import cv2
        cv2.setNumThreads(1)
        d = cv2.HOGDescriptor((size, size), (block * cell, block * cell),
                              (cell, cell), (cell, cell), bins)
        t = time.perf_counter()
        for _ in range(reps * 5):
            for w in ws:
                d.compute(w)
        print("opencv", (time.perf_counter() - t) / (reps * 5 * n))
    else:
        raise SystemExit(f"unknown mode {mode!r}")


if __name__ == "__main__":
    main()
