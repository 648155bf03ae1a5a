from setuptools import find_packages, setup

package_name = 'sessgan_evolver'

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
    description='SESS-GAN evolver: GAN population, genetic operators, fitness, '
                'campaigns, failure bags, replay and reports.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'campaign = sessgan_evolver.campaign_cli:main',
            'replay = sessgan_evolver.replay_cli:main',
            'evaluate = sessgan_evolver.evaluate_cli:main',
            'compare = sessgan_evolver.compare_cli:main',
            'suite = sessgan_evolver.suite_cli:main',
        ],
    },
)
