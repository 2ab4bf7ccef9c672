from setuptools import find_packages, setup

PACKAGE = "holonomic_analysis"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    # colcon test runs pytest (not unittest) on test/ when pytest is a test dependency
    extras_require={"test": ["pytest"]},
    zip_safe=True,
    maintainer="Holonomic base developers",
    maintainer_email="dev@holonomic.invalid",
    description="Mobility ellipsoid, holonomicity and caster isotropy (holonomic-analyze)",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "holonomic-analyze = holonomic_analysis.cli:main",
        ],
    },
)
