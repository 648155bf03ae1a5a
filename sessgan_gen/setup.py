from setuptools import find_packages, setup

package_name = 'sessgan_gen'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'sessgan_gen': ['data/checkpoints/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},  # colcon test runs test/ with pytest
    zip_safe=True,
    maintainer='SESS-GAN developers',
    maintainer_email='sessgan@example.org',
    description='SESS-GAN generator: token maps, scenarios, the single-shot tokenized '
                'GAN (TOAD-GAN pyramid), environment metrics and the generator node.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'generator = sessgan_gen.generator_node:main',
            'train = sessgan_gen.train_cli:main',
            'report = sessgan_gen.report_cli:main',
            'export = sessgan_gen.export_cli:main',
        ],
    },
)
