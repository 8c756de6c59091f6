// slamrun: a ROS-free offline driver for CNN-SVO's core (svo::FrameHandlerOnline: SVO + MonoDepth depth through
// monodepth-cpp), in place of the ROS node svo_ros/vo_monodepth_online. Same processing as that node: every
// frame in order through addImage(), frame_delay_ms between frames (the node sleeps 50 ms), then the map's
// keyframe poses (camera-to-world) written at the end. Differences: frames are the image files of a folder in
// name order (not <sequence_path>/<image_folder>/%06d.png), timestamps come from a one-timestamp-per-line file
// given by path (not <sequence_path>/times.txt; the first number of each line is taken, as upstream does),
// the output is one TUM file with full-precision timestamps (upstream writes 7 significant digits), and an
// initialisation that left the system paused is restarted (upstream stays paused to the end).
//
// usage: cnn_svo_offline PARAMS.yaml
//   PARAMS is a flat rosparam-style file (see slamrun/methods/recipes/common/svo-include/vikit/params_helper.h); besides SVO's own parameters:
//   svo/cam_model Pinhole|ATAN, svo/cam_width, svo/cam_height, svo/cam_fx, svo/cam_fy, svo/cam_cx, svo/cam_cy,
//   svo/cam_d0..cam_d3 (Pinhole distortion; ATAN: cam_d0 = omega), svo/image_folder, svo/times_file,
//   svo/cnn_model (frozen MonoDepth graph), svo/output_file (TUM, keyframes), svo/frame_delay_ms (default 50),
//   svo/skipped_frames (default 0).
// Exit status: 0 with poses written; 3 when no keyframe was left to write (the file is still created).
#include <dirent.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <svo/config.h>
#include <svo/frame.h>
#include <svo/frame_handler_online.h>
#include <svo/map.h>
#include <vikit/atan_camera.h>
#include <vikit/params_helper.h>
#include <vikit/pinhole_camera.h>

static std::vector<std::string> list_frames(const std::string& folder) {
  std::vector<std::string> names;
  DIR* dir = opendir(folder.c_str());
  if (!dir) return names;
  while (dirent* e = readdir(dir)) {
    std::string n = e->d_name;
    std::string lower = n;
    std::transform(lower.begin(), lower.end(), lower.begin(), ::tolower);
    for (const char* ext : {".png", ".jpg", ".jpeg", ".pgm", ".ppm", ".bmp"}) {
      const std::string x(ext);
      if (lower.size() > x.size() && lower.compare(lower.size() - x.size(), x.size(), x) == 0) {
        names.push_back(folder + "/" + n);
        break;
      }
    }
  }
  closedir(dir);
  std::sort(names.begin(), names.end());
  return names;
}

static std::vector<double> read_times(const std::string& path) {
  std::vector<double> t;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    double v;
    if (std::sscanf(line.c_str(), "%lf", &v) == 1) t.push_back(v);
  }
  return t;
}

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s PARAMS.yaml\n", argv[0]);
    return 2;
  }
  setenv("SVO_PARAMS", argv[1], 1);
  const std::string model = vk::getParam<std::string>("svo/cam_model");
  const int w = vk::getParam<int>("svo/cam_width"), h = vk::getParam<int>("svo/cam_height");
  const double fx = vk::getParam<double>("svo/cam_fx"), fy = vk::getParam<double>("svo/cam_fy");
  const double cx = vk::getParam<double>("svo/cam_cx"), cy = vk::getParam<double>("svo/cam_cy");
  vk::AbstractCamera* cam = nullptr;
  if (model == "Pinhole")
    cam = new vk::PinholeCamera(w, h, fx, fy, cx, cy, vk::getParam<double>("svo/cam_d0", 0.0),
                                vk::getParam<double>("svo/cam_d1", 0.0), vk::getParam<double>("svo/cam_d2", 0.0),
                                vk::getParam<double>("svo/cam_d3", 0.0));
  else if (model == "ATAN")
    cam = new vk::ATANCamera(w, h, fx, fy, cx, cy, vk::getParam<double>("svo/cam_d0"));
  else {
    std::fprintf(stderr, "svo/cam_model must be Pinhole or ATAN (got '%s')\n", model.c_str());
    return 2;
  }
  if (vk::getParam<std::string>("svo/cnn_model", "").empty()) {
    std::fprintf(stderr, "svo/cnn_model (the frozen MonoDepth graph) is not set\n");
    return 2;
  }

  const std::string folder = vk::getParam<std::string>("svo/image_folder");
  const std::vector<std::string> frames = list_frames(folder);
  const std::vector<double> times = read_times(vk::getParam<std::string>("svo/times_file"));
  if (frames.empty() || frames.size() != times.size()) {
    std::fprintf(stderr, "no images loaded: %zu frames in %s, %zu timestamps\n", frames.size(), folder.c_str(),
                 times.size());
    return 2;
  }
  const std::string out_path = vk::getParam<std::string>("svo/output_file");
  std::ofstream out(out_path);
  if (!out) {
    std::fprintf(stderr, "cannot write %s\n", out_path.c_str());
    return 2;
  }
  const int delay_ms = vk::getParam<int>("svo/frame_delay_ms", 50);
  const size_t first = vk::getParam<int>("svo/skipped_frames", 0);
  std::printf("got %zu frames and timestamps\n", frames.size());

  auto* vo = new svo::FrameHandlerOnline(cam);  // loads the MonoDepth graph (a TensorFlow Session)
  vo->start();
  for (size_t i = first; i < frames.size(); ++i) {
    cv::Mat img = cv::imread(frames[i], cv::IMREAD_COLOR);
    if (img.empty()) {
      std::fprintf(stderr, "could not load %s\n", frames[i].c_str());
      return 2;
    }
    if (img.cols != w || img.rows != h) {
      std::fprintf(stderr, "%s is %dx%d, the camera is %dx%d\n", frames[i].c_str(), img.cols, img.rows, w, h);
      return 2;
    }
    vo->addImage(img, times[i]);
    if (vo->stage() == svo::FrameHandlerBase::STAGE_PAUSED) {
      std::printf("slamrun: initialisation failed at frame %zu, restarting\n", i);
      vo->start();
    }
    if (delay_ms > 0) usleep(delay_ms * 1000);
  }

  size_t n = 0;
  out.precision(9);
  out << std::fixed;
  for (const svo::FramePtr& kf : vo->map().keyframes_) {
    const Sophus::SE3 T_w_f = kf->T_f_w_.inverse();
    const Eigen::Quaterniond q(T_w_f.unit_quaternion());
    const Eigen::Vector3d p = T_w_f.translation();
    out << kf->timestamp_ << " " << p.x() << " " << p.y() << " " << p.z() << " " << q.x() << " " << q.y() << " "
        << q.z() << " " << q.w() << "\n";
    ++n;
  }
  out.close();
  std::printf("slamrun: %zu keyframe poses written to %s\n", n, out_path.c_str());
  delete vo;  // stops the depth-filter thread
  delete cam;
  return n > 0 ? 0 : 3;
}
