"""DynaSLAM patches: no viewer, the loop-closure switch, usleep's header, and HEAD's CMakeLists that still
references the removed Examples/Monocular/mono_carla.cc."""
import os
import re
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from patchlib import orb_slam2_family  # noqa: E402

root = sys.argv[1]
cmake = os.path.join(root, "CMakeLists.txt")
with open(cmake) as f:
    text = f.read()
# drop the add_executable/target_link_libraries blocks of mono_carla
text, n = re.subn(r"add_executable\(\s*mono_carla[^)]*\)\s*target_link_libraries\(\s*mono_carla[^)]*\)\s*", "", text)
with open(cmake, "w") as f:
    f.write(text)
print("patch: CMakeLists.txt: %d mono_carla block(s) removed" % n)

mono = "Examples/Monocular/mono_tum.cc"
with open(os.path.join(root, mono)) as f:
    text = f.read()
text, n = re.subn(r"(ORB_SLAM2::System\s+SLAM\(argv\[1\],\s*argv\[2\],\s*ORB_SLAM2::System::MONOCULAR,\s*)true\)",
                  r"\1false)", text)
if n != 1:
    sys.exit("patch: %s: the System constructor with the viewer flag was not found once" % mono)
with open(os.path.join(root, mono), "w") as f:
    f.write(text)
print("patch: %s: viewer off" % mono)

orb_slam2_family(root, [mono])
