from setuptools import find_packages, setup

package_name = "sds_cli"

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
    description="The `sds` command: one thin module per subcommand over sds_workflows and the "
                "launcher.",
    license="MIT",
    entry_points={"console_scripts": ["sds = sds_cli.cli:main"]},
)
