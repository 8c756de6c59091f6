"""CNN-SVO patches: its CMakeLists turns ONLINE_MODE and HAVE_G2O on with personal absolute paths; point
them at the image's TensorFlow, monodepth-cpp and g2o. Then the shared Sophus fix."""
import os
import re
import sys

root, tf, monodepth = sys.argv[1], sys.argv[2], sys.argv[3]
changed = 0
for dirpath, _, files in os.walk(root):
    for name in files:
        if name != "CMakeLists.txt":
            continue
        path = os.path.join(dirpath, name)
        with open(path) as f:
            text = f.read()
        new = re.sub(r"(/home/[^\s\")]*?)tensorflow", tf, text)
        new = re.sub(r"(/home/[^\s\")]*?)monodepth[-_]?cpp", monodepth, new)
        if new != text:
            changed += 1
            with open(path, "w") as f:
                f.write(new)
        left = re.findall(r"/home/[^\s\")]+", new)
        if left:
            sys.exit("patch: %s still holds personal paths: %s" % (path, left[:5]))
print("patch: %d CMakeLists.txt with TensorFlow/monodepth-cpp paths set" % changed)
