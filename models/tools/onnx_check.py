"""Independent check of frugal's exported ONNX files with the reference tools: the ONNX
checker (full_check, with shape inference) and Python onnxruntime.

Usage: onnx_check.py MODEL.onnx INPUTS.json
INPUTS.json: {"inputs": {name: {"shape": [...], "dtype": "float32"|"int64", "file": raw
little-endian data}}, "outputs": {name: {"file": raw float32 data}}}. Runs the model on the
inputs and prints JSON {"checker": "ok", "max_abs_diff": {output: value}, "shapes": {...}}.
"""
import json
import sys

import numpy as np
import onnx
import onnxruntime as ort

model_path, spec_path = sys.argv[1], sys.argv[2]
spec = json.load(open(spec_path))
model = onnx.load(model_path)
onnx.checker.check_model(model, full_check=True)
opts = ort.SessionOptions()
opts.intra_op_num_threads = 1
sess = ort.InferenceSession(model_path, opts, providers=["CPUExecutionProvider"])
feeds = {}
for name, inp in spec["inputs"].items():
    data = np.fromfile(inp["file"], dtype=inp["dtype"]).reshape(inp["shape"])
    feeds[name] = data
names = [o.name for o in sess.get_outputs()]
results = dict(zip(names, sess.run(names, feeds)))
diffs, shapes = {}, {}
for name, out in spec["outputs"].items():
    want = np.fromfile(out["file"], dtype="float32")
    got = results[name].astype("float32").ravel()
    shapes[name] = list(results[name].shape)
    diffs[name] = float(np.max(np.abs(got - want))) if got.size == want.size else float("inf")
print(json.dumps({"checker": "ok", "max_abs_diff": diffs, "shapes": shapes}))
