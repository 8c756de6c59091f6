// slamrun: a stand-in for a frozen MonoDepth graph (model_city2kitti.pb), made at image build time with the
// TensorFlow C++ API (no Python, no download). It has the interface monodepth-cpp uses (src/monodepth.cpp):
//   input  "input_image"         float32 [2, 256, 512, 3]  (the image and its mirror, RGB in [0, 1])
//   output "model/output_depth"  float32 [2, 256, 512, 1]  (disparity, as monodepth's 0.3 * sigmoid(conv))
// and the output's structure of monodepth's freeze_graph (disp[:, :, :, 0] expanded back to rank 4).
// Its weights are NOT trained: by default the filter is zero, so every pixel gets the disparity of DEPTH
// metres through CNN-DSO's/CNN-SVO's conversion depth = 0.3128 / disparity; --random SEED draws small
// random filter weights instead (a depth map that varies with the image). Plumbing only: accuracy needs
// the authors' frozen graph.
// --producer N stamps the GraphDef with an older producer version (e.g. 24, TensorFlow 1.6's), to check
// that the Session still loads graphs frozen by TF 1.x.
// usage: make_standin_model OUT.pb [--depth METRES] [--random SEED] [--producer N]
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>

#include <tensorflow/cc/framework/scope.h>
#include <tensorflow/cc/ops/standard_ops.h>
#include <tensorflow/core/framework/graph.pb.h>
#include <tensorflow/core/framework/tensor.h>
#include <tensorflow/core/platform/env.h>

namespace ops = tensorflow::ops;

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s OUT.pb [--depth METRES] [--random SEED] [--producer N]\n", argv[0]);
    return 2;
  }
  const std::string out = argv[1];
  double depth = 10.0;
  long seed = -1;
  int producer = -1;
  for (int i = 2; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--depth")) depth = std::atof(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--random")) seed = std::atol(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--producer")) producer = std::atoi(argv[i + 1]);
    else { std::fprintf(stderr, "unknown option %s\n", argv[i]); return 2; }
  }
  // disparity = 0.3 * sigmoid(b) = 0.3128 / depth  ->  b = logit(0.3128 / (0.3 * depth))
  const double s = 0.3128 / (0.3 * depth);
  if (!(s > 0.0 && s < 1.0)) {
    std::fprintf(stderr, "--depth must be more than %.3f m\n", 0.3128 / 0.3);
    return 2;
  }
  const float bias = static_cast<float>(std::log(s / (1.0 - s)));

  const int B = 2, H = 256, W = 512, C = 3, K = 3, OUTC = 2;  // monodepth's get_disp has 2 channels
  tensorflow::Tensor filter(tensorflow::DT_FLOAT, tensorflow::TensorShape({K, K, C, OUTC}));
  auto f = filter.flat<float>();
  std::mt19937 rng(seed < 0 ? 0 : static_cast<unsigned>(seed));
  std::normal_distribution<float> normal(0.0f, 0.05f);
  for (int i = 0; i < f.size(); ++i) f(i) = seed < 0 ? 0.0f : normal(rng);
  tensorflow::Tensor b(tensorflow::DT_FLOAT, tensorflow::TensorShape({OUTC}));
  b.flat<float>().setConstant(bias);

  tensorflow::Scope root = tensorflow::Scope::NewRootScope();
  auto input = ops::Placeholder(root.WithOpName("input_image"), tensorflow::DT_FLOAT,
                                ops::Placeholder::Shape(tensorflow::PartialTensorShape({B, H, W, C})));
  tensorflow::Scope model = root.NewSubScope("model");
  auto conv = ops::Conv2D(model.WithOpName("conv"), input, ops::Const(model.WithOpName("weights"), filter),
                          {1, 1, 1, 1}, "SAME");
  auto logits = ops::BiasAdd(model.WithOpName("bias_add"), conv, ops::Const(model.WithOpName("biases"), b));
  auto disp = ops::Multiply(model.WithOpName("disp"), ops::Const(model, 0.3f), ops::Sigmoid(model, logits));
  auto ch0 = ops::Slice(model.WithOpName("disp_ch0"), disp, ops::Const(model, {0, 0, 0, 0}),
                        ops::Const(model, {-1, -1, -1, 1}));
  auto squeezed = ops::Squeeze(model, ch0, ops::Squeeze::Axis({3}));
  auto output = ops::ExpandDims(model.WithOpName("output_depth"), squeezed, 3);
  (void)output;
  if (!root.ok()) {
    std::fprintf(stderr, "graph construction failed: %s\n", root.status().ToString().c_str());
    return 1;
  }
  tensorflow::GraphDef graph;
  auto status = root.ToGraphDef(&graph);
  if (!status.ok()) {
    std::fprintf(stderr, "ToGraphDef failed: %s\n", status.ToString().c_str());
    return 1;
  }
  if (producer >= 0) graph.mutable_versions()->set_producer(producer);
  status = tensorflow::WriteBinaryProto(tensorflow::Env::Default(), out, graph);
  if (!status.ok()) {
    std::fprintf(stderr, "cannot write %s: %s\n", out.c_str(), status.ToString().c_str());
    return 1;
  }
  std::printf("make_standin_model: wrote %s (%d nodes; %s weights; constant-filter depth %.2f m) - NOT the "
              "trained MonoDepth network\n", out.c_str(), graph.node_size(), seed < 0 ? "zero" : "random", depth);
  return 0;
}
