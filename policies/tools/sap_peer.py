"""Independent streaming-AP peer for frugal's `policies::stream`.

Reads timestamped outputs and ground truth as JSON on stdin:

    {"categories": [0, 1, ...],
     "videos": [{"frames": [{"time_ms": t, "truth": [{"category_id": c, "bbox": [x, y, w, h]}],
                             "ignore": [{"category_id": c, "bbox": [x, y, w, h]}]}],
                 "outputs": [{"finish_ms": t, "detections": [{"category_id": c, "bbox": [x, y, w, h], "score": s}]}]}]}

(`ignore`, optional: crowd regions, given to COCOeval as `iscrowd: 1`), pairs every
ground-truth frame with the latest output whose finish_ms <= the frame's
time_ms (of outputs finishing at the same time, the later one listed), and scores the
pairs with pycocotools' COCOeval (bbox, area "all", 100 detections per image). Prints
{"sap50": AP@0.5, "sap": AP@[.5:.95], "sf1": F1@0.5} as JSON with full precision;
streaming F1 counts COCOeval's own matches at IoU 0.5 (every detection shown counts:
the outputs are already cut at their confidence threshold; a detection matched to a
crowd region, and a crowd region itself, count for nothing).
"""
import contextlib
import io
import json
import sys

import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval


def main():
    case = json.load(sys.stdin)
    images, annotations, results = [], [], []
    image_id = 0
    for video in case["videos"]:
        outputs = video["outputs"]
        for frame in video["frames"]:
            image_id += 1
            images.append({"id": image_id, "width": 10000, "height": 10000})
            for t in frame["truth"]:
                x, y, w, h = t["bbox"]
                annotations.append({"id": len(annotations) + 1, "image_id": image_id,
                                    "category_id": t["category_id"], "bbox": [x, y, w, h],
                                    "area": w * h, "iscrowd": 0})
            for t in frame.get("ignore", []):
                x, y, w, h = t["bbox"]
                annotations.append({"id": len(annotations) + 1, "image_id": image_id,
                                    "category_id": t["category_id"], "bbox": [x, y, w, h],
                                    "area": w * h, "iscrowd": 1})
            used = None
            for o in outputs:
                if o["finish_ms"] <= frame["time_ms"]:
                    used = o
            if used is not None:
                for d in used["detections"]:
                    results.append({"image_id": image_id, "category_id": d["category_id"],
                                    "bbox": d["bbox"], "score": d["score"]})
    if not results or not annotations:
        print(json.dumps({"sap50": 0.0, "sap": 0.0, "sf1": 0.0}))
        return
    gt = COCO()
    gt.dataset = {"images": images, "annotations": annotations,
                  "categories": [{"id": c} for c in case["categories"]]}
    with contextlib.redirect_stdout(io.StringIO()):
        gt.createIndex()
        dt = gt.loadRes(results)
        ev = COCOeval(gt, dt, "bbox")
        ev.evaluate()
        ev.accumulate()
    precision = ev.eval["precision"][:, :, :, 0, -1]  # IoU x recall x class, area all, 100 dets
    def mean(p):
        p = p[p > -1]
        return float(np.mean(p)) if p.size else 0.0
    # matches at IoU 0.5 (the first threshold), area "all" (the first range)
    tp = fp = fn = 0
    for e in ev.evalImgs:
        if e is None or e["aRng"] != ev.params.areaRng[0]:
            continue
        dt_matched = np.asarray(e["dtMatches"])[0] > 0
        dt_ignored = np.asarray(e["dtIgnore"])[0].astype(bool)
        gt_matched = np.asarray(e["gtMatches"])[0] > 0
        gt_ignored = np.asarray(e["gtIgnore"]).astype(bool)
        tp += int(np.sum(dt_matched & ~dt_ignored))
        fp += int(np.sum(~dt_matched & ~dt_ignored))
        fn += int(np.sum(~gt_matched & ~gt_ignored))
    sf1 = 2.0 * tp / (2 * tp + fp + fn) if tp + fp + fn else 0.0
    print(json.dumps({"sap50": mean(precision[0]), "sap": mean(precision), "sf1": sf1}))


if __name__ == "__main__":
    main()
