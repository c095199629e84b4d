# Included by tools/build_interfaces.sh right after project() (CMAKE_PROJECT_INCLUDE): generate only what
# rclpy needs (C, its type supports, Python), not the C++ code that no one in the venv links against: about
# 60 % less to compile. The generators register themselves when found; finding them here first (their
# configs guard against a second inclusion) lets this drop the C++ ones before rosidl_generate_interfaces.
find_package(rosidl_default_generators REQUIRED)
list(FILTER AMENT_EXTENSIONS_rosidl_generate_idl_interfaces EXCLUDE REGEX "_cpp:")
message(STATUS "micro_feeder: C and Python only: ${AMENT_EXTENSIONS_rosidl_generate_idl_interfaces}")
