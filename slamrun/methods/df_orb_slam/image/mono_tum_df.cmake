# slamrun: the offline monocular driver (upstream has monocular only as the ROS node Examples/ROS/.../ros_mono.cc)
set(CMAKE_RUNTIME_OUTPUT_DIRECTORY ${PROJECT_SOURCE_DIR}/Examples/Monocular)
add_executable(mono_tum_df ${PROJECT_SOURCE_DIR}/Examples/Monocular/mono_tum_df.cc)
target_link_libraries(mono_tum_df ${PROJECT_NAME})
