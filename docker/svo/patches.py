"""SVO patches: Sophus @ a621ff's one-line fix for gcc >= 5, and a restart of a stalled initialisation in
the benchmark node (upstream stays paused forever after an initialisation failure)."""
import os
import re
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from patchlib import patch  # noqa: E402

sophus, svo = sys.argv[1], sys.argv[2]
patch(sophus, "sophus/so2.cpp", "replace", "unit_complex_.real() = 1.;\n  unit_complex_.imag() = 0.;",
      "unit_complex_ = std::complex<double>(1, 0);")

bench = os.path.join(svo, "svo_ros", "src", "benchmark_node.cpp")
with open(bench) as f:
    text = f.read()
# after every addImage call, a stage stuck in 'paused' (initialisation failed) is restarted
new, n = re.subn(r"(\n(\s*)(vo_->addImage\([^;]*\);))",
                 r"\1\n\2if (vo_->stage() == svo::FrameHandlerMono::STAGE_PAUSED) {  // slamrun: restart init\n"
                 r"\2  printf(\"slamrun: initialisation stalled, restarting\\n\");\n\2  vo_->start();\n\2}",
                 text)
if n == 0:
    sys.exit("patch: benchmark_node.cpp: no 'vo_->addImage(...)' call found")
with open(bench, "w") as f:
    f.write(new)
print("patch: benchmark_node.cpp: %d restart(s) added" % n)
