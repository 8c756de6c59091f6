// slamrun: DF-ORB-SLAM's dense point-cloud mapping compiled out. Upstream's PointCloudMapping
// (src/pointcloudmapping.cpp, src/SLIC.cpp) needs PCL/VTK and ROS (roscpp, tf, pcl_ros publishers) and only
// serves RGB-D: System creates it only when its last argument bMapping is true (default false), and every use
// in Tracking/LoopClosing/System is guarded by `mpPointCloudMapping != NULL`. This header replaces
// "pointcloudmapping.h" with the members those guarded uses name, so the library builds and links with
// neither PCL nor ROS. Constructing it (bMapping = true) stops the program with a message.
#ifndef SLAMRUN_POINTCLOUD_OFF_H
#define SLAMRUN_POINTCLOUD_OFF_H

#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include <opencv2/core/core.hpp>

namespace ORB_SLAM2 { class KeyFrame; }

class PointCloudMapping
{
public:
    PointCloudMapping(const std::string &, bool = true)
    {
        std::cerr << "DF-ORB-SLAM: point-cloud mapping (bMapping=true) is compiled out of this build "
                     "(it needs PCL and ROS)" << std::endl;
        std::abort();
    }
    void save() {}
    void insertKeyFrame(ORB_SLAM2::KeyFrame *, cv::Mat &, cv::Mat &, int, std::vector<ORB_SLAM2::KeyFrame *>, double) {}
    void shutdown() {}
    void updateCloseLoopCloud() {}

    int loopcount = 0;
    bool mbCloudBusy = false;
    bool mbLoopBusy = false;
    bool mbStop = false;
};

#endif  // SLAMRUN_POINTCLOUD_OFF_H
