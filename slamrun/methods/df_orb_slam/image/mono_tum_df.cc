// slamrun's offline monocular driver for DF-ORB-SLAM (upstream has monocular only as a ROS node fed at real
// time with a queue of one, which drops frames when slower). Same interface and behaviour as ORB-SLAM2's
// mono_tum, so the two methods are driven alike:
//   mono_tum_df VOCABULARY SETTINGS SEQUENCE_DIR
// reads SEQUENCE_DIR/rgb.txt (three header lines, then "timestamp relative/path" per frame), feeds every frame
// in order, paced like mono_tum (it waits out the timestamp difference when tracking was faster; decreasing
// timestamps never wait), and writes KeyFrameTrajectory.txt (TUM, keyframes, camera-to-world) in the working
// directory. No viewer, no point-cloud mapping. An unreadable frame stops the run (exit 1), as in mono_tum.
// Settings entries `Slamrun.env.NAME: "value"` set the environment variable NAME (the image's switches, read
// with getenv: ORB_SLAM2_NO_LOOP, DF_ORB_SLAM_MONO_POSE) before the system starts, unless NAME is already
// set: the adapter writes its environment there too, so its switches hold however the process is started.
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>
#include <unistd.h>

#include <opencv2/core/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "System.h"

static bool LoadImages(const std::string &dir, std::vector<std::string> &files, std::vector<double> &times)
{
    std::ifstream f((dir + "/rgb.txt").c_str());
    if (!f.good()) return false;
    std::string line;
    for (int i = 0; i < 3 && std::getline(f, line); ++i) {}  // three header lines
    while (std::getline(f, line))
    {
        std::stringstream ss(line);
        double t;
        std::string name;
        if (!(ss >> t >> name)) continue;
        times.push_back(t);
        files.push_back(dir + "/" + name);
    }
    return !files.empty();
}

static void ApplySettingsEnvironment(const std::string &settings)
{
    cv::FileStorage fs(settings, cv::FileStorage::READ);
    if (!fs.isOpened()) return;  // the system reports an unreadable settings file
    const std::string prefix = "Slamrun.env.";
    cv::FileNode root = fs.root();
    for (cv::FileNodeIterator it = root.begin(); it != root.end(); ++it)
    {
        const cv::FileNode node = *it;
        const std::string key = node.name();
        if (key.compare(0, prefix.size(), prefix) != 0 || !node.isString()) continue;
        const std::string name = key.substr(prefix.size()), value = node.string();
        const char *given = getenv(name.c_str());
        if (!given) setenv(name.c_str(), value.c_str(), 0);
        std::cout << "mono_tum_df: " << name << "=" << (given ? given : value.c_str())
                  << (given ? " (environment)" : " (settings)") << std::endl;
    }
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
    const size_t n = files.size();
    std::cout << "mono_tum_df: " << n << " frames" << std::endl;

    ApplySettingsEnvironment(argv[2]);  // before the system's threads start
    // monocular, no viewer, no point-cloud mapping (bMapping keeps its default, false)
    ORB_SLAM2::System SLAM(argv[1], argv[2], ORB_SLAM2::System::MONOCULAR, false);

    std::vector<double> track_s;
    track_s.reserve(n);
    for (size_t i = 0; i < n; ++i)
    {
        cv::Mat im = cv::imread(files[i], cv::IMREAD_UNCHANGED);
        if (im.empty())
        {
            std::cerr << "mono_tum_df: failed to load image " << files[i] << std::endl;
            return 1;
        }
        auto t1 = std::chrono::steady_clock::now();
        SLAM.TrackMonocular(im, times[i]);
        auto t2 = std::chrono::steady_clock::now();
        double ttrack = std::chrono::duration<double>(t2 - t1).count();
        track_s.push_back(ttrack);

        double T = 0;  // pace like mono_tum: wait for the next frame's time
        if (i + 1 < n)
            T = times[i + 1] - times[i];
        else if (i > 0)
            T = times[i] - times[i - 1];
        if (ttrack < T)
            usleep(static_cast<useconds_t>((T - ttrack) * 1e6));
    }

    SLAM.Shutdown();

    std::vector<double> sorted(track_s);
    std::sort(sorted.begin(), sorted.end());
    double total = 0;
    for (double s : track_s) total += s;
    std::cout << "-------" << std::endl
              << "median tracking time: " << sorted[sorted.size() / 2] << std::endl
              << "mean tracking time: " << total / track_s.size() << std::endl;

    SLAM.SaveKeyFrameTrajectoryTUM("KeyFrameTrajectory.txt");
    return 0;
}
