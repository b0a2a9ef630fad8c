#!/usr/bin/python3
"""Copies an exported tray model with another declared window size (the same weights): the test
model tests/overhead/data/tray_obb_128.onnx, which the detector made for 256 x 256 windows must
refuse.

    /usr/bin/python3 tools/train/tray_obb/set_input_size.py models/tray_obb.onnx 128 OUT.onnx
"""
import sys

import onnx

src, size, dst = sys.argv[1], int(sys.argv[2]), sys.argv[3]
m = onnx.load(src)
dims = m.graph.input[0].type.tensor_type.shape.dim
dims[2].dim_value = dims[3].dim_value = size
out = m.graph.output[0].type.tensor_type.shape.dim
out[2].dim_value = out[3].dim_value = size // 8
onnx.checker.check_model(m)
onnx.save(m, dst)
