// slamrun: load a frozen MonoDepth graph through monodepth-cpp (TensorFlow Session + GraphDef) and run it
// once on a synthetic WIDTHxHEIGHT image, so a wrong or incompatible model.pb fails the image build, not a
// benchmark run. Prints the depth range it predicts (depth = 0.3128 / disparity, as CNN-DSO/CNN-SVO do).
// usage: check_model MODEL.pb [WIDTH HEIGHT]
#include <cstdio>
#include <cstdlib>
#include <monodepth/monodepth.h>
#include <opencv2/core.hpp>

int main(int argc, char** argv) {
  if (argc < 2) { std::fprintf(stderr, "usage: %s MODEL.pb [WIDTH HEIGHT]\n", argv[0]); return 2; }
  const int w = argc > 3 ? std::atoi(argv[2]) : 640, h = argc > 3 ? std::atoi(argv[3]) : 480;
  monodepth::MonoDepth net(w, h, argv[1]);
  cv::Mat image(h, w, CV_8UC3), disp;
  cv::randu(image, 0, 255);
  if (!net.inference(image, disp) || disp.rows != h || disp.cols != w || disp.type() != CV_32FC1) {
    std::fprintf(stderr, "check_model: %s gave no %dx%d float disparity map\n", argv[1], w, h);
    return 1;
  }
  cv::Mat depth = 0.3128f / (disp + 0.00001f);
  double lo, hi;
  cv::minMaxLoc(depth, &lo, &hi);
  std::printf("check_model: %s runs: %dx%d depth in [%.3f, %.3f] m\n", argv[1], w, h, lo, hi);
  return 0;
}
