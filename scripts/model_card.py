#!/usr/bin/env python3
"""Prints the facts a model card states about an exported nldf model: its size, its sha256
and every metadata entry (the embedded background is named, not printed).

Usage: .venv/bin/python scripts/model_card.py models/demo/model.onnx
"""
import hashlib
import sys

import onnx


def main() -> None:
    path = sys.argv[1]
    data = open(path, "rb").read()
    model = onnx.load_from_string(data)
    print(f"- bytes: `{len(data)}`")
    print(f"- sha256: `{hashlib.sha256(data).hexdigest()}`")
    print()
    print("| key | value |")
    print("| --- | --- |")
    for p in model.metadata_props:
        if p.key == "nldf.background_file" or len(p.value) > 200:
            print(f"| `{p.key}` | ({len(p.value)} characters) |")
        else:
            print(f"| `{p.key}` | `{p.value}` |")


if __name__ == "__main__":
    main()
