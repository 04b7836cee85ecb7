"""armfleet_ros: a colcon (ament_python) package and a pip distribution at once.

colcon build --packages-select armfleet_ros      # in a workspace: src/armfleet_ros -> here
python3 -m pip install ./packaging/armfleet-client ./packaging/armfleet-ros
"""

from setuptools import setup

PACKAGE = "armfleet_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=[PACKAGE],
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", ["launch/armfleet.launch.py"]),
    ],
    python_requires=">=3.10",
    install_requires=["armfleet-client"],
    zip_safe=True,
    description="armfleet's worlds as a ROS 2 node over armfleet's HTTP/WebSocket API",
    license="Apache-2.0",
    entry_points={"console_scripts": [f"armfleet_node = {PACKAGE}.node:main"]},
)
