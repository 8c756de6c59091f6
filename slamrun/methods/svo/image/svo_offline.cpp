// slamrun: a ROS-free offline driver for SVO's core (svo::FrameHandlerMono), in place of the ROS node
// svo_ros/benchmark. Same processing as that node: every frame of the list in order through addImage(), as fast
// as it goes, and the pose (camera-to-world) of every frame tracked in the default stage written as it is
// tracked. Differences: the camera can be TUM-Mono's camera.txt (the FOV model is vikit's ATAN camera, which
// takes the same relative fx fy cx cy omega), the first keyframe of each initialisation is written too (its pose
// is the map's origin), timestamps are written with all the digits of the list, and when the system is paused
// (an initialisation that failed resets SVO, and the ROS nodes then wait for a user's 's') it is started again:
// the study's setup.
//
// usage: svo_offline PARAMS.yaml
//   PARAMS is a flat rosparam-style file (see include/vikit/params_helper.h) with SVO's own parameters (svo/...,
//   read with the ROS node's defaults) and:
//   svo/dataset_directory  folder holding images.txt (`timestamp image_path`, paths relative to the folder)
//   svo/output_file        TUM trajectory written (default <svo/trace_dir>/traj_estimate.txt)
//   svo/cam_model          ATAN (default) or Pinhole
//   svo/camera_file        ATAN: a TUM-Mono camera.txt (`[FOV] fx fy cx cy omega` relative or in pixels,
//                          then `width height`); without it svo/cam_width, cam_height, cam_fx, cam_fy, cam_cx,
//                          cam_cy (relative, as vikit's ATAN camera takes them) and cam_d0 (omega)
//                          Pinhole: svo/cam_width, cam_height, cam_fx, cam_fy, cam_cx, cam_cy in pixels,
//                          cam_d0..cam_d3 (radial-tangential, default 0)
// Exit status: 0 with poses written; 3 when no pose was written (never initialised; the file is still
// created); 2 on bad input.
#include <unistd.h>

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <svo/config.h>
#include <svo/frame.h>
#include <svo/frame_handler_mono.h>
#include <svo/map.h>
#include <vikit/atan_camera.h>
#include <vikit/params_helper.h>
#include <vikit/pinhole_camera.h>

namespace {

struct Entry {
  std::string stamp;  // as written in the list: written back unchanged
  double t;
  std::string path;
};

std::vector<Entry> read_list(const std::string& dir) {
  std::vector<Entry> out;
  std::ifstream in(dir + "/images.txt");
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    Entry e;
    if (line.empty() || line[0] == '#' || !(s >> e.stamp >> e.path)) continue;
    char* end = nullptr;
    e.t = std::strtod(e.stamp.c_str(), &end);
    if (end == e.stamp.c_str() || *end != '\0') continue;
    if (e.path[0] != '/') e.path = dir + "/" + e.path;
    out.push_back(e);
  }
  return out;
}

// TUM-Mono camera.txt (DSO's reader): line 1 `[FOV] fx fy cx cy omega`, relative to the image size when cx and cy
// are below 1 (DSO's rule), else in pixels; line 2 `width height`. vikit's ATAN camera takes relative values and
// puts the centre at cx * width - 0.5, as DSO does.
vk::AbstractCamera* atan_from_camera_txt(const std::string& path) {
  std::ifstream in(path);
  std::string l1, l2;
  if (!std::getline(in, l1) || !std::getline(in, l2)) {
    std::fprintf(stderr, "%s: cannot read two lines\n", path.c_str());
    return nullptr;
  }
  std::istringstream s1(l1), s2(l2);
  std::string first;
  s1 >> first;
  if (!first.empty() && std::isalpha(static_cast<unsigned char>(first[0]))) {
    if (first != "FOV") {
      std::fprintf(stderr, "%s: camera model %s; SVO's ATAN camera is the FOV model\n", path.c_str(), first.c_str());
      return nullptr;
    }
    first.clear();
  }
  double p[5];
  int n = 0;
  if (!first.empty()) p[n++] = std::atof(first.c_str());
  while (n < 5 && (s1 >> p[n])) ++n;
  double w = 0, h = 0;
  if (n != 5 || !(s2 >> w >> h) || w <= 0 || h <= 0) {
    std::fprintf(stderr, "%s: expected `fx fy cx cy omega` and `width height`\n", path.c_str());
    return nullptr;
  }
  if (!(p[2] < 1 && p[3] < 1)) {  // pixels -> relative (the inverse of DSO's rescaling)
    p[0] /= w;
    p[1] /= h;
    p[2] = (p[2] + 0.5) / w;
    p[3] = (p[3] + 0.5) / h;
  }
  std::printf("slamrun: ATAN camera %gx%g fx %.9g fy %.9g cx %.9g cy %.9g omega %.9g (relative)\n", w, h, p[0], p[1],
              p[2], p[3], p[4]);
  return new vk::ATANCamera(w, h, p[0], p[1], p[2], p[3], p[4]);
}

