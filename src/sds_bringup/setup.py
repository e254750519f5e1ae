from setuptools import find_packages, setup

package_name = "sds_bringup"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["fastdds_profiles.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="SDS developers",
    maintainer_email="sds@example.org",
    description="Launcher of the SDS graph: processes of a graph file, their environment, "
                "the measuring chain with its progress bar.",
    license="MIT",
)
