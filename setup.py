from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = 'gyro_thermal_comp'
HERE = Path(__file__).resolve().parent


def requirements(name: str) -> list[str]:
    """The requirement lines of a requirements file, with the files it includes (-r)."""
    out = []
    for line in (HERE / name).read_text().splitlines():
        line = line.split('#', 1)[0].strip()
        if line.startswith('-r '):
            out += requirements(line[3:].strip())
        elif line:
            out.append(line)
    return out


setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml', 'LICENSE']),
        ('share/' + PACKAGE + '/config', sorted(glob('config/*.yaml'))),
        ('share/' + PACKAGE + '/config/import', sorted(glob('config/import/*.yaml'))),
        ('share/' + PACKAGE + '/launch', sorted(glob('launch/*.launch.py'))),
    ],
    install_requires=['setuptools'],   # ROS builds take the dependencies from package.xml (rosdep)
    # pip: .[robot] what the nodes import beyond ROS itself; .[tools] that plus the offline tools
    extras_require={'robot': requirements('requirements-robot.txt'), 'tools': requirements('requirements-tools.txt')},
    zip_safe=True,
    maintainer='gyro_thermal_comp maintainers',
    description='MEMS gyro thermal drift compensation (STKF), carousel demodulation, ROS 2 nodes',
    license='Apache-2.0',
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'gyro-thermal-comp = gyro_thermal_comp.cli:main',
            'stkf_node = gyro_thermal_comp.nodes.stkf_node:main',
            'carousel_node = gyro_thermal_comp.nodes.carousel_node:main',
        ],
    },
)
