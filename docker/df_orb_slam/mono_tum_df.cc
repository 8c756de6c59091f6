// slamrun's offline monocular driver for DF-ORB-SLAM (upstream has monocular only as a ROS node fed at
// real time with a queue of one). Same interface as ORB-SLAM2's mono_tum:
//   mono_tum_df VOCABULARY SETTINGS SEQUENCE_DIR   (reads SEQUENCE_DIR/rgb.txt, writes KeyFrameTrajectory.txt)
// Frames are fed one after the other without dropping any; an empty image is skipped with a message
// instead of being tracked (the empty-image fix).
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>
#include <unistd.h>

#include <opencv2/core/core.hpp>
#include <opencv2/highgui/highgui.hpp>

#include "System.h"

static bool LoadImages(const std::string &dir, std::vector<std::string> &files, std::vector<double> &times)
{
    std::ifstream f((dir + "/rgb.txt").c_str());
    if (!f.good()) return false;
    std::string line;
    for (int i = 0; i < 3 && std::getline(f, line); ++i) {}  // three header lines
    while (std::getline(f, line))
    {
        if (line.empty()) continue;
        std::stringstream ss(line);
        double t; std::string name;
        ss >> t >> name;
        times.push_back(t);
        files.push_back(dir + "/" + name);
    }
    return !files.empty();
}

int main(int argc, char **argv)
{
    if (argc != 4)
    {
        std::cerr << "usage: mono_tum_df VOCABULARY SETTINGS SEQUENCE_DIR" << std::endl;
        return 1;
    }
    std::vector<std::string> files;
    std::vector<double> times;
    if (!LoadImages(argv[3], files, times))
    {
        std::cerr << "mono_tum_df: no frames in " << argv[3] << "/rgb.txt" << std::endl;
        return 1;
    }
    ORB_SLAM2::System SLAM(argv[1], argv[2], ORB_SLAM2::System::MONOCULAR, false);
    int skipped = 0;
    for (size_t i = 0; i < files.size(); ++i)
    {
        cv::Mat im = cv::imread(files[i], CV_LOAD_IMAGE_UNCHANGED);
        if (im.empty())
        {
            std::cerr << "mono_tum_df: empty image " << files[i] << ", skipped" << std::endl;
            ++skipped;
            continue;
        }
        SLAM.TrackMonocular(im, times[i]);
    }
    SLAM.Shutdown();
    SLAM.SaveKeyFrameTrajectoryTUM("KeyFrameTrajectory.txt");
    std::cout << "mono_tum_df: " << files.size() - skipped << " frames fed, " << skipped << " skipped" << std::endl;
    return 0;
}
