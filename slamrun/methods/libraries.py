"""What several methods' images share: the libraries they build from (pinned as the methods' own sources are) and
MonoDepth's network, which CNN-DSO and CNN-SVO both load; and the TUM-Mono benchmark's own evaluator, which the bench
and the tests run beside slamrun's. A source one method alone builds from is in its folder's declaration."""

from __future__ import annotations

from slamrun.methods.declare import Source, Weights

# Lie groups on PyTorch (SE3, Sim3), compiled into each GPU image that takes it: DROID-SLAM's submodule (at the
# commit it records) and what MASt3R-SLAM's pyproject installs
LIETORCH = Source(
    "lietorch",
    "princeton-vl/lietorch",
    "7f687644fcea81ab337831749445224503c1290d",
    sha256="2c9c9be882509068e5ec78721d33ebd1258d1311cae2ee82ab399fc77cb94863",
    tree="15a27b463eaa0afe8b81101f338c899604d98d1c2c6fe22d9ce100357482fdcb",
)

LIBRARIES: tuple[Source, ...] = (
    Source(
        "pangolin-0.6",
        "stevenlovegrove/Pangolin",
        "dd801d244db3a8e27b7fe8020cd751404aa818fd",
        sha256="cc7326281613773bc22949da9cd3e06fe68b45a9c848e1a3740f6613e7fb5f2d",
        tree="47161a2af7b2a7aa31203bc473f8aa73e2e3b0e1dea8e6b6fa41f7557ff56223",
    ),
    Source(
        "pangolin-0.5",
        "stevenlovegrove/Pangolin",
        "7987c9ba6b6c2c46fdcf50baae28bfa4f8352696",
        sha256="e5ea71753fc4ea5c6b6576f12c375ba42a97a61b8b5e740eb21f3e95bb819050",
        tree="5f26ab14d5f6c8a1c78bb63c072cf1f730b9ca5c2630cee1411196ac541a7bca",
    ),
    Source(
        "sophus",
        "strasdat/Sophus",
        "a621ff2e56c56c839a6c40418d42c3c254424b5c",
        sha256="ff3b929eee08bd569a10d797158f13528ac30b866ac4c1d4bfbeed65adad93a6",
        tree="eb40e486714c49fd3a311d2bd0598a8e3710f54fff9ffc700035eeb6143903f5",
    ),
    Source(
        "fast",
        "uzh-rpg/fast",
        "1153981a7d0263909e998789a5b5029412c28f5a",
        sha256="75b156ca526ed01a3c27c9b9cd55402e54956a0fea870e4111a71c8676ab4ce3",
        tree="b67642e64abe584df9154e7533a70d51de09716518553ff0e40604b335c9156e",
    ),
    Source(
        "g2o",
        "RainerKuemmerle/g2o",
        "17fce87df9d5b2aa7b4239be1fbac9d40c95d72f",
        sha256="2e9e07587d3f6f06c92b55932a879eecbcbfa65d6863e7070a3df2fbd28854d1",
        tree="e56f748c20bffba0f6880ad1a7b8c65fbbdd551e57ed190735c04faa7d86a70d",
    ),
    Source(
        "monodepth-cpp",
        "yan99033/monodepth-cpp",
        "1ea2fc30b96deba4e4d094088e4dc9f4c9c7980a",
        sha256="f538a24032c14f1d7d25cf55fd27c5134d3e27b8e005952e2dfe03fb818c2696",
        tree="ce43a2595cc78ee27ca5032022c3773984ef2aad97ec3acb66a80e28647dfac0",
    ),
    LIETORCH,
    # the TUM-Mono benchmark's own code: its MATLAB evaluator, run under Octave beside slamrun's (bench, tests)
    Source(
        "mono_dataset_code",
        "tum-vision/mono_dataset_code",
        "3feba2f77488e5b3e05c739c2c7afb57822ad083",
        sha256="e9091b93701240867ccd1b424771a3b8831c0fcdd2fa264b0a1d2ebd1fdebe99",
        tree="1fbd1248c5b48a5f7047af46d8fc00da235c8b0e6783f313815fecb23b86fa25",
    ),
)

MONODEPTH = Weights(
    "model_city2kitti.pb",
    "a frozen MonoDepth graph: monodepth-cpp's model/README.md links the converted graph, freeze_graph/README.md "
    "the VGG (city2kitti) and ResNet50 graphs; MonoDepth's site serves .zip checkpoints only, which "
    "freeze_graph/freeze_graph.py (TensorFlow 1.x) turns into a .pb",
    standin=True,
)