vk::AbstractCamera* make_camera() {
  const std::string model = vk::getParam<std::string>("svo/cam_model", "ATAN");
  if (model == "ATAN") {
    const std::string file = vk::getParam<std::string>("svo/camera_file", "");
    if (!file.empty()) return atan_from_camera_txt(file);
    return new vk::ATANCamera(vk::getParam<int>("svo/cam_width"), vk::getParam<int>("svo/cam_height"),
                              vk::getParam<double>("svo/cam_fx"), vk::getParam<double>("svo/cam_fy"),
                              vk::getParam<double>("svo/cam_cx"), vk::getParam<double>("svo/cam_cy"),
                              vk::getParam<double>("svo/cam_d0"));
  }
  if (model == "Pinhole")
    return new vk::PinholeCamera(vk::getParam<int>("svo/cam_width"), vk::getParam<int>("svo/cam_height"),
                                 vk::getParam<double>("svo/cam_fx"), vk::getParam<double>("svo/cam_fy"),
                                 vk::getParam<double>("svo/cam_cx"), vk::getParam<double>("svo/cam_cy"),
                                 vk::getParam<double>("svo/cam_d0", 0.0), vk::getParam<double>("svo/cam_d1", 0.0),
                                 vk::getParam<double>("svo/cam_d2", 0.0), vk::getParam<double>("svo/cam_d3", 0.0));
  std::fprintf(stderr, "svo/cam_model must be ATAN or Pinhole (got '%s')\n", model.c_str());
  return nullptr;
}

void write_pose(std::FILE* out, const std::string& stamp, const Sophus::SE3& T_f_w) {
  const Sophus::SE3 T_w_f = T_f_w.inverse();
  const Eigen::Quaterniond q(T_w_f.unit_quaternion());
  const Eigen::Vector3d p = T_w_f.translation();
  std::fprintf(out, "%s %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", stamp.c_str(), p.x(), p.y(), p.z(), q.x(), q.y(),
               q.z(), q.w());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s PARAMS.yaml\n", argv[0]);
    return 2;
  }
  if (access(argv[1], R_OK) != 0) {
    std::fprintf(stderr, "cannot read %s\n", argv[1]);
    return 2;
  }
  setenv("SVO_PARAMS", argv[1], 1);
  vk::AbstractCamera* cam = make_camera();
  if (!cam) return 2;

  const std::string dir = vk::getParam<std::string>("svo/dataset_directory");
  const std::vector<Entry> frames = read_list(dir);
  if (frames.empty()) {
    std::fprintf(stderr, "no images loaded: %s/images.txt lists no frame\n", dir.c_str());
    return 2;
  }
  const std::string out_path =
      vk::getParam<std::string>("svo/output_file", svo::Config::traceDir() + "/traj_estimate.txt");
  std::FILE* out = std::fopen(out_path.c_str(), "w");
  if (!out) {
    std::fprintf(stderr, "cannot write %s\n", out_path.c_str());
    return 2;
  }
  std::printf("slamrun: %zu frames listed in %s/images.txt\n", frames.size(), dir.c_str());

  auto* vo = new svo::FrameHandlerMono(cam);  // starts the depth-filter thread
  vo->start();
  size_t n_poses = 0, n_lost = 0, n_restarts = 0;
  svo::FrameHandlerBase::Stage before = svo::FrameHandlerBase::STAGE_FIRST_FRAME;
  for (size_t i = 0; i < frames.size(); ++i) {
    cv::Mat img = cv::imread(frames[i].path, cv::IMREAD_GRAYSCALE);
    if (img.empty()) {
      std::fprintf(stderr, "could not load %s\n", frames[i].path.c_str());
      return 2;
    }
    if (img.cols != cam->width() || img.rows != cam->height()) {
      std::fprintf(stderr, "%s is %dx%d, the camera is %dx%d\n", frames[i].path.c_str(), img.cols, img.rows,
                   cam->width(), cam->height());
      return 2;
    }
    vo->addImage(img, frames[i].t);
    const svo::FrameHandlerBase::Stage stage = vo->stage();
    if (stage == svo::FrameHandlerBase::STAGE_DEFAULT_FRAME) {
      if (before == svo::FrameHandlerBase::STAGE_SECOND_FRAME) {
        // initialised on this frame: the first keyframe (the map's origin) comes first
        for (const svo::FramePtr& kf : vo->map().keyframes_) {
          if (kf->id_ == vo->lastFrame()->id_) continue;
          for (const Entry& e : frames)
            if (e.t == kf->timestamp_) {
              write_pose(out, e.stamp, kf->T_f_w_);
              ++n_poses;
              break;
            }
        }
        std::printf("slamrun: initialised at frame %zu\n", i);
      } else if (before == svo::FrameHandlerBase::STAGE_RELOCALIZING) {
        std::printf("slamrun: relocalised at frame %zu\n", i);
      }
      write_pose(out, frames[i].stamp, vo->lastFrame()->T_f_w_);
      ++n_poses;
    } else if (stage == svo::FrameHandlerBase::STAGE_RELOCALIZING && before == svo::FrameHandlerBase::STAGE_DEFAULT_FRAME) {
      std::printf("slamrun: tracking lost at frame %zu, relocalising\n", i);
      ++n_lost;
    } else if (stage == svo::FrameHandlerBase::STAGE_PAUSED) {
      std::printf("slamrun: initialisation failed at frame %zu, restarting\n", i);
      ++n_restarts;
      vo->start();
    }
    before = stage;
    std::fflush(out);
  }
  std::fclose(out);
  std::printf("slamrun: %zu poses of %zu frames written to %s; %zu restart(s) of the initialisation\n", n_poses,
              frames.size(), out_path.c_str(), n_restarts);
  if (n_lost) std::printf("slamrun: tracking lost %zu time(s)\n", n_lost);
  if (!n_poses) std::printf("slamrun: never initialised\n");
  delete vo;  // stops the depth-filter thread
  delete cam;
  return n_poses > 0 ? 0 : 3;
}
