from glob import glob

from setuptools import find_packages, setup

package_name = 'micro_feeder'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'bench']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    package_data={package_name: ['defaults/*.yaml']},
    python_requires='>=3.10',
    install_requires=[
        'setuptools',
        'numpy>=1.26',
        'scipy>=1.11',
        'numba>=0.59',
        'matplotlib>=3.8',
        'PyYAML>=6',
        'tqdm>=4.60',
        'mcap>=1.2',
        'mcap-ros2-support>=0.5',
        'zstandard>=0.22',
        'foxglove-sdk>=0.30',
    ],
    extras_require={
        'dask': ['dask[distributed]>=2025.1'],
        'test': ['pytest', 'pytest-timeout', 'rosbags', 'ruff', 'hypothesis', 'import-linter',
                 'dask[distributed]>=2025.1'],
    },
    zip_safe=True,
    maintainer='micro_feeder team',
    maintainer_email='micro-feeder@example.com',
    description='Simulator of a piezo-actuated micro-part feeder with rough-surface adhesion and friction.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'micro-feeder = micro_feeder.cli:main',
            'actuator = micro_feeder.nodes.launcher:actuator',
            'simulator = micro_feeder.nodes.launcher:simulator',
            'recorder = micro_feeder.nodes.launcher:recorder',
            'replay = micro_feeder.nodes.launcher:replay',
            'feed_controller = micro_feeder.nodes.launcher:feed_controller',
        ],
    },
)
