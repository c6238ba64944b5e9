from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'gyro_thermal_comp'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', sorted(glob('config/*.yaml'))),
        ('share/' + PACKAGE + '/launch', sorted(glob('launch/*.launch.py'))),
    ],
    install_requires=['setuptools'],
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
