"""Source patches as insertions at anchors that must occur exactly once (Python 3.4+, no f-strings).

An upstream change that moves an anchor fails the image build with the file and anchor named, instead
of silently producing a mis-patched binary.
"""
import os
import sys


def patch(root, path, where, anchor, text):
    full = os.path.join(root, path)
    with open(full) as f:
        src = f.read()
    count = src.count(anchor)
    if count != 1:
        sys.exit("patch: %s: anchor %r found %d times, expected once (did upstream change?)" % (path, anchor, count))
    if where == "before":
        src = src.replace(anchor, text + anchor)
    elif where == "after":
        src = src.replace(anchor, anchor + text)
    elif where == "replace":
        src = src.replace(anchor, text)
    else:
        sys.exit("patch: where must be before, after or replace")
    with open(full, "w") as f:
        f.write(src)
    print("patch: %s (%s %r)" % (path, where, anchor[:50]))


def include_once(root, path, header):
    """Add an #include at the top of a file unless it is there."""
    full = os.path.join(root, path)
    with open(full) as f:
        src = f.read()
    line = "#include <%s>\n" % header
    if line not in src:
        with open(full, "w") as f:
            f.write(line + src)
        print("patch: %s (+%s)" % (path, header))


LOOP_SWITCH = """
    if (getenv("ORB_SLAM2_NO_LOOP"))  // slamrun: loop closure switch
    {
        unique_lock<mutex> lock(mMutexLoopQueue);
        mpCurrentKF = mlpLoopKeyFrameQueue.front();
        mlpLoopKeyFrameQueue.pop_front();
        mpKeyFrameDB->add(mpCurrentKF);
        return false;
    }
"""


def orb_slam2_family(root, extra_sources=()):
    """The patches every ORB-SLAM2-based method needs: the loop-closure switch (ORB_SLAM2_NO_LOOP=1 leaves
    keyframes in the database but searches no loop) and usleep's header for gcc >= 7."""
    patch(root, "src/LoopClosing.cc", "after", "bool LoopClosing::DetectLoop()\n{", LOOP_SWITCH)
    include_once(root, "src/LoopClosing.cc", "cstdlib")
    for f in ("src/System.cc", "src/Tracking.cc", "src/LocalMapping.cc", "src/LoopClosing.cc") + tuple(extra_sources):
        include_once(root, f, "unistd.h")
