#!/bin/sh
# stage-runtime.sh for an ORB-SLAM2-layout tree (ORB-SLAM2, DF-ORB-SLAM, ORB-SLAM3), after build-orb-slam2.sh and
# orb_vocabulary.sh: the example TARGET, the library (lib/*.so), Thirdparty DBoW2 and g2o (linked by their paths
# in the tree, so they stay there) and Vocabulary/ORBvoc.txt.
# usage: stage-orb-slam2.sh ROOT TARGET
set -eu
root=$1
exec "$(dirname "$0")/stage-runtime.sh" "$root/$2" "$root"/lib/*.so "$root/Thirdparty/DBoW2/lib/libDBoW2.so" \
  "$root/Thirdparty/g2o/lib/libg2o.so" "$root/Vocabulary/ORBvoc.txt"
