"""ament_python package setup for ssm_localization."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'ssm_localization'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'ssm_localization.config': ['*.json']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml', 'README.md']),
        ('share/' + PACKAGE + '/config', glob('config/*.yaml')),
        ('share/' + PACKAGE + '/config/examples', glob('config/examples/*.yaml')),
        ('share/' + PACKAGE + '/launch', glob('launch/*.launch.py')),
        ('share/' + PACKAGE + '/rviz', glob('rviz/*.rviz')),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'numba', 'pyyaml', 'pillow', 'tqdm',
                      'rosbags'],
    # mcap: salvaging the readable part of a damaged bag (no rosdep key exists for it)
    extras_require={'plot': ['matplotlib'], 'salvage': ['mcap'], 'test': ['pytest']},
    zip_safe=True,
    maintainer='ssm_localization maintainers',
    maintainer_email='maintainers@ssm-localization.invalid',
    description='Single-scan global localization with spectral scan matching (Park & Park).',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            # through entry_points.py: one BLAS thread is set before numpy loads
            'ssm_localization = ssm_localization.entry_points:ssm_localization',
            'map_indexer = ssm_localization.entry_points:map_indexer',
            'global_localizer = ssm_localization.entry_points:global_localizer',
        ],
    },
)
