// slamrun's headless DSM driver: upstream's examples are Qt GUIs that process frames only after "Play"
// and never save a trajectory. This constructs dsm::FullSystem without a visualiser, feeds the
// (already undistorted) frames with their timestamps, then writes every keyframe pose as TUM.
//   dsm_headless CALIB.yaml SETTINGS.yaml IMAGE_DIR TIMES OUT
// CALIB: OpenCV YAML with Camera.fx fy cx cy width height (rectified pinhole, zero distortion).
// TIMES: `id timestamp [exposure]` per frame, in the order of the sorted image names.
#include <algorithm>
#include <cstdio>
#include <dirent.h>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "FullSystem/FullSystem.h"
#include "Utils/Settings.h"

static std::vector<std::string> listImages(const std::string &dir)
{
    std::vector<std::string> names;
    DIR *d = opendir(dir.c_str());
    if (!d) return names;
    while (dirent *e = readdir(d))
    {
        std::string n = e->d_name;
        if (n.size() > 4 && n[0] != '.') names.push_back(dir + "/" + n);
    }
    closedir(d);
    std::sort(names.begin(), names.end());
    return names;
}

int main(int argc, char **argv)
{
    if (argc != 6)
    {
        std::cerr << "usage: dsm_headless CALIB SETTINGS IMAGE_DIR TIMES OUT" << std::endl;
        return 1;
    }
    cv::FileStorage calib(argv[1], cv::FileStorage::READ);
    if (!calib.isOpened())
    {
        std::cerr << "dsm_headless: cannot read " << argv[1] << std::endl;
        return 1;
    }
    const int w = (int)calib["Camera.width"], h = (int)calib["Camera.height"];
    Eigen::Matrix3f K = Eigen::Matrix3f::Identity();
    K(0, 0) = (float)calib["Camera.fx"]; K(1, 1) = (float)calib["Camera.fy"];
    K(0, 2) = (float)calib["Camera.cx"]; K(1, 2) = (float)calib["Camera.cy"];

    std::vector<std::string> images = listImages(argv[3]);
    std::vector<double> times;
    std::ifstream tf(argv[4]);
    std::string line;
    while (std::getline(tf, line))
    {
        std::istringstream ss(line);
        std::string id; double t;
        if (ss >> id >> t) times.push_back(t);
    }
    if (images.empty() || images.size() != times.size())
    {
        std::cerr << "dsm_headless: " << images.size() << " images but " << times.size() << " timestamps" << std::endl;
        return 1;
    }
    dsm::FullSystem system(w, h, K, argv[2], nullptr);
    // With singleThreaded = false, frames are mapped asynchronously (and dropped when the queue grows) and
    // getTrajectory() is not synchronised with the mapping thread; DSM's wait is private, so block after
    // every frame: when the loop ends (or tracking is lost) the mapping thread is idle.
    dsm::Settings &settings = dsm::Settings::getInstance();
    if (!settings.singleThreaded) settings.blockUntilMapped = true;
    for (size_t i = 0; i < images.size(); ++i)
    {
        cv::Mat img = cv::imread(images[i], cv::IMREAD_GRAYSCALE);
        if (img.empty() || img.cols != w || img.rows != h)
        {
            std::cerr << "dsm_headless: " << images[i] << " unreadable or not " << w << "x" << h << std::endl;
            return 1;
        }
        system.trackFrame((int)i, times[i], img.data);
        if (system.isLost())
        {
            std::cout << "dsm_headless: tracking lost at frame " << i << std::endl;
            break;
        }
    }
    if (!system.isInitialized()) std::cout << "dsm_headless: not initialized" << std::endl;
    std::vector<Eigen::Matrix4f> poses;
    std::vector<double> stamps;
    system.getTrajectory(poses, stamps);
    std::ofstream out(argv[5]);
    out << std::setprecision(15);
    for (size_t i = 0; i < poses.size(); ++i)
    {
        const Eigen::Matrix4f &T = poses[i];  // camera-to-world
        Eigen::Quaternionf q(T.block<3, 3>(0, 0));
        q.normalize();
        out << stamps[i] << " " << T(0, 3) << " " << T(1, 3) << " " << T(2, 3) << " " << q.x() << " " << q.y()
            << " " << q.z() << " " << q.w() << "\n";
    }
    std::cout << "dsm_headless: " << poses.size() << " keyframe poses written" << std::endl;
    return 0;
}
