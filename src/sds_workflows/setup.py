from setuptools import find_packages, setup

package_name = "sds_workflows"

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
    description="The jobs of SDS: offline processing and export (one per-frame pipeline), the "
                "demo, the calibration workflows, the clock link, the analysis of a recording.",
    license="MIT",
)
