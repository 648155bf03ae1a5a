from setuptools import find_packages, setup

package_name = 'sessgan_controllers'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='SESS-GAN developers',
    maintainer_email='sessgan@example.org',
    description=('Robot-under-test controllers for SESS-GAN, each its own node speaking only the '
                 'robot-under-test topics (scan, odom, goal_pose, map; cmd_vel).'),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'nearness_diagram = sessgan_controllers.nearness_diagram_node:main',
            'velocity_projection = sessgan_controllers.velocity_projection_node:main',
            'race_controller = sessgan_controllers.race_controller_node:main',
            'reference_navigator = sessgan_controllers.reference_navigator_node:main',
        ],
    },
)
