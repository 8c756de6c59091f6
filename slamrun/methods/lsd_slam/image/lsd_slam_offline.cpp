// slamrun: a ROS-free offline driver for LSD-SLAM's core (lsd_slam::SlamSystem), in place of the ROS node
// `rosrun lsd_slam_core dataset_slam _files:=LIST _hz:=0 _calib:=CALIB [_doSLAM:=false]`
// (lsd_slam_core/src/main_on_images.cpp). The same processing: the calibration read by the same Undistorter (a
// TUM-Mono FOV camera.txt as is, or 8-number OpenCV), every image of the list undistorted and fed in order,
// frame 0 through randomInit() and the rest through trackFrame(..., blockUntilMapped = true, ...), i.e. `_hz:=0`:
// tracking waits for mapping, so the result does not depend on the machine's speed. The settings are the ROS
// node's effective ones (its dynamic_reconfigure defaults, cfg/LSDParams.cfg, which replace settings.cpp's
// initial values at start: KFUsageWeight 4, KFDistWeight 3, affine lighting estimation off, ...). No display
// and no ROS topics: upstream writes no trajectory file, so the poses are written at the end (after
// SlamSystem::finalize() when loop closure is on) with the list index of their frame.
//
// usage: lsd_slam_offline LIST CALIB OUT LOOP
//   LIST   image files, one per line, in processing order (relative paths: to the list's folder; `#` comments)
//   CALIB  camera file as upstream reads it
//   OUT    written: `list_index tx ty tz qx qy qz qw` per frame (camera-to-world, the world is frame 0's camera)
//   LOOP   1: SlamSystem with global mapping (doSLAM, loop closures, final optimisation); 0: without (the
//          equivalent of _doSLAM:=false: odometry, old keyframes dropped; finalize() is skipped: it would wait
//          for a constraint-search thread that does not exist and never return)
// Every pose of SlamSystem::getAllPoses() is written: tracked frames, keyframes (optimised ones at their graph
// pose) and frame 0 (the world's origin; with doSLAM off it is in no graph and has no tracking parent, so its
// pose is the identity). A frame whose tracking parent was discarded (its pose is no longer defined) is left out.
// Exit status: 0 with poses written; 2 on bad input; 3 when no frame was processed.
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "DataStructures/FramePoseStruct.h"
#include "SlamSystem.h"
#include "util/SophusUtil.h"
#include "util/Undistorter.h"
#include "util/settings.h"

using namespace lsd_slam;

namespace {

std::string trim(const std::string& s) {
  const char* ws = " \t\r\n";
  size_t a = s.find_first_not_of(ws);
  if (a == std::string::npos) return "";
  return s.substr(a, s.find_last_not_of(ws) - a + 1);
}

// main_on_images.cpp's getFile(): one path per line, relative paths taken from the list's folder
bool read_list(const std::string& path, std::vector<std::string>& files) {
  std::ifstream f(path);
  if (!f) return false;
  std::string line;
  while (std::getline(f, line)) {
    line = trim(line);
    if (!line.empty() && line[0] != '#') files.push_back(line);
  }
  size_t slash = path.find_last_of('/');
  std::string prefix = slash == std::string::npos ? "." : path.substr(0, slash);
  for (std::string& name : files)
    if (name[0] != '/') name = prefix + "/" + name;
  return true;
}

// the ROS node's parameters after dynamic_reconfigure applied its defaults (cfg/LSDParams.cfg,
// cfg/LSDDebugParams.cfg) in dynConfCb(); headless: no depth-map window, no on-screen info
void ros_node_settings(bool loop) {
  allowNegativeIdepths = true;
  useSubpixelStereo = true;
  multiThreading = true;
  useAffineLightningEstimation = false;
  KFDistWeight = 3;
  KFUsageWeight = 4;
  minUseGrad = 5;
  cameraPixelNoise2 = 4 * 4;
  depthSmoothingFactor = 1;
  doSlam = loop;
  useFabMap = false;
  doKFReActivation = true;
  doMapping = true;
  maxLoopClosureCandidates = 10;
  loopclosureStrictness = 1.5;
  relocalizationTH = 0.7;
  displayDepthMap = false;
  onSceenInfoDisplay = false;
  plotTracking = plotStereoImages = plotTrackingIterationInfo = false;
  saveKeyframes = saveAllTracked = saveLoopClosureImages = saveAllTrackingStages = false;
  continuousPCOutput = false;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 5 || (std::string(argv[4]) != "0" && std::string(argv[4]) != "1")) {
    std::fprintf(stderr, "usage: %s LIST CALIB OUT LOOP(0|1)\n", argv[0]);
    return 2;
  }
  const std::string list = argv[1], calib = argv[2], out_path = argv[3];
  const bool loop = std::string(argv[4]) == "1";
  ros_node_settings(loop);

