"""LSD-SLAM patches: write every frame's final pose with its frame index after finalize() (upstream writes
no trajectory file: poses only reach ROS topics with fake timestamps), and OpenCV 3+ constant names."""
import os
import re
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from patchlib import include_once, patch  # noqa: E402

root = sys.argv[1]
main = "lsd_slam_core/src/main_on_images.cpp"
patch(root, main, "after", "\tsystem->finalize();\n", """
	// slamrun: all frame poses (camera-to-world) with their frame index, to $SLAMRUN_POSES
	if (getenv("SLAMRUN_POSES"))
	{
		std::ofstream out(getenv("SLAMRUN_POSES"));
		out << std::setprecision(12);
		std::vector<FramePoseStruct*, Eigen::aligned_allocator<FramePoseStruct*> > poses = system->getAllPoses();
		for (unsigned int i = 0; i < poses.size(); i++)
		{
			if (!poses[i]->isInGraph && !poses[i]->trackingParent) continue;
			Sim3 camToWorld = poses[i]->getCamToWorld();
			Eigen::Vector3d t = camToWorld.translation();
			Eigen::Quaterniond q(camToWorld.rxso3().quaternion().normalized());
			out << poses[i]->frameID << " " << t.x() << " " << t.y() << " " << t.z() << " "
			    << q.x() << " " << q.y() << " " << q.z() << " " << q.w() << "\\n";
		}
		printf("slamrun: wrote %d poses\\n", (int)poses.size());
	}
""")
include_once(root, main, "iomanip")
include_once(root, main, "cstdlib")
include_once(root, main, "fstream")

# the debug windows: off by default (the wrapper also runs under a virtual display)
settings = os.path.join(root, "lsd_slam_core", "src", "util", "settings.cpp")
with open(settings) as f:
    text = f.read()
text, n = re.subn(r"(bool\s+displayDepthMap\s*=\s*)true", r"\1false", text)
with open(settings, "w") as f:
    f.write(text)
print("patch: settings.cpp: displayDepthMap off (%d)" % n)
