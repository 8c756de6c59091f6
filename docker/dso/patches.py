"""DSO patches for a current compiler and libraries (as measured on Debian 12 and needed on newer bases):
Boost's `_1` placeholders and OpenCV 4's cv::IMREAD_* constants. Harmless on Ubuntu 16.04."""
import os
import re
import sys

root = sys.argv[1]
ird = os.path.join(root, "src", "util", "IndexThreadReduce.h")
with open(ird) as f:
    text = f.read()
if "boost/bind/bind.hpp" not in text:
    text = text.replace("#include <boost/bind.hpp>", "#include <boost/bind/bind.hpp>\nusing namespace boost::placeholders;")
    if "boost::placeholders" not in text:
        sys.exit("patch: IndexThreadReduce.h: '#include <boost/bind.hpp>' not found")
    with open(ird, "w") as f:
        f.write(text)
    print("patch: IndexThreadReduce.h: boost placeholders")
n_total = 0
for dirpath, _, files in os.walk(os.path.join(root, "src")):
    for name in files:
        if name.endswith((".cpp", ".h")):
            path = os.path.join(dirpath, name)
            with open(path) as f:
                text = f.read()
            new, n = re.subn(r"\bCV_LOAD_IMAGE_(GRAYSCALE|UNCHANGED|COLOR)\b", r"cv::IMREAD_\1", text)
            if n:
                with open(path, "w") as f:
                    f.write(new)
                n_total += n
print("patch: %d OpenCV constant(s) updated" % n_total)
