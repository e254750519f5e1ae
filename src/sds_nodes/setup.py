from setuptools import find_packages, setup

package_name = "sds_nodes"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="SDS developers",
    maintainer_email="sds@example.org",
    description="The graph's nodes: thin rclpy wrappers around the SDS algorithm packages.",
    license="MIT",
    entry_points={
        "console_scripts": [
            "frame_source = sds_nodes.frame_source:main",
            "frame_monitor = sds_nodes.frame_monitor:main",
            "tracker = sds_nodes.tracker:main",
            "recon = sds_nodes.reconstruction:main",
            "sloshing = sds_nodes.sloshing:main",
            "recorder = sds_nodes.recorder:main",
            "player = sds_nodes.player:main",
            "arduino_bridge = sds_nodes.arduino_bridge:main",
            "viewer = sds_nodes.viewer:main",
        ],
    },
)
