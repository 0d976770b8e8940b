"""Per-class AP@0.5 from pycocotools' COCOeval, for the metric cross-check in tests.rs.

Usage: coco_ap.py GT.json DT.json  -> prints {"ap": {category_id: AP}} as JSON, AP being
the mean of COCOeval's 101-point interpolated precision at IoU 0.5, area "all",
maxDets 100 (-1 when the category has no ground truth)."""
import contextlib, io, json, sys
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval
import numpy as np

with contextlib.redirect_stdout(io.StringIO()):
    gt = COCO(sys.argv[1])
    dt = gt.loadRes(sys.argv[2])
    ev = COCOeval(gt, dt, "bbox")
    ev.params.iouThrs = np.array([0.5])
    ev.evaluate()
    ev.accumulate()
prec = ev.eval["precision"]  # [T, R, K, A, M]
out = {}
for k, cat in enumerate(ev.params.catIds):
    p = prec[0, :, k, 0, -1]
    p = p[p > -1]
    out[int(cat)] = float(np.mean(p)) if p.size else -1.0
print(json.dumps({"ap": out}))
