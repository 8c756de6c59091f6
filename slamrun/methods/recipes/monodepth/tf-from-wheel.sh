#!/bin/sh
# TensorFlow 2 C++ (libtensorflow_cc.so.2, libtensorflow_framework.so.2 and tensorflow/include/: TF, protobuf,
# Abseil, Eigen, tsl headers) taken from PyPI's tensorflow-cpu wheel for CPython 3.11, with no Bazel. The wheel
# is fetched on the host (the build context's pypi/ folder) and its SHA-256 checked here.
# usage: tf-from-wheel.sh WHEEL SHA256 DEST      (DEST gets the two libraries and include/)
set -eu
wheel=$1; sum=$2; dest=$3
test -f "$wheel" || { echo "tf-from-wheel: $wheel is missing: the runner fetches it from PyPI into the context's pypi/" >&2; exit 1; }
actual=$(sha256sum "$wheel" | cut -d' ' -f1)
if [ "$actual" != "$sum" ]; then
  echo "tf-from-wheel: $wheel has sha256 $actual, expected $sum: refusing it" >&2
  exit 1
fi
mkdir -p "$dest"
python3 - "$wheel" "$dest" <<'PY'
import os, sys, zipfile
wheel, dest = sys.argv[1], sys.argv[2]
libs = ("tensorflow/libtensorflow_cc.so.2", "tensorflow/libtensorflow_framework.so.2")
n = 0
with zipfile.ZipFile(wheel) as zf:
    for info in zf.infolist():
        name = info.filename
        if name in libs or (name.startswith("tensorflow/include/") and not name.endswith("/")):
            out = os.path.join(dest, name[len("tensorflow/"):])
            os.makedirs(os.path.dirname(out), exist_ok=True)
            with zf.open(info) as src, open(out, "wb") as dst:
                while True:
                    chunk = src.read(1 << 20)
                    if not chunk:
                        break
                    dst.write(chunk)
            n += 1
missing = [l for l in libs if not os.path.isfile(os.path.join(dest, l.split("/")[-1]))]
if missing or not os.path.isfile(os.path.join(dest, "include/tensorflow/core/public/session.h")):
    sys.exit("tf-from-wheel: %s lacks %s" % (wheel, missing or "include/tensorflow/core/public/session.h"))
print("tf-from-wheel: %d files from %s into %s" % (n, os.path.basename(wheel), dest))
PY