  Undistorter* undistorter = Undistorter::getUndistorterForFile(calib.c_str());
  if (undistorter == nullptr) {
    std::fprintf(stderr, "cannot read a camera calibration from %s\n", calib.c_str());
    return 2;
  }
  const int w = undistorter->getOutputWidth(), h = undistorter->getOutputHeight();
  const int w_inp = undistorter->getInputWidth(), h_inp = undistorter->getInputHeight();
  // as main_on_images.cpp: the PTAM (FOV) undistorter stores K transposed (cx at (2,0)); the OpenCV one does not
  const cv::Mat& Kcv = undistorter->getK();
  const float fx = Kcv.at<double>(0, 0), fy = Kcv.at<double>(1, 1);
  const float cx = Kcv.at<double>(2, 0) != 0 ? Kcv.at<double>(2, 0) : Kcv.at<double>(0, 2);
  const float cy = Kcv.at<double>(2, 1) != 0 ? Kcv.at<double>(2, 1) : Kcv.at<double>(1, 2);
  Sophus::Matrix3f K;
  K << fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0;
  std::printf("slamrun: %dx%d -> %dx%d, K fx %.4f fy %.4f cx %.4f cy %.4f; loop closure %s\n", w_inp, h_inp, w, h, fx,
              fy, cx, cy, loop ? "on" : "off");
  if (w % 16 != 0 || h % 16 != 0) {
    std::fprintf(stderr, "the output size %dx%d must be a multiple of 16 (camera.txt's last line)\n", w, h);
    return 2;
  }

  std::vector<std::string> files;
  if (!read_list(list, files) || files.empty()) {
    std::fprintf(stderr, "no images loaded: cannot read a file list from %s\n", list.c_str());
    return 2;
  }
  std::FILE* out = std::fopen(out_path.c_str(), "w");
  if (!out) {
    std::fprintf(stderr, "cannot write %s\n", out_path.c_str());
    return 2;
  }
  std::printf("slamrun: %zu image files in %s\n", files.size(), list.c_str());

  SlamSystem* system = new SlamSystem(w, h, K, doSlam);
  cv::Mat image(h, w, CV_8U);
  for (size_t i = 0; i < files.size(); ++i) {
    cv::Mat dist = cv::imread(files[i], cv::IMREAD_GRAYSCALE);
    if (dist.empty()) {
      std::fprintf(stderr, "could not load %s\n", files[i].c_str());
      return 2;
    }
    if (dist.rows != h_inp || dist.cols != w_inp) {
      std::fprintf(stderr, "image %s has wrong dimensions: expecting %d x %d, found %d x %d\n", files[i].c_str(),
                   w_inp, h_inp, dist.cols, dist.rows);
      return 2;
    }
    undistorter->undistort(dist, image);
    const double t = 0.03 * i;  // as the ROS node: only used for its topics
    if (i == 0)
      system->randomInit(image.data, t, 0);
    else
      system->trackFrame(image.data, i, true, t);  // frame id = list index; blockUntilMapped: _hz:=0
  }
  if (loop) system->finalize();

  std::vector<FramePoseStruct*, Eigen::aligned_allocator<FramePoseStruct*> > poses = system->getAllPoses();
  size_t written = 0, undefined = 0;
  for (FramePoseStruct* p : poses) {
    const bool origin = p->frameID == 0;
    if (!origin && p->trackingParent == nullptr && !p->isOptimized) {
      ++undefined;
      continue;
    }
    const Sim3 camToWorld = p->getCamToWorld();  // frame 0 without parent: the identity
    const Eigen::Vector3d t = camToWorld.translation();
    const Eigen::Quaterniond q = camToWorld.rxso3().quaternion().normalized();
    std::fprintf(out, "%d %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", p->frameID, t.x(), t.y(), t.z(), q.x(), q.y(), q.z(),
                 q.w());
    ++written;
  }
  std::fclose(out);
  std::printf("slamrun: %zu poses of %zu frames written to %s", written, files.size(), out_path.c_str());
  if (undefined) std::printf(" (%zu left out: their tracking parent was discarded)", undefined);
  std::printf("\n");
  delete system;
  delete undistorter;
  return written > 0 ? 0 : 3;
}
