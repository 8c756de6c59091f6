"""ORB-SLAM3 (UZ-SLAMLab/ORB_SLAM3 v1.0 @ 4452a3c) on Debian 12 (gcc 12, OpenCV 4.6, Eigen 3.4, Pangolin v0.6):
mono_tum without viewer, every frame's pose written per map of the Atlas, loop closure switchable without its
upstream defect, and the toolchain fixes. Every edit is anchored: an upstream change fails the build naming the
file and the anchor.

usage: patches.py ROOT [TRAINER_DIR]
TRAINER_DIR holds a copy of ORB-SLAM2's train_orb_vocabulary.cc, adapted here to ORB-SLAM3's names."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "recipes", "common"))  # in slamrun's tree
from families import drop_after  # noqa: E402
from patchlib import cxx_standard, include_once, patch, sub  # noqa: E402

# ------------------------------------------------------------------------------------------------ trajectory

SAVE_DECL = """
    // slamrun: every tracked frame's pose, one TUM file per map of the Atlas (PREFIX.map<ID>.txt), then the
    // index PREFIX.maps.txt ("map_id frames keyframes" per line), written last.
    void SaveFrameTrajectoryMaps(const string &prefix);
"""

SAVE_DEF = r"""
// slamrun: SaveTrajectoryTUM refuses monocular, and SaveTrajectoryEuRoC keeps only the largest map. This writes
// every frame whose tracking succeeded (Tracking.cc marks the others lost) in the world of the map its reference
// keyframe belongs to: one TUM file per map (timestamp tx ty tz qx qy qz qw, camera to world, the timestamps
// of rgb.txt), and last the index of the maps. Frames of a map reset after an early loss (keyframes without a
// map) have no pose.
void System::SaveFrameTrajectoryMaps(const string &prefix)
{
    // Shutdown() does not wait for the mapping threads: let them end before reading the keyframes (bounded)
    for(int waited = 0; waited < 120000 && (!mpLocalMapper->isFinished() || !mpLoopCloser->isFinished() ||
        mpLoopCloser->isRunningGBA()); waited += 5)
        usleep(5000);

    std::map<unsigned long, std::vector<std::string> > rows;
    std::map<unsigned long, unsigned long> keyframes;
    list<KeyFrame*>::iterator lRit = mpTracker->mlpReferences.begin();
    list<double>::iterator lT = mpTracker->mlFrameTimes.begin();
    list<bool>::iterator lbL = mpTracker->mlbLost.begin();
    for(list<Sophus::SE3f>::iterator lit=mpTracker->mlRelativeFramePoses.begin(),
        lend=mpTracker->mlRelativeFramePoses.end(); lit!=lend; lit++, lRit++, lT++, lbL++)
    {
        if(*lbL)
            continue;
        KeyFrame* pKF = *lRit;
        Sophus::SE3f Trw;
        while(pKF && pKF->isBad())  // a culled reference keyframe: go up the spanning tree
        {
            Trw = Trw * pKF->mTcp;
            pKF = pKF->GetParent();
        }
        if(!pKF)
            continue;
        Map* pMap = pKF->GetMap();
        if(!pMap || pMap->IsBad())
            continue;
        Trw = Trw * pKF->GetPose();
        Sophus::SE3f Twc = ((*lit) * Trw).inverse();
        Eigen::Vector3f t = Twc.translation();
        Eigen::Quaternionf q = Twc.unit_quaternion();
        std::ostringstream line;
        line << fixed << setprecision(6) << *lT << " " << setprecision(9) << t(0) << " " << t(1) << " " << t(2)
             << " " << q.x() << " " << q.y() << " " << q.z() << " " << q.w();
        rows[pMap->GetId()].push_back(line.str());
        keyframes[pMap->GetId()] = pMap->KeyFramesInMap();
    }
    cout << "slamrun: " << rows.size() << " map(s) with frame poses:";
    for(auto &m : rows)
    {
        ofstream f((prefix + ".map" + to_string(m.first) + ".txt").c_str());
        for(const std::string &r : m.second)
            f << r << "\n";
        f.close();
        cout << " map " << m.first << " (" << m.second.size() << " frames, " << keyframes[m.first] << " keyframes)";
    }
    cout << endl;
    ofstream index((prefix + ".maps.txt").c_str());
    index << "# map_id frames keyframes\n";
    for(auto &m : rows)
        index << m.first << " " << m.second.size() << " " << keyframes[m.first] << "\n";
    index.close();
}
"""

# ------------------------------------------------------------------------------------------- loop closure

# Upstream's own switch (the settings' `loopClosing: 0`) returns before taking the keyframe off the queue: the
# queue grows, the loop thread spins on it and no keyframe reaches the recognition database, so relocalisation
# finds none. Switched off, each keyframe now goes to the database and no loop or map merge is searched
# (ORB-SLAM2's switch in slamrun/methods/recipes/common/families.py does the same).
LOOP_OFF = """    if(!mbActiveLC)
    {
        // slamrun: loop closure and map merging off; the keyframe still serves relocalisation
        unique_lock<mutex> lock(mMutexLoopQueue);
        mpCurrentKF = mlpLoopKeyFrameQueue.front();
        mlpLoopKeyFrameQueue.pop_front();
        mpKeyFrameDB->add(mpCurrentKF);
        return false;
    }
