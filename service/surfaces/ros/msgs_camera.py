"""The ROS 2 camera messages armfleet publishes: sensor_msgs/Image and sensor_msgs/CameraInfo.

Their .msg fields (ROS 2 Humble and later), made into DDS types by idl.py like msgs.py's;
tests/test_camera_ros.py checks the bytes against rosbags' definitions and an rclpy node.
"""

from service.surfaces.ros import msgs  # noqa: F401 - declares std_msgs/Header used below
from service.surfaces.ros.idl import message

# An uncompressed image: rows top to bottom, `step` bytes a row; armfleet sends `rgb8`.
Image = message(
    "sensor_msgs/msg/Image",
    """
    std_msgs/Header header
    uint32 height
    uint32 width
    string encoding
    uint8 is_bigendian
    uint32 step
    uint8[] data
    """,
)

# The part of the image the calibration is for (all zero: the whole image).
RegionOfInterest = message(
    "sensor_msgs/msg/RegionOfInterest",
    "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify",
)

# Pinhole calibration: K (3x3), R (3x3), P (3x4) row-major; D for `distortion_model`.
CameraInfo = message(
    "sensor_msgs/msg/CameraInfo",
    """
    std_msgs/Header header
    uint32 height
    uint32 width
    string distortion_model
    float64[] d
    float64[9] k
    float64[9] r
    float64[12] p
    uint32 binning_x
    uint32 binning_y
    sensor_msgs/RegionOfInterest roi
    """,
)
