from setuptools import find_packages, setup

package_name = 'sessgan_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', ['config/nav2_params.yaml']),
        ('share/' + package_name + '/launch', ['launch/nav2_worker.launch.py']),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},  # colcon test runs test/ with pytest
    zip_safe=True,
    maintainer='SESS-GAN developers',
    maintainer_email='sessgan@example.org',
    description='SESS-GAN simulator worker: pybullet world builder, robots, sensors, '
                'episode metrics and the simulator node.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'simulator = sessgan_sim.simulator_node:main',
        ],
    },
)
