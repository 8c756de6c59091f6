// slamrun: LSD-SLAM's IOWrapper/ImageDisplay.h without a display, in place of
// IOWrapper/OpenCV/ImageDisplay_OpenCV.cpp (a display thread with OpenCV's highgui windows). The offline driver
// runs headless: no window is opened, no key is ever pressed (waitKey returns 0, which handleKey ignores), so
// neither X11 nor Xvfb is needed.
#include "IOWrapper/ImageDisplay.h"

namespace lsd_slam {
namespace Util {

void displayImage(const char*, const cv::Mat&, bool) {}

int waitKey(int) { return 0; }

int waitKeyNoConsume(int) { return 0; }

void closeAllWindows() {}

}  // namespace Util
}  // namespace lsd_slam
