// slamrun: train a small DBoW2 text vocabulary for ORB-SLAM2-family methods (ORB-SLAM2, DF-ORB-SLAM) when the
// source lacks Vocabulary/ORBvoc.txt(.tar.gz) and no file was given. Compiled against the method's own tree:
// its Thirdparty/DBoW2 (ORB_SLAM2::ORBVocabulary = TemplatedVocabulary<FORB::TDescriptor, FORB>) and its own
// ORB_SLAM2::ORBextractor (src/ORBextractor.cc, OpenCV only), so the words are built from exactly the
// descriptors the method computes at run time (octree-distributed FAST, 8 levels x 1.2, 32-byte rBRIEF).
// k-means tree with k = 10, L levels (default 5: Tracking/LocalMapping group features at 4 levels above the
// words, so L = 4 would leave a single group), TF-IDF weights, L1 scoring (the header of the authors'
// ORBvoc.txt: "10 6 0 0"), saved with saveToTextFile: the format System loads with loadFromTextFile.
// Seeded, so the same frames give the same file. Not the authors' vocabulary: relocalisation and loop closure
// made with it are not the study's.
//   train_orb_vocabulary OUT.txt IMAGE...          (environment: ORB_VOCAB_L=levels, ORB_VOCAB_FEATURES=n)
#include "ORBVocabulary.h"
#include "ORBextractor.h"
#include "Thirdparty/DBoW2/DUtils/Random.h"

#include <chrono>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include <opencv2/core/core.hpp>
#include <opencv2/imgcodecs.hpp>

static int env_int(const char *name, int def, int lo, int hi)
{
    const char *v = std::getenv(name);
    if (!v || !*v) return def;
    int x = std::atoi(v);
    if (x < lo || x > hi)
    {
        std::cerr << "train_orb_vocabulary: " << name << "=" << v << " out of [" << lo << ", " << hi << "]" << std::endl;
        std::exit(2);
    }
    return x;
}

int main(int argc, char **argv)
{
    if (argc < 3)
    {
        std::cerr << "usage: train_orb_vocabulary OUT.txt IMAGE..." << std::endl;
        return 2;
    }
    const int k = 10;
    const int L = env_int("ORB_VOCAB_L", 5, 2, 6);
    const int nFeatures = env_int("ORB_VOCAB_FEATURES", 1000, 100, 5000);
    auto t0 = std::chrono::steady_clock::now();

    // ORB-SLAM2's extractor with the settings of its TUM examples (scale 1.2, 8 levels, FAST 20/7).
    ORB_SLAM2::ORBextractor extractor(nFeatures, 1.2f, 8, 20, 7);
    std::vector<std::vector<cv::Mat> > features;
    size_t descriptors = 0;
    for (int i = 2; i < argc; ++i)
    {
        cv::Mat img = cv::imread(argv[i], cv::IMREAD_GRAYSCALE);
        if (img.empty())
        {
            std::cerr << "train_orb_vocabulary: cannot read " << argv[i] << std::endl;
            return 1;
        }
        std::vector<cv::KeyPoint> keypoints;
        cv::Mat d;
        extractor(img, cv::Mat(), keypoints, d);
        if (d.empty()) continue;
        features.push_back(std::vector<cv::Mat>());
        features.back().reserve(d.rows);
        for (int r = 0; r < d.rows; ++r) features.back().push_back(d.row(r));
        descriptors += d.rows;
    }
    if (descriptors < 20000)
    {
        std::cerr << "train_orb_vocabulary: only " << descriptors << " descriptors from " << argc - 2
                  << " images; give more (or more textured) frames" << std::endl;
        return 1;
    }
    std::cout << "train_orb_vocabulary: " << descriptors << " descriptors of " << features.size()
              << " images; k-means tree k=" << k << " L=" << L << " ..." << std::endl;

    DUtils::Random::SeedRandOnce(1);  // DBoW2 would seed k-means++ with the time
    ORB_SLAM2::ORBVocabulary voc(k, L, DBoW2::TF_IDF, DBoW2::L1_NORM);
    voc.create(features);
    voc.saveToTextFile(argv[1]);

    // Read it back the way ORB_SLAM2::System does, and check it transforms a frame.
    ORB_SLAM2::ORBVocabulary check;
    if (!check.loadFromTextFile(argv[1]) || check.size() == 0)
    {
        std::cerr << "train_orb_vocabulary: " << argv[1] << " does not load back" << std::endl;
        return 1;
    }
    DBoW2::BowVector bow;
    DBoW2::FeatureVector fv;
    check.transform(features[0], bow, fv, 4);
    double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cout << "train_orb_vocabulary: " << check.size() << " words (k=" << check.getBranchingFactor()
              << " L=" << check.getDepthLevels() << "), first image -> " << bow.size() << " words in "
              << fv.size() << " groups; " << s << " s -> " << argv[1] << std::endl;
    return bow.empty() ? 1 : 0;
}
