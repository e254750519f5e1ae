from setuptools import find_packages, setup

package_name = "sds_lateral"

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
    description="The lateral camera: pose, wall profile, clock and the top/side check.",
    license="MIT",
)
