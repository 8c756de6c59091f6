// slamrun: train a small DBoW3 vocabulary for LDSO when its source lacks vocab/orbvoc.dbow3.
// ORB descriptors (cv::ORB, 32 bytes, the layout of LDSO's own extractor) of every image given, then a
// k-means tree (k = 10, L = 5: LDSO's transform() uses 4 levels up), TF-IDF weighting, L1 scoring, saved in
// DBoW3's binary format. Not the authors' vocabulary: loop-closure results made with it are not the study's.
//   train_vocabulary OUT.dbow3 IMAGE...
#include "DBoW3/src/DBoW3.h"

#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

int main(int argc, char **argv)
{
    if (argc < 3)
    {
        std::cerr << "usage: train_vocabulary OUT.dbow3 IMAGE..." << std::endl;
        return 2;
    }
    cv::Ptr<cv::ORB> orb = cv::ORB::create(1000);
    std::vector<cv::Mat> features;
    size_t descriptors = 0;
    for (int i = 2; i < argc; ++i)
    {
        cv::Mat img = cv::imread(argv[i], cv::IMREAD_GRAYSCALE);
        if (img.empty())
        {
            std::cerr << "train_vocabulary: cannot read " << argv[i] << std::endl;
            return 1;
        }
        std::vector<cv::KeyPoint> keypoints;
        cv::Mat d;
        orb->detectAndCompute(img, cv::noArray(), keypoints, d);
        if (!d.empty())
        {
            features.push_back(d);
            descriptors += d.rows;
        }
    }
    if (descriptors < 1000)
    {
        std::cerr << "train_vocabulary: only " << descriptors << " descriptors; give more textured images" << std::endl;
        return 1;
    }
    DBoW3::Vocabulary voc(10, 5, DBoW3::TF_IDF, DBoW3::L1_NORM);
    voc.create(features);
    voc.save(argv[1]);
    DBoW3::Vocabulary check;
    check.load(argv[1]);
    std::cout << "train_vocabulary: " << check.size() << " words from " << descriptors << " descriptors of "
              << features.size() << " images -> " << argv[1] << std::endl;
    return check.size() > 0 ? 0 : 1;
}
