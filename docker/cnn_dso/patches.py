"""CNN-DSO patches: its CMakeLists holds placeholder and personal absolute paths for TensorFlow and
monodepth-cpp; point them at the image's builds. Then DSO's own fixes."""
import os
import re
import subprocess
import sys

root = sys.argv[1]
tf, monodepth = sys.argv[2], sys.argv[3]
cmake = os.path.join(root, "CMakeLists.txt")
with open(cmake) as f:
    text = f.read()
# every absolute path under a home directory or a placeholder that names tensorflow or monodepth
text, n_tf = re.subn(r"(/home/[^\s\")]*?|/path/to/[^\s\")]*?)tensorflow", tf, text)
text, n_md = re.subn(r"(/home/[^\s\")]*?|/path/to/[^\s\")]*?)monodepth[-_]?cpp", monodepth, text)
left = re.findall(r"/home/[^\s\")]+|/path/to/[^\s\")]+", text)
if left:
    sys.exit("patch: CNN-DSO CMakeLists.txt still holds personal paths: %s" % left[:5])
with open(cmake, "w") as f:
    f.write(text)
print("patch: CMakeLists.txt: %d TensorFlow and %d monodepth-cpp path(s) set" % (n_tf, n_md))
subprocess.check_call([sys.executable, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "dso",
                                                    "patches.py"), root])
