"""DF-ORB-SLAM patches: the monocular optical-flow fix, the loop-closure switch, usleep's header.

Monocular bug (methods.md): the previous/current images that calcOpticalFlowPyrLK reads are filled only
on the RGB-D path, so a monocular run hangs at the first motion-model track. The fix copies, into
GrabImageMonocular, the RGB-D path's statements that fill those images (found by name, not by line)."""
import os
import re
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from patchlib import orb_slam2_family  # noqa: E402

root = sys.argv[1]
tracking = os.path.join(root, "src", "Tracking.cc")
with open(tracking) as f:
    src = f.read()


def body(name):
    m = re.search(r"cv::Mat Tracking::%s\([^)]*\)\s*\{" % name, src)
    if not m:
        sys.exit("patch: Tracking.cc: no function %s (did upstream change?)" % name)
    depth, i = 1, m.end()
    while depth:
        depth += {"{": 1, "}": -1}.get(src[i], 0)
        i += 1
    return m.end(), i


# The image members the optical flow reads: the first two arguments of every calcOpticalFlowPyrLK call.
flow_args = set()
for call in re.finditer(r"calcOpticalFlowPyrLK\(\s*([\w.>-]+)\s*,\s*([\w.>-]+)", src):
    flow_args.update(a.split("->")[-1].split(".")[-1] for a in call.groups())
if not flow_args:
    sys.exit("patch: Tracking.cc: no calcOpticalFlowPyrLK call found")
start, end = body("GrabImageRGBD")
rgbd = src[start:end]
fills = [ln for ln in rgbd.splitlines()
         if any(re.search(r"\b%s\b" % re.escape(a), ln) for a in flow_args) and ("=" in ln or "copyTo" in ln)]
if not fills:
    sys.exit("patch: GrabImageRGBD fills none of %s; the fix needs updating" % sorted(flow_args))
mstart, mend = body("GrabImageMonocular")
mono = src[mstart:mend]
anchor = re.search(r"\n\s*mCurrentFrame\s*=\s*Frame\(", mono)
if not anchor:
    sys.exit("patch: GrabImageMonocular: no 'mCurrentFrame = Frame(' line")
insert = "\n    // slamrun: fill the optical-flow images as the RGB-D path does\n" + "\n".join(fills)
pos = mstart + anchor.start()
src = src[:pos] + insert + src[pos:]
with open(tracking, "w") as f:
    f.write(src)
print("patch: Tracking.cc monocular optical-flow images: %d statement(s) for %s" % (len(fills), sorted(flow_args)))

orb_slam2_family(root, [])
