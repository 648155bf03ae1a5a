from setuptools import find_packages, setup

package_name = 'sessgan_controllers'
# One executable per registered controller (sessgan_controllers.registry), all running the same
# node: the executable's name selects the controller.
controllers = ('nearness_diagram', 'velocity_projection', 'race_controller',
               'reference_navigator', 'tricycle_nearness_diagram')

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},  # colcon test runs test/ with pytest
    zip_safe=True,
    maintainer='SESS-GAN developers',
    maintainer_email='sessgan@example.org',
    description=('Robot-under-test controllers for SESS-GAN, each its own node speaking only the '
                 'robot-under-test topics (scan, odom, goal_pose, map; cmd_vel).'),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            f'{name} = sessgan_controllers.controller_node:main' for name in controllers
        ],
    },
)