"""

# ---------------------------------------------------------------------------------------------- trainer

def adapt_trainer(folder):
    """ORB-SLAM2's vocabulary trainer (slamrun/methods/recipes/orb_vocabulary/train_orb_vocabulary.cc, copied into `folder`) for
    ORB-SLAM3's tree: its namespace, and the extractor's lapping-area argument ({0, 1000}: Frame.cc's monocular
    value, the whole image)."""
    n = sub(folder, "train_orb_vocabulary.cc", r"\bORB_SLAM2::", "ORB_SLAM3::", min_count=6)
    if n != 6:
        sys.exit("patch: train_orb_vocabulary.cc: ORB_SLAM2:: found %d times, expected 6" % n)
    patch(folder, "train_orb_vocabulary.cc", "replace", "extractor(img, cv::Mat(), keypoints, d);",
          "std::vector<int> lapping = {0, 1000};  // slamrun: ORB-SLAM3's monocular Frame\n"
          "        extractor(img, cv::Mat(), keypoints, d, lapping);")


def orb_slam3(root):
    """The edits of ORB-SLAM3's tree."""
    # Headless: the viewer flag is hard-coded on in mono_tum.cc.
    patch(root, "Examples/Monocular/mono_tum.cc", "replace",
          "ORB_SLAM3::System SLAM(argv[1],argv[2],ORB_SLAM3::System::MONOCULAR,true);",
          "ORB_SLAM3::System SLAM(argv[1],argv[2],ORB_SLAM3::System::MONOCULAR,false);  // slamrun: no viewer")
    # Every frame's pose (SaveTrajectoryTUM refuses monocular), beside upstream's keyframe file.
    patch(root, "Examples/Monocular/mono_tum.cc", "after", 'SLAM.SaveKeyFrameTrajectoryTUM("KeyFrameTrajectory.txt");',
          '\n    SLAM.SaveFrameTrajectoryMaps("FrameTrajectory");  // slamrun')
    patch(root, "include/System.h", "after", "void SaveKeyFrameTrajectoryTUM(const string &filename);\n", SAVE_DECL)
    patch(root, "src/System.cc", "before", "} //namespace ORB_SLAM\n", SAVE_DEF + "\n")
    for header in ("map", "sstream", "vector"):
        include_once(root, "src/System.cc", header)
    # A frame whose tracking failed (RECENTLY_LOST: a failed relocalisation's or the motion model's guess, or a
    # copy of the previous frame's pose and time) is stored as lost, so no pose is invented for it.
    n = sub(root, "src/Tracking.cc", r"mlbLost\.push_back\(mState==LOST\);",
            "mlbLost.push_back(mState!=OK);  // slamrun: only tracked frames have a pose", min_count=2)
    if n != 2:
        sys.exit("patch: src/Tracking.cc: mlbLost.push_back(mState==LOST) found %d times, expected 2" % n)
    patch(root, "src/LoopClosing.cc", "replace", "    if(!mbActiveLC)\n        return false;\n", LOOP_OFF)
    # Toolchain: C++14 (Eigen 3.4 and Boost 1.74 headers; COMPILEDWITHC11 stays defined: steady_clock), and
    # <stdint.h> rather than gcc's internal <stdint-gcc.h>.
    cxx_standard(root, "CMakeLists.txt", "-std=c++11")
    # The CMakeLists ends with Examples_old/'s targets, a folder the stored archive lacks (CMake refuses a target
    # without sources even when it is never built): cut there; none of them is the monocular example.
    drop_after(root, "CMakeLists.txt", "#Old examples")
    patch(root, "src/ORBmatcher.cc", "replace", "#include<stdint-gcc.h>", "#include<stdint.h>")


if __name__ == "__main__":
    orb_slam3(sys.argv[1])
    if len(sys.argv) > 2:
        adapt_trainer(sys.argv[2])
