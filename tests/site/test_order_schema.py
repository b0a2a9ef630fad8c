#!/usr/bin/env python3
"""Validates the order that test_order writes against the VDA 5050 2.1.0 order schema.
Usage: test_order_schema.py TEST_ORDER_BINARY SCHEMA OUT_JSON"""
import json
import os
import subprocess
import sys

import jsonschema


def main():
    binary, schema_path, out = sys.argv[1:4]
    env = dict(os.environ, AGV_ORDER_OUT=out)
    subprocess.run([binary, "--gtest_filter=Order.RoundTrip"], env=env, check=True,
                   stdout=subprocess.DEVNULL)
    with open(schema_path) as f:
        schema = json.load(f)
    with open(out) as f:
        order = json.load(f)
    jsonschema.validate(order, schema)
    assert len(order["nodes"]) == len(order["edges"]) + 1
    print("order valid:", len(order["nodes"]), "nodes")


if __name__ == "__main__":
    main()
