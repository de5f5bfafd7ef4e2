"""Reads an ONNX model with the onnx package (full checker) and runs it with onnxruntime.

Usage: run_onnx.py MODEL INPUTS.json — INPUTS.json maps each input name to {"shape": [...], "data": [...]}.
Prints one JSON line: {"actions": [...flat...], "shape": [...], "metadata": {key: value}, "opset": N}.
"""
import json
import sys

import numpy as np
import onnx
import onnxruntime as ort

model_path, inputs_path = sys.argv[1], sys.argv[2]
model = onnx.load(model_path)
onnx.checker.check_model(model, full_check=True)
with open(inputs_path) as f:
    spec = json.load(f)
feeds = {name: np.asarray(v["data"], dtype=np.float32).reshape(v["shape"]) for name, v in spec.items()}
session = ort.InferenceSession(model_path, providers=["CPUExecutionProvider"])
names = [i.name for i in session.get_inputs()]
(out,) = session.run(["actions"], {n: feeds[n] for n in names})
print(json.dumps({
    "actions": [float(x) for x in out.reshape(-1)],
    "shape": list(out.shape),
    "inputs": names,
    "metadata": {p.key: p.value for p in model.metadata_props},
    "opset": [o.version for o in model.opset_import if o.domain in ("", "ai.onnx")][0],
}))
