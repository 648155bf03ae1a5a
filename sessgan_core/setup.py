from setuptools import find_packages, setup

package_name = 'sessgan_core'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'sessgan_core': ['data/maps/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},  # colcon test runs test/ with pytest
    zip_safe=True,
    maintainer='SESS-GAN developers',
    maintainer_email='sessgan@example.org',
    description='SESS-GAN core: scenarios, token maps, environments, valid tests (route '
                'certificates, missions, fleets), map_server files and shared helpers; '
                'no torch.',
    license='Apache-2.0',
)
