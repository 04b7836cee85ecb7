"""ros2 launch armfleet_ros armfleet.launch.py url:=http://127.0.0.1:8000 worlds:=0-7"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    args = [
        DeclareLaunchArgument("url", default_value="http://127.0.0.1:8000"),
        DeclareLaunchArgument("worlds", default_value="", description="e.g. 0-7 (world 0: root)"),
        DeclareLaunchArgument("rate", default_value="60.0"),
    ]
    node = Node(
        package="armfleet_ros",
        executable="armfleet_node",
        name="armfleet",
        output="screen",
        parameters=[
            {
                "url": LaunchConfiguration("url"),
                "worlds": LaunchConfiguration("worlds"),
                "rate": LaunchConfiguration("rate"),
            }
        ],
    )
    return LaunchDescription([*args, node])
